"""Mill geometries of the bead DEM and bead placement (pure Python/numpy, no numba).

Coordinates: the mill axis is z; the stirrer rotates about +z. The simulated cell is
axially periodic with period ``height_m`` and, optionally, an angular sector
[0, sector_deg) with rotational periodicity (only for sectors of 360/k degrees, k >= 4,
so that a sector is convex and no narrower than a right angle).

- ``annulus``: beads between a rotating shaft and a fixed chamber wall, no discs.
- ``disc_slice``: the PM-1 slice of seed 001 (section 2.1): shaft 15 mm, one full disc of
  radius 36 mm and thickness 8 mm centred at z = 0, chamber 45 mm, axial period
  D + b = 28 mm (disc spacing D = 20 mm between disc faces).
- ``accelerator_slice``: a rotor with a channel (:mod:`millfmu.dem.mills.accelerator`): the disc's
  slab becomes two shrouds (``eye_radius_m`` ... disc radius) around a channel of height
  ``channel_height_m`` that holds ``vane_count`` radial vanes from the shaft to the rim.

Stationary baffles (an option of any slice with a rotor; pin-mill style counter-elements):
``baffle_count`` radial plates over the full circle, fixed to the chamber wall, of
thickness ``baffle_thickness_m``, reaching from the chamber wall in to
``baffle_inner_radius_m``, in the gap between two rotors: axially centred on the mid-plane
between them (z_disc + height / 2) with height ``baffle_height_m``. The first baffle lies
at ``baffle_angle_deg``. They slow the liquid's and the beads' swirl between the rotors
(the return leg of an accelerator rotor's circulation).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np


class GeometryError(ValueError):
    """A geometry or placement request that cannot be met."""


@dataclass(frozen=True)
class MillGeometry:
    """Geometry of the simulated cell [m, degrees]."""

    shaft_radius_m: float
    chamber_radius_m: float
    height_m: float  # axial period
    disc_radius_m: float = 0.0  # 0: no disc
    disc_thickness_m: float = 0.0
    disc_z_m: float = 0.0  # axial position of the disc mid-plane
    sector_deg: float = 360.0
    # rotor with a channel (accelerator rotors); all 0: a solid disc
    eye_radius_m: float = 0.0  # inner radius of the shrouds (the channel's inlet) [m]
    channel_height_m: float = 0.0  # axial height of the channel between the shrouds [m]
    vane_count: int = 0  # radial vanes in the channel over the full circle
    vane_thickness_m: float = 0.0
    # stationary baffles on the chamber wall between the rotors; 0: none
    baffle_count: int = 0  # radial plates over the full circle
    baffle_thickness_m: float = 0.0
    baffle_inner_radius_m: float = 0.0  # the plates reach from the chamber wall to here [m]
    baffle_height_m: float = 0.0  # axial height, centred between two rotors [m]
    baffle_angle_deg: float = 0.0  # angle of the first baffle [degrees]

    def __post_init__(self):
        if not 0.0 < self.shaft_radius_m < self.chamber_radius_m:
            raise GeometryError(
                f"shaft_radius_m = {self.shaft_radius_m!r} and chamber_radius_m = "
                f"{self.chamber_radius_m!r}: need 0 < shaft radius < chamber radius")
        if self.height_m <= 0.0:
            raise GeometryError(f"height_m = {self.height_m!r}: must be > 0")
        if self.disc_radius_m:
            if not self.shaft_radius_m < self.disc_radius_m < self.chamber_radius_m:
                raise GeometryError(
                    f"disc_radius_m = {self.disc_radius_m!r}: must lie between the shaft "
                    f"({self.shaft_radius_m}) and the chamber ({self.chamber_radius_m}) radius")
            if not 0.0 < self.disc_thickness_m < self.height_m:
                raise GeometryError(
                    f"disc_thickness_m = {self.disc_thickness_m!r}: must be > 0 and below "
                    f"the axial period {self.height_m}")
        if self.channel_height_m:
            if not self.has_disc or not 0.0 < self.channel_height_m < self.disc_thickness_m:
                raise GeometryError(
                    f"channel_height_m = {self.channel_height_m!r}: needs a rotor and must lie "
                    f"between 0 and its thickness {self.disc_thickness_m}")
            if not self.shaft_radius_m < self.eye_radius_m < self.disc_radius_m:
                raise GeometryError(
                    f"eye_radius_m = {self.eye_radius_m!r}: must lie between the shaft "
                    f"({self.shaft_radius_m}) and the rotor ({self.disc_radius_m}) radius")
        if self.vane_count:
            if not self.channel_height_m or self.vane_count < 1:
                raise GeometryError(f"vane_count = {self.vane_count!r}: vanes need a channel "
                                    f"(channel_height_m > 0) and a count >= 1")
            self._check_plates("vane", self.vane_count, self.vane_thickness_m,
                               self.shaft_radius_m, "at the shaft")
        if self.baffle_count:
            self._check_baffles()
        k = 360.0 / self.sector_deg if self.sector_deg > 0 else 0.0
        if self.sector_deg != 360.0 and (k < 4.0 - 1e-9 or abs(k - round(k)) > 1e-9):
            raise GeometryError(
                f"sector_deg = {self.sector_deg!r}: allowed are 360 or 360/k for an integer "
                f"k >= 4 (90, 72, 60, 45, 40, 36, 30, ...)")

    def _check_baffles(self):
        if self.baffle_count < 1 or not self.has_disc:
            raise GeometryError(f"baffle_count = {self.baffle_count!r}: baffles sit between "
                                f"two rotors, so they need a rotor (disc) and a count >= 1")
        if not self.shaft_radius_m < self.baffle_inner_radius_m < self.chamber_radius_m:
            raise GeometryError(
                f"baffle_inner_radius_m = {self.baffle_inner_radius_m!r}: must lie between the "
                f"shaft ({self.shaft_radius_m}) and the chamber ({self.chamber_radius_m}) radius")
        gap = self.height_m - self.disc_thickness_m
        if not 0.0 < self.baffle_height_m < gap:
            raise GeometryError(
                f"baffle_height_m = {self.baffle_height_m!r}: must be > 0 and below the gap "
                f"between two rotors ({gap:.4g} m), so that the rotors pass the baffles")
        self._check_plates("baffle", self.baffle_count, self.baffle_thickness_m,
                           self.baffle_inner_radius_m, "at their inner radius")

    def _check_plates(self, name: str, count: int, thickness_m: float, radius_m: float,
                      where: str):
        """A row of ``count`` radial plates: thinner than half their pitch at ``radius_m``
        (their innermost), and a whole number of pitches in the sector (periodic)."""
        pitch = 2.0 * math.pi * radius_m / count
        if not 0.0 < thickness_m < 0.5 * pitch:
            raise GeometryError(
                f"{name}_thickness_m = {thickness_m!r}: must be > 0 and below half the {name} "
                f"pitch {where} ({0.5 * pitch:.3g} m)")
        per = count * self.sector_deg / 360.0
        if abs(per - round(per)) > 1e-9:
            raise GeometryError(
                f"sector_deg = {self.sector_deg!r}: must hold a whole number of {name} "
                f"pitches (360 / {count} degrees) to be periodic")

    @property
    def has_baffles(self) -> bool:
        return self.baffle_count > 0

    @property
    def has_disc(self) -> bool:
        return self.disc_radius_m > 0.0

    @property
    def has_channel(self) -> bool:
        return self.channel_height_m > 0.0

    @property
    def sector_fraction(self) -> float:
        """Simulated part of the full circle [-]."""
        return self.sector_deg / 360.0

    @property
    def sector_rad(self) -> float:
        """Sector angle [rad], 0 for the full circle (the kernels' convention)."""
        return 0.0 if self.sector_deg == 360.0 else math.radians(self.sector_deg)

    def free_volume_m3(self) -> float:
        """Volume open to beads and fluid in the simulated cell [m3]."""
        v = math.pi * (self.chamber_radius_m ** 2 - self.shaft_radius_m ** 2) * self.height_m
        return (v - self.rotor_volume_m3() - self.baffle_volume_m3()) * self.sector_fraction

    def baffle_volume_m3(self) -> float:
        """Solid volume of the baffles over the full circle [m3]: plates of constant
        thickness along their mid-line from the inner radius to the chamber wall (the
        corners cut by the curved wall, under 0.2 % of a 2 mm plate at 30 mm, are not
        taken off)."""
        return self.baffle_count * self.baffle_thickness_m * self.baffle_height_m * \
            (self.chamber_radius_m - self.baffle_inner_radius_m)

    def rotor_volume_m3(self) -> float:
        """Solid volume of the disc, or of the shrouds and vanes, over the full circle [m3]."""
        if not self.has_disc:
            return 0.0
        if not self.has_channel:
            return math.pi * (self.disc_radius_m ** 2 - self.shaft_radius_m ** 2) * \
                self.disc_thickness_m
        v = math.pi * (self.disc_radius_m ** 2 - self.eye_radius_m ** 2) * \
            (self.disc_thickness_m - self.channel_height_m)
        v += self.vane_count * self.vane_thickness_m * \
            (self.disc_radius_m - self.shaft_radius_m) * self.channel_height_m
        return v

    def inside(self, p: np.ndarray, radius_m: float) -> np.ndarray:
        """True where a bead of radius_m [m] centred at p [m] (n, 3) overlaps no wall and
        lies in the sector."""
        r = np.hypot(p[:, 0], p[:, 1])
        ok = (r >= self.shaft_radius_m + radius_m) & (r <= self.chamber_radius_m - radius_m)
        if self.has_disc:
            zr = p[:, 2] - self.disc_z_m
            zr -= self.height_m * np.floor(zr / self.height_m + 0.5)
            hb = 0.5 * self.disc_thickness_m
            if not self.has_channel:
                rc = np.clip(r, self.shaft_radius_m, self.disc_radius_m)
                zc = np.clip(zr, -hb, hb)
                ok &= np.hypot(r - rc, zr - zc) >= radius_m
            else:
                hc = 0.5 * self.channel_height_m
                rc = np.clip(r, self.eye_radius_m, self.disc_radius_m)
                zc = np.where(zr >= 0.0, np.clip(zr, hc, hb), np.clip(zr, -hb, -hc))
                ok &= np.hypot(r - rc, zr - zc) >= radius_m
                if self.vane_count:
                    ok &= self.vane_distance(p, 0.0) >= radius_m
            if self.baffle_count:
                ok &= self.baffle_distance(p) >= radius_m
        if self.sector_deg != 360.0:
            th = np.arctan2(p[:, 1], p[:, 0])
            ok &= (th >= 0.0) & (th < self.sector_rad)
        return ok


    def vane_distance(self, p: np.ndarray, rotor_angle_rad: float) -> np.ndarray:
        """Distance [m] from points p (n, 3) to the nearest vane with the first vane at
        ``rotor_angle_rad`` (the kernels' wall 3); inf without vanes."""
        if not self.vane_count:
            return np.full(p.shape[0], np.inf)
        return self._plate_distance(p, self.disc_z_m, rotor_angle_rad, self.vane_count,
                                    self.shaft_radius_m, self.disc_radius_m,
                                    self.vane_thickness_m, self.channel_height_m)

    def baffle_distance(self, p: np.ndarray) -> np.ndarray:
        """Distance [m] from points p (n, 3) to the nearest baffle (the kernels' wall 4);
        inf without baffles."""
        if not self.baffle_count:
            return np.full(p.shape[0], np.inf)
        return self._plate_distance(p, self.disc_z_m + 0.5 * self.height_m,
                                    math.radians(self.baffle_angle_deg), self.baffle_count,
                                    self.baffle_inner_radius_m, self.chamber_radius_m,
                                    self.baffle_thickness_m, self.baffle_height_m)

    def _plate_distance(self, p, z_mid_m, a0_rad, count, s_lo_m, s_hi_m, thickness_m,
                        height_m) -> np.ndarray:
        """Distance [m] from points p (n, 3) to the nearest of ``count`` radial plates over
        the circle, the first at a0, each from s_lo to s_hi along its mid-line, of the
        given thickness and axial height about z_mid (axially periodic)."""
        pitch = 2.0 * math.pi / count
        ang = a0_rad + pitch * np.floor((np.arctan2(p[:, 1], p[:, 0]) - a0_rad) / pitch + 0.5)
        s = p[:, 0] * np.cos(ang) + p[:, 1] * np.sin(ang)
        t = -p[:, 0] * np.sin(ang) + p[:, 1] * np.cos(ang)
        zp = p[:, 2] - z_mid_m
        zp -= self.height_m * np.floor(zp / self.height_m + 0.5)
        ds = s - np.clip(s, s_lo_m, s_hi_m)
        dt = t - np.clip(t, -0.5 * thickness_m, 0.5 * thickness_m)
        dz = zp - np.clip(zp, -0.5 * height_m, 0.5 * height_m)
        return np.sqrt(ds * ds + dt * dt + dz * dz)


def simple_cubic_annulus(spacing_m: float, r_min_m: float, r_max_m: float,
                         height_m: float) -> np.ndarray:
    """Sites [m] of a simple cubic lattice with origin 0 and the given spacing, with
    r_min <= r <= r_max and 0 <= z < height: the benchmark placement of issue 3, built the
    way LAMMPS' ``lattice sc`` + ``create_atoms`` builds it. Where the height is not a
    multiple of the spacing, the top layer and the periodic image of the bottom layer are
    closer than one spacing (for the bench, 4 mm / 0.84 mm: 0.64 mm, i.e. the beads of
    those layers start with 0.16 mm overlap)."""
    n = int(math.ceil(r_max_m / spacing_m)) + 1
    a = np.arange(-n, n + 1) * spacing_m
    nz = int(math.ceil(height_m / spacing_m - 1e-9))
    zs = np.arange(nz) * spacing_m
    gx, gy = np.meshgrid(a, a, indexing="ij")
    gx = gx.ravel()
    gy = gy.ravel()
    r = np.hypot(gx, gy)
    keep = (r >= r_min_m) & (r <= r_max_m)
    gx = gx[keep]
    gy = gy[keep]
    pts = np.empty((gx.size * nz, 3))
    for k, z in enumerate(zs):
        pts[k * gx.size:(k + 1) * gx.size, 0] = gx
        pts[k * gx.size:(k + 1) * gx.size, 1] = gy
        pts[k * gx.size:(k + 1) * gx.size, 2] = z
    return pts


def fcc_sites(geom: MillGeometry, radius_m: float, gap_m: float) -> np.ndarray:
    """Sites [m] of an fcc lattice (nearest-neighbour distance 2 radius + gap) inside the
    cell, none overlapping a wall. The axial lattice period is adapted to the cell period
    so that the periodic images do not overlap either."""
    d = 2.0 * radius_m + gap_m
    a = d * math.sqrt(2.0)  # cubic cell edge of fcc
    nzc = int(math.floor(geom.height_m / a))
    if nzc < 1:
        raise GeometryError(f"height_m = {geom.height_m!r}: too small for beads of radius "
                            f"{radius_m!r} m")
    az = geom.height_m / nzc  # >= a: stretched slightly along z
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    n = int(math.ceil(geom.chamber_radius_m / a)) + 1
    ix = iy = np.arange(-n, n + 1)
    if geom.sector_deg != 360.0:
        # Only the lattice cells that can hold a site of the sector (its bounding box, one cell of margin):
        # the same sites in the same order as over the whole circle (the order is lexicographic in the cell
        # indices, which are cut to contiguous ranges), at a fraction of the cost.
        th = geom.sector_rad  # <= 90 degrees
        lo_x, hi_x = geom.shaft_radius_m * math.cos(th), geom.chamber_radius_m
        hi_y = geom.chamber_radius_m * math.sin(th)
        ix = np.arange(max(-n, math.floor(lo_x / a) - 1), min(n, math.ceil(hi_x / a) + 1) + 1)
        iy = np.arange(max(-n, -1), min(n, math.ceil(hi_y / a) + 1) + 1)
    gx, gy, gz = np.meshgrid(ix, iy, np.arange(nzc), indexing="ij")
    cells = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1).astype(float)
    pts = (cells[:, None, :] + basis[None, :, :]).reshape(-1, 3)
    pts[:, 0] *= a
    pts[:, 1] *= a
    pts[:, 2] *= az
    pts[:, 2] += 0.25 * az
    pts = pts[geom.inside(pts, radius_m + 0.5 * gap_m)]
    if geom.sector_deg != 360.0:
        # keep clear of both boundary rays so that rotated images cannot overlap
        r = np.hypot(pts[:, 0], pts[:, 1])
        th = np.arctan2(pts[:, 1], pts[:, 0])
        clear = radius_m + 0.5 * gap_m
        ok = (r * np.sin(th) >= clear) & (r * np.sin(geom.sector_rad - th) >= clear)
        pts = pts[ok]
    return pts


def bead_count_for_filling(geom: MillGeometry, filling: float, diameter_m: float,
                           bulk_porosity: float = 0.4) -> int:
    """Number of beads for a grinding-media filling phi [-] (seed 001 eq. 2):
    phi = V_gm / (V (1 - eps)), V the free volume of the cell, eps the bulk porosity."""
    v_bead = math.pi / 6.0 * diameter_m ** 3
    return int(round(filling * (1.0 - bulk_porosity) * geom.free_volume_m3() / v_bead))


def placement_gap_m(radius_m: float) -> float:
    """Gap [m] between neighbouring sites of the initial lattice: 2 % of a bead diameter."""
    return 0.02 * 2.0 * radius_m


#: Sector angles [degrees] a cell can be widened to where beads do not fit its own sector: the whole-degree
#: divisors of 360 from 4 to 90 (rotational periodicity needs 360/k degrees with k >= 4).
SECTORS_DEG = tuple(float(360 // k) for k in range(90, 3, -1) if 360 % k == 0)


@functools.lru_cache(maxsize=256)
def placement_capacity(geom: MillGeometry, radius_m: float) -> int:
    """How many beads of ``radius_m`` [m] :func:`place_beads` can place in the cell (0 where
    the cell is too low for one lattice layer). Remembered per cell and radius: a table's
    points ask it of the same cells again and again (their cell is chosen by it)."""
    try:
        return int(fcc_sites(geom, radius_m, placement_gap_m(radius_m)).shape[0])
    except GeometryError:
        return 0


def place_beads(geom: MillGeometry, n_beads: int, radius_m: float, seed: int = 1,
                gap_m: float | None = None) -> np.ndarray:
    """n_beads positions [m] without overlap (with each other and with the walls): a random
    subset of fcc sites. Raises GeometryError if the cell cannot hold them."""
    sites = fcc_sites(geom, radius_m, placement_gap_m(radius_m) if gap_m is None else gap_m)
    if n_beads > sites.shape[0]:
        raise GeometryError(
            f"n_beads = {n_beads}: the cell holds at most {sites.shape[0]} beads of diameter "
            f"{2.0 * radius_m:g} m placed without overlap; lower the filling or the bead size")
    rng = np.random.default_rng(seed)
    pick = rng.choice(sites.shape[0], size=n_beads, replace=False)
    return np.ascontiguousarray(sites[np.sort(pick)])
