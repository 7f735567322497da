"""Log-normally distributed burst energies of cells (binary intact/disrupted breakage).

Seed 000 (yeast cells as a test material: a cell wall is intact or disrupted; burst
energies are distributed and tunable by the osmotic condition, Arfsten et al. 2009;
damage accumulation below the burst energy is neglected).
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr


def burst_probability(energy_J, median_J: float, sigma_ln: float):
    """Probability [-] that one stress of energy_J [J] exceeds a cell's burst energy.

    The burst energies are log-normal with median median_J [J] and standard deviation of
    their logarithm sigma_ln [-]; this is their cumulative distribution at energy_J.
    """
    e = np.asarray(energy_J, dtype=float)
    with np.errstate(divide="ignore"):
        z = np.log(np.maximum(e, 0.0) / median_J) / sigma_ln
    return ndtr(z)
