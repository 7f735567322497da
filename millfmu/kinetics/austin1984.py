"""Austin's selection and breakage functions.

Austin, L.G., Klimpel, R.R., Luckie, P.T. (1984): Process Engineering of Size Reduction:
Ball Milling. SME, New York (also Austin & Luckie 1972, Powder Technol. 5, 267-271).
"""

from __future__ import annotations

import numpy as np


def selection_per_s(x_m, a_per_s: float, x0_m: float, alpha: float, mu_m: float, lam: float):
    """Specific breakage rate S(x) = a (x/x0)^alpha / (1 + (x/mu)^Lambda) [1/s].

    a_per_s: rate at x = x0 without the maximum term [1/s]; x0_m: reference size [m];
    alpha [-]: slope; mu_m: size where the maximum term halves the rate [m] (infinite for
    no maximum); lam [-]: steepness of the fall beyond mu.
    """
    x = np.asarray(x_m, dtype=float)
    s = a_per_s * (x / x0_m) ** alpha
    if np.isfinite(mu_m) and lam != 0.0:
        s = s / (1.0 + (x / mu_m) ** lam)
    return s


def breakage_cdf(ratio, phi: float, gamma: float, beta: float):
    """Cumulative breakage function B(x, y) = phi (x/y)^gamma + (1 - phi)(x/y)^beta [-].

    ratio = x/y, the fragment size over the parent size; B is the mass fraction of the
    fragments of a parent of size y that are smaller than x. B(1) = 1, B(0) = 0.
    """
    r = np.clip(np.asarray(ratio, dtype=float), 0.0, 1.0)
    return phi * r**gamma + (1.0 - phi) * r**beta
