"""Operating point and specific breakage rates S(x) from the stress models.

- "simple" (Kwade 1999; seed 000 section 2.1): every stress carries the stress energy at the
  product SE_P; S(x) = SF(x) P_break(x, SE_P).
- "detailed" (seed 000): the stresses carry a distribution of energies; per zone z,
  S(x) = sum_z f_z (n_c/t)_z sum_b w_zb P_break(x, E_zb,P) P_cap(x) / (n_p (1 - c_v)),
  the distribution of stress energies times the probability that a stress exceeds the
  particle's breakage energy times the collision frequency times the capture probability.
  A captured particle receives E_zb,P = eta_E E_zb (1 + Y_P/Y_GM)^-1 of a collision's
  energy E_zb: eta_E (``energy_transfer``) is the detailed model's one fitted constant,
  as k_c is the simple model's (seed 000 calibrates each model at one operating point).
- "none": S(x) taken from the scene (Austin's selection function).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import stress


#: Mean breakage probability per stress [-] of the detailed model below which its rate
#: follows the collision power rather than the collision frequency: with Vogel and
#: Peukert's P = 1 - exp(-f_Mat x k W_m), P ~ f_Mat x k W_m while P is small, so the rate
#: sums the collisions' energies. There the detailed model's trends along bead diameter and
#: density leave the simple model's, whose every captured stress breaks (the trend study in
#: docs/rates-and-calibration.md measures both sides).
ENERGY_LIMITED_P = 0.5

@dataclass(frozen=True)
class OperatingPoint:
    """Operating conditions and the stress model's characteristic numbers (SI).

    Inputs: tip_speed_m_per_s, filling [-], porosity [-], r_stirrer_m, bead diameter
    d_gb_m, bead density rho_gb_kg_per_m3, bead Young's modulus y_gb_Pa, product Young's
    modulus y_p_Pa, product density rho_p_kg_per_m3, liquid density rho_l_kg_per_m3,
    suspension viscosity eta_susp_Pa_s, solids mass fraction of the suspension
    solids_mass_fraction [-]; the two models' fitted constants: k_c [-], Kwade's
    stress-frequency constant (simple model), and energy_transfer [-], the share of a
    collision's energy that reaches a captured particle (detailed model).
    """

    tip_speed_m_per_s: float
    filling: float
    porosity: float
    r_stirrer_m: float
    d_gb_m: float
    rho_gb_kg_per_m3: float
    y_gb_Pa: float
    y_p_Pa: float
    rho_p_kg_per_m3: float
    rho_l_kg_per_m3: float
    eta_susp_Pa_s: float
    solids_mass_fraction: float
    k_c: float = 1.0
    energy_transfer: float = 1.0

    # ---- derived numbers -------------------------------------------------------------
    @property
    def se_beads_J(self) -> float:
        """Stress energy of the beads SE [J] (seed 000 eq. 1)."""
        return stress.stress_energy_beads_J(self.d_gb_m, self.rho_gb_kg_per_m3, self.tip_speed_m_per_s)

    @property
    def se_product_J(self) -> float:
        """Stress energy at the product SE_P [J] (Becker et al. 2001)."""
        return stress.stress_energy_product_J(self.se_beads_J, self.y_p_Pa, self.y_gb_Pa)

    @property
    def elasticity_factor(self) -> float:
        """Share of a bead collision's energy that reaches the product, (1 + Y_P/Y_GM)^-1 [-]."""
        return 1.0 / (1.0 + self.y_p_Pa / self.y_gb_Pa)

    @property
    def omega_rad_per_s(self) -> float:
        return stress.angular_velocity_rad_per_s(self.tip_speed_m_per_s, self.r_stirrer_m)

    @property
    def n_gb_per_m3(self) -> float:
        return stress.bead_number_concentration_per_m3(self.filling, self.porosity, self.d_gb_m)

    @property
    def bead_volume_fraction(self) -> float:
        return stress.bead_volume_fraction(self.filling, self.porosity)

    @property
    def collision_rate_per_m3_s(self) -> float:
        """Bead contacts per time and chamber volume, k_c omega n_gb [1/(m3 s)]."""
        return stress.collision_rate_per_m3_s(self.omega_rad_per_s, self.n_gb_per_m3, self.k_c)

    @property
    def rho_susp_kg_per_m3(self) -> float:
        """Suspension density from the solids mass fraction [kg/m3]."""
        w = self.solids_mass_fraction
        return 1.0 / (w / self.rho_p_kg_per_m3 + (1.0 - w) / self.rho_l_kg_per_m3)

    @property
    def solids_volume_fraction(self) -> float:
        """Volume fraction of product solids in the suspension c_v,P [-]."""
        return self.solids_mass_fraction * self.rho_susp_kg_per_m3 / self.rho_p_kg_per_m3

    @property
    def solids_concentration_kg_per_m3(self) -> float:
        """Product solids mass per suspension volume [kg/m3]."""
        return self.solids_mass_fraction * self.rho_susp_kg_per_m3

    @property
    def rho_eff_kg_per_m3(self) -> float:
        return stress.effective_density_kg_per_m3(
            self.filling, self.porosity, self.rho_gb_kg_per_m3, self.rho_susp_kg_per_m3
        )

    @property
    def eta_eff_Pa_s(self) -> float:
        return stress.krieger_dougherty_viscosity_Pa_s(self.eta_susp_Pa_s, self.bead_volume_fraction)

    @property
    def reynolds(self) -> float:
        return stress.mill_reynolds_number(
            self.rho_eff_kg_per_m3, self.eta_eff_Pa_s, self.tip_speed_m_per_s, self.r_stirrer_m
        )

    def class_number_concentration_per_m3(self, x_m):
        """Number concentration n_p [1/m3 suspension] if all solids were particles of size x_m.

        Used for the capture probability in the "class" mode: each size class sees the
        particle number it would have at the suspension's solids volume fraction, which keeps
        the rates independent of the state (so exact steps apply).
        """
        return self.solids_volume_fraction / (math.pi / 6.0 * np.asarray(x_m, dtype=float) ** 3)

    def stress_frequency_per_s(self, x_m, n_p_per_m3=None, collision_rate_per_m3_s=None):
        """Stress frequency SF(x) [1/s] (seed 000 eq. 2), with P_cap from eqs. 4-5.

        n_p_per_m3: number concentration of product particles [1/m3]; if None, the class
        concentration. collision_rate_per_m3_s: if None, Kwade's k_c omega n_gb.
        """
        x = np.asarray(x_m, dtype=float)
        if n_p_per_m3 is None:
            n_p_per_m3 = self.class_number_concentration_per_m3(x)
        if collision_rate_per_m3_s is None:
            collision_rate_per_m3_s = self.collision_rate_per_m3_s
        n_p = np.maximum(n_p_per_m3, np.finfo(float).tiny)
        p_cap = stress.capture_probability(n_p, stress.active_volume_m3(x, self.d_gb_m))
        return stress.stress_frequency_per_s(collision_rate_per_m3_s, n_p, p_cap, self.filling, self.porosity)


def selection_per_s(model: str, material, op: OperatingPoint, x_m, n_p_per_m3=None, source=None):
    """Specific breakage rate S(x) [1/s] at sizes x_m for the chosen stress model.

    model: "simple", "detailed" or "none"; material: from :mod:`millfmu.kinetics.materials`;
    n_p_per_m3: product number concentration for the capture probability (None: per class);
    source: a :class:`~millfmu.kinetics.stress_distribution.StressEnergySource` ("detailed").
    """
    if model not in ("simple", "detailed", "none"):
        raise ValueError(f"unknown stress model {model!r}; allowed: 'simple', 'detailed', 'none'")
    x = np.asarray(x_m, dtype=float)
    if model == "none":
        return np.asarray(material.selection_per_s(x), dtype=float)
    if op.tip_speed_m_per_s <= 0.0:
        return np.zeros_like(x)
    if model == "simple":
        sf = op.stress_frequency_per_s(x, n_p_per_m3)
        return sf * material.breakage_probability(x, op.se_product_J)
    # detailed
    total = np.zeros_like(x)
    for zone in source.zones(op):
        if zone.collision_rate_per_m3_s <= 0.0:
            continue
        # The share eta_E of the collision's energy that reaches the captured particle,
        # of which the elasticity factor leaves the particle its part.
        e_p = zone.energy_J * (op.energy_transfer * op.elasticity_factor)
        p = material.breakage_probability(x[..., None], e_p)
        # Collisions per chamber volume from this zone times the zone's mean breakage
        # probability per stress.
        total += zone.volume_fraction * zone.collision_rate_per_m3_s * (p @ zone.energy_weights)
    # SF with a unit collision rate, times the zone-weighted rate of breaking stresses.
    return op.stress_frequency_per_s(x, n_p_per_m3, collision_rate_per_m3_s=1.0) * total
