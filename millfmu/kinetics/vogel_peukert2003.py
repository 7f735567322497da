"""Breakage probability of Vogel & Peukert.

Vogel, L., Peukert, W. (2003): Breakage behaviour of different materials - construction of
a mastercurve for the breakage probability. Powder Technol. 129, 101-110.
"""

from __future__ import annotations

import numpy as np


def breakage_probability(x_m, w_m_kin_J_per_kg, f_mat_kg_per_J_m: float, x_w_min_J_m_per_kg: float, k: float = 1.0):
    """P = 1 - exp(-f_Mat x k (W_m,kin - W_m,min)) [-], zero below the threshold.

    x_m: particle size [m]; w_m_kin_J_per_kg: mass-specific energy of one stress event
    [J/kg]; f_mat_kg_per_J_m: material parameter f_Mat [kg/(J m)];
    x_w_min_J_m_per_kg: size-independent threshold x W_m,min [J m/kg]; k: number of
    stress events at that energy [-].
    """
    x = np.asarray(x_m, dtype=float)
    excess = np.maximum(np.asarray(w_m_kin_J_per_kg, dtype=float) - x_w_min_J_m_per_kg / x, 0.0)
    return -np.expm1(-f_mat_kg_per_J_m * x * k * excess)
