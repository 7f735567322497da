"""DemSimulation: owns the bead arrays and advances them with the numba kernels.

numba is imported here lazily (inside ``__init__``) so that importing this module stays
cheap; the kernels compile (or load from the cache) on the first simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millfmu.dem.geometry import MillGeometry
from millfmu.dem.params import BeadMaterial, koch_hill_f0_f3


@dataclass(frozen=True)
class FluidSettings:
    """Fluid seen by the beads [SI]. Defaults: water, seed 001 Table 1."""

    density_kg_m3: float = 998.2
    viscosity_pa_s: float = 1.002e-3
    drag: bool = True  # Koch-Hill drag from the prescribed swirl flow
    lubrication: bool = True
    lubrication_cutoff_m: float = 0.04e-3  # 0.05 d for 0.8 mm beads
    lubrication_min_gap_m: float = 0.4e-6  # 5e-4 d
    swirl_core_fraction: float = 0.25  # core rotation / stirrer rotation [-]
    swirl_layer_m: float = 0.7e-3  # boundary-layer thickness [m]
    void_fraction: float = 0.5  # used in the drag law [-]


@dataclass
class StepStats:
    """What one call of DemSimulation.run returns."""

    steps: int
    events: np.ndarray  # (n, EV_NF) rows, layout kernels.EV_*; step column made global
    torque_sum_nm_steps: float  # sum over steps of the torque beads exert on the stirrer
    chamber_torque_sum_nm_steps: float  # the same for the fixed chamber wall
    dropped_events: int
    neighbour_builds: int
    extra: dict = field(default_factory=dict)


class DemSimulation:
    """Soft-sphere DEM of monodisperse (or polydisperse) beads in a MillGeometry.

    Parameters (SI): geometry; material; positions_m (n, 3); radii_m (n,); omega_rad_s
    stirrer angular velocity about +z; dt_s; gravity_m_s2 (3,); fluid (None: no fluid
    forces at all); skin_m neighbour-list skin; threads: numba threads (None: all);
    sort_every_steps: reorder the beads along the cell grid every so many steps (memory
    locality; None: 200 for 2000 beads or more, else never); spins_rad_s (n, 3) initial
    angular velocities [rad/s] (None: at rest). After a reorder, row k of the bead arrays
    holds the bead ``ids[k]`` of the initial order.
    """

    def __init__(self, geometry: MillGeometry, material: BeadMaterial, positions_m,
                 radii_m, omega_rad_s: float, dt_s: float, gravity_m_s2=(0.0, 0.0, 0.0),
                 fluid: FluidSettings | None = None, skin_m: float | None = None,
                 max_neighbours: int = 24, velocities_m_s=None, threads: int | None = None,
                 sort_every_steps: int | None = None, spins_rad_s=None):
        import numba

        from millfmu.dem import kernels as K

        self.K = K
        self.geometry = geometry
        self.material = material
        self.fluid = fluid
        self.omega_rad_s = float(omega_rad_s)
        self.dt_s = float(dt_s)
        x = np.ascontiguousarray(positions_m, dtype=np.float64).copy()
        n = x.shape[0]
        if threads is None:
            # a few hundred beads gain nothing from threads, and parallel regions that
            # wait for a busy core cost more than the work
            threads = numba.config.NUMBA_NUM_THREADS if n >= 2000 else 1
        self.threads = int(threads)
        numba.set_num_threads(self.threads)
        self.n = n
        self.rad = np.ascontiguousarray(np.broadcast_to(radii_m, (n,)), dtype=np.float64).copy()
        rho = material.density_kg_m3
        self.mass = 4.0 / 3.0 * math.pi * self.rad ** 3 * rho
        self.inertia = 0.4 * self.mass * self.rad ** 2
        self.inv_m = 1.0 / self.mass
        self.inv_i = 1.0 / self.inertia
        self.x = x
        self.v = np.zeros((n, 3)) if velocities_m_s is None else \
            np.ascontiguousarray(velocities_m_s, dtype=np.float64).copy()
        self.w = np.zeros((n, 3)) if spins_rad_s is None else \
            np.ascontiguousarray(spins_rad_s, dtype=np.float64).copy()
        self.f = np.zeros((n, 3))
        self.t = np.zeros((n, 3))
        self.xref = x.copy()
        rmax = float(self.rad.max())
        hcut = fluid.lubrication_cutoff_m if (fluid and fluid.lubrication) else 0.0
        # default skin 0.375 d: on the annulus bench (2 threads) skins of 0.25, 0.375 and
        # 0.5 d gave 17, 22 and 19 M particle-steps/s (fewer builds against more pairs)
        self.skin_m = 0.375 * rmax * 2.0 if skin_m is None else float(skin_m)
        self.cutoff_m = 2.0 * rmax + hcut + self.skin_m
        if geometry.height_m / self.cutoff_m < 3.0:
            raise ValueError(
                f"height_m = {geometry.height_m!r}: the axial period must hold at least "
                f"three neighbour cells of {self.cutoff_m:.3e} m (bead diameter + "
                f"lubrication cutoff + skin)")
        prm = np.zeros(K.N_PRM)
        prm[K.P_DT] = self.dt_s
        prm[K.P_YSTAR] = material.effective_youngs_pa
        prm[K.P_GSTAR] = material.effective_shear_pa
        prm[K.P_BETA] = material.damping_beta
        prm[K.P_MU] = material.friction
        prm[K.P_MUR] = material.rolling_friction
        g = np.asarray(gravity_m_s2, dtype=float)
        if fluid is not None:
            # buoyancy: the fluid's pressure gradient carries rho_f / rho_p of the weight
            g = g * (1.0 - fluid.density_kg_m3 / rho)
            if fluid.lubrication:
                prm[K.P_LUB_ETA] = fluid.viscosity_pa_s
                prm[K.P_LUB_HCUT] = fluid.lubrication_cutoff_m
                prm[K.P_LUB_HMIN] = fluid.lubrication_min_gap_m
            prm[K.P_DRAG] = 1.0 if fluid.drag else 0.0
            prm[K.P_MUF] = fluid.viscosity_pa_s
            prm[K.P_EPSF] = fluid.void_fraction
            prm[K.P_KCORE] = fluid.swirl_core_fraction
            prm[K.P_DELTA] = fluid.swirl_layer_m
            prm[K.P_RHOF] = fluid.density_kg_m3
            prm[K.P_KH_F0], prm[K.P_KH_F3] = koch_hill_f0_f3(fluid.void_fraction)
        prm[K.P_GX:K.P_GZ + 1] = g
        prm[K.P_LZ] = geometry.height_m
        prm[K.P_SECTOR] = geometry.sector_rad
        prm[K.P_RSH] = geometry.shaft_radius_m
        prm[K.P_RCH] = geometry.chamber_radius_m
        prm[K.P_OMEGA] = self.omega_rad_s
        prm[K.P_RDISC] = geometry.disc_radius_m
        prm[K.P_BDISC] = geometry.disc_thickness_m
        prm[K.P_ZDISC] = geometry.disc_z_m
        prm[K.P_SKIN] = self.skin_m
        self.prm = prm
        # one chunk of beads per thread: each chunk has its own force buffer
        nch = max(1, self.threads)
        self.cb = np.linspace(0, n, nch + 1).astype(np.int64)
        self.need = np.zeros(nch, np.int64)
        self.maxj = np.zeros(nch, np.int64)
        self.fb = np.zeros((nch, n, 3))
        self.tb = np.zeros((nch, n, 3))
        self.dmax = np.zeros(nch)
        self.wrapk = np.zeros(n, np.int8)
        self._alloc_lists(max_neighbours)
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
        self.step_count = 0
        self.ids = np.arange(n)
        if sort_every_steps is None:
            sort_every_steps = 200 if n >= 2000 else 0
        self.sort_every_steps = int(sort_every_steps)
        self._last_sort = 0
        self._build()
        if self.sort_every_steps:
            self._sort()
        # forces of the initial state; contacts present now are not "new" later
        self._finish(record=False, kick=0.0)

    def register_per_bead(self, name: str, array: np.ndarray):
        """Keep ``array`` (first axis: beads, current row order) in ``per_bead[name]`` and
        reorder it with the beads whenever they are sorted."""
        if array.shape[0] != self.n:
            raise ValueError(f"{name}: first axis {array.shape[0]}, expected {self.n} beads")
        self.per_bead[name] = array

    # ---- neighbour lists --------------------------------------------------------------
    _LISTS = ("nb", "img", "nnb", "sh", "fl")

    def _alloc_lists(self, m: int, keep: bool = False):
        """Allocate current and spare neighbour lists with m slots per bead; with keep the
        current lists' contents are preserved."""
        n = self.n
        new = dict(nb=np.zeros((n, m), np.int32), img=np.zeros((n, m), np.int8),
                   nnb=np.zeros(n, np.int64), sh=np.zeros((n, m, 3)),
                   fl=np.zeros((n, m), np.uint8))
        if keep:
            old_m = self.nb.shape[1]
            for k in new:
                if k == "nnb":
                    new[k][:] = self.nnb
                else:
                    new[k][:, :old_m] = getattr(self, k)
        for k, a in new.items():
            setattr(self, k, a)
            setattr(self, k + "_o", np.zeros_like(a))

    def _swap_lists(self):
        for k in self._LISTS:
            a, b = getattr(self, k), getattr(self, k + "_o")
            setattr(self, k, b)
            setattr(self, k + "_o", a)

    def _build(self, do_wrap: bool = True):
        """Build new neighbour lists from the current ones and make them current."""
        K = self.K
        while True:
            longest = K.rebuild(self.x, self.v, self.w, self.shw, self.xref, self.prm,
                                self.wrapk, self.cutoff_m, do_wrap, self.nb, self.img,
                                self.nnb, self.sh, self.fl, self.nb_o, self.img_o,
                                self.nnb_o, self.sh_o, self.fl_o, self.cb, self.need,
                                self.maxj)
            if longest <= self.nb_o.shape[1]:
                self._swap_lists()
                return
            self._alloc_lists(int(longest * 1.3) + 4, keep=True)
            do_wrap = False

    def _finish(self, record: bool, kick: float):
        self.K.finish_step(self.x, self.v, self.w, self.f, self.t, self.rad, self.mass,
                           self.inertia, self.inv_m, self.inv_i, self.prm, self.nb,
                           self.img, self.nnb, self.sh, self.fl, self.shw, self.flw,
                           self.cb, self.maxj, record, self.evc, self.evn, self.torq,
                           self.xref, self.dmax, self.fb, self.tb, kick, self.fext)

    _PER_BEAD = ("x", "v", "w", "f", "t", "xref", "rad", "mass", "inertia", "inv_m",
                 "inv_i", "wrapk", "shw", "flw", "ids", "fext")

    def _sort(self):
        """Reorder beads by neighbour cell (z fastest), remapping the neighbour lists, so
        that beads close in space are close in memory."""
        g = self.geometry
        cs = self.cutoff_m
        x = self.x
        ix = np.floor((x[:, 0] + g.chamber_radius_m) / cs).astype(np.int64)
        iy = np.floor((x[:, 1] + g.chamber_radius_m) / cs).astype(np.int64)
        iz = np.floor(np.mod(x[:, 2], g.height_m) / cs).astype(np.int64)
        key = (ix * (iy.max() + 1) + iy) * (iz.max() + 1) + iz
        perm = np.argsort(key, kind="stable")
        inv = np.empty_like(perm)
        inv[perm] = np.arange(perm.size)
        # the pairs, flattened; a pair stays with its lower (new) index
        nnb = self.nnb
        rows = np.repeat(np.arange(self.n), nnb)
        cols = np.arange(rows.size) - np.repeat(np.cumsum(nnb) - nnb, nnb)
        pj = self.nb[rows, cols].astype(np.int64)
        ps = self.img[rows, cols].astype(np.int64)
        psh = self.sh[rows, cols].copy()
        pfl = self.fl[rows, cols]
        a = inv[rows]
        b = inv[pj]
        swap = a > b
        owner = np.where(swap, b, a)
        partner = np.where(swap, a, b)
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
            if k != "nnb":
                setattr(self, k, np.ascontiguousarray(getattr(self, k)[perm]))
        for k, a in self.per_bead.items():
            a[:] = a[perm]
        counts = np.bincount(owner, minlength=self.n)
        m = self.nb.shape[1]
        if counts.max() > m:
            m = int(counts.max() * 1.3) + 4
            self._alloc_lists(m)
        order = np.argsort(owner, kind="stable")
        owner, partner, ps, psh, pfl = (owner[order], partner[order], ps[order], psh[order],
                                        pfl[order])
        slot = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
        self.nb[:] = 0
        self.img[:] = 0
        self.sh[:] = 0.0
        self.fl[:] = 0
        self.nb[owner, slot] = partner
        self.img[owner, slot] = ps
        self.sh[owner, slot] = psh
        self.fl[owner, slot] = pfl
        self.nnb[:] = counts
        # the chunks' partner ranges changed with the names: recompute them
        for c in range(self.cb.size - 1):
            lo, hi = self.cb[c], self.cb[c + 1]
            rowmax = self.nb[lo:hi][np.arange(m)[None, :] < self.nnb[lo:hi, None]]
            self.maxj[c] = max(int(rowmax.max()) if rowmax.size else 0, hi - 1)
        self._last_sort = self.step_count

    # ---- time stepping ----------------------------------------------------------------
    def run(self, nsteps: int, record: bool = False) -> StepStats:
        """Advance nsteps steps; with record, return every contact at its first overlap."""
        import numba

        K = self.K
        numba.set_num_threads(self.threads)
        if self.sort_every_steps and self.step_count - self._last_sort >= self.sort_every_steps:
            self._sort()
        done = 0
        chunks = []
        torque = 0.0
        chamber = 0.0
        dropped = 0
        builds = 0
        while done < nsteps:
            self.evcount[0] = 0
            self.acc[:] = 0.0
            k, status, parity = K.advance(nsteps - done, self.x, self.v, self.w, self.f, self.t,
                                  self.rad, self.mass, self.inertia, self.inv_m, self.inv_i,
                                  self.xref, self.prm, self.wrapk, self.cutoff_m, self.nb,
                                  self.img, self.nnb, self.sh, self.fl, self.nb_o,
                                  self.img_o, self.nnb_o, self.sh_o, self.fl_o, self.shw,
                                  self.flw, self.cb, self.need, self.maxj, self.dmax, record,
                                  self.evc, self.evn, self.evbuf, self.evcount, self.acc,
                                  self.fb, self.tb, self.torq, self.fext)
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
                self._alloc_lists(int(self.nb.shape[1] * 1.5) + 4, keep=True)
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
        for i in range(self.n):
            for k in range(int(self.nnb[i])):
                j = int(self.nb[i, k])
                if j <= i:
                    continue
                s = int(self.img[i, k])
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
