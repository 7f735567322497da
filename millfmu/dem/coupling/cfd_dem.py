"""CfdDem: the two-way coupling loop of beads and liquid (unresolved CFD-DEM).

Every coupling interval of ``steps`` DEM steps (seed 001: 10 DEM steps of 5e-6 s, CFD step
and coupling 5e-5 s):

1. beads -> grid (:mod:`millfmu.dem.coupling.projection`): bead volumes give the void
   fraction; each bead's drag coefficient c_i = V_i beta_i (Koch & Hill 2001 at its local
   void fraction and relative speed, :mod:`millfmu.dem.engine.koch_hill2001`; held
   explicitly over the interval, or relaxed exactly where a bead's relaxation time is
   shorter than the interval) and
   c_i v_i give the implicit drag coefficient K and the explicit source per velocity node;
   in model A the reaction of the beads' pressure-gradient force V_i grad p joins the source.
2. the fluid advances over the interval (:class:`millfmu.dem.fluid.solver.FluidSolver`),
   the drag implicit in its velocity;
3. grid -> beads: the fluid velocity averaged over the interval's substeps and the pressure
   gradient, read at each bead through the transposed projection; the bead's force
   F_i = c_i (u(x_i) - v_i) - V_i grad p(x_i) (model A; model B: drag only, beta / eps;
   model A with ``bead_stress_force``: its last term - V_i (grad p - div tau)(x_i),
   :mod:`millfmu.dem.fluid.anderson_jackson1967`, the reaction deposited as the pressure
   part's) is held over the next ``steps`` DEM steps (``DemSimulation.fext``, in cylindrical
   components so that its torque about the axis is exact).

Conservation: the fluid's momentum sink sum_f (C_f u_f - D_f) equals the beads' gain
sum_i c_i (u(x_i) - v_i) to round-off, because interpolation is the transpose of
deposition (weights sum to one per bead) and both use the same interval-mean velocity; the
pressure-gradient part uses the previous interval's gradient on both sides (with
``pressure_gradient = "this_interval"`` the beads take this interval's, and the liquid its
reaction one interval later: exact over a run up to the last interval's impulse). In model A the
liquid's -eps grad p is written as -grad p + (1 - eps) grad p with the second term the
deposited reaction of the beads' pressure force, so one pressure equation (coefficient 1)
serves both models. Angular momentum is exchanged as torque (c_i r_i deposited on the theta
nodes, whose equation is in angular-momentum form).
"""

from __future__ import annotations

import warnings

import numpy as np

from millfmu.dem.coupling.settings import CouplingSettings
from millfmu.dem.fluid.solver import VANE_SLIP_TIME_S, FluidProperties, FluidSolver


class CfdDem:
    """Couples a :class:`millfmu.dem.engine.sim.DemSimulation` to a fluid on ``grid``."""

    def __init__(self, sim, grid, fluid: FluidProperties, settings: CouplingSettings,
                 omega_rad_per_s: float):
        # numba kernels: compiled when a coupled run is built, not with a scene file.
        from millfmu.dem.coupling import exchange_kernels as EK
        from millfmu.dem.coupling import projection as PJ
        from millfmu.dem.coupling.projection import Projector

        self.EK = EK
        self.PJ = PJ
        self.sim = sim
        self.grid = grid
        self.settings = settings
        self.model_b = settings.model == "B"
        # model A: the beads take this interval's pressure gradient (settings.py)
        self._gradient_now = settings.pressure_gradient == "this_interval"
        self.solver = FluidSolver(grid, fluid, omega_rad_per_s, settings.turbulence,
                                  settings.model, cfl=settings.cfl,
                                  pressure_solver=settings.pressure_solver,
                                  stress_force=settings.bead_stress_force != "none")
        d = 2.0 * float(sim.rad.max())
        self.projector = Projector(grid, settings.smoothing_diameters * d, settings.eps_min,
                                   settings.smoothing, settings.smoothing_steps)
        self.interval_s = settings.steps * sim.dt_s
        n = sim.n
        ncell = int(np.prod(grid.shape))
        # the beads' cell stencils, 4 wide on an axisymmetric grid (projection.stencil_width)
        ns = self.PJ.stencil_width(grid.shape[1])
        self._idx = np.zeros((n, ns), np.int64)
        self._w = np.zeros((n, ns))
        self._cyl = np.zeros((n, 4))
        self._c = np.zeros(n)
        self._q = np.zeros((n, 6))
        self._x = np.zeros(n)
        self._tot = np.zeros((6, ncell))
        self._cellv = np.zeros((6, ncell))
        s = self.solver
        self._eps = [np.ones(grid.shape), np.ones(s.ur.shape), np.ones(grid.shape),
                     np.ones(grid.shape)]
        self._kd = [np.zeros(s.ur.shape), np.zeros(grid.shape), np.zeros(grid.shape)]
        self._sd = [np.zeros(s.ur.shape), np.zeros(grid.shape), np.zeros(grid.shape)]
        self._vol_r = np.ascontiguousarray(s.vol_r[:, 0, 0])
        self._vc = np.ascontiguousarray(grid.cell_volume_m3)
        # per bead, carried across intervals (permuted with the beads by the DEM's sort):
        # fluid velocity (u_r, u_t, u_z) [m/s] and pressure gradient [Pa/m] at the bead
        sim.register_per_bead("fluid_at_bead", np.zeros((n, 6)))
        self.clipped_cells = 0
        self.stiffness = 0.0  # largest interval / bead relaxation time of the last interval
        self.intervals = 0
        self.angular_impulse_to_beads_nms = 0.0
        self.axial_impulse_to_beads_ns = 0.0
        #: running time integral [N m s] of the torque about the axis that the beads'
        #: (buoyancy-reduced) weight exerts: nonzero where gravity lies across the axis of a
        #: full slice and the bed's centre of mass is off the vertical through the axis
        self.gravity_angular_impulse_nms = 0.0
        #: the beads' side of each exchange (stencils, deposit, held forces) and the
        #: smoothing of the cell fields on the GPU where the DEM steps there
        #: (:mod:`millfmu.dem.coupling.gpu_exchange`; set at the end of construction); None
        #: on the CPU
        self._gpu_side = None
        # the beads' drag law reads the void fraction of the previous interval (one
        # interval late, which saves a second smoothing per interval); start with the
        # initial beads'
        self._deposit_and_split(np.ones(ncell))
        self._eps_cells = self._eps[0].ravel().copy()
        # DEM step count at the last exchange: the liquid expects the beads one interval
        # (or no step) further at the next (see exchange)
        self._synced_step = sim.step_count
        #: an interval's exchange in one compiled call where its form allows
        #: (:mod:`millfmu.dem.coupling.fused_exchange`; the same results to the bit)
        self.fused = self.fused_possible()
        #: runs of such intervals, each exchange and the DEM's steps after it, in one
        #: compiled call where they record no contacts (:meth:`_run_compiled`; the same
        #: results to the bit)
        self.compiled = True
        #: the fused exchange's two-task forms (None: where numba runs one or two threads;
        #: the same results either way)
        self.two_tasks = None
        self.set_gpu_beads(sim._gpu is not None)

    def set_gpu_beads(self, on: bool) -> None:
        """Whether the beads' side of each exchange and the smoothing run on the GPU (the
        default where the DEM steps there) or on the CPU's threads, from the beads' state
        copied to the host and with the held force uploaded before the DEM's steps (a bench
        times the two on the same beads). Either way the same model, to round-off. On the
        CPU's DEM only False is allowed (ValueError)."""
        sim = self.sim
        if on and sim._gpu is None:
            raise ValueError("set_gpu_beads(True): the DEM steps on the CPU")
        if bool(on) == (self._gpu_side is not None):
            return
        if on:
            from millfmu.dem.coupling.gpu_exchange import GpuBeadSide

            self._gpu_side = GpuBeadSide(self)
        else:
            self._gpu_side.to_host()
            self._gpu_side.stencils_to_host()  # read by void_fraction_at_beads until the next exchange
            sim._gpu.fext_on_device = False
            self._gpu_side = None

    def fused_possible(self) -> bool:
        """Whether :mod:`millfmu.dem.coupling.fused_exchange` can take this coupling's
        exchange: explicit smoothing sweeps (or none), the pressure by ``direct_ldl``, no
        stator plates whose torque the liquid integrates per substep."""
        s = self.solver
        return (self.projector._implicit is None and s.pressure.method == "direct_ldl"
                and s._plate_faces is None)

    def _deposit_and_split(self, eps_cells):
        """Beads' deposit columns -> smoothed cell totals -> void fractions and exchange
        coefficients on the nodes (in self._eps, self._kd, self._sd)."""
        sim, g, s = self.sim, self.grid, self.solver
        nr, nt, nz = g.shape
        gpu = self._gpu_side
        smoothed = gpu is not None and gpu.smoother is not None
        if gpu is not None:
            stiffness = gpu.beads_in_and_deposit(eps_cells, self._tot, smooth=smoothed)
        else:
            self.EK.beads_in(sim.x, sim.v, sim.rad, sim.mass, sim.per_bead["fluid_at_bead"],
                             eps_cells, s.body_z, 0.0 if self.model_b else 1.0,
                             self.model_b, s.fluid.viscosity_Pa_s, s.rho, self.interval_s,
                             self.projector.rc, self.projector.rtab, self.projector.rh,
                             g.dtheta_rad, nt, g.dz_m, nz, g.height_m, g.solid, self._idx,
                             self._w, self._cyl, self._c, self._q, self._x)
            self.PJ.deposit(self._idx, self._w, self._q, self._tot)
            stiffness = float(self._x.max()) if self._x.size else 0.0
        if not smoothed:
            self.projector.smooth_totals(self._tot)
        e = self._eps
        self.clipped_cells = self.EK.cells_to_exchange(
            self._tot.reshape((6,) + g.shape), self._vc,
            self.settings.eps_min, g.solid, s.kr, s.kt, s.kz, self._vol_r, self.projector.rc,
            e[0], e[1], e[2], e[3], *self._kd, *self._sd)
        self.stiffness = stiffness

    # ---- one coupling interval ----------------------------------------------------------
    def exchange(self):
        """Beads -> grid, advance the fluid by one interval, grid -> bead forces (held in
        ``sim.fext`` over the next ``settings.steps`` DEM steps)."""
        sim, s = self.sim, self.solver
        # The DEM advanced without the liquid (``sim.run`` called directly, as the bench
        # does to time the DEM alone): the beads' displacement over that gap was never a
        # flux the liquid saw, so it must not enter continuity as d(eps)/dt over one
        # interval (which drove pressure gradients large enough to throw beads out of the
        # chamber). The liquid and the drag laws take the beads' present void fraction.
        gap = sim.step_count - self._synced_step not in (0, self.settings.steps)
        self._synced_step = sim.step_count
        if self.fused and self._gpu_side is None:
            return self._exchange_fused(gap)
        if gap:
            self._deposit_and_split(self._eps_cells)
            self._eps_cells[:] = self._eps[0].ravel()
        self._deposit_and_split(self._eps_cells)
        e = self._eps
        s.set_beads(e[0], e[1], e[2], e[3], self._kd, self._sd, self.interval_s)
        if gap or self.intervals == 0:
            # no change of the void fraction over this interval: after a gap, and at the
            # first exchange, where the liquid's previous void fraction is the bead-free 1
            # (the beads were not poured in over one interval)
            s.eps_c_old[:] = s.eps_c
        s.advance(self.interval_s)
        self._eps_cells[:] = e[0].ravel()
        self.EK.nodes_to_cell_values(s.mean_u[0], s.mean_u[1], s.mean_u[2], s.mean_gp[0],
                                     s.mean_gp[1], s.mean_gp[2], s.kr, s.kt, s.kz,
                                     self.grid.solid, self._cellv)
        # only the velocity needs the transpose of the deposit (the drag's exchange is
        # exact through it); the pressure gradient, a smooth field, is read by the stencil.
        # With the beads' side on the GPU its smoother does this there (the host's cell
        # values then stay unsmoothed).
        gpu = self._gpu_side
        if gpu is None or gpu.smoother is None:
            self.projector.smooth_values(self._cellv, ncols=3)
        if gpu is not None:
            ts, fs = gpu.bead_forces(self._cellv, 0.0 if self.model_b else 1.0,
                                     self._gradient_now, s.body_z,
                                     smooth=gpu.smoother is not None)
        else:
            ts, fs = self.EK.bead_forces(self._idx, self._w, self._cellv, self._c,
                                         self._cyl, sim.rad, sim.per_bead["fluid_at_bead"],
                                         0.0 if self.model_b else 1.0, self._gradient_now,
                                         s.body_z, sim.fext)
        self.angular_impulse_to_beads_nms += ts * self.interval_s
        self.axial_impulse_to_beads_ns += fs * self.interval_s
        self.intervals += 1

    def _fused_groups(self) -> tuple:
        """The first nine argument groups of
        :func:`~millfmu.dem.coupling.fused_exchange.exchange_interval` (the same arrays every
        interval until the beads are reordered)."""
        sim, g, s, pj = self.sim, self.grid, self.solver, self.projector
        fac = s.pressure._lu
        if pj.sweeps and (pj._tmp is None or pj._tmp.shape != (6,) + g.shape):
            pj._tmp = np.zeros((6,) + g.shape)
        # the pressure increment's buffer (the calls' path makes one per solve)
        phi = getattr(self, "_phi", None)
        if phi is None:
            phi = self._phi = np.empty(g.shape)
        _, nt, nz = g.shape
        e = self._eps
        s.interval_s = float(self.interval_s)
        pf = 0.0 if self.model_b else 1.0
        return (
            (sim.x, sim.v, sim.rad, sim.mass, sim.per_bead["fluid_at_bead"], sim.fext,
             self._eps_cells),
            (s.body_z, pf, s.fluid.viscosity_Pa_s, s.rho, self.interval_s, self.model_b,
             self._gradient_now),
            (self._idx, self._w, self._cyl, self._c, self._q, self._x),
            (pj.rc, pj.rtab, pj.rh, g.dtheta_rad, nt, g.dz_m, nz, g.height_m, g.solid,
             self._vc, self._vol_r, self.settings.eps_min),
            (self._tot, self._cellv, pj._vol_r, pj._ar, pj._at, pj._az,
             pj._tmp if pj.sweeps else self._cellv.reshape((6,) + g.shape), pj.sweeps),
            (e[0], e[1], e[2], e[3], *self._kd, *self._sd),
            (s._F, s._W, s._K, s._driven, s._acc, s.wall, s.wall_om, s.rf, s.rc, s.dr,
             s.vc),
            (s.rho, s.nu, VANE_SLIP_TIME_S, s.omega, s.om_shaft, s.body_z, s.dth, s.dz,
             s.cfl, s.interval_s or 0.0, s.turbulence == "k_epsilon", s.model == "A",
             s.stress_force),
            (s.pressure._cells, s.pressure.volume, s.pressure._volume_sum, fac.indptr,
             fac.indices, fac.values, fac.inv_d, fac.order, fac._rhs, fac._work, fac._x,
             phi, s._div))

    def _exchange_fused(self, gap: bool = False):
        """:meth:`exchange` in one call of
        :func:`millfmu.dem.coupling.fused_exchange.exchange_interval`; after a gap, the
        beads' present void fraction first (one call of
        :func:`~millfmu.dem.coupling.fused_exchange.present_void_fraction`), as the calls'
        path makes it, without the calls' cost (about 1 ms on the coupled bench, where every
        block of coupled intervals follows a block of the DEM alone)."""
        from millfmu.dem.coupling.fused_exchange import exchange_interval, present_void_fraction

        s = self.solver
        groups = self._fused_groups()
        tasks = self._tasks()
        if gap:
            present_void_fraction(*groups[:6], s._K, tasks)
        out = exchange_interval(*groups, gap or self.intervals == 0,
                                -1.0 if s._dt_stable is None else s._dt_stable, s.time_s,
                                tasks)
        self._close_fused(*out)

    def _tasks(self) -> bool:
        """Whether the fused exchange takes its two-task forms: on one or two of numba's
        threads (where they fill the second thread), not on more (where the kernels' own
        loops over fields and rows use them all), unless ``two_tasks`` says."""
        if self.two_tasks is not None:
            return bool(self.two_tasks)
        import numba

        return numba.get_num_threads() <= 2

    def _close_fused(self, clipped, stiff, n, dt_stable, time_s, finite, ts, fs):
        """The bookkeeping after a fused exchange (its returns, in order): the liquid's
        clock, substeps and impulses (FluidError where a velocity is not finite), the
        beads' impulses, the interval count."""
        s = self.solver
        self.clipped_cells = int(clipped)
        self.stiffness = float(stiff)
        s._dt_stable = float(dt_stable)
        s.time_s = float(time_s)
        s.pressure.solves += int(n)
        s.close_interval(int(n), bool(finite))
        self.angular_impulse_to_beads_nms += ts * self.interval_s
        self.axial_impulse_to_beads_ns += fs * self.interval_s
        self.intervals += 1

    def _compiled_intervals(self, left: int, record: bool, tau) -> int:
        """How many of the next ``left`` intervals :meth:`_run_compiled` may take: those
        whose exchange is fused and follows the DEM's steps without a gap, with no contacts
        recorded, no weight's torque to integrate (gravity along the axis or none) and the
        DEM on the CPU, up to the next reordering of the beads (which run() makes between an
        exchange and the DEM's steps). 0: run the next interval by the calls."""
        sim = self.sim
        if (record or tau is not None or not self.fused or sim._gpu is not None
                or self.intervals == 0
                or sim.step_count - self._synced_step != self.settings.steps):
            return 0
        m = sim.runs_before_sort(self.settings.steps)
        return left if m is None else min(left, m)

    def _run_compiled(self, m: int) -> list:
        """``m`` coupling intervals (exchange, then the DEM's steps) in one compiled call
        (:func:`~millfmu.dem.coupling.fused_exchange.coupled_intervals`): the same kernels
        in the same order as :meth:`exchange` and ``sim.run`` called in turn, so the same
        results to the bit, without the Python and the argument checks between them.
        Returns the DEM's StepStats, one per interval."""
        import numba

        from millfmu.dem.coupling.fused_exchange import PER_INTERVAL, coupled_intervals
        from millfmu.dem.engine._jit import use_threads
        from millfmu.dem.engine.sim import StepStats

        sim, s = self.sim, self.solver
        k = self.settings.steps
        use_threads(sim.threads)
        per = np.zeros((m, PER_INTERVAL))
        done, kk, status, parity = coupled_intervals(
            m, k, self._fused_groups(), -1.0 if s._dt_stable is None else s._dt_stable,
            s.time_s, sim.advance_args(False), sim.advance_args(False, swapped=True),
            sim.evcount, sim.acc, numba.get_parallel_chunksize(), per, self._tasks())
        if parity:
            sim._swap_lists()
        out = []
        # each interval's bookkeeping in turn, as exchange() and sim.run() do it
        for i in range(min(m, done + 1)):
            r = per[i]
            self._synced_step = sim.step_count
            s._acc[:] = r[8:13]
            self._close_fused(*(float(a) for a in r[:8]))
            if i == done:
                # its DEM steps stopped early (the neighbour lists overflowed): the rest of
                # them as run() goes on after such a stop
                out.append(sim.resume_run(k, (int(kk), int(status))))
                break
            sim.step_count += k
            out.append(StepStats(steps=k, events=np.zeros((0, sim.K.EV_NF)),
                                 torque_sum_nm_steps=0.0 + r[13],
                                 chamber_torque_sum_nm_steps=0.0 + r[14],
                                 dropped_events=int(r[15]), neighbour_builds=int(r[16])))
        return out

    def prime(self, duration_s: float, chunk_s: float = 1e-3) -> None:
        """Primed start: advance the liquid alone for ``duration_s`` [s] (no beads: void
        fraction 1, no drag; the rotor pumping the bead-free liquid), then give every bead
        the liquid's velocity at its centre, so that a run starts from the bead-free
        circulation instead of assuming that it forms. The liquid keeps its velocities; its
        void fractions are then the beads' (no momentum moved by their arrival)."""
        if duration_s <= 0.0:
            return
        sim, g, s = self.sim, self.grid, self.solver
        ones = [np.ones(g.shape), np.ones(s.ur.shape), np.ones(g.shape), np.ones(g.shape)]
        none = [np.zeros(s.ur.shape), np.zeros(g.shape), np.zeros(g.shape)]
        s.set_beads(*ones, none, [a.copy() for a in none], chunk_s)
        n = max(1, int(np.ceil(duration_s / chunk_s - 1e-9)))
        for _ in range(n):
            s.eps_c_old[:] = s.eps_c
            s.advance(duration_s / n)
        # bead velocities from the liquid's (smoothed) cell velocities at their centres
        self.EK.nodes_to_cell_values(s.ur, s.ut, s.uz, none[0], none[1], none[2], s.kr,
                                     s.kt, s.kz, g.solid, self._cellv)
        self.projector.smooth_values(self._cellv, ncols=3)
        nr, nt, nz = g.shape
        r = np.zeros(sim.n)
        self.PJ.bead_stencils(sim.x, self.projector.rc, self.projector.rtab,
                              self.projector.rh, g.dtheta_rad, nt, g.dz_m, nz, g.height_m,
                              g.solid, self._idx, self._w, r)
        u = np.zeros((sim.n, 3))
        self.PJ.gather(self._idx, self._w, np.ascontiguousarray(self._cellv[:3]), u)
        inv = np.where(r > 0.0, 1.0 / np.where(r > 0.0, r, 1.0), 0.0)
        c, sn = sim.x[:, 0] * inv, sim.x[:, 1] * inv
        sim.v[:, 0] = c * u[:, 0] - sn * u[:, 1]
        sim.v[:, 1] = sn * u[:, 0] + c * u[:, 1]
        sim.v[:, 2] = u[:, 2]
        sim.host_state_changed("v")
        sim.per_bead["fluid_at_bead"][:, 0:3] = u
        if self._gpu_side is not None:
            self._gpu_side.upload_fluid_at_beads()
        # the beads' void fractions without rescaling the liquid's velocities
        self._deposit_and_split(self._eps_cells)
        e = self._eps
        s.eps_c[:] = e[0]
        s.eps_c_old[:] = e[0]
        s.eps_r[:], s.eps_t[:], s.eps_z[:] = e[1], e[2], e[3]
        self._eps_cells[:] = e[0].ravel()
        self.primed_s = float(duration_s)

    def __setstate__(self, d):
        self.__dict__.update(d)
        # a checkpoint of earlier sources, which did not integrate the weight's torque:
        # its impulse before the checkpoint is unknown
        self.__dict__.setdefault("gravity_angular_impulse_nms", float("nan"))
        if "fused" not in self.__dict__:
            self.fused = self.fused_possible()
        self.__dict__.setdefault("compiled", True)
        self.__dict__.setdefault("two_tasks", None)
        self.__dict__.setdefault("_gpu_side", None)  # checkpoints are of CPU runs

    def gravity_torque_nm(self) -> float:
        """Torque [N m] about the axis (+z) of the beads' buoyancy-reduced weight at
        their present positions: sum of m_i (x_i g_y - y_i g_x); 0 where gravity lies along
        the axis."""
        sim = self.sim
        gx, gy = float(sim.prm[sim.K.P_GX]), float(sim.prm[sim.K.P_GY])
        return float(gy * np.dot(sim.mass, sim.x[:, 0]) - gx * np.dot(sim.mass, sim.x[:, 1]))

    def _weight_torque_start(self):
        """The weight's torque [N m] at the start of a run (see :meth:`_dem_run`); None
        where gravity lies along the axis (no torque about it)."""
        sim = self.sim
        if sim.prm[sim.K.P_GX] == 0.0 and sim.prm[sim.K.P_GY] == 0.0:
            return None
        return self.gravity_torque_nm()

    def _dem_run(self, k: int, record: bool, tau):
        """``k`` DEM steps, adding the weight's angular impulse over them by the
        trapezoidal rule from ``tau``, the torque at their start (None: none to add), as
        the velocity-Verlet kicks apply it over each step. The bed's centre of mass moves
        over tenths of a second: in the disc full slice (torque swinging by 1.3e-3 N m once
        in 0.17 s) the rule's error over 0.3 s is at most 1e-10 N m s, 1e-8 of the
        stirrer's drive. Returns (the DEM's StepStats, the torque at the end)."""
        st = self.sim.run(k, record=record)
        if tau is not None:
            t1 = self.gravity_torque_nm()
            self.gravity_angular_impulse_nms += 0.5 * (tau + t1) * k * self.sim.dt_s
            tau = t1
        return st, tau

    def liquid_changed(self):
        """The liquid's fields were set from outside (initial conditions): nothing to do
        here, the next exchange reads them."""

    @property
    def unit_steps(self) -> int:
        """DEM steps that runs are made of: the coupling interval."""
        return self.settings.steps

    def run(self, nsteps: int, record: bool = False):
        """Advance the coupled system by ``nsteps`` DEM steps (a whole number of coupling
        intervals); returns the list of the DEM's StepStats, one per interval."""
        k = self.settings.steps
        if nsteps % k:
            raise ValueError(f"nsteps = {nsteps}: must be a multiple of the coupling "
                             f"interval of {k} DEM steps")
        out = []
        tau = self._weight_torque_start()
        left = nsteps // k
        while left:
            m = self._compiled_intervals(left, record, tau) if self.compiled else 0
            if m:
                # fewer than m where the DEM's steps stopped early (then finished by run())
                done = self._run_compiled(m)
                out.extend(done)
                left -= len(done)
                continue
            self.exchange()
            st, tau = self._dem_run(k, record, tau)
            out.append(st)
            left -= 1
        if self._gpu_side is not None:
            self._gpu_side.to_host()
        return out

    # ---- observation --------------------------------------------------------------------
    def void_fraction_at_beads(self) -> np.ndarray:
        """Void fraction [-] read at each bead from the latest cell field."""
        if self._gpu_side is not None:
            self._gpu_side.stencils_to_host()
        out = np.zeros((self.sim.n, 1))
        self.PJ.gather(self._idx, self._w, self._eps_cells.reshape(1, -1), out)
        return out[:, 0]

    def section_fields(self) -> dict:
        """Fluid fields at the cell centres of the axial section, averaged over theta:
        void fraction eps [-], velocities u_r, u_theta, u_z [m/s], axial volume flux
        density eps u_z [m/s], turbulent viscosity nu_t [m2/s], turbulent kinetic energy
        k [m2/s2]; (n_r, n_z) arrays, NaN in solid cells."""
        s = self.solver
        solid = self.grid.solid != 0
        ur = 0.5 * (s.ur[:-1] + s.ur[1:])
        ut = 0.5 * (s.ut + np.roll(s.ut, 1, axis=1))
        uz = 0.5 * (s.uz + np.roll(s.uz, 1, axis=2))
        fz = 0.5 * (s.eps_z * s.uz + np.roll(s.eps_z * s.uz, 1, axis=2))
        out = {}
        for name, a in (("eps", s.eps_c), ("u_r", ur), ("u_theta", ut), ("u_z", uz),
                        ("flux_z", fz), ("nu_t", s.nu_t), ("k", s.k)):
            b = np.where(solid, np.nan, a)
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                # rows solid in every theta cell (the shrouds) stay NaN, as with one cell
                warnings.simplefilter("ignore", RuntimeWarning)
                out[name] = np.nanmean(b, axis=1) if b.shape[1] > 1 else b[:, 0, :]
        return out

    def angular_impulses_nms(self) -> dict:
        """Running time integrals [N m s] of the torques the fluid exerted on shaft, rotor
        cells (disc) and the walls at rest, in the simulated sector."""
        s = self.solver
        return dict(shaft=s.angular_impulse_shaft_nms, rotor_cells=s.angular_impulse_rotor_nms,
                    stator=s.angular_impulse_stator_nms)
