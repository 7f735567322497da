"""Evaluation zones of the bead DEM (pure numpy).

Disc mills: the four volumes of Stender et al. as used in seed 001 (section 2.4, Table 2,
Figure 2). Only Table 2's dimensions are printed in the seed; the zones' shapes come from
its Figure 2 and text, read as follows (z measured from the disc mid-plane, b the disc
thickness, w1 the V1 width, R the disc radius, r_c the chamber radius):

- V1: the shear layer beside the disc face, r_V1 <= r < R, b/2 <= |z| < b/2 + w1;
- V2: between the disc rim and the chamber wall, r >= R, |z| < b/2 + w1;
- V3: the outer part between the discs, r >= r_V3, |z| >= b/2 + w1;
- V4: the inner part between the discs, r < r_V3, outside V1 and the disc.

With the PM-1 dimensions this makes V3 > V4 > V2 > V1 in volume, the order that seed 001
(section 3.4, Figure 14a) says the absolute collision numbers follow "corresponding to the
order of volume size". Defaults: w1 = 2.5 mm (the seed suggests 3 mm), r_V1 = 0.55 R,
r_V3 = 0.8 R.

Annulus (no disc): a single zone ``annulus``, the whole cell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millfmu.dem.mills.geometry import MillGeometry


class ZoneError(ValueError):
    """Zone dimensions that do not fit the geometry."""


@dataclass(frozen=True)
class ZoneSpec:
    """Zone dimensions [m and fractions of the disc radius]."""

    v1_width_m: float = 2.5e-3
    r_v1_over_disc_radius: float = 0.55
    r_v3_over_disc_radius: float = 0.80


class Zones:
    """Classifies points of a MillGeometry into zones and gives the zones' volumes."""

    def __init__(self, geometry: MillGeometry, spec: ZoneSpec = ZoneSpec()):
        self.g = geometry
        self.spec = spec
        if geometry.has_disc:
            R = geometry.disc_radius_m
            r1 = spec.r_v1_over_disc_radius * R
            r3 = spec.r_v3_over_disc_radius * R
            if not geometry.shaft_radius_m < r1 < r3 < R:
                raise ZoneError(
                    f"r_v1_over_disc_radius = {spec.r_v1_over_disc_radius!r}, "
                    f"r_v3_over_disc_radius = {spec.r_v3_over_disc_radius!r}: need shaft "
                    f"radius < r_V1 < r_V3 < R")
            if not 0.0 < spec.v1_width_m < 0.5 * (geometry.height_m - geometry.disc_thickness_m):
                raise ZoneError(
                    f"v1_width_m = {spec.v1_width_m!r}: must be > 0 and below half the gap "
                    f"between the discs ({0.5 * (geometry.height_m - geometry.disc_thickness_m)})")
            self.names = ("V1", "V2", "V3", "V4")
        else:
            self.names = ("annulus",)

    def classify(self, p: np.ndarray) -> np.ndarray:
        """Zone index per point p [m] (n, 3); -1 for points outside every zone."""
        g = self.g
        r = np.hypot(p[:, 0], p[:, 1])
        if not g.has_disc:
            return np.where((r >= g.shaft_radius_m) & (r <= g.chamber_radius_m), 0, -1)
        zr = p[:, 2] - g.disc_z_m
        zr = zr - g.height_m * np.floor(zr / g.height_m + 0.5)
        a = np.abs(zr)
        hb = 0.5 * g.disc_thickness_m
        w1 = self.spec.v1_width_m
        R = g.disc_radius_m
        r1 = self.spec.r_v1_over_disc_radius * R
        r3 = self.spec.r_v3_over_disc_radius * R
        out = np.full(p.shape[0], -1, dtype=np.int64)
        in_disc = (a < hb) & (r < R)
        v1 = (r >= r1) & (r < R) & (a >= hb) & (a < hb + w1)
        v2 = (r >= R) & (a < hb + w1)
        v3 = (r >= r3) & (a >= hb + w1)
        v4 = (r < r3) & ~v1 & ~in_disc
        out[v4] = 3
        out[v3] = 2
        out[v2] = 1
        out[v1] = 0
        inside = (r >= g.shaft_radius_m) & (r <= g.chamber_radius_m)
        out[~inside] = -1
        return out

    def volumes_m3(self) -> np.ndarray:
        """Volume of each zone within the simulated cell (sector included) [m3]."""
        g = self.g
        f = g.sector_fraction
        pi = math.pi
        if not g.has_disc:
            return np.array([g.free_volume_m3()])
        R = g.disc_radius_m
        rc = g.chamber_radius_m
        rs = g.shaft_radius_m
        r1 = self.spec.r_v1_over_disc_radius * R
        r3 = self.spec.r_v3_over_disc_radius * R
        w1 = self.spec.v1_width_m
        b = g.disc_thickness_m
        L = g.height_m
        v1 = pi * (R ** 2 - r1 ** 2) * 2 * w1
        v2 = pi * (rc ** 2 - R ** 2) * (b + 2 * w1)
        v3 = pi * (rc ** 2 - r3 ** 2) * (L - b - 2 * w1)
        v4 = pi * (r3 ** 2 - rs ** 2) * (L - b) - pi * (r3 ** 2 - r1 ** 2) * 2 * w1
        return f * np.array([v1, v2, v3, v4])
