"""Dilute discrete phase model (dpm): the beads tracked through a liquid that does not see
their volume, as Fluent's discrete phase model that seed 002 coupled its DEM with.

What differs from the volume-averaged scheme (:mod:`millfmu.dem.coupling.cfd_dem`):

- no void fraction: the liquid's continuity and momentum equations are those of the pure
  liquid (eps = 1 everywhere); the beads act on it only through their drag;
- drag only, no pressure-gradient force (buoyancy stays in the DEM's reduced gravity), by
  the law ``settings.dpm_drag`` names
  (:data:`millfmu.dem.coupling.settings.DPM_DRAG_LAWS`): an isolated sphere's
  (``schiller_naumann``, :mod:`millfmu.dem.coupling.schiller_naumann`), or Koch & Hill's
  (``koch_hill2001``, :mod:`millfmu.dem.engine.koch_hill2001`: the law seed 002 adopted)
  at the void fraction of the beads around the bead, V_p beta / eps as the volume-averaged
  scheme's model B takes it. That void fraction is the beads' deposited volume, smoothed
  as the volume-averaged scheme's, at the start of each CFD step, and frozen over it with
  the liquid's velocity (the coupling exchanges once per CFD step); the liquid itself
  still sees none;
- two time scales: the liquid advances by a CFD step of ``cfd_step_s`` (seed 002: 0.01 s,
  about 19 relaxation times of a 0.8 mm zirconia bead at 0.4 Pa s); over that step its
  velocity field is frozen, and every bead's drag c (u(x) - v) is evaluated again every
  ``steps`` DEM steps at the bead's present position and velocity (the particle tracking
  of a discrete phase model), so that a bead relaxes to the frozen field as it would;
- the liquid's source: the beads' drag averaged over the CFD step, linearised as the
  volume-averaged scheme's (implicit coefficient sum c, explicit part sum c v), deposited
  with the same smoothing.

Exchange: the beads' momentum gain over a CFD step is sum c (u_old - v) with the field
frozen at the step's start; the liquid's loss is sum c (u_new - v) with its own new
velocity (implicit). They differ by sum c (u_new - u_old), a lag of one CFD step that a
discrete phase model has by construction (the liquid's impulse is
``solver.exchange_axial_ns``, the beads' ``axial_impulse_to_beads_ns``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numba import prange

from millfmu.dem.coupling import exchange_kernels as EK
from millfmu.dem.coupling import projection as PJ
from millfmu.dem.coupling.cfd_dem import CfdDem
from millfmu.dem.coupling.exchange_kernels import held_coefficient, held_sums
from millfmu.dem.coupling.projection import at_bead, at_bead3, bead_cyl
from millfmu.dem.coupling.schiller_naumann import drag_coefficient
from millfmu.dem.engine._jit import kernel
from millfmu.dem.engine.koch_hill2001 import beta


@kernel
def particle_drag(x, v, rad, mass, cellv, mu, rho, interval, rc, rtab, rh, dth, nt, dz, nz,
                  lz, solid, idx, w, fab, q, fext, xmax, koch_hill, eps_cells):
    """Drag of every bead in the frozen liquid: stencil at the bead's present position,
    the liquid's velocity read there (cellv[0:3], smoothed cell values), the coefficient c
    at the present relative speed (Schiller-Naumann's or, with ``koch_hill``, Koch and
    Hill's V_p beta / eps at the void fraction eps read from eps_cells; held over the
    interval by :func:`~millfmu.dem.coupling.exchange_kernels.held_coefficient`), the force
    held over the next ``interval`` [s], fext = (F_r [N], T_z [N m], F_z [N]), the deposit
    columns q (0, c, c r, c v_r, r c v_theta, c v_z) and fab[:, 0:3] the liquid's velocity
    at the bead. Returns the sums of T_z and F_z."""
    for b in prange(x.shape[0]):
        r, vr, vt, vz = bead_cyl(b, x, v, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w)
        u0, u1, u2 = at_bead3(b, idx, w, cellv, 0)
        urel = math.sqrt((u0 - vr) ** 2 + (u1 - vt) ** 2 + (u2 - vz) ** 2)
        if koch_hill:
            eb = at_bead(b, idx, w, eps_cells)
            d = 2.0 * rad[b]
            cf = math.pi / 6.0 * d * d * d * beta(d, eb, mu, rho, urel) / eb
        else:
            cf = drag_coefficient(2.0 * rad[b], mu, rho, urel)
        c, xx = held_coefficient(cf, mass[b], interval)
        xmax[b] = xx
        fr = c * (u0 - vr)
        tz = r * c * (u1 - vt)
        fz = c * (u2 - vz)
        fext[b, 0] = fr
        fext[b, 1] = tz
        fext[b, 2] = fz
        fab[b, 0] = u0
        fab[b, 1] = u1
        fab[b, 2] = u2
        q[b, 0] = 0.0
        q[b, 1] = c
        q[b, 2] = c * r
        q[b, 3] = c * vr
        q[b, 4] = r * c * vt
        q[b, 5] = c * vz
    return held_sums(fext)


class DiscretePhaseCoupling(CfdDem):
    """A :class:`millfmu.dem.engine.sim.DemSimulation` tracked through a liquid on ``grid``
    by a dilute discrete phase model (module docstring); the interface of
    :class:`CfdDem`. ``settings.steps``: DEM steps between drag updates;
    ``settings.cfd_step_s``: the CFD step [s], a whole number of drag updates."""

    def __init__(self, sim, grid, fluid, settings, omega_rad_per_s: float):
        steps = settings.steps
        cfd = int(round(settings.cfd_step_s / sim.dt_s))
        if cfd < steps or cfd % steps or abs(cfd * sim.dt_s - settings.cfd_step_s) > \
                1e-9 * settings.cfd_step_s:
            raise ValueError(
                f"fluid.coupled.cfd_step_s = {settings.cfd_step_s!r}: must be a whole "
                f"number of drag updates of coupling_steps x dt = {steps} x {sim.dt_s:g} s")
        # the liquid's equations without the beads' pressure force (eps = 1: A = B)
        super().__init__(sim, grid, fluid, replace(settings, model="B"), omega_rad_per_s)
        self.settings = settings
        self.cfd_steps = cfd
        self.cfd_interval_s = cfd * sim.dt_s
        self.drag_interval_s = steps * sim.dt_s
        ncell = self._tot.shape[1]
        self._acc = np.zeros((6, ncell))
        self._acc_n = 0
        self._eps_cells[:] = 1.0
        self._xb = np.zeros(sim.n)
        #: Koch-Hill's drag (settings.dpm_drag), at the void fraction per cell [-] that
        #: :meth:`_drag_void_fraction` gives at each CFD step's start
        self.koch_hill = settings.dpm_drag == "koch_hill2001"
        self._eps_drag = np.ones(ncell)
        # the frozen field of the first CFD step is the liquid as it starts, and the beads'
        # drag in it is what the liquid sees over its first step (no DEM step made yet)
        self._read_liquid(initial=True)
        self._drag(account=False)

    def liquid_changed(self):
        """The liquid's fields were set from outside (initial conditions): freeze them for
        the beads and make the first CFD step's drag of them again."""
        self._acc[:] = 0.0
        self._acc_n = 0
        self._eps_cells[:] = 1.0
        self._read_liquid(initial=True)
        self._drag(account=False)

    @property
    def unit_steps(self) -> int:
        """DEM steps that runs are made of: the CFD step."""
        return self.cfd_steps

    def _read_liquid(self, initial: bool = False):
        s = self.solver
        if initial:
            u = (s.ur, s.ut, s.uz)
            gp = (np.zeros_like(s.ur), np.zeros_like(s.ut), np.zeros_like(s.uz))
        else:
            u = s.mean_u
            gp = s.mean_gp
        EK.nodes_to_cell_values(u[0], u[1], u[2], gp[0], gp[1], gp[2], s.kr, s.kt, s.kz,
                                self.grid.solid, self._cellv)
        self.projector.smooth_values(self._cellv, ncols=3)
        if self.koch_hill:
            self._drag_void_fraction()

    def _drag_void_fraction(self) -> None:
        """The beads' void fraction per cell [-] at their present positions, for the drag
        over the next CFD step: their volumes deposited and smoothed as the volume-averaged
        scheme's (:meth:`CfdDem._deposit_and_split`), 1 - V_beads / V per cell clipped to
        [eps_min, 1], 1 in solid cells. The liquid does not see it."""
        sim, g, pj = self.sim, self.grid, self.projector
        nr, nt, nz = g.shape
        PJ.bead_stencils(sim.x, pj.rc, pj.rtab, pj.rh, g.dtheta_rad, nt, g.dz_m, nz,
                         g.height_m, g.solid, self._idx, self._w, np.empty(sim.n))
        q = np.zeros_like(self._q)
        q[:, 0] = math.pi / 6.0 * (2.0 * sim.rad) ** 3
        tot = np.zeros_like(self._tot)
        PJ.deposit(self._idx, self._w, q, tot)
        pj.smooth_totals(tot)
        e = 1.0 - tot[0].reshape(g.shape) / self._vc[:, None, None]
        e = np.clip(e, self.settings.eps_min, 1.0)
        e[g.solid != 0] = 1.0
        self._eps_drag[:] = e.ravel()

    def drag_void_fraction_at_beads(self) -> np.ndarray:
        """The void fraction [-] that Koch-Hill's drag reads at each bead (from the cells
        of :meth:`_drag_void_fraction`, through the stencils of the last drag update); 1
        everywhere with Schiller-Naumann's."""
        out = np.zeros((self.sim.n, 1))
        PJ.gather(self._idx, self._w, self._eps_drag.reshape(1, -1), out)
        return out[:, 0]

    def __setstate__(self, d):
        super().__setstate__(d)
        # a checkpoint of sources before the drag law was a choice: Schiller-Naumann
        self.__dict__.setdefault("koch_hill", False)
        self.__dict__.setdefault("_eps_drag", np.ones(self._tot.shape[1]))

    def _drag(self, account: bool = True) -> None:
        """Drag of every bead for the next ``steps`` DEM steps; its deposit summed into
        the accumulator of the liquid's next CFD step; ``account``: the DEM steps it is
        held over follow (its impulse counts)."""
        sim, g, s = self.sim, self.grid, self.solver
        nr, nt, nz = g.shape
        ts, fs = particle_drag(sim.x, sim.v, sim.rad, sim.mass, self._cellv,
                               s.fluid.viscosity_Pa_s, s.rho, self.drag_interval_s,
                               self.projector.rc, self.projector.rtab, self.projector.rh,
                               g.dtheta_rad, nt, g.dz_m, nz, g.height_m, g.solid, self._idx,
                               self._w, sim.per_bead["fluid_at_bead"], self._q, sim.fext,
                               self._xb, self.koch_hill, self._eps_drag)
        PJ.deposit(self._idx, self._w, self._q, self._tot)
        self._acc += self._tot
        self._acc_n += 1
        self.stiffness = max(self.stiffness, float(self._xb.max()) if self._xb.size else 0.0)
        if account:
            self.angular_impulse_to_beads_nms += ts * self.drag_interval_s
            self.axial_impulse_to_beads_ns += fs * self.drag_interval_s

    def exchange(self):
        """Advance the liquid by one CFD step with the beads' drag of the step before
        (averaged), then freeze its new field for the beads."""
        s = self.solver
        tot = self._acc / max(self._acc_n, 1)
        self._acc[:] = 0.0
        self._acc_n = 0
        self.projector.smooth_totals(tot)
        e = self._eps
        self.clipped_cells = EK.cells_to_exchange(
            tot.reshape((6,) + self.grid.shape), self._vc, self.settings.eps_min,
            self.grid.solid, s.kr, s.kt, s.kz, self._vol_r, self.projector.rc,
            e[0], e[1], e[2], e[3], *self._kd, *self._sd)
        s.set_beads(e[0], e[1], e[2], e[3], self._kd, self._sd, self.cfd_interval_s)
        s.eps_c_old[:] = s.eps_c
        s.advance(self.cfd_interval_s)
        self._read_liquid()
        self.intervals += 1
        self.stiffness = 0.0

    def run(self, nsteps: int, record: bool = False):
        """Advance by ``nsteps`` DEM steps (whole CFD steps); the DEM's StepStats, one per
        drag update."""
        k, m = self.settings.steps, self.cfd_steps
        if nsteps % m:
            raise ValueError(f"nsteps = {nsteps}: must be a multiple of the CFD step of "
                             f"{m} DEM steps")
        out = []
        tau = self._weight_torque_start()
        for _ in range(nsteps // m):
            self.exchange()
            for _ in range(m // k):
                self._drag()
                st, tau = self._dem_run(k, record, tau)
                out.append(st)
        return out
