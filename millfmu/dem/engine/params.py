"""Material and contact parameters of the bead DEM (pure Python, no numba).

Effective moduli and damping as in LIGGGHTS (project REFERENCE, "DEM contact model"):
1/Y* = (1 - nu_i^2)/Y_i + (1 - nu_j^2)/Y_j, 1/G* = 2(2 - nu_i)(1 + nu_i)/Y_i + (same for j),
beta = ln e / sqrt(ln^2 e + pi^2). Walls are made of the bead material.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class BeadMaterial:
    """Grinding-bead material. Defaults: seed 001 Table 1 (glass, Y reduced by 1e4)."""

    density_kg_per_m3: float = 2510.0
    youngs_modulus_pa: float = 6.3e6
    poisson_ratio: float = 0.25
    restitution: float = 0.99
    friction: float = 0.3
    rolling_friction: float = 0.10
    #: bead-wall Coulomb and rolling friction coefficients [-] where they differ from the
    #: bead-bead ones (None: the bead-bead values, as seeds 001 and 002 give one value for
    #: both): the walls being another material, or to see which contacts a result hangs on
    wall_friction: float | None = None
    wall_rolling_friction: float | None = None

    @property
    def bead_wall_friction(self) -> float:
        """Coulomb friction coefficient [-] of bead-wall contacts."""
        return self.friction if self.wall_friction is None else self.wall_friction

    @property
    def bead_wall_rolling_friction(self) -> float:
        """Rolling friction coefficient [-] of bead-wall contacts."""
        return self.rolling_friction if self.wall_rolling_friction is None else self.wall_rolling_friction

    @property
    def effective_youngs_pa(self) -> float:
        """Y* [Pa] of two beads (or bead and wall) of this material."""
        nu = self.poisson_ratio
        return 1.0 / (2.0 * (1.0 - nu * nu) / self.youngs_modulus_pa)

    @property
    def effective_shear_pa(self) -> float:
        """G* [Pa] of two beads (or bead and wall) of this material."""
        nu = self.poisson_ratio
        return 1.0 / (2.0 * 2.0 * (2.0 - nu) * (1.0 + nu) / self.youngs_modulus_pa)

    @property
    def damping_beta(self) -> float:
        """beta = ln e / sqrt(ln^2 e + pi^2) [-] (0 for e = 1)."""
        return damping_beta_of(self.restitution)


def damping_beta_of(e: float) -> float:
    """Damping ratio beta = ln e / sqrt(ln^2 e + pi^2) [-] of restitution e (-1 at e <= 0,
    the critically damped contact; 0 at e >= 1)."""
    if e <= 0.0:
        return -1.0
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return le / math.sqrt(le * le + math.pi ** 2)


def hertz_contact_time_s(m_star_kg: float, r_star_m: float, y_star_pa: float,
                         v_impact_m_per_s: float) -> float:
    """Duration [s] of an elastic Hertz impact, 2.87 (m*^2 / (R* Y*^2 v))^(1/5)
    (Johnson 1985, with the force law F = 4/3 Y* sqrt(R*) delta^(3/2))."""
    return 2.87 * (m_star_kg ** 2 / (r_star_m * y_star_pa ** 2 * v_impact_m_per_s)) ** 0.2


def bead_mass_kg(diameter_m: float, density_kg_per_m3: float) -> float:
    """Mass [kg] of a sphere."""
    return math.pi / 6.0 * diameter_m ** 3 * density_kg_per_m3
