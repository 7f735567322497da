"""Product materials, chosen by name in the scene.

Each material says how likely one stress of a given energy breaks a particle of a given
size (its breakage energy distribution), and how the fragments are distributed (its
breakage function B). Sources are cited at each class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import austin1984, burst_energy, vogel_peukert2003


@dataclass(frozen=True)
class AustinBreakage:
    """Austin's breakage function parameters (Austin et al. 1984): B = phi r^gamma + (1-phi) r^beta."""

    phi: float
    gamma: float
    beta: float

    def cdf(self, ratio):
        return austin1984.breakage_cdf(ratio, self.phi, self.gamma, self.beta)


@dataclass(frozen=True)
class Mineral:
    """Brittle mineral (limestone-like).

    Breakage energy distribution: Vogel & Peukert (2003), P = 1 - exp(-f_Mat x (W_m - W_m,min)),
    with W_m the stress energy at the product per particle mass [J/kg].
    density_kg_per_m3 and youngs_modulus_Pa are the particles' (for the elasticity factor).
    """

    density_kg_per_m3: float
    youngs_modulus_Pa: float
    f_mat_kg_per_J_m: float
    x_w_min_J_m_per_kg: float
    breakage: AustinBreakage
    name: str = "mineral"
    inert_fragments: bool = False
    has_stress_model: bool = True

    def breakage_probability(self, x_m, energy_J):
        x = np.asarray(x_m, dtype=float)
        m_p = self.density_kg_per_m3 * math.pi / 6.0 * x**3
        return vogel_peukert2003.breakage_probability(
            x, np.asarray(energy_J) / m_p, self.f_mat_kg_per_J_m, self.x_w_min_J_m_per_kg
        )


@dataclass(frozen=True)
class Yeast:
    """Yeast cells: binary intact/disrupted (seed 000).

    A stress disrupts a cell when its energy exceeds the cell's burst energy; burst
    energies are log-normal (median_J, sigma_ln). Disrupted cells become debris, distributed
    by the breakage function, that is not stressed further (inert fragments), so the
    disrupted fraction is the debris' share of the mass.
    """

    density_kg_per_m3: float
    youngs_modulus_Pa: float
    burst_median_J: float
    burst_sigma_ln: float
    breakage: AustinBreakage
    name: str = "yeast"
    inert_fragments: bool = True
    has_stress_model: bool = True

    def breakage_probability(self, x_m, energy_J):
        p = burst_energy.burst_probability(energy_J, self.burst_median_J, self.burst_sigma_ln)
        return np.broadcast_to(p, np.broadcast_shapes(np.shape(x_m), np.shape(p)))


@dataclass(frozen=True)
class Austin:
    """Generic material with Austin's selection function taken straight from the scene.

    S(x) = a (x/x0)^alpha / (1 + (x/mu)^Lambda) (Austin et al. 1984); no stress model.
    """

    density_kg_per_m3: float
    youngs_modulus_Pa: float
    a_per_s: float
    x0_m: float
    alpha: float
    mu_m: float
    lam: float
    breakage: AustinBreakage
    name: str = "austin"
    inert_fragments: bool = False
    has_stress_model: bool = False

    def selection_per_s(self, x_m):
        return austin1984.selection_per_s(x_m, self.a_per_s, self.x0_m, self.alpha, self.mu_m, self.lam)
