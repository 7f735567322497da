"""Structured cylindrical grid of the fluid solver (pure numpy, no numba).

Cells are annular sectors: radius r in [r_f[i], r_f[i+1]] (i < n_r, piecewise uniform
spacing), angle theta in [j dtheta, (j + 1) dtheta) (j < n_theta, periodic over the
simulated sector, which is the full circle or the DEM's sector), axial position z in
[k dz, (k + 1) dz) (k < n_z, periodic with the axial period). One theta cell is the
axisymmetric mode with swirl: every theta derivative vanishes, u_r, u_theta and u_z are
all kept.

Velocities sit on a staggered (MAC) grid: u_r[i, j, k] on the r-face at r_f[i]
(i = 0 ... n_r; the shaft and chamber faces are walls), u_theta[i, j, k] on the theta-face
between cells j and j + 1, u_z[i, j, k] on the z-face between cells k and k + 1; pressure,
void fraction and the turbulence quantities at cell centres.

Solids are whole cells (``solid``: 0 fluid, 1 rotor: turns with the stirrer, 2 stationary
housing). ``driven`` marks fluid cells between a rotor's vanes (accelerator rotors): the
vanes hold the swirl there at the rotor's speed while the liquid moves freely along them
(radially and axially), see :class:`millfmu.dem.fluid.solver.FluidSolver`. The PM-1 disc is an annular slab r_sh ... R, |z - z_disc| <= b/2 whose faces lie
on cell faces: :func:`mill_grid` chooses the spacings so that they do. The shaft
(r = r_sh, rotating or not) and the chamber wall (r = r_ch, fixed) are the grid's radial
boundaries. A closed housing (walls in z) is a row of stationary solid cells at k = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millfmu.dem.limits import MAX_THETA_CELL_RAD, least_theta_cells

FLUID = 0
ROTOR = 1
STATOR = 2


class GridError(ValueError):
    """A grid request that cannot be met."""


@dataclass(frozen=True, eq=False)
class CylGrid:
    """Cylindrical MAC grid [m, rad]. Build with :func:`mill_grid` or :func:`annulus_grid`.

    r_faces_m: (n_r + 1,) increasing radii of the r-faces, r_faces_m[0] the shaft radius,
    r_faces_m[-1] the chamber radius; sector_rad: the simulated angle (2 pi or the DEM
    sector); n_theta: theta cells; height_m: axial period; n_z: axial cells;
    solid: (n_r, n_theta, n_z) int8 cell kinds (FLUID, ROTOR, STATOR);
    shaft_rotates: whether the r = r_sh wall turns with the stirrer.
    """

    r_faces_m: np.ndarray
    sector_rad: float
    n_theta: int
    height_m: float
    n_z: int
    solid: np.ndarray
    shaft_rotates: bool = True
    driven: np.ndarray | None = None  # (n_r, n_theta, n_z) bool: cells between vanes

    def __post_init__(self):
        rf = np.asarray(self.r_faces_m, float)
        if rf.ndim != 1 or rf.size < 3 or not np.all(np.diff(rf) > 0) or rf[0] <= 0:
            raise GridError("r_faces_m: need at least 3 increasing positive radii")
        if self.n_theta < 1 or self.n_z < 3:
            raise GridError(f"n_theta = {self.n_theta}, n_z = {self.n_z}: need n_theta >= 1 "
                            f"and n_z >= 3")
        if self.n_theta > 1 and self.sector_rad / self.n_theta > MAX_THETA_CELL_RAD:
            need = least_theta_cells(self.sector_rad)
            raise GridError(f"n_theta = {self.n_theta}: theta cells of "
                            f"{self.sector_rad / self.n_theta:.3g} rad, wider than the "
                            f"{MAX_THETA_CELL_RAD:g} rad allowed; use 1 (axisymmetric) or at "
                            f"least {need} for {math.degrees(self.sector_rad):g} degrees")
        if self.solid.shape != (rf.size - 1, self.n_theta, self.n_z):
            raise GridError(f"solid: shape {self.solid.shape}, expected "
                            f"{(rf.size - 1, self.n_theta, self.n_z)}")
        if self.driven is not None and (self.driven.shape != self.solid.shape or
                                        (self.driven & (self.solid != FLUID)).any()):
            raise GridError("driven: must have the cells' shape and mark fluid cells only")

    # ---- sizes ---------------------------------------------------------------------------
    @property
    def n_r(self) -> int:
        return self.r_faces_m.size - 1

    @property
    def shape(self) -> tuple:
        return (self.n_r, self.n_theta, self.n_z)

    @property
    def r_centres_m(self) -> np.ndarray:
        """Cell-centre radii [m]: the mid-points of the r-faces."""
        return 0.5 * (self.r_faces_m[1:] + self.r_faces_m[:-1])

    @property
    def dr_m(self) -> np.ndarray:
        """Radial cell widths [m]."""
        return np.diff(self.r_faces_m)

    @property
    def dtheta_rad(self) -> float:
        return self.sector_rad / self.n_theta

    @property
    def dz_m(self) -> float:
        return self.height_m / self.n_z

    @property
    def z_centres_m(self) -> np.ndarray:
        return (np.arange(self.n_z) + 0.5) * self.dz_m

    @property
    def cell_volume_m3(self) -> np.ndarray:
        """Volume of a cell in radial row i [m3] (n_r,)."""
        rf = self.r_faces_m
        return 0.5 * (rf[1:] ** 2 - rf[:-1] ** 2) * self.dtheta_rad * self.dz_m

    def face_conductances_m(self):
        """Face area over the distance between the centres it parts [m], per radial row:
        the r faces between rows i and i + 1 (n_r - 1,), the theta faces (n_r,), the z faces
        (n_r,). The pressure equation's Laplacian and the beads' smoothing diffusion both
        couple neighbouring cells by these."""
        rf, rc, dth, dz = self.r_faces_m, self.r_centres_m, self.dtheta_rad, self.dz_m
        nr = rc.size
        return (rf[1:nr] * dth * dz / (rc[1:] - rc[:-1]), self.dr_m * dz / (rc * dth),
                self.cell_volume_m3 / dz ** 2)

    @property
    def fluid_volume_m3(self) -> float:
        """Volume of all fluid cells [m3] (beads included)."""
        return float((self.cell_volume_m3[:, None, None] * (self.solid == FLUID)).sum())

    def describe(self) -> dict:
        """Plain description for outputs: sizes [m], counts."""
        dr = self.dr_m
        return dict(n_r=self.n_r, n_theta=self.n_theta, n_z=self.n_z,
                    dr_m=[float(dr.min()), float(dr.max())], dz_m=self.dz_m,
                    sector_deg=math.degrees(self.sector_rad),
                    fluid_cells=int((self.solid == FLUID).sum()),
                    mode="axisymmetric with swirl" if self.n_theta == 1 else "3-D")


def _piecewise_faces(points, cell_m):
    """Faces from r0 to rN through every breakpoint in ``points``, each segment cut into
    equal cells no wider than ``cell_m``."""
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(math.ceil((b - a) / cell_m - 1e-9)))
        out.extend(a + (b - a) * np.arange(1, n + 1) / n)
    return np.array(out)


def _axial_cells(lengths, cell_m):
    """n_z and dz for an axial period made of segments ``lengths`` [m] that must each be a
    whole number of equal cells no larger than cell_m (the pressure solver and the disc
    faces want one uniform axial spacing)."""
    total = sum(lengths)
    n = max(3, int(math.ceil(total / cell_m - 1e-9)))
    for m in range(n, n + 4000):
        dz = total / m
        if all(abs(L / dz - round(L / dz)) < 1e-6 for L in lengths):
            return m
    raise GridError(f"axial segments {lengths} m: no common cell size <= {cell_m} m found")


#: theta cells per baffle pitch the liquid needs at least: the baffle's column and cells on
#: either side of it that the liquid can pass through
MIN_THETA_PER_BAFFLE = 4


def _check_baffle_columns(g, n_theta: int):
    per = g.baffle_count * g.sector_deg / 360.0  # baffles in the simulated sector (whole)
    if n_theta < MIN_THETA_PER_BAFFLE * per or n_theta % round(per):
        raise GridError(
            f"n_theta = {n_theta}: a liquid with {round(per)} baffle(s) in its "
            f"{g.sector_deg:g}-degree sector needs a multiple of {round(per)} theta cells, at "
            f"least {MIN_THETA_PER_BAFFLE} per baffle pitch (a baffle is one column of "
            f"stationary cells; one theta cell is the axisymmetric mode, which has none)")


def _baffle_cells(g, rf, nz: int, n_theta: int):
    """Index (i, j, k) arrays of the cells that stand for the baffles: in each baffle's
    theta column (the column that holds its mid-plane's angle; place the baffle at a
    column's centre for the best match), r beyond its inner
    radius and within its axial band (both on cell faces, :func:`mill_grid`). A column is
    a wedge of the sector's angle over n_theta: at the grid chosen for the accelerator
    slice (60 degrees, 12 columns) 1.4 mm wide at r = 16 mm and 2.6 mm at the wall, the
    DEM's plate 2 mm."""
    sector = 2.0 * math.pi if g.sector_deg == 360.0 else math.radians(g.sector_deg)
    dth = sector / n_theta
    pitch = 2.0 * math.pi / g.baffle_count
    a0 = math.radians(g.baffle_angle_deg) % pitch
    cols = sorted({int(math.floor((a0 + m * pitch) / dth + 1e-9)) % n_theta
                   for m in range(int(round(sector / pitch)))})
    rc = 0.5 * (rf[1:] + rf[:-1])
    dz = g.height_m / nz
    zb = (np.arange(nz) + 0.5) * dz - g.disc_z_m - 0.5 * g.height_m
    zb -= g.height_m * np.floor(zb / g.height_m + 0.5)
    ir = np.nonzero(rc > g.baffle_inner_radius_m)[0]
    kz = np.nonzero(np.abs(zb) < 0.5 * g.baffle_height_m)[0]
    return np.ix_(ir, np.array(cols), kz)


def mill_grid(geometry, cell_m: float = 0.75e-3, n_theta: int = 1,
              walls_z: bool = False, shaft_rotates: bool = True) -> CylGrid:
    """Grid of a :class:`millfmu.dem.mills.geometry.MillGeometry` (annulus or disc slice) with
    cells of about ``cell_m`` [m]: the disc's tip radius and faces lie on cell faces, the
    radial spacing is uniform between shaft and disc tip and between tip and chamber; the
    theta range is the geometry's sector. ``walls_z`` closes the axial period with a
    stationary wall (a row of housing cells at z = 0)."""
    g = geometry
    if not cell_m > 0:
        raise GridError(f"cell_m = {cell_m!r}: must be > 0")
    pts = [g.shaft_radius_m, g.chamber_radius_m]
    if g.has_disc:
        pts = [g.shaft_radius_m, g.disc_radius_m, g.chamber_radius_m]
    if g.has_channel:
        pts = [g.shaft_radius_m, g.eye_radius_m, g.disc_radius_m, g.chamber_radius_m]
    baffles = g.has_baffles
    if baffles:
        _check_baffle_columns(g, n_theta)
        pts = sorted(set(pts) | {g.baffle_inner_radius_m})
    rf = _piecewise_faces(pts, cell_m)
    lengths = [g.height_m]
    if g.has_disc:
        # the disc faces at z_disc -+ b/2 (and a channel's at -+ h_ch/2) must be z-faces:
        # cut the period there (and at 0)
        zs = [0.5 * g.disc_thickness_m]
        if g.has_channel:
            zs.append(0.5 * g.channel_height_m)
        cuts = sorted({0.0} | {(g.disc_z_m + sg * h) % g.height_m for h in zs
                               for sg in (-1.0, 1.0)})
        if baffles:  # the baffles' axial faces, half a period from the rotor's mid-plane
            cuts = sorted(set(cuts) | {
                (g.disc_z_m + 0.5 * g.height_m + sg * 0.5 * g.baffle_height_m) % g.height_m
                for sg in (-1.0, 1.0)})
        cuts.append(g.height_m)
        lengths = [b - a for a, b in zip(cuts[:-1], cuts[1:]) if b - a > 1e-12]
    nz = _axial_cells(lengths, cell_m)
    sector = 2.0 * math.pi if g.sector_deg == 360.0 else math.radians(g.sector_deg)
    nr = rf.size - 1
    solid = np.zeros((nr, n_theta, nz), np.int8)
    driven = None
    dz = g.height_m / nz
    if g.has_disc:
        rc = 0.5 * (rf[1:] + rf[:-1])
        zc = (np.arange(nz) + 0.5) * dz
        zr = zc - g.disc_z_m
        zr -= g.height_m * np.floor(zr / g.height_m + 0.5)
        in_z = np.abs(zr) < 0.5 * g.disc_thickness_m
        in_r = rc < g.disc_radius_m
        if not g.has_channel:
            solid[np.ix_(in_r, np.arange(n_theta), in_z)] = ROTOR
        else:
            # shrouds r_eye..R around the channel; the channel's cells are driven (vanes)
            in_ch = np.abs(zr) < 0.5 * g.channel_height_m
            shroud = in_z & ~in_ch
            solid[np.ix_(in_r & (rc > g.eye_radius_m), np.arange(n_theta), shroud)] = ROTOR
            driven = np.zeros((nr, n_theta, nz), np.bool_)
            if g.vane_count:
                driven[np.ix_(in_r, np.arange(n_theta), in_ch)] = True
    if baffles:
        solid[_baffle_cells(g, rf, nz, n_theta)] = STATOR
    if walls_z:
        solid[:, :, 0] = STATOR
        if driven is not None:
            driven[:, :, 0] = False
    return CylGrid(rf, sector, int(n_theta), g.height_m, nz, solid, shaft_rotates, driven)


def annulus_grid(r_inner_m: float, r_outer_m: float, height_m: float, n_r: int, n_z: int,
                 n_theta: int = 1, sector_rad: float = 2.0 * math.pi,
                 shaft_rotates: bool = True) -> CylGrid:
    """Plain annulus with uniform spacing and no solids (tests, Couette flow)."""
    rf = np.linspace(r_inner_m, r_outer_m, n_r + 1)
    return CylGrid(rf, sector_rad, n_theta, height_m, n_z,
                   np.zeros((n_r, n_theta, n_z), np.int8), shaft_rotates)


def housing_grid(disc_radius_m: float, gap_m: float, disc_thickness_m: float,
                 shaft_radius_m: float, rim_clearance_m: float, cell_r_m: float,
                 cell_z_m: float, n_theta: int = 1,
                 sector_rad: float = 2.0 * math.pi) -> CylGrid:
    """A disc rotating in a closed cylindrical housing (Daily & Nece 1960): disc of radius
    a and thickness b on a shaft, axial gap s between each disc face and the housing's end
    wall, radial clearance between disc tip and housing wall. Axially: housing wall row,
    gap, disc, gap (periodic with the wall row closing it)."""
    rf = _piecewise_faces([shaft_radius_m, disc_radius_m, disc_radius_m + rim_clearance_m],
                          cell_r_m)
    lengths = [gap_m, disc_thickness_m, gap_m]
    n_in = _axial_cells(lengths, cell_z_m)
    dz = sum(lengths) / n_in
    nz = n_in + 1  # plus the wall row
    nr = rf.size - 1
    solid = np.zeros((nr, n_theta, nz), np.int8)
    solid[:, :, 0] = STATOR
    rc = 0.5 * (rf[1:] + rf[:-1])
    zc = (np.arange(nz) + 0.5) * dz
    z0 = dz + gap_m
    in_z = (zc > z0) & (zc < z0 + disc_thickness_m)
    solid[np.ix_(rc < disc_radius_m, np.arange(n_theta), in_z)] = ROTOR
    return CylGrid(rf, sector_rad, n_theta, nz * dz, nz, solid, True)
