"""FluidSolver: the volume-averaged liquid of the bead mill on a :class:`CylGrid`.

State: u_r, u_theta, u_z [m/s] on the staggered nodes, pressure p [Pa] (dynamic: the
hydrostatic part rho g.x is taken out, the beads' gravity is reduced by rho_f/rho_p
instead), and for k-epsilon the turbulent kinetic energy k [m2/s2] and its dissipation
epsilon [m2/s3] at cell centres. What the beads give it (void fraction per cell and per
velocity node, drag coefficients K [kg/(m3 s)] and drag sources S [N/m3] per node) is set
by the coupling (:mod:`millfmu.dem.coupling`) once per coupling interval; without beads the
void fraction is 1 and the solver is a plain single-phase solver (the closed-form checks
use that).

One call of :meth:`FluidSolver.advance` covers a coupling interval in as many equal
substeps as the advective CFL number (default 0.4) and the explicit diffusion limit need,
and returns nothing; the node velocities and pressure gradients averaged over the
substeps (what the beads feel over that interval) are in ``mean_u`` and ``mean_gp`` (with
``stress_force``, model A's beads' share of the viscous stress too: ``mean_gp`` then holds
grad p - div tau, :mod:`~millfmu.dem.fluid.anderson_jackson1967`).
Torques the fluid exerts on rotor and stator are accumulated as angular impulse [N m s]
over time so that any window's mean torque follows from two readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millfmu.dem.fluid.grid import FLUID, ROTOR, STATOR, CylGrid
from millfmu.dem.fluid.pressure import PressureSolver
from millfmu.dem.fluid.settings import DEFAULT_PRESSURE_SOLVER

MODELS = ("A", "B")
#: Slip time [s] of the liquid between a rotor's vanes (driven cells): the vanes hold the
#: swirl there at the rotor's speed. Radial vanes leave no path for relative swirl, so the
#: slip is set far below the coupling interval (5e-5 s); the implicit predictor keeps any
#: value stable, and the torque it takes is the vanes' share of the rotor torque.
VANE_SLIP_TIME_S = 1e-5
TURBULENCE = ("k_epsilon", "laminar")
#: what a run's description says of each pressure solver
#: (:data:`millfmu.dem.fluid.settings.PRESSURE_SOLVERS`)
PRESSURE_DESCRIPTIONS = {
    "direct_lu": "direct sparse LU of the constant projection operator",
    "theta_fft": "FFT in theta and a direct sparse LU of each mode's 2D operator (theta_fft)",
    "direct_ldl": "direct symmetric factor L D L^T of the constant projection operator on a "
                  "minimum-degree ordering (direct_ldl)",
}


class FluidError(ValueError):
    """A fluid setting that is not allowed, or a fluid state that went bad."""


@dataclass(frozen=True)
class FluidProperties:
    """Liquid [SI]. Defaults: water, seed 001 Table 1."""

    density_kg_per_m3: float = 998.2
    viscosity_Pa_s: float = 1.002e-3

    @property
    def nu_m2_per_s(self) -> float:
        return self.viscosity_Pa_s / self.density_kg_per_m3


def _check_options(model: str, turbulence: str, cfl: float, stress_force: bool = False) -> None:
    """Refuse by name (FluidError) a model, turbulence model or CFL number not allowed, and
    the beads' stress force with a model other than A."""
    if model not in MODELS:
        raise FluidError(f"fluid model = {model!r}: allowed {list(MODELS)}")
    if stress_force and model != "A":
        raise FluidError(f"stress_force with fluid model = {model!r}: only model A gives the "
                         f"beads the generalized buoyancy (model B's drag over eps carries it)")
    if turbulence not in TURBULENCE:
        raise FluidError(f"turbulence = {turbulence!r}: allowed {list(TURBULENCE)}")
    if not 0.0 < cfl <= 0.5:
        raise FluidError(f"cfl = {cfl!r}: allowed 0 < cfl <= 0.5")


class FluidSolver:
    """VANS solver (model "A" or "B", turbulence "k_epsilon" or "laminar") on ``grid``,
    with the rotor (shaft if ``grid.shaft_rotates``, and ROTOR cells) turning at
    ``omega_rad_per_s`` [rad/s] about +z. ``stress_force`` (model A): the beads take their
    share of the resolved viscous stress (:mod:`~millfmu.dem.fluid.anderson_jackson1967`)."""

    def __init__(self, grid: CylGrid, fluid: FluidProperties = FluidProperties(),
                 omega_rad_per_s: float = 0.0, turbulence: str = "k_epsilon", model: str = "A",
                 cfl: float = 0.4, pressure_solver: str = DEFAULT_PRESSURE_SOLVER,
                 stress_force: bool = False):
        # numba kernels: compiled when a fluid is built, not with a scene file.
        from millfmu.dem.fluid import k_epsilon as KE
        from millfmu.dem.fluid import step_kernels as SK
        from millfmu.dem.fluid import vans_kernels as VK

        _check_options(model, turbulence, cfl, stress_force)
        self.VK = VK
        self.KE = KE
        self.SK = SK
        self.grid = grid
        self.fluid = fluid
        self.rho = float(fluid.density_kg_per_m3)
        self.nu = float(fluid.nu_m2_per_s)
        self.model = model
        self.stress_force = bool(stress_force)
        self.turbulence = turbulence
        self.cfl = float(cfl)
        g = grid
        self.rf = np.ascontiguousarray(g.r_faces_m, float)
        self.rc = np.ascontiguousarray(g.r_centres_m, float)
        self.dr = np.ascontiguousarray(g.dr_m, float)
        self.vc = np.ascontiguousarray(g.cell_volume_m3, float)
        self.dth = float(g.dtheta_rad)
        self.dz = float(g.dz_m)
        self.solid = np.ascontiguousarray(g.solid)
        self._make_node_kinds()
        self._make_control_volumes()
        self._make_walls()
        self._make_state()
        self._make_work_arrays()
        self._kf = self._turbulence_faces()
        self.pressure = PressureSolver(grid, pressure_solver)
        self._plate_faces = self._find_plate_faces()
        self._F = (self.ur, self.ut, self.uz, self.p, self.k, self.e, self.nu_t, self.eps_c,
                   self.eps_c_old, self.eps_r, self.eps_t, self.eps_z, self.kd_r, self.kd_t,
                   self.kd_z, self.sd_r, self.sd_t, self.sd_z, self.fixed_t, *self.mean_u,
                   *self.mean_gp, self.kd_t_all, self.sd_t_all)
        self._W = (self._fr, self._ft, self._fz, self._div, self._trr, self._ttt, self._tzz,
                   self._s2, self._ert, self._erz, self._etz, self._grt, self._grz,
                   self._gtz, self._rr, self._rt, self._rz, self._gpr, self._gpt, self._gpz,
                   self._em, self._prod, self._ewall, self._knew, self._enew, *self._gphi,
                   self._zero_r, self._zero_c, *self._kf)
        self._K = (self.kr, self.kt, self.kz, self.solid)
        self._acc = np.zeros(5)
        self._dt_stable = None
        # ---- accounting ----
        self.time_s = 0.0
        self.substeps = 0
        # time integrals of the fluid's torque on the turning shaft, on the rotor's solid
        # cells (disc) and vanes, and on the walls at rest [N m s]
        self.angular_impulse_shaft_nms = 0.0
        self.angular_impulse_rotor_nms = 0.0
        self.angular_impulse_stator_nms = 0.0
        # of which through the pressure and normal stress on stator plates' theta faces
        self.angular_impulse_plates_nms = 0.0
        self.exchange_angular_nms = 0.0  # angular impulse the beads gave the fluid
        self.exchange_axial_ns = 0.0
        self.last_substeps = 0
        self.set_omega(omega_rad_per_s)

    def _make_node_kinds(self) -> None:
        """Each velocity node's kind (kr, kt, kz: 0 solved, 1 on a wall surface, 2 inside
        a solid) and the theta nodes a rotor fixes (inside it or on its theta-normal
        face)."""
        nr = self.grid.shape[0]
        s = self.solid != FLUID
        kr = np.zeros((nr + 1,) + self.grid.shape[1:], np.int8)
        kr[0] = np.where(s[0], 2, 1)
        kr[nr] = np.where(s[nr - 1], 2, 1)
        kr[1:nr] = s[:-1].astype(np.int8) + s[1:]
        kt = (s.astype(np.int8) + np.roll(s, -1, axis=1)).astype(np.int8)
        kz = (s.astype(np.int8) + np.roll(s, -1, axis=2)).astype(np.int8)
        self.kr, self.kt, self.kz = kr, kt, kz
        rot = (self.solid == ROTOR)
        self._rot_t = (rot | np.roll(rot, -1, axis=1)) & (kt > 0)

    def _make_control_volumes(self) -> None:
        """Control volumes [m3], face areas [m2] and node distances [m] per node (r nodes
        on the radial faces, theta and z nodes with their cells)."""
        g = self.grid
        nr = g.shape[0]
        shp_r = (nr + 1,) + g.shape[1:]
        vr = np.zeros(nr + 1)
        vr[1:nr] = 0.5 * (self.vc[:-1] + self.vc[1:])
        vr[0], vr[nr] = 0.5 * self.vc[0], 0.5 * self.vc[-1]
        self.vol_r = np.broadcast_to(vr[:, None, None], shp_r).copy()
        self.vol_c = np.broadcast_to(self.vc[:, None, None], g.shape).copy()
        hr = np.ones(nr + 1)
        hr[1:nr] = self.rc[1:] - self.rc[:-1]
        self.area_r = np.broadcast_to((self.rf * self.dth * self.dz)[:, None, None], shp_r).copy()
        self.h_r = np.broadcast_to(hr[:, None, None], shp_r).copy()
        self.area_t = np.broadcast_to((self.dr * self.dz)[:, None, None], g.shape).copy()
        self.h_t = np.broadcast_to((self.rc * self.dth)[:, None, None], g.shape).copy()
        self.area_z = np.broadcast_to((self.vc / self.dz)[:, None, None], g.shape).copy()
        self.h_z = np.full(g.shape, self.dz)

    def _make_walls(self) -> None:
        """The walls the turbulence model sees: ``wall`` (face d of a fluid cell on a
        solid or the domain's radial bounds) and each such wall's angular velocity per
        unit omega (1 on the rotor, 0 at rest)."""
        g = self.grid
        nr, nt = g.shape[0], g.shape[1]
        s = self.solid != FLUID
        rot = (self.solid == ROTOR)
        wall = np.zeros(g.shape + (6,), np.bool_)
        f = ~s
        wall[0, :, :, 0] = f[0]
        wall[1:, :, :, 0] = f[1:] & s[:-1]
        wall[nr - 1, :, :, 1] = f[nr - 1]
        wall[:-1, :, :, 1] |= f[:-1] & s[1:]
        if nt > 1:
            wall[..., 2] = f & np.roll(s, 1, axis=1)
            wall[..., 3] = f & np.roll(s, -1, axis=1)
        wall[..., 4] = f & np.roll(s, 1, axis=2)
        wall[..., 5] = f & np.roll(s, -1, axis=2)
        self.wall = wall
        wom = np.zeros(g.shape + (6,))
        wom[0, :, :, 0] = 1.0 if g.shaft_rotates else 0.0
        wom[1:, :, :, 0] = rot[:-1]
        wom[:-1, :, :, 1] = rot[1:]
        wom[nr - 1, :, :, 1] = 0.0  # the chamber wall is at rest
        if nt > 1:
            wom[..., 2] = np.roll(rot, 1, axis=1)
            wom[..., 3] = np.roll(rot, -1, axis=1)
        wom[..., 4] = np.roll(rot, 1, axis=2)
        wom[..., 5] = np.roll(rot, -1, axis=2)
        self._wom_rot = wom * wall

    def _make_state(self) -> None:
        """The liquid at rest and what the beads impose on it (no beads: void fraction 1,
        no drag)."""
        g = self.grid
        shp_r = self.kr.shape
        self.ur = np.zeros(shp_r)
        self.ut = np.zeros(g.shape)
        self.uz = np.zeros(g.shape)
        self.p = np.zeros(g.shape)
        self.k = np.zeros(g.shape)
        self.e = np.zeros(g.shape)
        self.nu_t = np.zeros(g.shape)
        self.eps_c = np.ones(g.shape)
        self.eps_c_old = np.ones(g.shape)
        self.eps_r = np.ones(shp_r)
        self.eps_t = np.ones(g.shape)
        self.eps_z = np.ones(g.shape)
        self.kd_r = np.zeros(shp_r)
        self.kd_t = np.zeros(g.shape)
        self.kd_z = np.zeros(g.shape)
        self.sd_r = np.zeros(shp_r)
        self.sd_t = np.zeros(g.shape)
        self.sd_z = np.zeros(g.shape)
        self.body_z = 0.0  # axial body force per unit volume [N/m3] (e.g. -dP/dz)
        self.interval_s = None  # last coupling interval (continuity's d(eps)/dt)
        self.fixed_t = np.zeros(g.shape)  # u_theta of fixed theta nodes [m/s]
        # theta drag of beads and vanes together (what the predictor uses): the vanes of a
        # driven zone hold the swirl at omega r with a slip time of VANE_SLIP_TIME_S
        self.kd_t_all = np.zeros(g.shape)
        self.sd_t_all = np.zeros(g.shape)
        self._driven = (np.zeros(g.shape, np.bool_) if g.driven is None
                        else np.asarray(g.driven, np.bool_) & (self.kt == 0))

    def _make_work_arrays(self) -> None:
        """The kernels' work arrays and the interval's means (velocities and pressure
        gradients)."""
        shape = self.grid.shape
        shp_r = self.kr.shape
        self._fr = np.zeros(shp_r)
        self._ft = np.zeros(shape)
        self._fz = np.zeros(shape)
        self._div = np.zeros(shape)
        self._trr = np.zeros(shape)
        self._ttt = np.zeros(shape)
        self._tzz = np.zeros(shape)
        self._s2 = np.zeros(shape)
        self._ert = np.zeros(shp_r)
        self._erz = np.zeros(shp_r)
        self._etz = np.zeros(shape)
        self._grt = np.zeros(shp_r)
        self._grz = np.zeros(shp_r)
        self._gtz = np.zeros(shape)
        self._rr = np.zeros(shp_r)
        self._rt = np.zeros(shape)
        self._rz = np.zeros(shape)
        self._gpr = np.zeros(shp_r)
        self._gpt = np.zeros(shape)
        self._gpz = np.zeros(shape)
        self._em = np.zeros(shape)
        self._prod = np.zeros(shape)
        self._ewall = np.zeros(shape)
        self._knew = np.zeros(shape)
        self._enew = np.zeros(shape)
        self.mean_u = (np.zeros(shp_r), np.zeros(shape), np.zeros(shape))
        self.mean_gp = (np.zeros(shp_r), np.zeros(shape), np.zeros(shape))
        self._zero_r = np.zeros(shp_r)
        self._zero_c = np.zeros(shape)
        self._gphi = (np.zeros(shp_r), np.zeros(shape), np.zeros(shape))

    # ---- settings ---------------------------------------------------------------------
    def set_omega(self, omega_rad_per_s: float):
        """Rotor angular velocity [rad/s]: sets the fixed velocities of the solid nodes."""
        self.omega = float(omega_rad_per_s)
        self.om_shaft = self.omega if self.grid.shaft_rotates else 0.0
        self.fixed_t[:] = np.where(self._rot_t, self.omega * self.rc[:, None, None], 0.0)
        self.wall_om = self._wom_rot * self.omega
        self.SK.theta_drag_and_fixed(self._F, self._K, self._driven, self.rc, self.rho,
                                     VANE_SLIP_TIME_S, self.omega)

    def init_turbulence(self, k_m2_s2: float, length_m: float):
        """Uniform initial k [m2/s2] and epsilon = C_mu^(3/4) k^(3/2) / length [m2/s3]."""
        f = self.solid == FLUID
        self.k[:] = np.where(f, k_m2_s2, 0.0)
        self.e[:] = np.where(f, 0.09 ** 0.75 * k_m2_s2 ** 1.5 / length_m, 0.0)

    def init_solid_body(self, fraction: float):
        """u_theta = fraction * omega * r in the fluid (a start closer to the stirred state)."""
        m = self.kt == 0
        self.ut[m] = (fraction * self.omega * np.broadcast_to(self.rc[:, None, None],
                                                              self.ut.shape))[m]

    def set_beads(self, eps_c, eps_r, eps_t, eps_z, kd, sd, interval_s: float):
        """What the beads impose over the next coupling interval of ``interval_s`` [s]:
        void fractions per cell and per velocity node, drag coefficients per unit volume
        kd = (kd_r, kd_t, kd_z) [kg/(m3 s)] and sources sd [N/m3]. The node momenta
        eps u are kept (u rescaled by eps_old / eps_new): a change of the void fraction moves
        no momentum; the change per cell enters continuity as d(eps)/dt over the interval."""
        self.SK.take_beads(self._F, self._K, self._driven, eps_c, eps_r, eps_t, eps_z,
                           kd[0], kd[1], kd[2], sd[0], sd[1], sd[2], self.rc, self.rho,
                           VANE_SLIP_TIME_S, self.omega)
        self.interval_s = float(interval_s)

    # ---- stepping ---------------------------------------------------------------------
    def stable_dt(self) -> float:
        """Largest substep [s] for the advective CFL number and explicit diffusion."""
        return self.SK.stable_dt(self.ur, self.ut, self.uz, self.nu_t, self.rc, self.dr,
                                 self.dth, self.dz, self.nu, self.cfl)

    def advance(self, interval_s: float):
        """Advance the fluid by ``interval_s`` [s] (one coupling interval), in substeps of
        equal length within what :meth:`stable_dt` allows (re-evaluated after each)."""
        SK = self.SK
        acc = self._acc
        SK.start_interval(self._F, acc)
        if self._dt_stable is None:
            self._dt_stable = self.stable_dt()
        rho, nu = self.rho, self.nu
        model_a = self.model == "A"
        kturb = self.turbulence == "k_epsilon"
        done = 0.0
        n = 0
        while interval_s - done > 1e-12 * interval_s:
            rest = interval_s - done
            dt = rest / max(1, int(math.ceil(rest / self._dt_stable - 1e-9)))
            SK.predictor(self._F, self._W, self._K, self.rf, self.rc, self.dr, self.vc,
                         self.dth, self.dz, self.om_shaft, rho, nu, kturb, model_a,
                         self.stress_force, self.body_z, dt, self.interval_s or 0.0, acc)
            phi = self.pressure.solve(self._div)
            self._dt_stable = SK.corrector(self._F, self._W, self._K, phi, self.wall,
                                           self.wall_om, self.rf, self.rc, self.dr, self.vc,
                                           self.dth, self.dz, rho, nu, kturb, dt, self.cfl)
            if self._plate_faces is not None:
                jp = self.plate_torque_nm() * dt
                acc[2] += jp
                self.angular_impulse_plates_nms += jp
            done += dt
            n += 1
            self.time_s += dt
        self.close_interval(n, SK.finish_interval(self._F, interval_s))

    def close_interval(self, n: int, finite: bool):
        """After an interval of ``n`` substeps (:meth:`advance`, or the coupling's
        :mod:`~millfmu.dem.coupling.fused_exchange`): its impulses added to the running
        totals; FluidError where a velocity is not finite."""
        acc = self._acc
        self.substeps += n
        if self.grid.shaft_rotates:
            self.angular_impulse_shaft_nms += acc[0]
        else:
            self.angular_impulse_stator_nms += acc[0]
        self.angular_impulse_rotor_nms += acc[1]
        self.angular_impulse_stator_nms += acc[2]
        self.exchange_angular_nms += acc[3]
        self.exchange_axial_ns += acc[4]
        self.last_substeps = n
        if not finite:
            raise FluidError(f"fluid velocity not finite at t = {self.time_s:.6g} s")

    # ---- observables ------------------------------------------------------------------
    def angular_momentum_kgm2_s(self) -> float:
        """Angular momentum about +z of the liquid in the solved cells [kg m2/s]."""
        m = self.kt == 0
        lz = self.rho * self.eps_t * self.vol_c * self.rc[:, None, None] * self.ut
        return float(lz[m].sum())

    def axial_momentum_kgm_s(self) -> float:
        m = self.kz == 0
        return float((self.rho * self.eps_z * self.vol_c * self.uz)[m].sum())

    def _find_plate_faces(self):
        """Theta faces between a stator cell and a fluid cell (the faces of radial plates:
        baffles; the axisymmetric walls have none): the liquid pushes on them with its
        pressure and normal stress tau_theta_theta, which the scheme takes at the fluid
        cell beside the face; their torque goes to the stator (see advance). None without
        such faces, else (fluid cells ahead of a plate, their r dr dz [m3], fluid cells
        behind one, theirs)."""
        solid = self.grid.solid
        nt = solid.shape[1]
        if nt == 1:
            return None
        st = solid == STATOR
        fl = solid == FLUID
        ahead = np.nonzero(st & np.roll(fl, 1, axis=1))  # fluid at j - 1 pushes +theta
        behind = np.nonzero(st & np.roll(fl, -1, axis=1))  # fluid at j + 1 pushes -theta
        if not (ahead[0].size or behind[0].size):
            return None
        arm = self.rc * self.dr * self.dz
        return ((ahead[0], (ahead[1] - 1) % nt, ahead[2]), arm[ahead[0]],
                (behind[0], (behind[1] + 1) % nt, behind[2]), arm[behind[0]])

    def _turbulence_faces(self) -> tuple:
        """Work arrays of the k-epsilon transport's faces (advective flux and diffusive
        term per r-, theta- and z-face: :func:`millfmu.dem.fluid.k_epsilon.transport`)."""
        shp_r = self.ur.shape
        shp = self.ut.shape
        return (np.zeros(shp_r), np.zeros(shp_r), np.zeros(shp), np.zeros(shp),
                np.zeros(shp), np.zeros(shp))

    def __setstate__(self, state):
        # a solver pickled by sources before the plates' torque was counted (a run's
        # checkpoint) goes on with it counted from the resume on
        self.__dict__.update(state)
        if "stress_force" not in state:
            # sources before the beads' stress force: model A's beads had none
            self.stress_force = False
        if "_plate_faces" not in state:
            self._plate_faces = self._find_plate_faces()
            self.angular_impulse_plates_nms = 0.0
        if "_kf" not in state:
            # work arrays added since (their values are not state)
            self._kf = self._turbulence_faces()
            self._W = tuple(self._W) + self._kf

    def plate_torque_nm(self) -> float:
        """Torque about +z [N m] the liquid exerts through its pressure and normal stress on
        the theta faces of stator plates (baffles), in the last substep (simulated sector):
        the fluid cell beside a face holds the face's stress (as the theta momentum takes
        it), so the sum is what the liquid's solved nodes lose to the plates. 0 without
        plates."""
        if self._plate_faces is None:
            return 0.0
        ahead, arm_ahead, behind, arm_behind = self._plate_faces
        # p after the substep's projection, a tau_theta_theta of the substep; read at the
        # faces' cells only (a full-grid difference per substep for a few hundred faces)
        p, ttt = self.p, self._ttt
        return float((arm_ahead * (p[ahead] - ttt[ahead])).sum()
                     - (arm_behind * (p[behind] - ttt[behind])).sum())

    def wall_torques_nm(self) -> dict:
        """Torques [N m] the fluid exerted on shaft, rotor cells (disc) and stator in the
        last substep (simulated sector)."""
        sh, rot, sta = self.VK.wall_torques(self._ert, self._etz, self.kt, self.solid,
                                            self.rf, self.rc, self.vc, self.dth, self.dz)
        return dict(shaft=sh, rotor_cells=rot, stator=sta)

    def max_divergence_s(self) -> float:
        """Largest |div(eps u) + d eps/dt| over cells, per cell volume [1/s]."""
        VK = self.VK
        VK.face_fluxes(self.ur, self.ut, self.uz, self.eps_r, self.eps_t, self.eps_z,
                       self.rf, self.dr, self.vc, self.dth, self.dz, self._fr, self._ft,
                       self._fz)
        VK.divergence(self._fr, self._ft, self._fz, self._div)
        b = self._div / self.vol_c
        if self.interval_s:
            b = b + (self.eps_c - self.eps_c_old) / self.interval_s
        return float(np.abs(b[self.solid == FLUID]).max())

    def describe(self) -> dict:
        d = dict(model=self.model, turbulence=self.turbulence, grid=self.grid.describe(),
                 density_kg_per_m3=self.rho, viscosity_Pa_s=self.fluid.viscosity_Pa_s,
                 pressure=PRESSURE_DESCRIPTIONS[self.pressure.method],
                 cfl=self.cfl)
        if self.stress_force:
            d["bead_stress_force"] = "anderson_jackson1967"
        return d
