"""CfdDem: the two-way coupling loop of beads and liquid (unresolved CFD-DEM).

Every coupling interval of ``steps`` DEM steps (seed 001: 10 DEM steps of 5e-6 s, CFD step
and coupling 5e-5 s):

1. beads -> grid (:mod:`millfmu.dem.coupling.projection`): bead volumes give the void
   fraction; each bead's drag coefficient c_i = V_i beta_i (Koch & Hill 2001 at its local
   void fraction and relative speed, :mod:`millfmu.dem.coupling.koch_hill2001`; held
   explicitly over the interval, or relaxed exactly where a bead's relaxation time is
   shorter than the interval) and
   c_i v_i give the implicit drag coefficient K and the explicit source per velocity node;
   in model A the reaction of the beads' pressure-gradient force V_i grad p joins the source.
2. the fluid advances over the interval (:class:`millfmu.dem.fluid.solver.FluidSolver`),
   the drag implicit in its velocity;
3. grid -> beads: the fluid velocity averaged over the interval's substeps and the pressure
   gradient, read at each bead through the transposed projection; the bead's force
   F_i = c_i (u(x_i) - v_i) - V_i grad p(x_i) (model A; model B: drag only, beta / eps) is
   held over the next ``steps`` DEM steps (``DemSimulation.fext``, in cylindrical
   components so that its torque about the axis is exact).

Conservation: the fluid's momentum sink sum_f (C_f u_f - D_f) equals the beads' gain
sum_i c_i (u(x_i) - v_i) to round-off, because interpolation is the transpose of
deposition (weights sum to one per bead) and both use the same interval-mean velocity; the
pressure-gradient part uses the previous interval's gradient on both sides. In model A the
liquid's -eps grad p is written as -grad p + (1 - eps) grad p with the second term the
deposited reaction of the beads' pressure force, so one pressure equation (coefficient 1)
serves both models. Angular momentum is exchanged as torque (c_i r_i deposited on the theta
nodes, whose equation is in angular-momentum form).
"""

from __future__ import annotations

import math
import numpy as np

from millfmu.dem.coupling.settings import CouplingSettings
from millfmu.dem.fluid.solver import FluidProperties, FluidSolver


class CfdDem:
    """Couples a :class:`millfmu.dem.sim.DemSimulation` to a fluid on ``grid``."""

    def __init__(self, sim, grid, fluid: FluidProperties, settings: CouplingSettings,
                 omega_rad_s: float):
        from millfmu.dem.coupling import koch_hill2001 as KH
        from millfmu.dem.coupling import projection as PJ
        from millfmu.dem.coupling.projection import Projector

        self.KH = KH
        self.PJ = PJ
        self.sim = sim
        self.grid = grid
        self.settings = settings
        self.model_b = settings.model == "B"
        self.solver = FluidSolver(grid, fluid, omega_rad_s, settings.turbulence,
                                  settings.model, cfl=settings.cfl)
        d = 2.0 * float(sim.rad.max())
        self.projector = Projector(grid, settings.smoothing_diameters * d, settings.eps_min)
        self.interval_s = settings.steps * sim.dt_s
        n = sim.n
        ncell = int(np.prod(grid.shape))
        self._idx = np.zeros((n, 8), np.int64)
        self._w = np.zeros((n, 8))
        self._tot = np.zeros((ncell, 6))
        self._vtot = np.zeros((ncell, 1))
        self._cellv = np.zeros((ncell, 6))
        self._bead = np.zeros((n, 6))
        self._eps_b = np.zeros((n, 1))
        self._c = np.zeros(n)
        # per bead, carried across intervals (permuted with the beads by the DEM's sort):
        # fluid velocity (u_r, u_t, u_z) [m/s] and pressure gradient [Pa/m] at the bead
        sim.register_per_bead("fluid_at_bead", np.zeros((n, 6)))
        self.vol = 4.0 / 3.0 * math.pi * sim.rad ** 3
        self.clipped_cells = 0
        self.stiffness = 0.0  # largest interval / bead relaxation time of the last interval
        self.intervals = 0
        self.angular_impulse_to_beads_nms = 0.0
        self.axial_impulse_to_beads_ns = 0.0

    # ---- one coupling interval ----------------------------------------------------------
    def exchange(self):
        """Beads -> grid, advance the fluid by one interval, grid -> bead forces (held in
        ``sim.fext`` over the next ``settings.steps`` DEM steps)."""
        sim, g, PJ, s = self.sim, self.grid, self.PJ, self.solver
        nr, nt, nz = g.shape
        vol = 4.0 / 3.0 * math.pi * sim.rad ** 3  # rows follow the DEM's sort
        rr, tt, zz = PJ.bead_stencils(sim.x, self.projector.rc, g.r_faces_m[0],
                                      g.r_faces_m[-1], g.dtheta_rad, nt, g.dz_m, nz,
                                      g.height_m, g.solid, self._idx, self._w)
        x, v = sim.x, sim.v
        inv_r = 1.0 / np.maximum(rr, 1e-300)
        vr = (x[:, 0] * v[:, 0] + x[:, 1] * v[:, 1]) * inv_r
        vt = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]) * inv_r
        vz = v[:, 2]
        # ---- void fraction ----
        PJ.deposit(self._idx, self._w, vol[:, None], self._vtot)
        self.projector.smooth_totals(self._vtot)
        vc = self.projector.vol_cells
        eps_c = 1.0 - self._vtot[:, 0].reshape(g.shape) / vc
        fluid = g.solid == 0
        low = fluid & (eps_c < self.settings.eps_min)
        self.clipped_cells = int(low.sum())
        eps_c = np.where(fluid, np.clip(eps_c, self.settings.eps_min, 1.0), 1.0)
        PJ.gather(self._idx, self._w, eps_c.reshape(-1, 1), self._eps_b)
        # ---- drag coefficients at the beads ----
        fab = sim.per_bead["fluid_at_bead"]
        urel = np.sqrt((fab[:, 0] - vr) ** 2 + (fab[:, 1] - vt) ** 2 + (fab[:, 2] - vz) ** 2)
        self.stiffness = self.KH.bead_coefficients(
            sim.rad, sim.mass, self._eps_b[:, 0], urel, s.fluid.viscosity_pa_s, s.rho,
            self.interval_s, self.model_b, self._c)
        c = self._c
        pf = 0.0 if self.model_b else 1.0  # beads feel grad p in model A only
        gpr, gpt, gpz = fab[:, 3], fab[:, 4], fab[:, 5] - s.body_z
        q = self._bead
        q[:, 0] = c  # drag coefficient, r and z
        q[:, 1] = c * rr  # torque coefficient, theta
        q[:, 2] = c * vr + pf * vol * gpr
        q[:, 3] = rr * (c * vt + pf * vol * gpt)
        q[:, 4] = c * vz + pf * vol * gpz
        q[:, 5] = 0.0
        PJ.deposit(self._idx, self._w, q, self._tot)
        self.projector.smooth_totals(self._tot)
        tot = self._tot.reshape(g.shape + (6,))
        kd, sd = [], []
        vols = (s.vol_r, s.vol_c, s.vol_c)
        for axis, (kind, ck, cs) in enumerate(((s.kr, 0, 2), (s.kt, 1, 3), (s.kz, 0, 4))):
            a = np.zeros(kind.shape)
            b = np.zeros(kind.shape)
            PJ.cells_to_nodes(np.ascontiguousarray(tot[..., ck]), kind, axis, a)
            PJ.cells_to_nodes(np.ascontiguousarray(tot[..., cs]), kind, axis, b)
            scale = vols[axis] * (s.rc[:, None, None] if axis == 1 else 1.0)
            kd.append(a / scale)
            sd.append(b / scale)
        # void fraction on the nodes: volume-weighted means of the cells beside them
        ve = vc * eps_c
        eps_r = np.ones(s.ur.shape)
        eps_r[1:nr] = (ve[:-1] + ve[1:]) / (vc[:-1] + vc[1:])
        eps_t = (ve + np.roll(ve, -1, axis=1)) / (vc + np.roll(vc, -1, axis=1))
        eps_z = (ve + np.roll(ve, -1, axis=2)) / (vc + np.roll(vc, -1, axis=2))
        s.set_beads(eps_c, eps_r, eps_t, eps_z, kd, sd, self.interval_s)
        s.advance(self.interval_s)
        # ---- grid -> beads ----
        cellv = self._cellv.reshape(g.shape + (6,))
        tmp = np.zeros(g.shape)
        for m, (val, kind, axis) in enumerate(((s.mean_u[0], s.kr, 0), (s.mean_u[1], s.kt, 1),
                                               (s.mean_u[2], s.kz, 2), (s.mean_gp[0], s.kr, 0),
                                               (s.mean_gp[1], s.kt, 1),
                                               (s.mean_gp[2], s.kz, 2))):
            PJ.nodes_to_cells(val, kind, axis, g.solid, tmp)
            cellv[..., m] = tmp
        self.projector.smooth_values(self._cellv)
        at = np.zeros((sim.n, 6))
        PJ.gather(self._idx, self._w, self._cellv, at)
        # forces over the next interval, with this interval's drag coefficients and the
        # pressure gradient the fluid was given the reaction of (the previous one)
        fr = c * (at[:, 0] - vr) - pf * vol * gpr
        tz = rr * (c * (at[:, 1] - vt) - pf * vol * gpt)
        fz = c * (at[:, 2] - vz) - pf * vol * gpz
        sim.fext[:, 0] = fr
        sim.fext[:, 1] = tz
        sim.fext[:, 2] = fz
        self.angular_impulse_to_beads_nms += float(tz.sum()) * self.interval_s
        self.axial_impulse_to_beads_ns += float(fz.sum()) * self.interval_s
        fab[:] = at
        self.intervals += 1

    def run(self, nsteps: int, record: bool = False):
        """Advance the coupled system by ``nsteps`` DEM steps (a whole number of coupling
        intervals); returns the list of the DEM's StepStats, one per interval."""
        k = self.settings.steps
        if nsteps % k:
            raise ValueError(f"nsteps = {nsteps}: must be a multiple of the coupling "
                             f"interval of {k} DEM steps")
        out = []
        for _ in range(nsteps // k):
            self.exchange()
            out.append(self.sim.run(k, record=record))
        return out

    # ---- observation --------------------------------------------------------------------
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
            with np.errstate(invalid="ignore"):
                out[name] = np.nanmean(b, axis=1) if b.shape[1] > 1 else b[:, 0, :]
        return out

    def angular_impulses_nms(self) -> dict:
        """Running time integrals [N m s] of the torques the fluid exerted on shaft, rotor
        cells (disc) and the walls at rest, in the simulated sector."""
        s = self.solver
        return dict(shaft=s.angular_impulse_shaft_nms, rotor_cells=s.angular_impulse_rotor_nms,
                    stator=s.angular_impulse_stator_nms)
