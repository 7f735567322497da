"""DemSimulation: owns the bead arrays and advances them with the numba kernels.

numba is imported here lazily (inside ``__init__``) so that importing this module stays
cheap; the kernels compile (or load from the cache) on the first simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.mills.geometry import MillGeometry


@dataclass(frozen=True)
class FluidSettings:
    """Fluid seen by the beads [SI]. Defaults: water, seed 001 Table 1."""

    density_kg_per_m3: float = 998.2
    viscosity_Pa_s: float = 1.002e-3
    drag: bool = True  # Koch-Hill drag from the prescribed swirl flow
    lubrication: bool = True
    lubrication_cutoff_m: float = 0.04e-3  # 0.05 d for 0.8 mm beads
    lubrication_min_gap_m: float = 0.4e-6  # 5e-4 d
    swirl_core_fraction: float = 0.25  # core rotation / stirrer rotation [-]
    swirl_layer_m: float = 0.7e-3  # boundary-layer thickness [m]
    void_fraction: float = 0.5  # used in the drag law [-]
    # how a collision loses energy to the liquid: "lubrication" (the force above between
    # close beads, seed 001) or "legendre2006" (a restitution per contact from its Stokes
    # number, :mod:`millfmu.dem.engine.legendre2006`; lubrication off)
    wet_collisions: str = "lubrication"


@dataclass
class StepStats:
    """What one call of DemSimulation.run returns."""

    steps: int
    events: np.ndarray  # (n, EV_NF) rows, layout kernels.EV_*; step column made global
    torque_sum_nm_steps: float  # sum over steps of the torque beads exert on the stirrer
    chamber_torque_sum_nm_steps: float  # the same for the fixed chamber wall and baffles
    dropped_events: int
    neighbour_builds: int
    extra: dict = field(default_factory=dict)


class DemSimulation:
    """Soft-sphere DEM of monodisperse (or polydisperse) beads in a MillGeometry.

    Parameters (SI): geometry; material; positions_m (n, 3); radii_m (n,); omega_rad_per_s
    stirrer angular velocity about +z; dt_s; gravity_m_per_s2 (3,); fluid (None: no fluid
    forces at all); skin_m neighbour-list skin; max_neighbours: initial list room in pairs
    per bead (the lists grow as needed and are fitted after the first build); threads:
    numba threads (None: all);
    sort_every_steps: reorder the beads along the cell grid every so many steps (memory
    locality; None: 200 for 2000 beads or more, else never); spins_rad_per_s (n, 3) initial
    angular velocities [rad/s] (None: at rest); device: "cpu" (numba threads) or "gpu"
    (numba.cuda, :mod:`millfmu.dem.engine.gpu`: same model; beads are not reordered; the host
    arrays x, v, w, f, t are refreshed after each run() call and fext is read before it;
    rad and mass are read once, here). After a reorder, row k of the bead arrays holds
    the bead ``ids[k]`` of the initial order. tangential_history: how a contact's
    tangential spring follows its turning contact plane, ``"rescaled"`` (projected onto
    the plane, its length kept; the default, what every table was computed with) or
    ``"projected"`` (projected only, as LAMMPS' gran/hertz/history and LIGGGHTS);
    see :func:`millfmu.dem.engine.kernels.hertz_mindlin`. history_at_start: the tangential
    springs of the contacts present at construction (positions carry no history) when the
    initial forces are evaluated: ``"zero"`` (the default, as LAMMPS and LIGGGHTS, which
    update no history in their set-up: zero at the start, v_t dt after the first step) or
    ``"advanced"`` (to repeat runs made so: the initial evaluation already adds one step of
    sliding, v_t dt, to each spring, and the first step the next, one step of sliding too
    many). Scenes place their beads without
    overlap, so a scene's run starts the same either way (the shipped tables are
    unchanged); a moving, packed start shows the difference: on the DEM bench bed, whose
    shaft layer slides at several m/s, "advanced" gave a kinetic energy after 1000 steps
    about 16 % above LAMMPS', "zero" within 1 % of it (four runs each).
    """

    #: how collisions lose energy to the liquid (FluidSettings.wet_collisions), and their
    #: kernel codes (prm[P_WET])
    WET_COLLISIONS = {"lubrication": 0.0, "legendre2006": 1.0}
    #: the names of ``tangential_history`` and their kernel codes (prm[P_THIST])
    TANGENTIAL_HISTORIES = {"rescaled": 0.0, "projected": 1.0}
    #: the names of ``history_at_start``
    HISTORIES_AT_START = ("advanced", "zero")

    def __init__(self, geometry: MillGeometry, material: BeadMaterial, positions_m,
                 radii_m, omega_rad_per_s: float, dt_s: float, gravity_m_per_s2=(0.0, 0.0, 0.0),
                 fluid: FluidSettings | None = None, skin_m: float | None = None,
                 max_neighbours: int = 24, velocities_m_per_s=None, threads: int | None = None,
                 sort_every_steps: int | None = None, spins_rad_per_s=None, device: str = "cpu",
                 tangential_history: str = "rescaled", history_at_start: str = "zero"):
        # numba and the kernels load when a simulation is built, not with a scene file.
        import numba

        from millfmu.dem.engine import kernels as K
        from millfmu.dem.engine._jit import use_threads

        self.K = K
        self.geometry = geometry
        self.material = material
        self.fluid = fluid
        self.omega_rad_per_s = float(omega_rad_per_s)
        self.dt_s = float(dt_s)
        x = np.ascontiguousarray(positions_m, dtype=np.float64).copy()
        n = x.shape[0]
        if threads is None:
            # a few hundred beads gain nothing from threads, and parallel regions that
            # wait for a busy core cost more than the work
            threads = numba.config.NUMBA_NUM_THREADS if n >= 2000 else 1
        self.threads = int(threads)
        use_threads(self.threads)
        self.n = n
        self.rad = np.ascontiguousarray(np.broadcast_to(radii_m, (n,)), dtype=np.float64).copy()
        rho = material.density_kg_per_m3
        self.mass = 4.0 / 3.0 * math.pi * self.rad ** 3 * rho
        self.inertia = 0.4 * self.mass * self.rad ** 2
        self.inv_m = 1.0 / self.mass
        self.inv_i = 1.0 / self.inertia
        self.x = x
        self.v = np.zeros((n, 3)) if velocities_m_per_s is None else \
            np.ascontiguousarray(velocities_m_per_s, dtype=np.float64).copy()
        self.w = np.zeros((n, 3)) if spins_rad_per_s is None else \
            np.ascontiguousarray(spins_rad_per_s, dtype=np.float64).copy()
        self.f = np.zeros((n, 3))
        self.t = np.zeros((n, 3))
        self.xref = x.copy()
        rmax = float(self.rad.max())
        hcut = fluid.lubrication_cutoff_m if (fluid and fluid.lubrication) else 0.0
        # skin 0.375 d: on the annulus bench (2 threads) the fastest of 0.25, 0.375 and
        # 0.5 d (fewer builds against more pairs)
        self.skin_m = 0.375 * rmax * 2.0 if skin_m is None else float(skin_m)
        self.cutoff_m = 2.0 * rmax + hcut + self.skin_m
        if geometry.height_m / self.cutoff_m < 3.0:
            raise ValueError(
                f"height_m = {geometry.height_m!r}: the axial period must hold at least "
                f"three neighbour cells of {self.cutoff_m:.3e} m (bead diameter + "
                f"lubrication cutoff + skin)")
        if fluid is not None and fluid.wet_collisions not in self.WET_COLLISIONS:
            raise ValueError(f"fluid wet_collisions = {fluid.wet_collisions!r}: one of "
                             f"{list(self.WET_COLLISIONS)}")
        self.wet_restitution = fluid is not None and fluid.wet_collisions == "legendre2006"
        if self.wet_restitution and fluid.lubrication:
            raise ValueError("fluid wet_collisions = 'legendre2006' with lubrication on: the "
                             "published restitution includes the liquid film's damping; switch "
                             "lubrication off")
        prm = self._parameters(gravity_m_per_s2)
        if tangential_history not in self.TANGENTIAL_HISTORIES:
            raise ValueError(f"tangential_history = {tangential_history!r}: one of "
                             f"{sorted(self.TANGENTIAL_HISTORIES)}")
        self.tangential_history = tangential_history
        prm[K.P_THIST] = self.TANGENTIAL_HISTORIES[tangential_history]
        if history_at_start not in self.HISTORIES_AT_START:
            raise ValueError(f"history_at_start = {history_at_start!r}: one of "
                             f"{list(self.HISTORIES_AT_START)}")
        self.history_at_start = history_at_start
        self.prm = prm
        self._allocate(max_neighbours)
        self.step_count = 0
        self.ids = np.arange(n)
        if sort_every_steps is None:
            sort_every_steps = 200 if n >= 2000 else 0
        self.sort_every_steps = int(sort_every_steps)
        self._last_sort = 0
        if device not in ("cpu", "gpu"):
            raise ValueError(f"device = {device!r}: 'cpu' or 'gpu'")
        self.device = device
        self._gpu = None
        if device == "gpu" and self.wet_restitution:
            raise ValueError("device = 'gpu': the GPU stepper has no wet restitution per contact "
                             "(fluid wet_collisions = 'legendre2006'); use device 'cpu'")
        if device == "gpu" and geometry.vane_count:
            raise ValueError(f"device = 'gpu': the GPU stepper does not turn vanes "
                             f"(vane_count = {geometry.vane_count}); use device 'cpu'")
        if device == "gpu":
            from millfmu.dem.engine.gpu import GpuStepper  # numba.cuda only for the GPU

            self.sort_every_steps = 0
            self._gpu = GpuStepper(self, max_neighbours)  # builds and computes f, t
            return
        self._start_cpu()

    def _parameters(self, gravity_m_per_s2) -> np.ndarray:
        """The kernels' parameter vector (layout ``P_*`` of
        :mod:`millfmu.dem.engine.kernels`) of this simulation's material, fluid, geometry,
        stirrer speed, time step and skin; the tangential history's code is set by the
        caller. Gravity [m/s2] is reduced by the fluid's buoyancy."""
        from millfmu.dem.engine.koch_hill2001 import f0_f3_python

        K, material, fluid, geometry = self.K, self.material, self.fluid, self.geometry
        prm = np.zeros(K.N_PRM)
        prm[K.P_DT] = self.dt_s
        prm[K.P_YSTAR] = material.effective_youngs_pa
        prm[K.P_GSTAR] = material.effective_shear_pa
        prm[K.P_BETA] = material.damping_beta
        prm[K.P_MU] = material.friction
        prm[K.P_MUR] = material.rolling_friction
        prm[K.P_MUW] = material.bead_wall_friction
        prm[K.P_MURW] = material.bead_wall_rolling_friction
        g = np.asarray(gravity_m_per_s2, dtype=float)
        if fluid is not None:
            # buoyancy: the fluid's pressure gradient carries rho_f / rho_p of the weight
            g = g * (1.0 - fluid.density_kg_per_m3 / material.density_kg_per_m3)
            if fluid.lubrication:
                prm[K.P_LUB_ETA] = fluid.viscosity_Pa_s
                prm[K.P_LUB_HCUT] = fluid.lubrication_cutoff_m
                prm[K.P_LUB_HMIN] = fluid.lubrication_min_gap_m
            prm[K.P_DRAG] = 1.0 if fluid.drag else 0.0
            prm[K.P_MUF] = fluid.viscosity_Pa_s
            prm[K.P_EPSF] = fluid.void_fraction
            prm[K.P_KCORE] = fluid.swirl_core_fraction
            prm[K.P_DELTA] = fluid.swirl_layer_m
            prm[K.P_RHOF] = fluid.density_kg_per_m3
            prm[K.P_KH_F0], prm[K.P_KH_F3] = f0_f3_python(fluid.void_fraction)
            if fluid.wet_collisions == "legendre2006":
                from millfmu.dem.engine import legendre2006

                prm[K.P_WET] = self.WET_COLLISIONS[fluid.wet_collisions]
                prm[K.P_WET_ETA] = fluid.viscosity_Pa_s
                prm[K.P_WET_ST] = legendre2006.ST_SCALE
                prm[K.P_WTAB:K.P_WTAB + legendre2006.LEVELS + 2] = \
                    legendre2006.beta_table(material.restitution)
        prm[K.P_GX:K.P_GZ + 1] = g
        prm[K.P_LZ] = geometry.height_m
        prm[K.P_SECTOR] = geometry.sector_rad
        prm[K.P_RSH] = geometry.shaft_radius_m
        prm[K.P_RCH] = geometry.chamber_radius_m
        prm[K.P_OMEGA] = self.omega_rad_per_s
        prm[K.P_RDISC] = geometry.disc_radius_m
        prm[K.P_BDISC] = geometry.disc_thickness_m
        prm[K.P_ZDISC] = geometry.disc_z_m
        prm[K.P_REYE] = geometry.eye_radius_m
        prm[K.P_HCH] = geometry.channel_height_m
        prm[K.P_NVANE] = geometry.vane_count
        prm[K.P_TVANE] = geometry.vane_thickness_m
        prm[K.P_ROTANG] = 0.0
        prm[K.P_NBAF] = geometry.baffle_count
        prm[K.P_TBAF] = geometry.baffle_thickness_m
        prm[K.P_RBAF] = geometry.baffle_inner_radius_m
        prm[K.P_HBAF] = geometry.baffle_height_m
        prm[K.P_ABAF] = math.radians(geometry.baffle_angle_deg)
        prm[K.P_SKIN] = self.skin_m
        return prm

    def _allocate(self, max_neighbours: int) -> None:
        """The chunks of beads and the kernels' buffers: neighbour lists of
        ``max_neighbours`` per bead of the largest chunk, walls' histories, recorded
        contacts, accumulators, the held fluid force."""
        K, n = self.K, self.n
        # chunks of beads, each with its own force buffer: a fixed number for a given bead
        # count (about 4096 beads each), so that results do not depend on the thread count
        # (while threads <= chunks) and a thread held up on a shared machine leaves its
        # chunks to the others (each thread takes its own region's chunks first:
        # chunk_claims)
        nch = min(max(1, self.threads, min(64, n // 4096)), max(n, 1))
        self.cb = np.linspace(0, n, nch + 1).astype(np.int64)
        self.need = np.zeros(nch, np.int64)
        self.maxj = np.zeros(nch, np.int64)
        self.fb = np.zeros((nch, n, 3))
        self.tb = np.zeros((nch, n, 3))
        self.dmax = np.zeros(nch)
        self.wrapk = np.zeros(n, np.int8)
        self._alloc_lists(int(max_neighbours) * int(np.diff(self.cb).max()))
        self.shw = np.zeros((n, K.NWALL, 3))
        self.flw = np.zeros((n, K.NWALL), np.uint8)
        self.evc = np.zeros((nch, 2048, K.EV_NF))
        self.evn = np.zeros(nch, np.int64)
        self.evbuf = np.zeros((max(65536, 4 * 2048 * nch), K.EV_NF))
        self.evcount = np.zeros(1, np.int64)
        self.acc = np.zeros(5)
        self.torq = np.zeros((nch, 2))
        # force held over a run() call: (F_r [N], T_z [N m], F_z [N]) per bead, set by a
        # coupled fluid (millfmu.dem.coupling); zeros otherwise
        self.fext = np.zeros((n, 3))
        # further per-bead arrays of a coupling, permuted with the beads (register_per_bead)
        self.per_bead = {}

    def __setstate__(self, state: dict) -> None:
        """A checkpoint whose parameter vector predates the wet restitution's entries goes
        on with them zero: the lubrication law it was made with; one that predates the
        bead-wall friction's entries, with the bead-bead friction for its walls, as it was
        made."""
        self.__dict__.update(state)
        self.__dict__.setdefault("wet_restitution", False)
        K = self.K
        n_old = self.prm.shape[0]
        if n_old < K.N_PRM:
            self.prm = np.concatenate([self.prm, np.zeros(K.N_PRM - n_old)])
            if n_old <= K.P_MUW:
                self.prm[K.P_MUW] = self.prm[K.P_MU]
                self.prm[K.P_MURW] = self.prm[K.P_MUR]

    def _start_cpu(self) -> None:
        """The first neighbour lists (made to fit where ``max_neighbours`` was generous),
        the first sort and the forces of the initial state, whose contacts are not "new"
        later."""
        K = self.K
        self._build()
        if self.pair_capacity > 1.5 * self.need.max() + 64:
            # max_neighbours was generous: lists that fit (nothing to carry over yet)
            self._alloc_lists(int(1.3 * self.need.max()) + 16)
            self._build(do_wrap=False)
        if self.sort_every_steps:
            self._sort()
        # "zero": the contact law uses dt only for the spring's increment, none at the start
        dt = self.prm[K.P_DT]
        if self.history_at_start == "zero":
            self.prm[K.P_DT] = 0.0
        self._finish(record=False, kick=0.0)
        self.prm[K.P_DT] = dt

    def host_state_changed(self, *names: str) -> None:
        """The host arrays named (of "v", "w": velocities and spins) were changed in place
        outside ``run`` (a coupling giving the beads the liquid's velocity): on the GPU
        they are uploaded; on the CPU the arrays are the state and nothing is done.
        Positions are not among them: moving beads by hand would also need new neighbour
        lists, on either device."""
        bad = [k for k in names if k not in ("v", "w")]
        if bad:
            raise ValueError(f"host_state_changed: {bad}: allowed 'v', 'w'")
        if self._gpu is not None:
            self._gpu.upload(names)

    def register_per_bead(self, name: str, array: np.ndarray):
        """Keep ``array`` (first axis: beads, current row order) in ``per_bead[name]`` and
        reorder it with the beads whenever they are sorted."""
        if array.shape[0] != self.n:
            raise ValueError(f"{name}: first axis {array.shape[0]}, expected {self.n} beads")
        self.per_bead[name] = array

    # ---- neighbour lists --------------------------------------------------------------
    # Two sets of half lists (kernels.build_nlist): the current one (pst, nnb, pj, pim,
    # psh, pfl) and the spare one (the same names + "_o") that the next build fills; pair
    # arrays hold `cap` pairs per chunk.
    _LISTS = ("pst", "nnb", "pj", "pim", "psh", "pfl")
    _LISTS_O = tuple(k + "_o" for k in _LISTS)

    def _new_lists(self, cap: int) -> dict:
        n, nch = self.n, self.cb.size - 1
        return dict(pst=np.zeros(n, np.int64), nnb=np.zeros(n, np.int64),
                    pj=np.zeros(nch * cap, np.int32), pim=np.zeros(nch * cap, np.int8),
                    psh=np.zeros((nch * cap, 3)), pfl=np.zeros(nch * cap, np.uint8))

    def _alloc_lists(self, cap: int):
        """Empty current and spare lists with room for cap pairs per chunk."""
        for k, a in self._new_lists(cap).items():
            setattr(self, k, a)
        for k, a in self._new_lists(cap).items():
            setattr(self, k + "_o", a)

    def _alloc_spare(self, cap: int):
        for k, a in self._new_lists(cap).items():
            setattr(self, k + "_o", a)

    @property
    def pair_capacity(self) -> int:
        """Pairs the current lists hold per chunk."""
        return self.pj.shape[0] // (self.cb.size - 1)

    @property
    def slots_per_bead(self) -> int:
        """List capacity in pairs per bead of the largest chunk (max_neighbours at the
        start; grows when the lists overflow)."""
        return self.pair_capacity // int(np.diff(self.cb).max())

    def _swap_lists(self):
        for k in self._LISTS:
            a, b = getattr(self, k), getattr(self, k + "_o")
            setattr(self, k, b)
            setattr(self, k + "_o", a)

    def claims(self):
        """The counters by which the CPU kernels' threads take the chunks
        (:mod:`millfmu.dem.engine.chunk_claims`): one region per thread of the run. Made
        when first needed (a simulation restored from an earlier checkpoint has none)."""
        from millfmu.dem.engine.chunk_claims import CLAIM_STRIDE, claim_counters

        c = getattr(self, "_claims", None)
        if c is None or c.size != CLAIM_STRIDE * max(1, self.threads):
            c = self._claims = claim_counters(self.threads)
        return c

    def _build(self, do_wrap: bool = True):
        """Build new neighbour lists from the current ones and make them current; the spare
        lists are enlarged (by 30 %) until the fullest chunk's pairs fit."""
        K = self.K
        nch = self.cb.size - 1
        while True:
            needed = K.rebuild(self.x, self.v, self.w, self.shw, self.xref, self.prm,
                               self.wrapk, self.cutoff_m, do_wrap, self.pst, self.nnb, self.pj,
                               self.pim, self.psh, self.pfl, self.pst_o, self.nnb_o,
                               self.pj_o, self.pim_o, self.psh_o, self.pfl_o, self.cb,
                               self.need, self.maxj, self.claims())
            if needed <= self.pj_o.shape[0] // nch:
                self._swap_lists()
                if self.pj_o.shape[0] < self.pj.shape[0]:
                    # both sets the same size, so that the next build fits too
                    self._alloc_spare(self.pair_capacity)
                return
            self._alloc_spare(int(needed * 1.3) + 16)
            do_wrap = False

    def _finish(self, record: bool, kick: float):
        self.K.finish_step(self.x, self.v, self.w, self.f, self.t, self.rad, self.mass,
                           self.inertia, self.inv_m, self.inv_i, self.prm, self.pst,
                           self.nnb, self.pj, self.pim, self.psh, self.pfl, self.shw,
                           self.flw, self.cb, self.maxj, record, self.evc, self.evn,
                           self.torq, self.xref, self.dmax, self.fb, self.tb, kick,
                           self.fext, self.claims())

    _PER_BEAD = ("x", "v", "w", "f", "t", "xref", "rad", "mass", "inertia", "inv_m",
                 "inv_i", "wrapk", "shw", "flw", "ids", "fext")

    def _sort(self):
        """Reorder beads by neighbour cell (z fastest), remapping the neighbour lists, so
        that beads close in space are close in memory."""
        g = self.geometry
        cs = self.cutoff_m
        x = self.x
        n = self.n
        ix = np.floor((x[:, 0] + g.chamber_radius_m) / cs).astype(np.int64)
        iy = np.floor((x[:, 1] + g.chamber_radius_m) / cs).astype(np.int64)
        iz = np.floor(np.mod(x[:, 2], g.height_m) / cs).astype(np.int64)
        key = (ix * (iy.max() + 1) + iy) * (iz.max() + 1) + iz
        perm = np.argsort(key, kind="stable")
        inv = np.empty_like(perm)
        inv[perm] = np.arange(perm.size)
        # the pairs, flattened; a pair stays with its lower (new) index (engine.reorder)
        from millfmu.dem.engine import reorder

        m = int(self.nnb.sum())
        owner = np.empty(m, np.int64)
        partner = np.empty(m, np.int64)
        ps = np.empty(m, np.int64)
        psh = np.empty((m, 3))
        pfl = np.empty(m, np.uint8)
        swap = np.empty(m, np.bool_)
        reorder.flatten_pairs(self.nnb, self.pst, self.pj, self.pim, self.psh, self.pfl, inv,
                              owner, partner, ps, psh, pfl, swap)
        if swap.any():
            # seen from the other bead: opposite spring, in that bead's frame (rotated by
            # -s sector for image pairs), image code negated
            th = -ps[swap] * self.geometry.sector_rad
            c, sn = np.cos(th), np.sin(th)
            s0, s1 = psh[swap, 0].copy(), psh[swap, 1].copy()
            psh[swap, 0] = -(c * s0 - sn * s1)
            psh[swap, 1] = -(sn * s0 + c * s1)
            psh[swap, 2] = -psh[swap, 2]
            ps = np.where(swap, -ps, ps)
        for k in self._PER_BEAD:
            setattr(self, k, np.ascontiguousarray(getattr(self, k)[perm]))
        for k, arr in self.per_bead.items():
            arr[:] = arr[perm]
        # rows in the new order, each chunk's rows one after the other in its region
        cb = self.cb
        counts = np.empty(n, np.int64)
        per_chunk = np.empty(cb.size - 1, np.int64)
        reorder.pair_counts(owner, cb, counts, per_chunk)
        if per_chunk.size and per_chunk.max() > self.pair_capacity:
            self._alloc_lists(int(per_chunk.max() * 1.3) + 16)
        reorder.place_pairs(owner, partner, ps, psh, pfl, counts, cb, self.pair_capacity,
                            np.empty(n, np.int64), self.pst, self.nnb, self.pj, self.pim,
                            self.psh, self.pfl, self.maxj)
        self._last_sort = self.step_count

    # ---- time stepping ----------------------------------------------------------------
    def run(self, nsteps: int, record: bool = False) -> StepStats:
        """Advance nsteps steps; with record, return every contact at its first overlap."""
        if self._gpu is not None:
            ev, torque, chamber, dropped, builds = self._gpu.run(nsteps, record)
            ev[:, self.K.EV_STEP] += self.step_count
            self.step_count += nsteps
            return StepStats(steps=nsteps, events=ev, torque_sum_nm_steps=torque,
                             chamber_torque_sum_nm_steps=chamber, dropped_events=dropped,
                             neighbour_builds=builds)
        return self._on_threads(self._run_cpu, nsteps, record)

    def _on_threads(self, fn, *args):
        """fn(*args) with numba's thread count and chunk size set for the DEM's kernels."""
        import numba

        from millfmu.dem.engine._jit import use_threads

        use_threads(self.threads)
        # every parallel loop of a DEM step runs over the chunks, whose work differs (their
        # pairs and wall contacts): hand them out one at a time as threads come free
        # instead of numba's equal static blocks, so that no thread waits with its block
        # done (the force loop, the reduction and the neighbour build take them from
        # counters of their own instead, each thread its region first: chunk_claims); the
        # results do not change, since each chunk sums into its own buffer. Set per call,
        # as numba keeps it per calling thread, and restored after, for the coupled
        # liquid's loops over cells.
        with numba.parallel_chunksize(1):
            return fn(*args)

    def resume_run(self, nsteps: int, first) -> StepStats:
        """The rest of a run of ``nsteps`` steps (no contacts recorded) whose first
        ``advance`` call was made elsewhere (a compiled coupling loop) and stopped early:
        ``first`` = (its steps, its status), its lists swapped, its counts in acc."""
        return self._on_threads(self._steps, nsteps, False, first)

    def _run_cpu(self, nsteps: int, record: bool) -> StepStats:
        """run() on the CPU (numba's thread count and chunk size set by the caller)."""
        if self.sort_every_steps and self.step_count - self._last_sort >= self.sort_every_steps:
            self._sort()
        return self._steps(nsteps, record)

    def runs_before_sort(self, steps: int) -> int | None:
        """How many run() calls of ``steps`` steps each, the first starting now, start
        without reordering the beads (:meth:`_sort`, due every ``sort_every_steps``); None:
        no reordering."""
        if not self.sort_every_steps:
            return None
        left = self.sort_every_steps - (self.step_count - self._last_sort)
        return max(0, -(-left // int(steps)))

    def advance_args(self, record: bool, swapped: bool = False) -> tuple:
        """The arguments of the kernels' ``advance`` after the step count, the neighbour
        lists as they are (or, with swapped, the spare set in their place: the lists after
        one build)."""
        a, b = self._LISTS, self._LISTS_O
        if swapped:
            a, b = b, a
        lists = tuple(getattr(self, k) for k in a) + tuple(getattr(self, k) for k in b)
        return ((self.x, self.v, self.w, self.f, self.t, self.rad, self.mass, self.inertia,
                 self.inv_m, self.inv_i, self.xref, self.prm, self.wrapk, self.cutoff_m)
                + lists + (self.shw, self.flw, self.cb, self.need, self.maxj, self.dmax,
                           record, self.evc, self.evn, self.evbuf, self.evcount, self.acc,
                           self.fb, self.tb, self.torq, self.fext, self.claims()))

    def _steps(self, nsteps: int, record: bool, first=None) -> StepStats:
        """nsteps steps by the kernels' ``advance`` (and, where its neighbour lists
        overflow, the build and the step's end here). ``first``: (steps, status) of an
        ``advance`` call already made for these nsteps (its lists swapped, its counts in
        acc and evcount), which is taken as this loop's first call's."""
        K = self.K
        done = 0
        chunks = []
        torque = 0.0
        chamber = 0.0
        dropped = 0
        builds = 0
        while done < nsteps:
            if first is not None:
                k, status = first
                first = None
            else:
                self.evcount[0] = 0
                self.acc[:] = 0.0
                k, status, parity = K.advance(nsteps - done, *self.advance_args(record))
                if parity:
                    self._swap_lists()
            m = int(self.evcount[0])
            if m:
                ev = self.evbuf[:m].copy()
                ev[:, K.EV_STEP] += self.step_count + done
                # bead slots -> initial bead ids
                ev[:, K.EV_I] = self.ids[ev[:, K.EV_I].astype(np.int64)]
                bb = ev[:, K.EV_J] >= 0
                ev[bb, K.EV_J] = self.ids[ev[bb, K.EV_J].astype(np.int64)]
                chunks.append(ev)
            torque += self.acc[0]
            chamber += self.acc[4]
            dropped += int(self.acc[3])
            builds += int(self.acc[2])
            if status == 1:
                # the new lists overflowed during step k: enlarge, rebuild, close the step
                self._build(do_wrap=False)
                self._finish(record=record, kick=0.5 * self.dt_s)
                torque += float(self.torq[:, 0].sum())
                chamber += float(self.torq[:, 1].sum())
                for c in range(self.evn.size):
                    kk = min(int(self.evn[c]), self.evc.shape[1])
                    if kk:
                        ev = self.evc[c, :kk].copy()
                        ev[:, K.EV_STEP] = self.step_count + done + k
                        ev[:, K.EV_I] = self.ids[ev[:, K.EV_I].astype(np.int64)]
                        bb = ev[:, K.EV_J] >= 0
                        ev[bb, K.EV_J] = self.ids[ev[bb, K.EV_J].astype(np.int64)]
                        chunks.append(ev)
                k += 1
            elif status == 2:
                pass  # buffer drained above; continue
            done += k
        self.step_count += nsteps
        events = np.concatenate(chunks) if chunks else np.zeros((0, K.EV_NF))
        return StepStats(steps=nsteps, events=events, torque_sum_nm_steps=torque,
                         chamber_torque_sum_nm_steps=chamber,
                         dropped_events=dropped, neighbour_builds=builds)

    def _pairs(self):
        """(i, j, s) of every pair in the current neighbour lists (partner j > i, image
        code s), as arrays."""
        if self._gpu is not None:
            return self._gpu.pairs()
        i = np.repeat(np.arange(self.n), self.nnb)
        first = np.cumsum(self.nnb) - self.nnb
        pos = np.repeat(self.pst, self.nnb) + (np.arange(i.size) - np.repeat(first, self.nnb))
        return i, self.pj[pos].astype(np.int64), self.pim[pos].astype(np.int64)

    # ---- observables ------------------------------------------------------------------
    def kinetic_energy_j(self) -> tuple[float, float]:
        """Translational and rotational kinetic energy of all beads [J]."""
        et = 0.5 * float(np.sum(self.mass * np.einsum("ij,ij->i", self.v, self.v)))
        er = 0.5 * float(np.sum(self.inertia * np.einsum("ij,ij->i", self.w, self.w)))
        return et, er

    def hertz_energy_j(self) -> float:
        """Elastic energy stored in bead-bead and bead-wall overlaps [J]:
        U = 8/15 Y* sqrt(R*) delta^(5/2) per contact (integral of the Hertz force)."""
        K = self.K
        ys = self.material.effective_youngs_pa
        x = self.x
        u = 0.0
        lz = self.geometry.height_m
        sec = self.geometry.sector_rad
        for i, j, s in zip(*self._pairs()):
            xj = x[j].copy()
            if s:
                c, sn = math.cos(s * sec), math.sin(s * sec)
                xj[0], xj[1] = c * x[j, 0] - sn * x[j, 1], sn * x[j, 0] + c * x[j, 1]
            d = x[i] - xj
            d[2] -= lz * math.floor(d[2] / lz + 0.5)
            delta = self.rad[i] + self.rad[j] - math.sqrt(d @ d)
            if delta > 0:
                rs = self.rad[i] * self.rad[j] / (self.rad[i] + self.rad[j])
                u += 8.0 / 15.0 * ys * math.sqrt(rs) * delta ** 2.5
        for i in range(self.n):
            for q in range(K.NWALL):
                dist, _, _, _, ok = K.wall_gap(x[i, 0], x[i, 1], x[i, 2], self.rad[i], q,
                                               self.prm)
                delta = self.rad[i] - dist
                if ok and delta > 0:
                    u += 8.0 / 15.0 * ys * math.sqrt(self.rad[i]) * delta ** 2.5
        return u
