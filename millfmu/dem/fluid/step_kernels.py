"""One fluid substep as two numba calls (the pressure solve between them is SuperLU's):
:func:`predictor` (fluxes, stresses, explicit rates, wall torques, implicit-drag predictor,
exchange bookkeeping, the projection's right-hand side) and :func:`corrector`
(projection, pressure, turbulence, the next stable step). They only sequence the kernels
of :mod:`~millfmu.dem.fluid.vans_kernels` and :mod:`~millfmu.dem.fluid.k_epsilon`, so that
a substep pays the call overhead of two dispatches instead of some thirty.

Arrays travel in tuples (see :class:`millfmu.dem.fluid.solver.FluidSolver`): F, the state
and what the beads impose; W, work arrays; K, the int8 node kinds and cell kinds.
"""

import math

import numpy as np

from millfmu.dem.engine._jit import serial
from millfmu.dem.fluid import anderson_jackson1967 as AJ
from millfmu.dem.fluid import k_epsilon as KE
from millfmu.dem.fluid import vans_kernels as VK

# positions in the tuples
(UR, UT, UZ, P, KT, ET, NUT, EPSC, EPSC0, EPSR, EPST, EPSZ, KDR, KDT, KDZ, SDR, SDT, SDZ,
 FIXT, MUR, MUT, MUZ, MGR, MGT, MGZ, KDTA, SDTA) = range(27)
(FR, FT, FZ, DIV, TRR, TTT, TZZ, S2, ERT, ERZ, ETZ, GRT, GRZ, GTZ, RR, RT, RZ, GPR, GPT,
 GPZ, EM, PROD, EWALL, KNEW, ENEW, GHR, GHT, GHZ, ZR, ZC, TFR, DFR, TFT, DFT, TFZ,
 DFZ) = range(36)
KR, KTH, KZ, SOLID = range(4)


@serial
def predictor(F, W, K, rf, rc, dr, vc, dth, dz, om_sh, rho, nu, kturb, model_a,
              stress_force, body_z, dt, interval, acc):
    """Explicit part and implicit-drag predictor of one substep of dt [s]; leaves the
    projection's right-hand side (rho / dt) (net outflow of eps u* + V d eps / dt) in
    W[DIV] and adds to acc: [0] shaft, [1] rotor cells and vanes, [2] stator angular impulse
    the fluid gave [N m s], [3] angular and [4] axial impulse the beads gave the fluid
    [N m s, N s]. The theta predictor uses the beads' and the vanes' drag together (KDTA,
    SDTA); the vanes' part (KDTA - KDT, SDTA - SDT) is their torque. Three parts, of which
    the last two are independent (the fused exchange runs them side by side):
    :func:`predict_velocities`, :func:`predictor_sums`, :func:`projection_rhs`."""
    predict_velocities(F, W, K, rf, rc, dr, vc, dth, dz, om_sh, rho, nu, kturb, model_a,
                       stress_force, body_z, dt)
    predictor_sums(F, W, K, rf, rc, vc, dth, dz, dt, acc)
    projection_rhs(F, W, rf, dr, vc, dth, dz, rho, dt, interval)


@serial
def predict_velocities(F, W, K, rf, rc, dr, vc, dth, dz, om_sh, rho, nu, kturb, model_a,
                       stress_force, body_z, dt):
    """The predictor's first part: fluxes, stresses, explicit rates, pressure gradients and
    the implicit-drag predicted velocities u* (in place of u). stress_force (model A): the
    beads take the resolved viscous stress's share too
    (:mod:`~millfmu.dem.fluid.anderson_jackson1967`): the stresses carry no eps, and
    -dt div tau joins the interval's pressure-gradient sums, which the beads read."""
    kr, kt, kz, solid = K[KR], K[KTH], K[KZ], K[SOLID]
    ur, ut, uz = F[UR], F[UT], F[UZ]
    VK.face_fluxes(ur, ut, uz, F[EPSR], F[EPST], F[EPSZ], rf, dr, vc, dth, dz, W[FR], W[FT],
                   W[FZ])
    if kturb:
        KE.eddy_viscosity(F[KT], F[ET], solid, F[NUT])
    em = W[EM]
    # the stresses' weight: eps in model A, unless the beads take their share of them
    eps_weight = model_a and not stress_force
    nr, nt, nz = ut.shape
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                if solid[i, j, k] != 0:
                    em[i, j, k] = 0.0
                else:
                    a = F[EPSC][i, j, k] if eps_weight else 1.0
                    em[i, j, k] = a * rho * (nu + F[NUT][i, j, k])
    VK.stresses(ur, ut, uz, kr, kt, kz, em, F[EPSC], F[KT], solid, rf, rc, dr, dth, dz, om_sh,
                rho, nu, kturb, eps_weight, W[TRR], W[TTT], W[TZZ], W[S2], W[ERT], W[ERZ],
                W[ETZ], W[GRT], W[GRZ], W[GTZ])
    VK.rates(ur, ut, uz, W[FR], W[FT], W[FZ], kr, kt, kz, W[TRR], W[TTT], W[TZZ], W[ERT],
             W[ERZ], W[ETZ], F[EPSR], rf, rc, dr, vc, dth, dz, rho, W[RR], W[RT], W[RZ])
    if stress_force:
        AJ.add_stress_force(W[TRR], W[TTT], W[TZZ], W[ERT], W[ERZ], W[ETZ], kr, kt, kz, rf, rc,
                            dr, vc, dth, dz, -dt, F[MGR], F[MGT], F[MGZ])
    VK.pressure_gradients(F[P], solid, rc, dr, dth, dz, W[GPR], W[GPT], W[GPZ])
    VK.predict(ur.reshape(-1), kr.reshape(-1), F[EPSR].reshape(-1), W[RR].reshape(-1),
               F[KDR].reshape(-1), F[SDR].reshape(-1), W[GPR].reshape(-1), 0.0, rho, dt,
               W[ZR].reshape(-1))
    VK.predict(ut.reshape(-1), kt.reshape(-1), F[EPST].reshape(-1), W[RT].reshape(-1),
               F[KDTA].reshape(-1), F[SDTA].reshape(-1), W[GPT].reshape(-1), 0.0, rho, dt,
               F[FIXT].reshape(-1))
    VK.predict(uz.reshape(-1), kz.reshape(-1), F[EPSZ].reshape(-1), W[RZ].reshape(-1),
               F[KDZ].reshape(-1), F[SDZ].reshape(-1), W[GPZ].reshape(-1), body_z, rho, dt,
               W[ZC].reshape(-1))


@serial
def predictor_sums(F, W, K, rf, rc, vc, dth, dz, dt, acc):
    """The predictor's sums after u*: the wall torques' and the beads' impulses into acc
    (in this order: [0]-[2] the walls, [1] the vanes, [3], [4] the beads) and u* added,
    times dt, to the interval's mean velocities."""
    kt, kz, solid = K[KTH], K[KZ], K[SOLID]
    ur, ut, uz = F[UR], F[UT], F[UZ]
    sh, rot, sta = VK.wall_torques(W[ERT], W[ETZ], kt, solid, rf, rc, vc, dth, dz)
    acc[0] += sh * dt
    acc[1] += rot * dt
    acc[2] += sta * dt
    # the beads' drag acted on u* (implicit in the predictor): what they exchange, and the
    # velocity they are given back
    ang = 0.0
    axl = 0.0
    vane = 0.0
    nr, nt, nz = ut.shape
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                if kt[i, j, k] == 0:
                    ang += rc[i] * vc[i] * (F[KDT][i, j, k] * ut[i, j, k] - F[SDT][i, j, k])
                    vane += rc[i] * vc[i] * ((F[KDTA][i, j, k] - F[KDT][i, j, k]) *
                                             ut[i, j, k] - (F[SDTA][i, j, k] -
                                                            F[SDT][i, j, k]))
                if kz[i, j, k] == 0:
                    axl += vc[i] * (F[KDZ][i, j, k] * uz[i, j, k] - F[SDZ][i, j, k])
                F[MUT][i, j, k] += dt * ut[i, j, k]
                F[MUZ][i, j, k] += dt * uz[i, j, k]
    acc[1] += vane * dt
    acc[3] -= ang * dt
    acc[4] -= axl * dt
    mr = F[MUR]
    for i in range(nr + 1):
        for j in range(nt):
            for k in range(nz):
                mr[i, j, k] += dt * ur[i, j, k]


@serial
def projection_rhs(F, W, rf, dr, vc, dth, dz, rho, dt, interval):
    """The projection's right-hand side from u*: (rho / dt) (net outflow of eps u* +
    V d eps / dt) in W[DIV]."""
    ur, ut, uz = F[UR], F[UT], F[UZ]
    VK.face_fluxes(ur, ut, uz, F[EPSR], F[EPST], F[EPSZ], rf, dr, vc, dth, dz, W[FR], W[FT],
                   W[FZ])
    div = W[DIV]
    VK.divergence(W[FR], W[FT], W[FZ], div)
    nr, nt, nz = ut.shape
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                b = div[i, j, k]
                if interval > 0.0:
                    b += vc[i] * (F[EPSC][i, j, k] - F[EPSC0][i, j, k]) / interval
                div[i, j, k] = b * rho / dt


@serial
def corrector(F, W, K, phi, wall, wall_om, rf, rc, dr, vc, dth, dz, rho, nu, kturb, dt,
              cfl):
    """Projection with the pressure increment phi [Pa], the new pressure and its gradient
    (added, times dt, to the interval means), k-epsilon; returns the largest stable
    substep [s] for the new state (advective CFL number ``cfl``, explicit diffusion)."""
    project(F, W, K, phi, rc, dr, dth, dz, rho, dt)
    return turbulence(F, W, K, wall, wall_om, rf, rc, dr, vc, dth, dz, nu, kturb, dt, cfl,
                      np.bool_(True))


@serial
def project(F, W, K, phi, rc, dr, dth, dz, rho, dt):
    """The corrector's first part: the projection with the pressure increment phi [Pa], the
    new pressure and its gradient (added, times dt, to the interval means)."""
    kr, kt, kz, solid = K[KR], K[KTH], K[KZ], K[SOLID]
    ur, ut, uz = F[UR], F[UT], F[UZ]
    VK.pressure_gradients(phi, solid, rc, dr, dth, dz, W[GHR], W[GHT], W[GHZ])
    VK.correct(ur.reshape(-1), kr.reshape(-1), F[EPSR].reshape(-1), W[GHR].reshape(-1), rho, dt)
    VK.correct(ut.reshape(-1), kt.reshape(-1), F[EPST].reshape(-1), W[GHT].reshape(-1), rho, dt)
    VK.correct(uz.reshape(-1), kz.reshape(-1), F[EPSZ].reshape(-1), W[GHZ].reshape(-1), rho, dt)
    p = F[P]
    nr, nt, nz = ut.shape
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                p[i, j, k] += phi[i, j, k]
    VK.pressure_gradients(p, solid, rc, dr, dth, dz, W[GPR], W[GPT], W[GPZ])
    for i in range(nr + 1):
        for j in range(nt):
            for k in range(nz):
                F[MGR][i, j, k] += dt * W[GPR][i, j, k]
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                F[MGT][i, j, k] += dt * W[GPT][i, j, k]
                F[MGZ][i, j, k] += dt * W[GPZ][i, j, k]


@serial
def turbulence(F, W, K, wall, wall_om, rf, rc, dr, vc, dth, dz, nu, kturb, dt, cfl,
               on_threads):
    """The corrector's second part: k-epsilon (where kturb) on the corrected velocities,
    its rows on the threads (on_threads) or all on the calling thread (the same results:
    each row writes its own cells); returns the largest stable substep [s] for the new
    state. Reads only the velocities, the void fraction and its own fields: the coupled
    exchange runs the interval's last one beside the smoothing of the cell values
    (:func:`millfmu.dem.coupling.fused_exchange.exchange_interval`)."""
    solid = K[SOLID]
    ur, ut, uz = F[UR], F[UT], F[UZ]
    if kturb:
        VK.face_fluxes(ur, ut, uz, F[EPSR], F[EPST], F[EPSZ], rf, dr, vc, dth, dz, W[FR],
                       W[FT], W[FZ])
        # is_eps as a typed value, not a constant: numba compiles a kernel once for each
        # constant a compiled caller passes; one transport for k and epsilon saves a
        # compilation of each form (about 15 s on 2 cores), the same code either way
        is_k = np.bool_(False)
        is_e = np.bool_(True)
        if on_threads:
            KE.production(ur, ut, uz, F[NUT], W[S2], W[GRT], W[GRZ], W[GTZ], solid, wall,
                          wall_om, F[KT], rc, dr, dth, dz, nu, W[PROD], W[EWALL])
            KE.transport(F[KT], F[KT], F[ET], is_k, W[FR], W[FT], W[FZ], F[EPSC], F[NUT],
                         solid, W[PROD], W[EWALL], rf, rc, dr, vc, dth, dz, nu, dt, KE.K_MIN,
                         W[KNEW], W[TFR], W[DFR], W[TFT], W[DFT], W[TFZ], W[DFZ])
            KE.transport(F[ET], F[KT], F[ET], is_e, W[FR], W[FT], W[FZ], F[EPSC], F[NUT],
                         solid, W[PROD], W[EWALL], rf, rc, dr, vc, dth, dz, nu, dt,
                         KE.EPS_MIN, W[ENEW], W[TFR], W[DFR], W[TFT], W[DFT], W[TFZ],
                         W[DFZ])
        else:
            KE.production_serial(ur, ut, uz, F[NUT], W[S2], W[GRT], W[GRZ], W[GTZ], solid,
                                 wall, wall_om, F[KT], rc, dr, dth, dz, nu, W[PROD],
                                 W[EWALL])
            KE.transport_serial(F[KT], F[KT], F[ET], is_k, W[FR], W[FT], W[FZ], F[EPSC],
                                F[NUT], solid, W[PROD], W[EWALL], rf, rc, dr, vc, dth, dz,
                                nu, dt, KE.K_MIN, W[KNEW], W[TFR], W[DFR], W[TFT],
                                W[DFT], W[TFZ], W[DFZ])
            KE.transport_serial(F[ET], F[KT], F[ET], is_e, W[FR], W[FT], W[FZ], F[EPSC],
                                F[NUT], solid, W[PROD], W[EWALL], rf, rc, dr, vc, dth, dz,
                                nu, dt, KE.EPS_MIN, W[ENEW], W[TFR], W[DFR], W[TFT],
                                W[DFT], W[TFZ], W[DFZ])
        F[KT][:] = W[KNEW]
        F[ET][:] = W[ENEW]
        KE.eddy_viscosity(F[KT], F[ET], solid, F[NUT])
    return stable_dt(ur, ut, uz, F[NUT], rc, dr, dth, dz, nu, cfl)


@serial
def _scale(a, zero, div):
    """a[:] = 0 (zero) or a[:] = a / div, element by element as numpy's."""
    f = a.reshape(-1)
    for n in range(f.size):
        f[n] = 0.0 if zero else f[n] / div


@serial
def start_interval(F, acc):
    """Before an interval's substeps: the sums of its mean velocities and pressure
    gradients and the impulse accumulator acc zeroed (one call instead of seven numpy
    passes, each a few microseconds on arrays that the DEM's steps pushed out of cache)."""
    _scale(F[MUR], True, 1.0)
    _scale(F[MUT], True, 1.0)
    _scale(F[MUZ], True, 1.0)
    _scale(F[MGR], True, 1.0)
    _scale(F[MGT], True, 1.0)
    _scale(F[MGZ], True, 1.0)
    for n in range(acc.size):
        acc[n] = 0.0


@serial
def finish_interval(F, interval):
    """After an interval's substeps: the sums divided by its length interval [s] (the
    means); returns whether every velocity u_r, u_theta is finite."""
    _scale(F[MUR], False, interval)
    _scale(F[MUT], False, interval)
    _scale(F[MUZ], False, interval)
    _scale(F[MGR], False, interval)
    _scale(F[MGT], False, interval)
    _scale(F[MGZ], False, interval)
    ok = True
    for a in (F[UT].reshape(-1), F[UR].reshape(-1)):
        for n in range(a.size):
            if not math.isfinite(a[n]):
                ok = False
    return ok


@serial
def ldl_solve(lp, li, lx, inv_d, order, b, y, x):
    """x with P A P^T = L D L^T and A x = b: y = b in the permuted order (row k of the
    permuted system is row order[k]), L y' = y with L unit lower triangular whose strictly
    lower part is (lp, li, lx) in compressed columns, y' / D, L^T x' = y'', x = x' in a's
    order (:mod:`millfmu.dem.fluid.ldl_pressure`). y: work array of b's size."""
    n = b.shape[0]
    for k in range(n):
        y[k] = b[order[k]]
    for j in range(n):
        yj = y[j]
        if yj != 0.0:
            for p in range(lp[j], lp[j + 1]):
                y[li[p]] -= lx[p] * yj
    for j in range(n):
        y[j] *= inv_d[j]
    for j in range(n - 1, -1, -1):
        s = y[j]
        for p in range(lp[j], lp[j + 1]):
            s -= lx[p] * y[li[p]]
        y[j] = s
    for k in range(n):
        x[order[k]] = y[k]


@serial
def ldl_project(b_cells, cells, volume, volume_sum, lp, li, lx, inv_d, order, rhs, y, x,
                out):
    """The projection's pressure solve with an L D L^T factor in one call
    (``pressure_solver = "direct_ldl"``): rhs = -(b - V mean) on the fluid cells (b_cells
    flat, cells their flat indices, volume their volumes [m3], volume_sum the sum), the
    pinned first unknown 0, :func:`ldl_solve`, and the solution written into out (flat,
    zero elsewhere). The gathers, sums and scatters of the LU path's numpy calls, here
    without their passes over arrays the DEM's steps pushed out of cache."""
    n = cells.shape[0]
    s = 0.0
    for k in range(n):
        rhs[k] = b_cells[cells[k]]
        s += rhs[k]
    mean = s / volume_sum
    for k in range(n):
        rhs[k] = -(rhs[k] - volume[k] * mean)
    rhs[0] = 0.0
    ldl_solve(lp, li, lx, inv_d, order, rhs, y, x)
    for c in range(out.shape[0]):
        out[c] = 0.0
    for k in range(n):
        out[cells[k]] = x[k]


@serial
def stable_dt(ur, ut, uz, nu_t, rc, dr, dth, dz, nu, cfl):
    """Largest substep [s]: advective CFL number ``cfl`` on every node, and explicit
    diffusion, dt (nu + nu_t)_max sum 1/h^2 <= 1/4."""
    nr, nt, nz = ut.shape
    m = 0.0
    for i in range(1, nr):
        h = rc[i] - rc[i - 1]
        for j in range(nt):
            for k in range(nz):
                a = abs(ur[i, j, k]) / h
                if a > m:
                    m = a
    ntm = 0.0
    for i in range(nr):
        ht = rc[i] * dth
        for j in range(nt):
            for k in range(nz):
                a = abs(uz[i, j, k]) / dz
                if a > m:
                    m = a
                if nt > 1:
                    a = abs(ut[i, j, k]) / ht
                    if a > m:
                        m = a
                if nu_t[i, j, k] > ntm:
                    ntm = nu_t[i, j, k]
    inv_h2 = 1.0 / dr.min() ** 2 + 1.0 / (dz * dz)
    if nt > 1:
        inv_h2 += 1.0 / (rc.min() * dth) ** 2
    dt_dif = 0.25 / ((nu + ntm) * inv_h2)
    if m <= 0.0:
        return dt_dif
    return min(cfl / m, dt_dif)


@serial
def take_beads(F, K, driven, eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z,
               rc, rho, slip_s, omega):
    """:meth:`millfmu.dem.fluid.solver.FluidSolver.set_beads` in two passes over the nodes
    (instead of some twenty numpy calls, each a pass): velocities rescaled by eps_old / eps_new
    (the node momenta kept), the new void fractions, drag coefficients and sources; then
    :func:`theta_drag_and_fixed`. The same arithmetic, element by element, as the numpy
    calls."""
    ur, ut, uz = F[UR], F[UT], F[UZ]
    er, et, ez = F[EPSR], F[EPST], F[EPSZ]
    nr1, nt, nz = ur.shape
    for i in range(nr1):
        for j in range(nt):
            for k in range(nz):
                ur[i, j, k] *= er[i, j, k] / eps_r[i, j, k]
                er[i, j, k] = eps_r[i, j, k]
                F[KDR][i, j, k] = kd_r[i, j, k]
                F[SDR][i, j, k] = sd_r[i, j, k]
    for i in range(nr1 - 1):
        for j in range(nt):
            for k in range(nz):
                ut[i, j, k] *= et[i, j, k] / eps_t[i, j, k]
                et[i, j, k] = eps_t[i, j, k]
                uz[i, j, k] *= ez[i, j, k] / eps_z[i, j, k]
                ez[i, j, k] = eps_z[i, j, k]
                F[EPSC0][i, j, k] = F[EPSC][i, j, k]
                F[EPSC][i, j, k] = eps_c[i, j, k]
                F[KDT][i, j, k] = kd_t[i, j, k]
                F[KDZ][i, j, k] = kd_z[i, j, k]
                F[SDT][i, j, k] = sd_t[i, j, k]
                F[SDZ][i, j, k] = sd_z[i, j, k]
    theta_drag_and_fixed(F, K, driven, rc, rho, slip_s, omega)


@serial
def theta_drag_and_fixed(F, K, driven, rc, rho, slip_s, omega):
    """The theta drag of beads and vanes together, (KDTA, SDTA) = (KDT, SDT) + K_v (1, omega
    r) with K_v = eps rho / slip_s at driven theta nodes (the vanes hold the swirl at omega
    r), 0 elsewhere; then the fixed nodes' velocities (u_r, u_z 0, u_theta FIXT). After the
    beads' fields (take_beads) and a new rotor speed (FluidSolver.set_omega)."""
    kr, kt, kz = K[KR], K[KTH], K[KZ]
    ur, ut, uz = F[UR], F[UT], F[UZ]
    et = F[EPST]
    nr1, nt, nz = ur.shape
    for i in range(nr1):
        for j in range(nt):
            for k in range(nz):
                if kr[i, j, k] != 0:
                    ur[i, j, k] = 0.0
    for i in range(nr1 - 1):
        for j in range(nt):
            for k in range(nz):
                kv = et[i, j, k] * rho / slip_s if driven[i, j, k] else 0.0
                F[KDTA][i, j, k] = F[KDT][i, j, k] + kv
                F[SDTA][i, j, k] = F[SDT][i, j, k] + kv * omega * rc[i]
                if kz[i, j, k] != 0:
                    uz[i, j, k] = 0.0
                if kt[i, j, k] != 0:
                    ut[i, j, k] = F[FIXT][i, j, k]
