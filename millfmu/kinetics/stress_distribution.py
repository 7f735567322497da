"""Stress-energy distributions: the one interface through which the detailed model reads them.

A source describes, for an operating point, the chamber split into zones; each zone has its
share of the chamber volume, its bead collision frequency per volume, and the distribution
of the collision (stress) energies on log-spaced bins. Until DEM tables exist, the
log-normal source below, parameterised in the scene, stands behind this interface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.special import ndtr


@dataclass(frozen=True)
class Zone:
    """One zone of the chamber at one operating point.

    volume_fraction: share of the chamber volume [-]; collision_rate_per_m3_s: bead-bead
    collisions per time and zone volume [1/(m3 s)]; energy_edges_J: bin edges of the
    collision energy [J], ascending, length k + 1; energy_weights: probability of each bin
    [-], summing to one.
    """

    name: str
    volume_fraction: float
    collision_rate_per_m3_s: float
    energy_edges_J: np.ndarray
    energy_weights: np.ndarray

    @property
    def energy_J(self) -> np.ndarray:
        """Representative energy of each bin [J]: geometric mean of its edges."""
        e = self.energy_edges_J
        return np.sqrt(e[:-1] * e[1:])

    @property
    def median_energy_J(self) -> float:
        """Representative energy [J] of the bin that holds the median collision."""
        i = int(np.searchsorted(np.cumsum(self.energy_weights), 0.5))
        return float(self.energy_J[min(i, self.energy_weights.size - 1)])


def chamber_collision_rate_per_m3_s(source, op) -> float:
    """Collisions per chamber volume and time of a source at operating point ``op``,
    sum_z v_z (n_c/t)_z [1/(m3 s)] (v_z the zone's share of the chamber volume)."""
    return float(sum(z.volume_fraction * z.collision_rate_per_m3_s for z in source.zones(op)))


class StressEnergySource(Protocol):
    """What the detailed breakage model needs from a stress-energy source."""

    def zones(self, op) -> list[Zone]:
        """Zones at operating point ``op`` (a :class:`millfmu.kinetics.rates.OperatingPoint`)."""
        ...


@dataclass(frozen=True)
class LogNormalStressSource:
    """Single-zone log-normal collision-energy distribution, scaled with the operating point.

    The median collision energy is ``median_fraction`` of the beads' stress energy SE at the
    operating point (DEM studies find collision energies far below SE: seed 002 reports the
    collision stress energy at most 0.45 % of SE_net), with ``sigma_ln`` the standard
    deviation of ln(energy). The collision frequency per volume is
    ``collision_factor`` * omega * n_gb (Kwade's proportionality, seed 000 eq. 3).
    """

    median_fraction: float
    sigma_ln: float
    collision_factor: float
    n_bins: int = 64
    width_sigmas: float = 5.0

    def zones(self, op) -> list[Zone]:
        median = self.median_fraction * op.se_beads_J
        rate = self.collision_factor * op.omega_rad_per_s * op.n_gb_per_m3
        if not median > 0.0:
            # Stirrer at rest: no collisions carry energy.
            edges = np.array([1e-300, 2e-300])
            return [Zone("lognormal", 1.0, 0.0, edges, np.array([1.0]))]
        z = np.linspace(-self.width_sigmas, self.width_sigmas, self.n_bins + 1)
        edges = median * np.exp(self.sigma_ln * z)
        cdf = ndtr(z)
        w = np.diff(cdf)
        # The tails beyond +-width_sigmas go to the outermost bins so nothing is lost.
        w[0] += cdf[0]
        w[-1] += 1.0 - cdf[-1]
        return [Zone("lognormal", 1.0, rate, edges, w / w.sum())]
