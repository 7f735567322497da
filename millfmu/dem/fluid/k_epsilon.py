"""Standard k-epsilon turbulence model with wall functions (Launder & Spalding 1974, Comput.
Methods Appl. Mech. Eng. 3, 269-289), volume-averaged like the momentum equations (the
form CFDEM and Lethe use): for q = k [m2/s2] and q = epsilon [m2/s3]

    d(eps q)/dt + div(eps u q) = div(eps (nu + nu_t / sigma_q) grad q) + eps S_q,
    S_k = P - epsilon,  S_eps = (C_1 P - C_2 epsilon) epsilon / k,  P = nu_t 2 S:S,
    nu_t = C_mu k^2 / epsilon.

Constants: C_mu 0.09, C_1 1.44, C_2 1.92, sigma_k 1.0, sigma_eps 1.3. The beads' effect on
the turbulence is not modelled (plain model, as the seeds used it).

Wall functions (as OpenFOAM's epsilonWallFunction and nutkWallFunction): in a cell next to
a wall, u_tau = C_mu^(1/4) k^(1/2), y+ = u_tau y / nu with y the distance of the cell centre
from the wall; for y+ > 11.225 epsilon = C_mu^(3/4) k^(3/2) / (kappa y) and the production
is tau_w u_tau / (kappa y), tau_w / rho = nu_w |u - u_wall|_tangential / y with the log-law
viscosity nu_w = nu y+ kappa / ln(E y+) (kappa 0.41, E 9.8); in the sublayer epsilon =
2 k nu / y^2 and no production. A cell with several walls takes their mean. The momentum
equations use the same nu_w at their wall edges (:func:`millfmu.dem.fluid.vans_kernels.wall_nu`).

The production and the transport step run their rows of cells in parallel, each row
writing its own cells, so the results are the same to the bit on any thread count. The
transport computes each face's advective flux and diffusive term once, in a pass of their
own, for the two cells beside it (each cell sums its faces in a fixed order), instead of
once per cell with its divisions.
Their ``_serial`` twins run the same rows on the calling thread, for a caller that runs
the turbulence as one task beside another (the coupled exchange's last substep).
"""

import math

from numba import prange

from millfmu.dem.engine._jit import inlined, kernel, serial
from millfmu.dem.fluid.vans_kernels import (C_MU, E_LOG, KAPPA, YPLUS_LAM, tvd_flux, wrap)

C_1 = 1.44
C_2 = 1.92
SIGMA_K = 1.0
SIGMA_EPS = 1.3
K_MIN = 1e-10  # floors [m2/s2], [m2/s3]: keep nu_t finite and the sinks defined
EPS_MIN = 1e-10


@serial
def eddy_viscosity(k, e, solid, nu_t):
    """nu_t = C_mu k^2 / epsilon [m2/s] at fluid cells, 0 in solids."""
    nr, nt, nz = k.shape
    for i in range(nr):
        for j in range(nt):
            for k_ in range(nz):
                if solid[i, j, k_] != 0:
                    nu_t[i, j, k_] = 0.0
                else:
                    nu_t[i, j, k_] = C_MU * k[i, j, k_] ** 2 / max(e[i, j, k_], EPS_MIN)


@kernel
def production(ur, ut, uz, nu_t, s2diag, g_rt, g_rz, g_tz, solid, wall, wall_om, k, rc, dr,
               dth, dz, nu, prod, e_wall):
    """Turbulence production P [m2/s3] at fluid cells: nu_t 2 S:S from the cell-centred
    normal strains (s2diag) and the squared edge shear rates around the cell, replaced by the
    wall-function value in cells next to walls; e_wall [m2/s3] receives the wall-function
    epsilon there (negative elsewhere). wall[i, j, k, d] marks a wall on face d
    (0 -r, 1 +r, 2 -theta, 3 +theta, 4 -z, 5 +z); wall_om its angular velocity [rad/s]."""
    for i in prange(k.shape[0]):
        production_row(i, ur, ut, uz, nu_t, s2diag, g_rt, g_rz, g_tz, solid, wall, wall_om, k, rc,
                          dr, dth, dz, nu, prod, e_wall)


@serial
def production_serial(ur, ut, uz, nu_t, s2diag, g_rt, g_rz, g_tz, solid, wall, wall_om, k, rc,
                      dr, dth, dz, nu, prod, e_wall):
    """:func:`production` on the calling thread (the same rows, the same results)."""
    for i in range(k.shape[0]):
        production_row(i, ur, ut, uz, nu_t, s2diag, g_rt, g_rz, g_tz, solid, wall, wall_om, k, rc,
                          dr, dth, dz, nu, prod, e_wall)


@inlined
def production_row(i, ur, ut, uz, nu_t, s2diag, g_rt, g_rz, g_tz, solid, wall, wall_om, k, rc,
                      dr, dth, dz, nu, prod, e_wall):
    """Row i of :func:`production`."""
    nr, nt, nz = k.shape
    for j in range(nt):
        jm = wrap(j - 1, nt)
        for kk in range(nz):
            if solid[i, j, kk] != 0:
                prod[i, j, kk] = 0.0
                e_wall[i, j, kk] = -1.0
                continue
            km = wrap(kk - 1, nz)
            nw = 0
            for d in range(6):
                if wall[i, j, kk, d]:
                    nw += 1
            if nw == 0:
                grt = 0.25 * (g_rt[i, j, kk] ** 2 + g_rt[i + 1, j, kk] ** 2 +
                              g_rt[i, jm, kk] ** 2 + g_rt[i + 1, jm, kk] ** 2)
                grz = 0.25 * (g_rz[i, j, kk] ** 2 + g_rz[i + 1, j, kk] ** 2 +
                              g_rz[i, j, km] ** 2 + g_rz[i + 1, j, km] ** 2)
                gtz = 0.25 * (g_tz[i, j, kk] ** 2 + g_tz[i, jm, kk] ** 2 +
                              g_tz[i, j, km] ** 2 + g_tz[i, jm, km] ** 2)
                prod[i, j, kk] = nu_t[i, j, kk] * (s2diag[i, j, kk] + grt + grz + gtz)
                e_wall[i, j, kk] = -1.0
                continue
            vr = 0.5 * (ur[i, j, kk] + ur[i + 1, j, kk])
            vt = 0.5 * (ut[i, j, kk] + ut[i, jm, kk])
            vz = 0.5 * (uz[i, j, kk] + uz[i, j, km])
            kc = max(k[i, j, kk], K_MIN)
            utau = C_MU ** 0.25 * math.sqrt(kc)
            ps = 0.0
            es = 0.0
            for d in range(6):
                if not wall[i, j, kk, d]:
                    continue
                rel_t = vt - wall_om[i, j, kk, d] * rc[i]
                if d < 2:
                    y = 0.5 * dr[i]
                    slip = math.sqrt(rel_t * rel_t + vz * vz)
                elif d < 4:
                    y = 0.5 * rc[i] * dth
                    slip = math.sqrt(vr * vr + vz * vz)
                else:
                    y = 0.5 * dz
                    slip = math.sqrt(vr * vr + rel_t * rel_t)
                yp = utau * y / nu
                if yp > YPLUS_LAM:
                    nuw = nu * yp * KAPPA / math.log(E_LOG * yp)
                    ps += nuw * slip / y * utau / (KAPPA * y)
                    es += C_MU ** 0.75 * kc ** 1.5 / (KAPPA * y)
                else:
                    es += 2.0 * kc * nu / (y * y)
            prod[i, j, kk] = ps / nw
            e_wall[i, j, kk] = es / nw


@kernel
def transport(q, q_old_k, q_old_e, is_eps, fr, ft, fz, epsc, nu_t, solid, prod, e_wall,
              rf, rc, dr, vc, dth, dz, nu, dt, qmin, out, tfr, dfr, tft, dft, tfz, dfz):
    """One explicit step of dt [s] of k (is_eps False) or epsilon (True) at fluid cells:
    van Leer limited advection by the eps-weighted face fluxes (in the non-conservative
    form, so that the void fraction's change does not act as a source), diffusion with
    eps (nu + nu_t / sigma) and zero flux through walls, the sources with the sink implicit.
    q_old_k, q_old_e: k and epsilon of the old level for the source terms. Cells next to a
    wall take epsilon from the wall function (e_wall >= 0).

    tfr, dfr (n_r + 1, n_t, n_z), tft, dft, tfz, dfz (n_r, n_t, n_z): work arrays for each
    face's advective flux and diffusive term (:func:`transport_faces_row`), computed once
    for the two cells beside it (the cells' loop computed each twice: twice the
    divisions)."""
    for i in prange(q.shape[0]):
        transport_faces_row(i, q, is_eps, fr, ft, fz, epsc, nu_t, solid, rf, rc, dr, vc,
                            dth, dz, nu, tfr, dfr, tft, dft, tfz, dfz)
    for i in prange(q.shape[0]):
        transport_row(i, q, q_old_k, q_old_e, is_eps, fr, ft, fz, epsc, solid, prod, e_wall,
                      vc, dt, qmin, out, tfr, dfr, tft, dft, tfz, dfz)


@serial
def transport_serial(q, q_old_k, q_old_e, is_eps, fr, ft, fz, epsc, nu_t, solid, prod,
                     e_wall, rf, rc, dr, vc, dth, dz, nu, dt, qmin, out, tfr, dfr, tft, dft,
                     tfz, dfz):
    """:func:`transport` on the calling thread (the same rows, the same results)."""
    for i in range(q.shape[0]):
        transport_faces_row(i, q, is_eps, fr, ft, fz, epsc, nu_t, solid, rf, rc, dr, vc,
                            dth, dz, nu, tfr, dfr, tft, dft, tfz, dfz)
    for i in range(q.shape[0]):
        transport_row(i, q, q_old_k, q_old_e, is_eps, fr, ft, fz, epsc, solid, prod, e_wall,
                      vc, dt, qmin, out, tfr, dfr, tft, dft, tfz, dfz)


@inlined
def _diffusivity(epsc, nu_t, i, j, k, nu, is_eps):
    """eps (nu + nu_t / sigma) [m2/s] of cell (i, j, k); sigma_k = 1 divides nothing
    (x / 1.0 is x)."""
    if is_eps:
        return epsc[i, j, k] * (nu + nu_t[i, j, k] / SIGMA_EPS)
    if SIGMA_K == 1.0:
        return epsc[i, j, k] * (nu + nu_t[i, j, k])
    return epsc[i, j, k] * (nu + nu_t[i, j, k] / SIGMA_K)


@inlined
def transport_faces_row(i, q, is_eps, fr, ft, fz, epsc, nu_t, solid, rf, rc, dr, vc, dth,
                        dz, nu, tfr, dfr, tft, dft, tfz, dfz):
    """The faces of row i between two fluid cells: the -r face of each cell (r-face i),
    its +theta and +z faces. For each, the van Leer advective flux tf (which the cell
    before the face subtracts and the one after it adds) and the diffusive term df that the
    cell before it adds, g (q_after - q_before) / h A with g the mean of the two cells'
    diffusivities; the cell after it adds -df, which is its own term to the bit (IEEE
    negation is exact and commutes with the rounding of +, -, *, /)."""
    nr, nt, nz = q.shape
    az = vc[i] / dz
    for j in range(nt):
        jm = wrap(j - 1, nt)
        jp = wrap(j + 1, nt)
        for kk in range(nz):
            if solid[i, j, kk] != 0:
                continue
            km = wrap(kk - 1, nz)
            kp = wrap(kk + 1, nz)
            qc = q[i, j, kk]
            gc = _diffusivity(epsc, nu_t, i, j, kk, nu, is_eps)
            if i > 0 and solid[i - 1, j, kk] == 0:
                tfr[i, j, kk] = tvd_flux(fr[i, j, kk], q[max(i - 2, 0), j, kk],
                                         q[i - 1, j, kk], qc, q[min(i + 1, nr - 1), j, kk],
                                         i - 2 >= 0 and solid[max(i - 2, 0), j, kk] == 0,
                                         i + 1 < nr and solid[min(i + 1, nr - 1), j, kk] == 0)
                g = 0.5 * (_diffusivity(epsc, nu_t, i - 1, j, kk, nu, is_eps) + gc)
                dfr[i, j, kk] = g * ((qc - q[i - 1, j, kk]) / (rc[i] - rc[i - 1])) * \
                    (rf[i] * dth * dz)
            if nt > 1 and solid[i, jp, kk] == 0:
                tft[i, j, kk] = tvd_flux(ft[i, j, kk], q[i, jm, kk], qc, q[i, jp, kk],
                                         q[i, wrap(j + 2, nt), kk], solid[i, jm, kk] == 0,
                                         solid[i, wrap(j + 2, nt), kk] == 0)
                g = 0.5 * (gc + _diffusivity(epsc, nu_t, i, jp, kk, nu, is_eps))
                dft[i, j, kk] = g * (q[i, jp, kk] - qc) / (rc[i] * dth) * dr[i] * dz
            if solid[i, j, kp] == 0:
                tfz[i, j, kk] = tvd_flux(fz[i, j, kk], q[i, j, km], qc, q[i, j, kp],
                                         q[i, j, wrap(kk + 2, nz)], solid[i, j, km] == 0,
                                         solid[i, j, wrap(kk + 2, nz)] == 0)
                g = 0.5 * (gc + _diffusivity(epsc, nu_t, i, j, kp, nu, is_eps))
                dfz[i, j, kk] = g * (q[i, j, kp] - qc) / dz * az


@inlined
def transport_row(i, q, q_old_k, q_old_e, is_eps, fr, ft, fz, epsc, solid, prod, e_wall, vc,
                  dt, qmin, out, tfr, dfr, tft, dft, tfz, dfz):
    """Row i of :func:`transport`: each cell's faces (:func:`transport_faces_row`) summed
    in the order of the cell-by-cell form (-r, +r, -theta, +theta, -z, +z), then the
    sources."""
    nr, nt, nz = q.shape
    vol = vc[i]
    for j in range(nt):
        jm = wrap(j - 1, nt)
        jp = wrap(j + 1, nt)
        for kk in range(nz):
            if solid[i, j, kk] != 0:
                out[i, j, kk] = q[i, j, kk]
                continue
            if is_eps and e_wall[i, j, kk] >= 0.0:
                out[i, j, kk] = max(e_wall[i, j, kk], qmin)
                continue
            km = wrap(kk - 1, nz)
            kp = wrap(kk + 1, nz)
            qc = q[i, j, kk]
            adv = 0.0
            net = 0.0
            dif = 0.0
            # r-faces
            if i > 0 and solid[i - 1, j, kk] == 0:
                adv += tfr[i, j, kk]
                net -= fr[i, j, kk]
                dif -= dfr[i, j, kk]
            if i < nr - 1 and solid[i + 1, j, kk] == 0:
                adv -= tfr[i + 1, j, kk]
                net += fr[i + 1, j, kk]
                dif += dfr[i + 1, j, kk]
            if nt > 1:
                if solid[i, jm, kk] == 0:
                    dif -= dft[i, jm, kk]
                    adv += tft[i, jm, kk]
                    net -= ft[i, jm, kk]
                if solid[i, jp, kk] == 0:
                    dif += dft[i, j, kk]
                    adv -= tft[i, j, kk]
                    net += ft[i, j, kk]
            if solid[i, j, km] == 0:
                dif -= dfz[i, j, km]
                adv += tfz[i, j, km]
                net -= fz[i, j, km]
            if solid[i, j, kp] == 0:
                dif += dfz[i, j, kk]
                adv -= tfz[i, j, kk]
                net += fz[i, j, kk]
            # non-conservative advection: remove q * (net outflow) so that a change of
            # the void fraction (div(eps u) != 0) is no source of q
            adv += qc * net
            ep = epsc[i, j, kk]
            ko = max(q_old_k[i, j, kk], K_MIN)
            eo = max(q_old_e[i, j, kk], EPS_MIN)
            if is_eps:
                src = C_1 * prod[i, j, kk] * eo / ko
                sink = C_2 * eo / ko
            else:
                src = prod[i, j, kk]
                ew = e_wall[i, j, kk]
                sink = (ew if ew >= 0.0 else eo) / ko
            num = ep * vol * qc / dt + adv + dif + ep * vol * src
            den = ep * vol / dt + ep * vol * sink
            out[i, j, kk] = max(num / den, qmin)
