"""Options of the coupled fluid (plain data; no numba, no scipy)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CouplingSettings:
    """Choices of the coupled fluid [SI]. Defaults: seed 001 (coupling every 10 DEM steps,
    k-epsilon, Koch-Hill drag, model A)."""

    model: str = "A"  # "A" (Anderson & Jackson set I as in CFDEM) or "B"
    turbulence: str = "k_epsilon"  # or "laminar"
    steps: int = 10  # DEM steps per coupling interval
    cell_m: float = 0.75e-3  # target fluid cell size
    n_theta: int = 1  # theta cells over the sector (1: axisymmetric with swirl)
    smoothing_diameters: float = 1.0  # Helmholtz smoothing length in bead diameters
    eps_min: float = 0.35  # lower clip of the void fraction
    cfl: float = 0.4
    # "vans": volume-averaged Navier-Stokes (CfdDem; the void fraction in the liquid, the
    # drag held over each coupling interval); "dpm": a dilute discrete phase model
    # (millfmu.dem.coupling.dpm: no void fraction, Schiller-Naumann drag updated every
    # ``steps`` DEM steps in the liquid's field frozen over a CFD step of ``cfd_step_s``)
    scheme: str = "vans"
    cfd_step_s: float = 0.01  # dpm: CFD step and exchange interval [s] (seed 002: 0.01)
