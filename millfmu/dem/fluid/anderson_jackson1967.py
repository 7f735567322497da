"""The beads' share of the liquid's resolved viscous stress (Anderson & Jackson 1967, model A).

In Anderson and Jackson's equations (1967, Ind. Eng. Chem. Fundam. 6, 527-539; "set I" in
Zhou, Kuang, Chu & Yu 2010, J. Fluid Mech. 661, 482-510) the liquid acts on a bead of
volume V_i with the drag and the generalized buoyancy V_i (-grad p + div tau): the gradient
of the liquid's whole stress at the bead, of which the pressure is one part and the
resolved (volume-averaged) viscous stress tau, turbulent viscosity included, the other.
The liquid keeps eps (-grad p + div tau) of it. CFDEM's model A takes the second part as
its ``viscForce`` (V_i div tau read in the bead's cell, the beads' side only) and refuses
to run model A without it.

Without this force model A gives the beads the pressure part only and weights the
liquid's stresses by eps: the share (1 - eps) div tau reaches neither phase. Beside a
moving wall that is the part of the wall's shear that the beads in the wall cell would
take: with ``[fluid.coupled] bead_stress_force = "anderson_jackson1967"`` the liquid's
stresses carry no eps (the full tau, walls included), each bead feels -V_i (grad p -
div tau) with the interval-mean of both read at it as the pressure gradient is, and the
liquid receives the reaction of that force through the same deposit as the pressure
part's, so that the liquid keeps eps (-grad p + div tau) and the exchange stays exact
(the angular-momentum budget closes as without it).

:func:`add_stress_force` adds ``scale`` times div tau [N/m3] at every solved velocity
node to the interval's pressure-gradient sums, from the stresses the liquid's step has
just computed (:func:`millfmu.dem.fluid.vans_kernels.stresses`), with the same finite
volumes as the momentum equations' viscous terms (:func:`~millfmu.dem.fluid.vans_kernels.rhs_r_row`
and the theta and z rows), so that what the beads take is what the liquid's own
equations see. :func:`stress_divergence` gives div tau of a solver's present velocities,
for checks: on u_theta = c r^2 it is 3 mu c with a relative error dr^2 / (12 r^2) (second
order in the radial cell size dr), on u_z = c r^2 4 mu c and on u_r = c / r zero, both to
round-off.

Units: SI (Pa, m, s).
"""

import numpy as np
from numba import prange

from millfmu.dem.engine._jit import kernel
from millfmu.dem.fluid.vans_kernels import wrap


@kernel
def add_stress_force(trr, ttt, tzz, e_rt, e_rz, e_tz, kr, kt_, kz, rf, rc, dr, vc, dth, dz,
                     scale, gr, gt, gz):
    """gr, gt, gz (the r, theta and z velocity nodes' arrays) += scale * div tau [N/m3] at
    every solved node (kind 0), from the normal stresses at the cell centres (trr, ttt, tzz)
    and the shear stresses on the edges (e_rt, e_rz, e_tz) [Pa], laid out as in
    :mod:`millfmu.dem.fluid.vans_kernels`; in the finite volumes of its momentum rows (the
    theta row's angular-momentum form divided by r). Rows of nodes on the threads, each
    writing its own (the same results on any thread count)."""
    nr, nt, nz = kt_.shape
    for i in prange(nr):
        if i > 0:
            vol = 0.5 * (vc[i - 1] + vc[i])
            hr = rc[i] - rc[i - 1]
            for j in range(nt):
                jm = wrap(j - 1, nt)
                for k in range(nz):
                    if kr[i, j, k] != 0:
                        continue
                    km = wrap(k - 1, nz)
                    vis = (rc[i] * trr[i, j, k] - rc[i - 1] * trr[i - 1, j, k]) * dth * dz
                    if nt > 1:
                        vis += (e_rt[i, j, k] - e_rt[i, jm, k]) * hr * dz
                    vis += (e_rz[i, j, k] - e_rz[i, j, km]) * rf[i] * hr * dth
                    vis -= 0.5 * (ttt[i - 1, j, k] + ttt[i, j, k]) / rf[i] * vol
                    gr[i, j, k] += scale * vis / vol
        vol = vc[i]
        az = vc[i] / dz
        for j in range(nt):
            jm = wrap(j - 1, nt)
            jp = wrap(j + 1, nt)
            for k in range(nz):
                km = wrap(k - 1, nz)
                kp = wrap(k + 1, nz)
                if kt_[i, j, k] == 0:
                    vis = (rf[i + 1] ** 2 * e_rt[i + 1, j, k] - rf[i] ** 2 * e_rt[i, j, k]) \
                        * dth * dz
                    if nt > 1:
                        vis += rc[i] * (ttt[i, jp, k] - ttt[i, j, k]) * dr[i] * dz
                    vis += rc[i] * (e_tz[i, j, k] - e_tz[i, j, km]) * vc[i] / dz
                    gt[i, j, k] += scale * vis / (rc[i] * vol)
                if kz[i, j, k] == 0:
                    vis = (rf[i + 1] * e_rz[i + 1, j, k] - rf[i] * e_rz[i, j, k]) * dth * dz
                    if nt > 1:
                        vis += (e_tz[i, j, k] - e_tz[i, jm, k]) * dr[i] * dz
                    vis += (tzz[i, j, kp] - tzz[i, j, k]) * az
                    gz[i, j, k] += scale * vis / vol


def stress_divergence(solver) -> tuple:
    """div tau [N/m3] of ``solver``'s (:class:`millfmu.dem.fluid.solver.FluidSolver`)
    present velocities at its r, theta and z nodes (0 at fixed nodes), with the full
    stresses (no eps weight) as the option gives them to the beads: for checks."""
    from millfmu.dem.fluid import step_kernels as SK

    s = solver
    W, F = s._W, s._F
    em = W[SK.EM]
    em[:] = np.where(s.solid != 0, 0.0, s.rho * (s.nu + s.nu_t))
    s.VK.stresses(s.ur, s.ut, s.uz, s.kr, s.kt, s.kz, em, F[SK.EPSC], F[SK.KT], s.solid,
                  s.rf, s.rc, s.dr, s.dth, s.dz, s.om_shaft, s.rho, s.nu,
                  s.turbulence == "k_epsilon", False, W[SK.TRR], W[SK.TTT], W[SK.TZZ],
                  W[SK.S2], W[SK.ERT], W[SK.ERZ], W[SK.ETZ], W[SK.GRT], W[SK.GRZ],
                  W[SK.GTZ])
    out = (np.zeros(s.ur.shape), np.zeros(s.ut.shape), np.zeros(s.uz.shape))
    add_stress_force(W[SK.TRR], W[SK.TTT], W[SK.TZZ], W[SK.ERT], W[SK.ERZ], W[SK.ETZ], s.kr,
                     s.kt, s.kz, s.rf, s.rc, s.dr, s.vc, s.dth, s.dz, 1.0, *out)
    return out
