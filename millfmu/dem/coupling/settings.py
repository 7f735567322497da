"""Options of the coupled fluid (plain data; no numba, no scipy). The pressure equation's
solvers are the liquid's (:mod:`millfmu.dem.fluid.settings`), named here too beside the
coupling's other choices."""

from __future__ import annotations

from dataclasses import dataclass

from millfmu.dem.fluid.settings import DEFAULT_PRESSURE_SOLVER, PRESSURE_SOLVERS

__all__ = ["PRESSURE_GRADIENT_TIMINGS", "SMOOTHINGS", "DPM_DRAG_LAWS", "PRESSURE_SOLVERS",
           "DEFAULT_PRESSURE_SOLVER", "BEAD_STRESS_FORCES", "CouplingSettings"]


#: Model A's pressure-gradient force on the beads, by the interval whose gradient it takes:
#: - ``previous_interval``: the gradient of the interval before the one just solved, which
#:   is also the one whose reaction the liquid was given in that interval (the exchange is
#:   exact interval by interval); the force lags the liquid by two intervals;
#: - ``this_interval``: the interval just solved, as the drag takes that interval's
#:   velocity; the liquid receives the reaction in the next interval, so the exchange is
#:   exact over a run up to the last interval's pressure impulse. With a packed, compacting
#:   bed the two-interval lag feeds an oscillation of compaction and pressure (a
#:   consolidation integrated explicitly): at 1200 rpm and 80 % in the accelerator slice
#:   ``previous_interval`` blows up at 0.83 s, ``this_interval`` runs on (docs/cfd-dem.md).
PRESSURE_GRADIENT_TIMINGS = ("previous_interval", "this_interval")

#: How the beads' fields are smoothed to the smoothing length (same per-axis variance):
#: - ``explicit_diffusion``: explicit finite-volume diffusion sweeps
#:   (:mod:`millfmu.dem.coupling.projection`), as many as the smallest cell's stability
#:   needs (the kernel approaches a Gaussian);
#: - ``split_implicit``: ``smoothing_steps`` backward-Euler steps split by direction
#:   (:mod:`millfmu.dem.coupling.split_implicit_smoothing`), a cost independent of the
#:   cell size; with theta cells (a full slice) the explicit sweeps, whose count grows as
#:   the smallest cell shrinks, are the largest part of a coupling interval.
SMOOTHINGS = ("explicit_diffusion", "split_implicit")

#: The discrete phase model's drag law (``scheme = "dpm"``; millfmu.dem.coupling.dpm):
#: - ``schiller_naumann``: an isolated sphere's (Schiller & Naumann 1933), as a dilute
#:   discrete phase model has it;
#: - ``koch_hill2001``: Koch & Hill (2001) at the beads' void fraction around the bead, the
#:   law seed 002 adopted with its discrete phase model (section 2.3); the liquid still
#:   sees no void fraction.
DPM_DRAG_LAWS = ("schiller_naumann", "koch_hill2001")

#: Model A's generalized buoyancy on the beads (``bead_stress_force``):
#: - ``none``: its pressure part -V_i grad p only, the liquid's stresses weighted by eps (the
#:   share (1 - eps) div tau reaches neither phase);
#: - ``anderson_jackson1967``: its viscous part V_i div tau too, as Anderson and Jackson's
#:   equations and CFDEM's model A (``viscForce``) have it; the liquid's stresses carry no
#:   eps and the beads' force is taken from them (millfmu.dem.fluid.anderson_jackson1967).
BEAD_STRESS_FORCES = ("none", "anderson_jackson1967")


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
    smoothing: str = "explicit_diffusion"  # SMOOTHINGS
    smoothing_steps: int = 4  # split_implicit: backward-Euler steps to the variance
    pressure_solver: str = DEFAULT_PRESSURE_SOLVER  # PRESSURE_SOLVERS
    eps_min: float = 0.35  # lower clip of the void fraction
    cfl: float = 0.4
    # "vans": volume-averaged Navier-Stokes (CfdDem; the void fraction in the liquid, the
    # drag held over each coupling interval); "dpm": a dilute discrete phase model
    # (millfmu.dem.coupling.dpm: no void fraction, the drag of ``dpm_drag`` updated every
    # ``steps`` DEM steps in the liquid's field frozen over a CFD step of ``cfd_step_s``)
    scheme: str = "vans"
    # model A: which interval's pressure gradient the beads feel (PRESSURE_GRADIENT_TIMINGS)
    pressure_gradient: str = "previous_interval"
    cfd_step_s: float = 0.01  # dpm: CFD step and exchange interval [s] (seed 002: 0.01)
    dpm_drag: str = "schiller_naumann"  # dpm: the beads' drag law (DPM_DRAG_LAWS)
    # model A: whether the beads take the viscous part of the generalized buoyancy
    # (BEAD_STRESS_FORCES)
    bead_stress_force: str = "none"
