"""Numba kernels of one coupling interval (:meth:`millfmu.dem.coupling.cfd_dem.CfdDem.exchange`):
what each bead deposits, the split of the smoothed cell totals onto the velocity nodes, the
read-back of node fields into cells, and the bead forces. Fused so that the beads are
visited twice per interval and no temporary per-bead arrays are made.

Bead columns deposited (q): 0 bead volume V [m3]; 1 drag coefficient c [kg/s] (r and z
nodes); 2 c r [kg m/s] (theta nodes, torque form); 3 c v_r + a V dp/dr; 4 r (c v_theta +
a V dp/(r dtheta)); 5 c v_z + a V (dp/dz - G) [N, N m, N] with a = 1 in model A (the
reaction of the beads' pressure-gradient force) and 0 in model B.
"""

import math

from numba import prange

from millfmu.dem.coupling.projection import at_bead, at_bead3, bead_cyl
from millfmu.dem.engine._jit import inlined, kernel, serial
from millfmu.dem.engine.koch_hill2001 import beta
from millfmu.dem.fluid.vans_kernels import wrap

NQ = 6

#: Largest ratio x = interval c / m of a coupling interval to a bead's drag relaxation
#: time m / c [-] for which the drag c (u - v) is held over the interval as it is; beyond
#: it a held force would overshoot the liquid's velocity (:func:`held_coefficient`).
STIFF_RATIO = 0.5


@inlined
def held_coefficient(c, m, interval):
    """The drag coefficient [kg/s] that a bead of mass m [kg] holds over ``interval`` [s]
    for its coefficient c [kg/s], and x = interval c / m [-] (a stiffness diagnostic).
    Where x > STIFF_RATIO (a viscous suspension; never water with sub-millimetre beads at
    5e-5 s) the coefficient is m (1 - exp(-x)) / interval, the exact mean drag over the
    interval of a bead relaxing under drag alone."""
    x = interval * c / m
    if x > STIFF_RATIO:
        c = m * (1.0 - math.exp(-x)) / interval
    return c, x


@inlined
def split(kind_a, kind_b):
    """Shares of a cell's total for its two faces of a component, by their node kinds:
    half each when both are solved, all to the solved one next to a wall or solid."""
    fa = kind_a == 0
    fb = kind_b == 0
    if fa and fb:
        return 0.5, 0.5
    return (1.0 if fa else 0.0), (1.0 if fb else 0.0)


@inlined
def bead_in(b, x, v, rad, mass, fab, eps_cells, body_z, pf, model_b, mu, rho, interval,
            rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, cyl, c, q):
    """Bead b's part of :func:`beads_in` (its stencil, cylindrical coordinates, drag
    coefficient and deposit columns); returns x = interval c / m [-]. One body for the
    CPU's loop and the GPU's thread (:mod:`millfmu.dem.coupling.gpu_exchange`)."""
    r, vr, vt, vz = bead_cyl(b, x, v, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w)
    eb = at_bead(b, idx, w, eps_cells)
    d = 2.0 * rad[b]
    vol = math.pi / 6.0 * d * d * d
    urel = math.sqrt((fab[b, 0] - vr) ** 2 + (fab[b, 1] - vt) ** 2 + (fab[b, 2] - vz) ** 2)
    bt = beta(d, eb, mu, rho, urel)
    if model_b:
        bt /= eb
    cc, xx = held_coefficient(vol * bt, mass[b], interval)
    c[b] = cc
    cyl[b, 0] = r
    cyl[b, 1] = vr
    cyl[b, 2] = vt
    cyl[b, 3] = vz
    q[b, 0] = vol
    q[b, 1] = cc
    q[b, 2] = cc * r
    q[b, 3] = cc * vr + pf * vol * fab[b, 3]
    q[b, 4] = r * (cc * vt + pf * vol * fab[b, 4])
    q[b, 5] = cc * vz + pf * vol * (fab[b, 5] - body_z)
    return xx


@kernel
def beads_in(x, v, rad, mass, fab, eps_cells, body_z, pf, model_b, mu, rho, interval,
             rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, cyl, c, q, xmax):
    """Stencils, cylindrical coordinates cyl = (r, v_r, v_theta, v_z), drag coefficients
    c (Koch-Hill at the void fraction read from eps_cells and the relative speed to the
    fluid velocity of the last interval, fab[:, 0:3]; held over the interval by
    :func:`held_coefficient`) and the deposit columns q of every bead; xmax[b] =
    interval c / m."""
    for b in prange(x.shape[0]):
        xmax[b] = bead_in(b, x, v, rad, mass, fab, eps_cells, body_z, pf, model_b, mu, rho,
                          interval, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, cyl, c, q)


@serial
def cells_to_exchange(tot, vc, eps_min, solid, kr, kt, kz, vol_r, rc, eps_c, eps_r, eps_t,
                      eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z):
    """From the smoothed cell totals tot (NQ, n_r, n_t, n_z): the void fraction per cell
    (1 - V_beads / V, clipped below at eps_min; returns the number of clipped cells) and per
    velocity node (volume-weighted mean of the two cells), and the drag coefficient kd
    [kg/(m3 s)] and source sd [N/m3] per node: each cell's totals go half to each of its two
    faces of a component (all to the free one next to a wall), divided by the node's control
    volume (theta: also by r, the totals being in torque form). Two independent parts
    (:func:`cells_to_eps_kd` from columns 0-2, :func:`cells_to_sd` from 3-5), which the
    fused exchange runs on two threads."""
    clipped = cells_to_eps_kd(tot, vc, eps_min, solid, kr, kt, kz, vol_r, rc, eps_c, eps_r,
                              eps_t, eps_z, kd_r, kd_t, kd_z)
    cells_to_sd(tot, vc, solid, kr, kt, kz, vol_r, rc, sd_r, sd_t, sd_z)
    return clipped


@inlined
def cells_to_eps_kd(tot, vc, eps_min, solid, kr, kt, kz, vol_r, rc, eps_c, eps_r, eps_t,
                    eps_z, kd_r, kd_t, kd_z):
    """:func:`cells_to_exchange`'s void fractions and drag coefficients (columns 0-2 of
    tot); returns the number of clipped cells."""
    nr, nt, nz = solid.shape
    clipped = 0
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                if solid[i, j, k] != 0:
                    eps_c[i, j, k] = 1.0
                    continue
                e = 1.0 - tot[0, i, j, k] / vc[i]
                if e < eps_min:
                    e = eps_min
                    clipped += 1
                elif e > 1.0:
                    e = 1.0
                eps_c[i, j, k] = e
    split_to_nodes(tot, 1, 2, 1, solid, kr, kt, kz, vol_r, rc, vc, kd_r, kd_t, kd_z)
    for i in range(nr + 1):
        for j in range(nt):
            for k in range(nz):
                if i == 0 or i == nr:
                    eps_r[i, j, k] = 1.0
                else:
                    a = vc[i - 1] * eps_c[i - 1, j, k]
                    b = vc[i] * eps_c[i, j, k]
                    eps_r[i, j, k] = (a + b) / (vc[i - 1] + vc[i])
    for i in range(nr):
        for j in range(nt):
            jp = wrap(j + 1, nt)
            for k in range(nz):
                kp = wrap(k + 1, nz)
                eps_t[i, j, k] = 0.5 * (eps_c[i, j, k] + eps_c[i, jp, k])
                eps_z[i, j, k] = 0.5 * (eps_c[i, j, k] + eps_c[i, j, kp])
    return clipped


@inlined
def cells_to_sd(tot, vc, solid, kr, kt, kz, vol_r, rc, sd_r, sd_t, sd_z):
    """:func:`cells_to_exchange`'s sources (columns 3-5 of tot)."""
    split_to_nodes(tot, 3, 4, 5, solid, kr, kt, kz, vol_r, rc, vc, sd_r, sd_t, sd_z)


@inlined
def split_to_nodes(tot, cr, ct, cz, solid, kr, kt, kz, vol_r, rc, vc, out_r, out_t, out_z):
    """Columns cr, ct, cz of the cell totals tot onto the r, theta and z nodes (out_r,
    out_t, out_z): half of a cell's total to each of its two faces of a component (all to
    the free one next to a wall), per unit of the node's control volume (theta: also per
    r, the totals being in torque form)."""
    nr, nt, nz = solid.shape
    out_r[:] = 0.0
    out_t[:] = 0.0
    out_z[:] = 0.0
    for i in range(nr):
        for j in range(nt):
            jm = wrap(j - 1, nt)
            for k in range(nz):
                if solid[i, j, k] != 0:
                    continue
                km = wrap(k - 1, nz)
                # r: faces i (low) and i + 1
                wa, wb = split(kr[i, j, k], kr[i + 1, j, k])
                out_r[i, j, k] += wa * tot[cr, i, j, k]
                out_r[i + 1, j, k] += wb * tot[cr, i, j, k]
                # theta: faces jm and j
                wa, wb = split(kt[i, jm, k], kt[i, j, k])
                out_t[i, jm, k] += wa * tot[ct, i, j, k]
                out_t[i, j, k] += wb * tot[ct, i, j, k]
                # z: faces km and k
                wa, wb = split(kz[i, j, km], kz[i, j, k])
                out_z[i, j, km] += wa * tot[cz, i, j, k]
                out_z[i, j, k] += wb * tot[cz, i, j, k]
    for i in range(nr + 1):
        for j in range(nt):
            for k in range(nz):
                out_r[i, j, k] /= vol_r[i]
    for i in range(nr):
        sc = 1.0 / (rc[i] * vc[i])
        for j in range(nt):
            for k in range(nz):
                out_t[i, j, k] *= sc
                out_z[i, j, k] /= vc[i]


@serial
def nodes_to_cell_values(ur, ut, uz, gr, gt, gz, kr, kt, kz, solid, out):
    """Transpose of the node split in :func:`cells_to_exchange` for intensive node
    values: out[0:3, cell] the fluid velocity (u_r, u_theta, u_z) [m/s], out[3:6, cell] the
    pressure gradient [Pa/m], each the split-weighted mean of the cell's two faces."""
    nr, nt, nz = solid.shape
    for i in range(nr):
        for j in range(nt):
            jm = wrap(j - 1, nt)
            for k in range(nz):
                c = (i * nt + j) * nz + k
                if solid[i, j, k] != 0:
                    for m in range(6):
                        out[m, c] = 0.0
                    continue
                km = wrap(k - 1, nz)
                wa, wb = split(kr[i, j, k], kr[i + 1, j, k])
                out[0, c] = wa * ur[i, j, k] + wb * ur[i + 1, j, k]
                out[3, c] = wa * gr[i, j, k] + wb * gr[i + 1, j, k]
                wa, wb = split(kt[i, jm, k], kt[i, j, k])
                out[1, c] = wa * ut[i, jm, k] + wb * ut[i, j, k]
                out[4, c] = wa * gt[i, jm, k] + wb * gt[i, j, k]
                wa, wb = split(kz[i, j, km], kz[i, j, k])
                out[2, c] = wa * uz[i, j, km] + wb * uz[i, j, k]
                out[5, c] = wa * gz[i, j, km] + wb * gz[i, j, k]


@serial
def held_sums(fext):
    """Sums of T_z [N m] and F_z [N] of the held forces fext over the beads, in bead order.
    Summed after the parallel loop that sets them, not as its reduction: numba's parfor
    pass fails to compile a prange loop with a scalar reduction beside an inner loop with
    a conditional read (numba issue 10132, on Python 3.12); and so the sum does not depend
    on the thread count."""
    tsum = 0.0
    fsum = 0.0
    for b in range(fext.shape[0]):
        tsum += fext[b, 1]
        fsum += fext[b, 2]
    return tsum, fsum


@inlined
def bead_force(b, idx, w, cellv, c, cyl, rad, fab, pf, now, body_z, fext):
    """Bead b's part of :func:`bead_forces` (the cell values read back at it, its held
    force fext[b] and its fab[b]); returns (T_z [N m], F_z [N]). One body for the CPU's
    loop and the GPU's thread (:mod:`millfmu.dem.coupling.gpu_exchange`)."""
    at0, at1, at2 = at_bead3(b, idx, w, cellv, 0)
    at3, at4, at5 = at_bead3(b, idx, w, cellv, 3)
    d = 2.0 * rad[b]
    vol = math.pi / 6.0 * d * d * d
    r = cyl[b, 0]
    if now:
        g3 = at3
        g4 = at4
        g5 = at5
    else:
        g3 = fab[b, 3]
        g4 = fab[b, 4]
        g5 = fab[b, 5]
    fr = c[b] * (at0 - cyl[b, 1]) - pf * vol * g3
    tz = r * (c[b] * (at1 - cyl[b, 2]) - pf * vol * g4)
    fz = c[b] * (at2 - cyl[b, 3]) - pf * vol * (g5 - body_z)
    fext[b, 0] = fr
    fext[b, 1] = tz
    fext[b, 2] = fz
    fab[b, 0] = at0
    fab[b, 1] = at1
    fab[b, 2] = at2
    fab[b, 3] = at3
    fab[b, 4] = at4
    fab[b, 5] = at5
    return tz, fz


@kernel
def bead_forces(idx, w, cellv, c, cyl, rad, fab, pf, now, body_z, fext):
    """Read the smoothed cell values back at each bead (fluid velocity and pressure
    gradient), set the force held over the next interval, fext = (F_r [N], T_z [N m],
    F_z [N]): drag c (u - v) with the fluid velocity of this interval, and in model A
    (pf = 1) the pressure-gradient force -V (grad p - G e_z) with the gradient of the last
    interval (the one whose reaction the fluid was given; now = False) or of this interval
    (now = True); then store the new values in fab. Returns the sums of T_z and F_z over
    the beads."""
    for b in prange(idx.shape[0]):
        bead_force(b, idx, w, cellv, c, cyl, rad, fab, pf, now, body_z, fext)
    return held_sums(fext)
