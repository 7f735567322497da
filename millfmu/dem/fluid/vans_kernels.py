"""Numba kernels of the volume-averaged Navier-Stokes (VANS) solver on the cylindrical MAC
grid of :mod:`millfmu.dem.fluid.grid`. Plain arrays, SI units; the Python side is
:class:`millfmu.dem.fluid.solver.FluidSolver`.

Equations (incompressible liquid of density rho, void fraction eps; Anderson & Jackson 1967,
"model A" and "model B" as in Zhou, Kuang, Chu & Yu 2010, J. Fluid Mech. 661, 482-510):

    d(eps)/dt + div(eps u) = 0
    rho [d(eps u)/dt + div(eps u u)] = -grad p + div(a tau) - (K u - S) + f_body

with a = eps in model A and a = 1 in model B; K u - S is what the beads take per unit
volume: the drag K (u - v_p), treated implicitly in u, and in model A the reaction of the
beads' pressure-gradient force, (1 - eps) grad p, which turns -grad p into model A's
-eps grad p (:mod:`millfmu.dem.coupling.cfd_dem` deposits both); tau = mu_eff (grad u +
grad u^T) - 2/3 mu_eff (div u) I is the full viscous stress in cylindrical coordinates,
mu_eff = rho (nu + nu_t).

Discretisation: finite volumes on the staggered grid, conservative fluxes for all three
components; the theta equation is written for the angular momentum r u_theta, so that the
fluid's angular momentum changes only through the wall torques and the exchange with the
beads (its budget closes to round-off). Advection: van Leer limited upwind faces (second
order where smooth). Time: forward Euler for advection, diffusion and curvature terms,
implicit drag in the predictor, pressure by an incremental projection
(:mod:`millfmu.dem.fluid.pressure`).

Walls: the grid's r-boundaries (shaft, chamber) and solid cells (the disc, a housing).
Velocity nodes are classified per component as 0 fluid (solved), 1 on a wall surface
(the wall-normal component on the wall, value fixed) or 2 inside a solid (value fixed to the
solid's velocity); a gradient taken between a fluid node and an inside node uses the wall
at the face between them, half a cell away. With wall functions the viscosity at such a
wall edge follows the log law (see :mod:`millfmu.dem.fluid.k_epsilon`).

Threads: the heaviest kernels (the stresses, the three explicit rates) run their rows of
nodes in parallel (``prange`` over i); each row writes only its own nodes from values no
row writes, so the results are the same to the bit on any thread count. Sums over the grid
(wall torques) stay serial, in their order. :func:`stresses` (the normal and edge
stresses) and :func:`rates` (the three rates) each make one parallel loop over the rows,
so that a substep pays two launches instead of seven.

Index conventions: cells (i, j, k); u_r[i] on r-face i (0..n_r), u_t[j] on the theta face
between cells j and j + 1, u_z[k] on the z-face between k and k + 1 (both periodic).
Edge stresses: e_rt[i, j, k] = a tau_r_theta at (r_f[i], theta_{j+1/2}, z_k),
e_rz[i, j, k] = a tau_rz at (r_f[i], theta_j, z_{k+1/2}),
e_tz[i, j, k] = a tau_theta_z at (r_c[i], theta_{j+1/2}, z_{k+1/2}).
"""

import math

from numba import prange

from millfmu.dem.engine._jit import device, inlined, kernel, nonneg, serial

KAPPA = 0.41  # von Karman constant (Launder & Spalding 1974)
E_LOG = 9.8  # log-law constant E
YPLUS_LAM = 11.225  # intersection of the linear and the log law, ln(E y+)/kappa = y+
C_MU = 0.09


@inlined
def wrap(a, n):
    """a % n for the periodic neighbours' indices (a within two periods of [0, n)): the
    same index as Python's modulo, by adding or taking away n instead of an integer
    division (tens of cycles each; four to eight per cell in the liquid's kernels)."""
    while a >= n:
        a -= n
    while a < 0:
        a += n
    return nonneg(a)


@inlined
def wall_nu(nu, k, y, wallfn):
    """Kinematic viscosity [m2/s] that gives the wall shear stress over a fluid node at
    distance y [m] from a wall: nu in the laminar sublayer or without wall functions, else
    the log law with u_tau = C_mu^(1/4) k^(1/2) (Launder & Spalding 1974):
    nu_w = nu y+ kappa / ln(E y+)."""
    if not wallfn:
        return nu
    ut = C_MU ** 0.25 * math.sqrt(max(k, 0.0))
    yp = ut * y / nu
    if yp <= YPLUS_LAM:
        return nu
    return nu * yp * KAPPA / math.log(E_LOG * yp)


@inlined
def grad2(ua, ub, ka, kb, ha, hb):
    """Gradient between node a and node b at distances ha, hb [m] from the point between
    them. A node inside a solid (kind 2) stands for the wall at that point: the gradient
    then spans only the fluid node's distance. Returns (gradient, wall side: 0 none,
    1 wall on a's side, 2 on b's side, 3 both inside)."""
    if ka == 2:
        if kb == 2:
            return 0.0, 3
        return (ub - ua) / hb, 1
    if kb == 2:
        return (ub - ua) / ha, 2
    return (ub - ua) / (ha + hb), 0


@inlined
def tvd_flux(F, um, u0, u1, u2, okm, ok2):
    """Advective flux F * u_face [m3/s * (transported unit)] through the face between nodes
    0 and 1 with volumetric flux F (positive from 0 to 1): van Leer limited upwind value;
    um (left of 0) and u2 (right of 1) when okm/ok2, else first-order upwind."""
    if F >= 0.0:
        c = u0
        d = u1
        u = um
        ok = okm
    else:
        c = u1
        d = u0
        u = u2
        ok = ok2
    dd = d - c
    if ok and dd != 0.0:
        r = (c - u) / dd
        ar = abs(r)
        psi = (r + ar) / (1.0 + ar)
        return F * (c + 0.5 * psi * dd)
    return F * c


@serial
def face_fluxes(ur, ut, uz, epsr, epst, epsz, rf, dr, vc, dth, dz, fr, ft, fz):
    """Volumetric fluxes [m3/s] of eps u through the cell faces: fr on r-faces (zero on the
    walls since u_r is), ft on theta faces, fz on z-faces."""
    nr, nt, nz = ut.shape
    for i in range(nr + 1):
        a = rf[i] * dth * dz
        for j in range(nt):
            for k in range(nz):
                fr[i, j, k] = epsr[i, j, k] * ur[i, j, k] * a
    for i in range(nr):
        at = dr[i] * dz
        az = vc[i] / dz
        for j in range(nt):
            for k in range(nz):
                ft[i, j, k] = epst[i, j, k] * ut[i, j, k] * at
                fz[i, j, k] = epsz[i, j, k] * uz[i, j, k] * az


@serial
def divergence(fr, ft, fz, out):
    """Net outflow [m3/s] of each cell from the face fluxes."""
    nr, nt, nz = out.shape
    for i in range(nr):
        for j in range(nt):
            jm = wrap(j - 1, nt)
            for k in range(nz):
                km = wrap(k - 1, nz)
                out[i, j, k] = (fr[i + 1, j, k] - fr[i, j, k] + ft[i, j, k] - ft[i, jm, k]
                                + fz[i, j, k] - fz[i, j, km])


# The row helpers of stresses and rates (normal_row, edge_*_row, rhs_*_row) are compiled
# functions of their own, called once per row, not inlined into the kernels: inlined, the
# kernels' bodies grow so large that numba's clean-up of them before the parallel loop's
# lowering took most of their compilation (rates 51 s, stresses 24 s on 2 cores); a call
# per row costs nothing measurable, and the per-node helpers stay inlined in the rows.
@device
def normal_row(i, ur, ut, uz, em, solid, rf, rc, dr, dth, dz, trr, ttt, tzz, s2diag):
    """Row i of the normal stresses at cell centres [Pa]: a tau_rr, a tau_tt, a tau_zz
    with em = a mu_eff per cell [Pa s] (0 in solids), tau_ii = 2 mu (S_ii - div u / 3);
    and 2 (S_rr^2 + S_tt^2 + S_zz^2) [1/s2] for the turbulence production."""
    nr, nt, nz = ut.shape
    for j in range(nt):
        jm = wrap(j - 1, nt)
        for k in range(nz):
            if solid[i, j, k] != 0:
                trr[i, j, k] = 0.0
                ttt[i, j, k] = 0.0
                tzz[i, j, k] = 0.0
                s2diag[i, j, k] = 0.0
                continue
            km = wrap(k - 1, nz)
            srr = (ur[i + 1, j, k] - ur[i, j, k]) / dr[i]
            stt = (ut[i, j, k] - ut[i, jm, k]) / (rc[i] * dth) + \
                0.5 * (ur[i, j, k] + ur[i + 1, j, k]) / rc[i]
            szz = (uz[i, j, k] - uz[i, j, km]) / dz
            div3 = (srr + stt + szz) / 3.0
            m2 = 2.0 * em[i, j, k]
            trr[i, j, k] = m2 * (srr - div3)
            ttt[i, j, k] = m2 * (stt - div3)
            tzz[i, j, k] = m2 * (szz - div3)
            s2diag[i, j, k] = 2.0 * (srr * srr + stt * stt + szz * szz)


@kernel
def stresses(ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz, om_sh,
             rho, nu, wallfn, model_a, trr, ttt, tzz, s2diag, e_rt, e_rz, e_tz, g_rt, g_rz,
             g_tz):
    """Normal stresses at the cell centres (:func:`normal_row`) and shear stresses a tau
    [Pa] on the grid edges (layout in the module docstring) with the matching strain rates
    gamma = 2 S_ab [1/s] (g_rt, g_rz, g_tz) for the turbulence production, in one parallel
    loop over the rows (each row's cell centres and edges: the same results to the bit on
    any thread count, each row writing only its own values from values no row writes). kr, kt_, kz: node kinds (0 fluid, 1 wall surface, 2 inside solid); the
    shaft (r = r_f[0], angular velocity om_sh) and the chamber (r = r_f[-1], at rest) are
    walls beyond the first and last radial nodes. At a wall edge the viscosity is
    rho a nu_w (:func:`wall_nu`) with the mean k of the fluid cells beside the edge."""
    nr = ut.shape[0]
    for i in prange(nr + 1):
        if i < nr:
            normal_row(i, ur, ut, uz, em, solid, rf, rc, dr, dth, dz, trr, ttt, tzz, s2diag)
        edge_rt_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz,
                    om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz, g_tz)
        edge_rz_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz,
                    om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz, g_tz)
        if i < nr:
            edge_tz_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth,
                        dz, om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz,
                        g_tz)


@kernel
def rates(ur, ut, uz, fr, ft, fz, kr, kt_, kz, trr, ttt, tzz, e_rt, e_rz, e_tz, epsr, rf,
          rc, dr, vc, dth, dz, rho, out_r, out_t, out_z):
    """The explicit rates of eps u_r, eps u_theta and eps u_z (:func:`rhs_r_row`,
    :func:`rhs_t_row`, :func:`rhs_z_row`) into out_r, out_t, out_z, in one parallel loop
    over the rows (the same results to the bit on any thread count)."""
    nr = ut.shape[0]
    for i in prange(nr):
        if i > 0:
            rhs_r_row(i, ur, ut, fr, ft, fz, kr, trr, ttt, e_rt, e_rz, epsr, rf, rc, dr, vc,
                      dth, dz, rho, out_r)
        rhs_t_row(i, ut, fr, ft, fz, kt_, ttt, e_rt, e_tz, rf, rc, dr, vc, dth, dz, rho,
                  out_t)
        rhs_z_row(i, uz, fr, ft, fz, kz, tzz, e_rz, e_tz, rf, dr, vc, dth, dz, rho, out_z)


@inlined
def _edge_visc(em, epsc, kt, solid, i0, i1, j0, j1, k0, k1, nr, nt, nz):
    """Mean of em [Pa s] and of eps and k over the fluid cells among the (up to 4) cells
    (i0|i1, j0|j1, k0|k1) around an edge; indices outside 0..nr-1 in r are skipped."""
    s = 0.0
    se = 0.0
    sk = 0.0
    n = 0
    for t in range(2):
        # i0, then i1: not a tuple of them, whose types differ where i1 is a prange's
        # (unsigned) row index and i0 = i1 - 1 (signed)
        i = i0 + t * (i1 - i0)
        if i < 0 or i >= nr:
            continue
        for j in (j0, j1):
            for k in (k0, k1):
                if solid[i, j, k] == 0:
                    s += em[i, j, k]
                    se += epsc[i, j, k]
                    sk += kt[i, j, k]
                    n += 1
    if n == 0:
        return 0.0, 1.0, 0.0
    return s / n, se / n, sk / n


@device
def edge_rt_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz,
                om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz, g_tz):
    """The r-theta edges (r_f[i], theta_{j+1/2}, z_k) of row i = 0..nr of
    :func:`stresses`."""
    nr, nt, nz = ut.shape
    for j in range(nt):
        jp = wrap(j + 1, nt)
        for k in range(nz):
            if i == 0:
                ka = 2
                wa = om_sh
                ha = 0.0
            else:
                ka = kt_[i - 1, j, k]
                wa = ut[i - 1, j, k] / rc[i - 1]
                ha = 0.5 * dr[i - 1]
            if i == nr:
                kb = 2
                wb = 0.0
                hb = 0.0
            else:
                kb = kt_[i, j, k]
                wb = ut[i, j, k] / rc[i]
                hb = 0.5 * dr[i]
            dw, side = grad2(wa, wb, ka, kb, ha, hb)
            if side == 3:
                e_rt[i, j, k] = 0.0
                g_rt[i, j, k] = 0.0
                continue
            gam = rf[i] * dw
            if nt > 1 and 0 < i < nr:
                hh = 0.5 * rf[i] * dth
                du, s2 = grad2(ur[i, j, k], ur[i, jp, k], kr[i, j, k], kr[i, jp, k], hh, hh)
                if s2 != 3:
                    gam += du  # (1/r) du_r/dtheta: hh already holds r
            mu, ea, ka_ = _edge_visc(em, epsc, ktur, solid, i - 1, i, j, jp, k, k,
                                     nr, nt, nz)
            if side != 0:
                y = hb if side == 1 else ha
                mu = rho * (ea if model_a else 1.0) * wall_nu(nu, ka_, y, wallfn)
            e_rt[i, j, k] = mu * gam
            g_rt[i, j, k] = gam


@device
def edge_rz_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz,
                om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz, g_tz):
    """The r-z edges (r_f[i], theta_j, z_{k+1/2}) of row i = 0..nr of
    :func:`stresses`."""
    nr, nt, nz = ut.shape
    for j in range(nt):
        for k in range(nz):
            kp = wrap(k + 1, nz)
            if i == 0:
                ka = 2
                za = 0.0
                ha = 0.0
            else:
                ka = kz[i - 1, j, k]
                za = uz[i - 1, j, k]
                ha = 0.5 * dr[i - 1]
            if i == nr:
                kb = 2
                zb = 0.0
                hb = 0.0
            else:
                kb = kz[i, j, k]
                zb = uz[i, j, k]
                hb = 0.5 * dr[i]
            duz, side = grad2(za, zb, ka, kb, ha, hb)
            dur = 0.0
            sidez = 0
            if 0 < i < nr:
                dur, sidez = grad2(ur[i, j, k], ur[i, j, kp], kr[i, j, k], kr[i, j, kp],
                                   0.5 * dz, 0.5 * dz)
            if side == 3 or sidez == 3:
                e_rz[i, j, k] = 0.0
                g_rz[i, j, k] = 0.0
                continue
            gam = dur + duz
            mu, ea, ka_ = _edge_visc(em, epsc, ktur, solid, i - 1, i, j, j, k, kp,
                                     nr, nt, nz)
            if side != 0:
                y = hb if side == 1 else ha
                mu = rho * (ea if model_a else 1.0) * wall_nu(nu, ka_, y, wallfn)
            elif sidez != 0:
                mu = rho * (ea if model_a else 1.0) * wall_nu(nu, ka_, 0.5 * dz, wallfn)
            e_rz[i, j, k] = mu * gam
            g_rz[i, j, k] = gam


@device
def edge_tz_row(i, ur, ut, uz, kr, kt_, kz, em, epsc, ktur, solid, rf, rc, dr, dth, dz,
                om_sh, rho, nu, wallfn, model_a, e_rt, e_rz, e_tz, g_rt, g_rz, g_tz):
    """The theta-z edges (r_c[i], theta_{j+1/2}, z_{k+1/2}) of row i = 0..nr - 1 of
    :func:`stresses`."""
    nr, nt, nz = ut.shape
    for j in range(nt):
        jp = wrap(j + 1, nt)
        for k in range(nz):
            kp = wrap(k + 1, nz)
            dut, side = grad2(ut[i, j, k], ut[i, j, kp], kt_[i, j, k], kt_[i, j, kp],
                              0.5 * dz, 0.5 * dz)
            if side == 3:
                e_tz[i, j, k] = 0.0
                g_tz[i, j, k] = 0.0
                continue
            gam = dut
            sidet = 0
            if nt > 1:
                hh = 0.5 * rc[i] * dth
                duz, sidet = grad2(uz[i, j, k], uz[i, jp, k], kz[i, j, k], kz[i, jp, k],
                                   hh, hh)
                if sidet == 3:
                    e_tz[i, j, k] = 0.0
                    g_tz[i, j, k] = 0.0
                    continue
                gam += duz  # (1/r) du_z/dtheta
            mu, ea, ka_ = _edge_visc(em, epsc, ktur, solid, i, i, j, jp, k, kp,
                                     nr, nt, nz)
            if side != 0:
                mu = rho * (ea if model_a else 1.0) * wall_nu(nu, ka_, 0.5 * dz, wallfn)
            elif sidet != 0:
                mu = rho * (ea if model_a else 1.0) * wall_nu(nu, ka_, 0.5 * rc[i] * dth,
                                                             wallfn)
            e_tz[i, j, k] = mu * gam
            g_tz[i, j, k] = gam


@device
def rhs_r_row(i, ur, ut, fr, ft, fz, kr, trr, ttt, e_rt, e_rz, epsr, rf, rc, dr, vc, dth,
              dz, rho, out):
    """Row i of the explicit rate of eps u_r per unit volume [m/s2] at every solved r-node:
    advection, viscous forces over rho, centrifugal term eps u_theta^2 / r; 0 at fixed
    nodes."""
    nr, nt, nz = ut.shape
    vol = 0.5 * (vc[i - 1] + vc[i])
    for j in range(nt):
        jm = wrap(j - 1, nt)
        jp = wrap(j + 1, nt)
        for k in range(nz):
            if kr[i, j, k] != 0:
                out[i, j, k] = 0.0
                continue
            km = wrap(k - 1, nz)
            kp = wrap(k + 1, nz)
            # advection, r-faces of the control volume at r_c[i - 1] and r_c[i]
            fe = 0.5 * (fr[i, j, k] + fr[i + 1, j, k])
            fw = 0.5 * (fr[i - 1, j, k] + fr[i, j, k])
            adv = -tvd_flux(fe, ur[i - 1, j, k], ur[i, j, k], ur[i + 1, j, k],
                            ur[min(i + 2, nr), j, k], True, i + 2 <= nr)
            adv += tvd_flux(fw, ur[max(i - 2, 0), j, k], ur[i - 1, j, k], ur[i, j, k],
                            ur[i + 1, j, k], i - 2 >= 0, True)
            if nt > 1:
                fn = 0.5 * (ft[i - 1, j, k] + ft[i, j, k])
                fs = 0.5 * (ft[i - 1, jm, k] + ft[i, jm, k])
                adv -= tvd_flux(fn, ur[i, jm, k], ur[i, j, k], ur[i, jp, k],
                                ur[i, wrap(j + 2, nt), k], True, True)
                adv += tvd_flux(fs, ur[i, wrap(j - 2, nt), k], ur[i, jm, k], ur[i, j, k],
                                ur[i, jp, k], True, True)
            ft_ = 0.5 * (fz[i - 1, j, k] + fz[i, j, k])
            fb_ = 0.5 * (fz[i - 1, j, km] + fz[i, j, km])
            adv -= tvd_flux(ft_, ur[i, j, km], ur[i, j, k], ur[i, j, kp],
                            ur[i, j, wrap(k + 2, nz)], True, True)
            adv += tvd_flux(fb_, ur[i, j, wrap(k - 2, nz)], ur[i, j, km], ur[i, j, k],
                            ur[i, j, kp], True, True)
            # viscous forces [N] (stresses already carry a)
            hr = rc[i] - rc[i - 1]
            vis = (rc[i] * trr[i, j, k] - rc[i - 1] * trr[i - 1, j, k]) * dth * dz
            if nt > 1:
                vis += (e_rt[i, j, k] - e_rt[i, jm, k]) * hr * dz
            vis += (e_rz[i, j, k] - e_rz[i, j, km]) * rf[i] * hr * dth
            vis -= 0.5 * (ttt[i - 1, j, k] + ttt[i, j, k]) / rf[i] * vol
            # centrifugal: eps <u_theta^2> / r from the four theta nodes around the face
            u2 = 0.25 * (ut[i - 1, j, k] ** 2 + ut[i, j, k] ** 2 +
                         ut[i - 1, jm, k] ** 2 + ut[i, jm, k] ** 2)
            out[i, j, k] = adv / vol + epsr[i, j, k] * u2 / rf[i] + vis / (rho * vol)


@device
def rhs_t_row(i, ut, fr, ft, fz, kt_, ttt, e_rt, e_tz, rf, rc, dr, vc, dth, dz, rho, out):
    """Row i of the explicit rate of eps u_theta per unit volume [m/s2] at every solved
    theta node, computed as the divergence of angular-momentum fluxes (advection of r u_theta, and
    r^2 tau_r_theta, r tau_theta_theta, r tau_theta_z over rho) divided by r; 0 at fixed
    nodes."""
    nr, nt, nz = ut.shape
    vol = vc[i]
    for j in range(nt):
        jm = wrap(j - 1, nt)
        jp = wrap(j + 1, nt)
        for k in range(nz):
            if kt_[i, j, k] != 0:
                out[i, j, k] = 0.0
                continue
            km = wrap(k - 1, nz)
            kp = wrap(k + 1, nz)
            adv = 0.0
            # r-faces at r_f[i] (inner) and r_f[i + 1] (outer)
            if i > 0:
                f = 0.5 * (fr[i, j, k] + fr[i, jp, k])
                adv += tvd_flux(f, rc[max(i - 2, 0)] * ut[max(i - 2, 0), j, k],
                                rc[i - 1] * ut[i - 1, j, k], rc[i] * ut[i, j, k],
                                rc[min(i + 1, nr - 1)] * ut[min(i + 1, nr - 1), j, k],
                                i - 2 >= 0, i + 1 <= nr - 1)
            if i < nr - 1:
                f = 0.5 * (fr[i + 1, j, k] + fr[i + 1, jp, k])
                adv -= tvd_flux(f, rc[max(i - 1, 0)] * ut[max(i - 1, 0), j, k],
                                rc[i] * ut[i, j, k], rc[i + 1] * ut[i + 1, j, k],
                                rc[min(i + 2, nr - 1)] * ut[min(i + 2, nr - 1), j, k],
                                i - 1 >= 0, i + 2 <= nr - 1)
            if nt > 1:
                fe = 0.5 * (ft[i, j, k] + ft[i, jp, k])
                fw = 0.5 * (ft[i, jm, k] + ft[i, j, k])
                r0 = rc[i]
                adv -= r0 * tvd_flux(fe, ut[i, jm, k], ut[i, j, k], ut[i, jp, k],
                                     ut[i, wrap(j + 2, nt), k], True, True)
                adv += r0 * tvd_flux(fw, ut[i, wrap(j - 2, nt), k], ut[i, jm, k],
                                     ut[i, j, k], ut[i, jp, k], True, True)
            fu = 0.5 * (fz[i, j, k] + fz[i, jp, k])
            fd = 0.5 * (fz[i, j, km] + fz[i, jp, km])
            r0 = rc[i]
            adv -= r0 * tvd_flux(fu, ut[i, j, km], ut[i, j, k], ut[i, j, kp],
                                 ut[i, j, wrap(k + 2, nz)], True, True)
            adv += r0 * tvd_flux(fd, ut[i, j, wrap(k - 2, nz)], ut[i, j, km],
                                 ut[i, j, k], ut[i, j, kp], True, True)
            vis = (rf[i + 1] ** 2 * e_rt[i + 1, j, k] - rf[i] ** 2 * e_rt[i, j, k]) * dth * dz
            if nt > 1:
                vis += rc[i] * (ttt[i, jp, k] - ttt[i, j, k]) * dr[i] * dz
            vis += rc[i] * (e_tz[i, j, k] - e_tz[i, j, km]) * vc[i] / dz
            out[i, j, k] = (adv + vis / rho) / (rc[i] * vol)


@device
def rhs_z_row(i, uz, fr, ft, fz, kz, tzz, e_rz, e_tz, rf, dr, vc, dth, dz, rho, out):
    """Row i of the explicit rate of eps u_z per unit volume [m/s2] at every solved z-node:
    advection and viscous forces over rho; 0 at fixed nodes."""
    nr, nt, nz = uz.shape
    vol = vc[i]
    az = vc[i] / dz
    for j in range(nt):
        jm = wrap(j - 1, nt)
        jp = wrap(j + 1, nt)
        for k in range(nz):
            if kz[i, j, k] != 0:
                out[i, j, k] = 0.0
                continue
            km = wrap(k - 1, nz)
            kp = wrap(k + 1, nz)
            adv = 0.0
            if i > 0:
                f = 0.5 * (fr[i, j, k] + fr[i, j, kp])
                adv += tvd_flux(f, uz[max(i - 2, 0), j, k], uz[i - 1, j, k], uz[i, j, k],
                                uz[min(i + 1, nr - 1), j, k], i - 2 >= 0, i + 1 <= nr - 1)
            if i < nr - 1:
                f = 0.5 * (fr[i + 1, j, k] + fr[i + 1, j, kp])
                adv -= tvd_flux(f, uz[max(i - 1, 0), j, k], uz[i, j, k], uz[i + 1, j, k],
                                uz[min(i + 2, nr - 1), j, k], i - 1 >= 0, i + 2 <= nr - 1)
            if nt > 1:
                fe = 0.5 * (ft[i, j, k] + ft[i, j, kp])
                fw = 0.5 * (ft[i, jm, k] + ft[i, jm, kp])
                adv -= tvd_flux(fe, uz[i, jm, k], uz[i, j, k], uz[i, jp, k],
                                uz[i, wrap(j + 2, nt), k], True, True)
                adv += tvd_flux(fw, uz[i, wrap(j - 2, nt), k], uz[i, jm, k], uz[i, j, k],
                                uz[i, jp, k], True, True)
            fu = 0.5 * (fz[i, j, k] + fz[i, j, kp])
            fd = 0.5 * (fz[i, j, km] + fz[i, j, k])
            adv -= tvd_flux(fu, uz[i, j, km], uz[i, j, k], uz[i, j, kp],
                            uz[i, j, wrap(k + 2, nz)], True, True)
            adv += tvd_flux(fd, uz[i, j, wrap(k - 2, nz)], uz[i, j, km], uz[i, j, k],
                            uz[i, j, kp], True, True)
            vis = (rf[i + 1] * e_rz[i + 1, j, k] - rf[i] * e_rz[i, j, k]) * dth * dz
            if nt > 1:
                vis += (e_tz[i, j, k] - e_tz[i, jm, k]) * dr[i] * dz
            vis += (tzz[i, j, kp] - tzz[i, j, k]) * az
            out[i, j, k] = adv / vol + vis / (rho * vol)


@serial
def pressure_gradients(p, solid, rc, dr, dth, dz, gr, gt, gz):
    """Pressure gradient [Pa/m] on the velocity nodes between two fluid cells (0 elsewhere):
    gr on r-faces, gt on theta faces (1/r dp/dtheta), gz on z-faces."""
    nr, nt, nz = p.shape
    gr[0, :, :] = 0.0
    gr[nr, :, :] = 0.0
    for i in range(nr):
        for j in range(nt):
            jp = wrap(j + 1, nt)
            for k in range(nz):
                kp = wrap(k + 1, nz)
                f = solid[i, j, k] == 0
                if i > 0:
                    if f and solid[i - 1, j, k] == 0:
                        gr[i, j, k] = (p[i, j, k] - p[i - 1, j, k]) / (rc[i] - rc[i - 1])
                    else:
                        gr[i, j, k] = 0.0
                if nt > 1 and f and solid[i, jp, k] == 0:
                    gt[i, j, k] = (p[i, jp, k] - p[i, j, k]) / (rc[i] * dth)
                else:
                    gt[i, j, k] = 0.0
                if f and solid[i, j, kp] == 0:
                    gz[i, j, k] = (p[i, j, kp] - p[i, j, k]) / dz
                else:
                    gz[i, j, k] = 0.0


@serial
def predict(u, kind, eps, rhs, kd, sd, gp, fb, rho, dt, fixed):
    """Momentum predictor on one component (flattened arrays): at solved nodes
    (kind == 0) u* = (eps u / dt + rhs + (sd + fb - gp) / rho) / (eps / dt + kd / rho)
    with rhs the explicit rate [m/s2], kd the drag coefficient per unit volume
    [kg/(m3 s)] (implicit), sd the beads' part of the exchange [N/m3], gp the pressure
    gradient [Pa/m], fb a body force per unit volume [N/m3]; fixed nodes get ``fixed``."""
    for n in range(u.size):
        if kind[n] != 0:
            u[n] = fixed[n]
            continue
        e = eps[n]
        u[n] = (e * u[n] / dt + rhs[n] + (sd[n] + fb - gp[n]) / rho) / (e / dt + kd[n] / rho)


@serial
def correct(u, kind, eps, gphi, rho, dt):
    """Projection: u -= dt / (rho eps) grad(phi) at solved nodes."""
    for n in range(u.size):
        if kind[n] == 0:
            u[n] -= dt * gphi[n] / (rho * eps[n])


@inlined
def _wall_kind(solid, i, j, k, nt):
    """Kind (ROTOR 1, STATOR 2) of the wall a fixed theta node (i, j, k) belongs to: a
    node inside a solid (kind 2) lies between two solid cells, a node on a plate's face
    (kind 1: baffles) between the plate's cell and a fluid cell."""
    s = solid[i, j, k]
    if s == 0:
        s = solid[i, wrap(j + 1, nt), k]
    return s


@serial
def wall_torques(e_rt, e_tz, kt_, solid, rf, rc, vc, dth, dz):
    """Torque about +z [N m] the fluid exerts on the shaft, on the rotor's solid cells
    (disc) and on the stationary walls (chamber, housing, baffles), from the same
    wall-edge stresses the theta momentum uses: every r- and z-edge between a solved theta
    node and a fixed one (inside a solid, or on a baffle's face); returns (shaft, rotor
    cells, stator). The baffles' theta faces, where the liquid pushes with its pressure,
    are FluidSolver.plate_torque_nm's."""
    nr, nt, nz = kt_.shape
    sh = 0.0
    rot = 0.0
    sta = 0.0
    for j in range(nt):
        for k in range(nz):
            kp = wrap(k + 1, nz)
            # shaft (inner face of the first cell) and chamber (outer face of the last)
            if kt_[0, j, k] == 0:
                sh += rf[0] ** 2 * e_rt[0, j, k] * dth * dz
            if kt_[nr - 1, j, k] == 0:
                sta -= rf[nr] ** 2 * e_rt[nr, j, k] * dth * dz
            for i in range(1, nr):
                ka = kt_[i - 1, j, k]
                kb = kt_[i, j, k]
                if ka != 0 and kb == 0:
                    t = rf[i] ** 2 * e_rt[i, j, k] * dth * dz
                    s = _wall_kind(solid, i - 1, j, k, nt)
                elif kb != 0 and ka == 0:
                    t = -rf[i] ** 2 * e_rt[i, j, k] * dth * dz
                    s = _wall_kind(solid, i, j, k, nt)
                else:
                    continue
                if s == 1:
                    rot += t
                else:
                    sta += t
            for i in range(nr):
                ka = kt_[i, j, k]
                kb = kt_[i, j, kp]
                if ka != 0 and kb == 0:
                    t = rc[i] * e_tz[i, j, k] * vc[i] / dz
                    s = _wall_kind(solid, i, j, k, nt)
                elif kb != 0 and ka == 0:
                    t = -rc[i] * e_tz[i, j, k] * vc[i] / dz
                    s = _wall_kind(solid, i, j, kp, nt)
                else:
                    continue
                if s == 1:
                    rot += t
                else:
                    sta += t
    return sh, rot, sta
