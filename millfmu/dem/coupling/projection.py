"""Beads <-> fluid grid: what the beads put on the grid, and what the grid gives back.

Three linear steps, each conserving totals; interpolation back to the beads applies the
transposes in reverse order, so that whatever the fluid loses to the beads through the
exchange terms the beads gain exactly (to round-off):

1. Deposit (cloud in cell): a bead's quantity goes to the (up to 8) cell centres around it
   with trilinear weights in (r, theta, z); weights on solid cells are dropped and the rest
   renormalised, so that each bead deposits exactly its total. Interpolation reads the
   same cells with the same weights.
2. Smoothing by diffusion (as CFDEM smooths its void fraction and exchange fields): a few
   explicit finite-volume diffusion steps of the densities q/V among the fluid cells, with
   zero flux through walls and solids, so that the totals are conserved exactly; the step
   size keeps every cell's loss below half its content, so nothing turns negative.
   Intensive fields are smoothed by the transpose (the same diffusion of the values). The
   smoothing length L [m] is a physical length (default one bead diameter): the kernel's
   variance per axis is 2 L^2 (as for a Helmholtz filter of length L, Lethe's form), reached
   in as many steps as the cell size needs, so the void fraction does not depend on the
   cell size when cells are smaller than a bead.
3. Cells -> velocity nodes (:mod:`millfmu.dem.coupling.exchange_kernels`): each cell's
   total goes half to each of its two faces of a component (all of it to the free one when
   the other is a wall or solid face); node values are read back into a cell as the mean
   of its faces with the same weights.

The void fraction per cell is 1 - (smoothed bead volume) / V, clipped to
[eps_min, 1] (clipping is counted). The void fraction on a velocity node is the volume-
weighted mean of the cells beside it.
"""

import math

import numpy as np
from numba import prange

from millfmu.dem.coupling.settings import SMOOTHINGS
from millfmu.dem.engine._jit import inlined, kernel, nonneg
from millfmu.dem.fluid.grid import FLUID
from millfmu.dem.fluid.vans_kernels import wrap


def radial_table(rc):
    """Lookup table for the radial cell index (see :func:`stencil_one`): bins of a quarter
    of the smallest centre spacing from rc[0]; entry = the largest i with rc[i] <= the bin's
    lower edge. Returns (table (int64), bin width [m])."""
    h = 0.25 * float(np.diff(rc).min())
    nb = int(np.ceil((rc[-1] - rc[0]) / h)) + 2
    edges = rc[0] + h * np.arange(nb)
    tab = np.clip(np.searchsorted(rc, edges, side="right") - 1, 0, rc.size - 2)
    return tab.astype(np.int64), h


@inlined
def stencil_one(b, x, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w):
    """Trilinear stencil of bead b (see :func:`bead_stencils`); returns its r [m]. rtab, rh:
    :func:`radial_table` of rc."""
    nr = rc.size
    ns = idx.shape[1]
    nbb = ns // 4  # theta corners: 2, or 1 in a 4-wide stencil (axisymmetric grid)
    r = math.sqrt(x[b, 0] ** 2 + x[b, 1] ** 2)
    th = 0.0
    if nt > 1:  # the axisymmetric mode needs no angle
        th = math.atan2(x[b, 1], x[b, 0])
        sec = nt * dth
        th -= sec * math.floor(th / sec)
    z = x[b, 2] - lz * math.floor(x[b, 2] / lz)
    # radial: cell centres around r (non-uniform spacing), clamped at the walls
    if r <= rc[0]:
        i0 = 0
        fr = 0.0
    elif r >= rc[nr - 1]:
        i0 = nr - 2
        fr = 1.0
    else:
        i0 = nonneg(rtab[nonneg(int((r - rc[0]) / rh))])
        while i0 < nr - 2 and rc[i0 + 1] <= r:  # at most a step or two
            i0 += 1
        fr = (r - rc[i0]) / (rc[i0 + 1] - rc[i0])
    if nt > 1:
        t = th / dth - 0.5
        j0f = math.floor(t)
        ft = t - j0f
        j0 = wrap(int(j0f), nt)
    else:
        j0 = 0
        ft = 0.0
    t = z / dz - 0.5
    k0f = math.floor(t)
    fz = t - k0f
    k0 = wrap(int(k0f), nz)
    s = 0.0
    m = 0
    # the wrapped neighbours once, not per corner (an integer modulo costs tens of cycles)
    j1 = j0 + 1 if j0 + 1 < nt else 0
    k1 = k0 + 1 if k0 + 1 < nz else 0
    for a in range(2):
        wa = fr if a else 1.0 - fr
        ia = i0 + a
        for bb in range(nbb):
            wb = ft if bb else 1.0 - ft
            jb = j1 if bb else j0
            for c in range(2):
                wc = fz if c else 1.0 - fz
                kc = k1 if c else k0
                ww = wa * wb * wc
                if solid[ia, jb, kc] != 0:
                    ww = 0.0
                idx[b, m] = (ia * nt + jb) * nz + kc
                w[b, m] = ww
                s += ww
                m += 1
    if s > 0.0:
        # w / 1.0 is w itself: the weights of a bead without a solid corner mostly sum to
        # exactly 1 (92 % of the running sector's beads), and their four divisions are
        # then skipped
        if s != 1.0:
            for m in range(ns):
                w[b, m] /= s
    else:
        # no fluid cell in the stencil (cannot happen for a bead in the fluid): the cell
        # that holds its centre
        ic = 0
        while ic < nr - 1 and rc[ic] + 0.5 * (rc[ic + 1] - rc[ic]) < r:
            ic += 1
        for m in range(ns):
            w[b, m] = 0.0
        idx[b, 0] = (ic * nt + int(th / dth) % nt) * nz + int(z / dz) % nz
        w[b, 0] = 1.0
    return r


def stencil_width(nt: int) -> int:
    """Entries of a bead's stencil on a grid of ``nt`` theta cells: 8 corners, or 4 where
    nt = 1 (the axisymmetric grid's two theta corners are one cell, the second of weight 0:
    leaving it out keeps every sum over the stencil the same, in the same order, and
    halves the stencils' memory and the loops over them)."""
    return 8 if int(nt) > 1 else 4



@inlined
def bead_cyl(b, x, v, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w):
    """Bead b's stencil (idx[b], w[b]; :func:`stencil_one`) and its cylindrical coordinates:
    returns (r [m], v_r, v_theta, v_z [m/s])."""
    r = stencil_one(b, x, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w)
    inv = 1.0 / r if r > 0.0 else 0.0
    vr = (x[b, 0] * v[b, 0] + x[b, 1] * v[b, 1]) * inv
    vt = (x[b, 0] * v[b, 1] - x[b, 1] * v[b, 0]) * inv
    return r, vr, vt, v[b, 2]


@inlined
def at_bead(b, idx, w, field):
    """A cell field (one value per cell, [any unit]) read at bead b through its stencil."""
    a = 0.0
    for s in range(idx.shape[1]):
        ww = w[b, s]
        if ww != 0.0:
            a += ww * field[nonneg(idx[b, s])]
    return a


@inlined
def at_bead3(b, idx, w, cellv, k):
    """Three cell fields, cellv[k], cellv[k + 1], cellv[k + 2], read at bead b through its
    stencil in one pass (each summed in the order :func:`at_bead` sums it)."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for s in range(idx.shape[1]):
        ww = w[b, s]
        if ww != 0.0:
            cc = nonneg(idx[b, s])
            a0 += ww * cellv[k, cc]
            a1 += ww * cellv[k + 1, cc]
            a2 += ww * cellv[k + 2, cc]
    return a0, a1, a2

@kernel
def bead_stencils(x, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, r_out):
    """Trilinear cell stencils of beads at Cartesian x [m] (n, 3): idx (n, ns) flat cell
    indices, w (n, ns) weights summing to 1 over fluid cells (weights on solid cells
    dropped, the rest renormalised); r_out [m] the beads' radii from the axis. Theta is
    taken in [0, nt dth), z in [0, lz). ns = 8 corners (r, theta, z), or 4 on an
    axisymmetric grid (nt = 1, see :func:`stencil_width`), whose two theta corners are the
    same cell and the second has weight 0."""
    for b in prange(x.shape[0]):
        r_out[b] = stencil_one(b, x, rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w)


@kernel
def deposit(idx, w, q, out):
    """out[m, cell] = sum over beads of w q[bead, m] (totals per cell; out (m, ncells)).
    Each column is summed over the beads in their order: the same totals on any thread
    count. Six columns (the coupling's): two halves of three on the threads, each reading
    a bead's three values once before its corners and adding into its three rows (two
    thirds of one serial pass's time; a thread per column would read a column's values
    again after every store, slower than the serial pass); any other column count, column
    by column."""
    nm = q.shape[1]
    nb = idx.shape[0]
    ns = idx.shape[1]
    if nm == 6:
        for h in prange(2):
            deposit_half(h, idx, w, q, out)
        return
    out[:, :] = 0.0
    for m in range(nm):
        om = out[m]
        for b in range(nb):
            qq = q[b, m]
            for s in range(ns):
                ww = w[b, s]
                if ww != 0.0:
                    om[nonneg(idx[b, s])] += ww * qq


@inlined
def deposit_half(h, idx, w, q, out):
    """Columns 3 h .. 3 h + 2 of :func:`deposit`'s six (h = 0 or 1), on the calling
    thread."""
    nb = idx.shape[0]
    ns = idx.shape[1]
    m0 = 3 * h
    o0 = out[m0]
    o1 = out[m0 + 1]
    o2 = out[m0 + 2]
    o0[:] = 0.0
    o1[:] = 0.0
    o2[:] = 0.0
    for b in range(nb):
        q0 = q[b, m0]
        q1 = q[b, m0 + 1]
        q2 = q[b, m0 + 2]
        for s in range(ns):
            ww = w[b, s]
            if ww != 0.0:
                c = nonneg(idx[b, s])
                o0[c] += ww * q0
                o1[c] += ww * q1
                o2[c] += ww * q2


@kernel
def gather(idx, w, field, out):
    """out[bead, m] = sum over the stencil of w field[m, cell] (field (m, ncells))."""
    nm = field.shape[0]
    ns = idx.shape[1]
    for b in prange(idx.shape[0]):
        for m in range(nm):
            out[b, m] = 0.0
        for s in range(ns):
            ww = w[b, s]
            if ww != 0.0:
                c = nonneg(idx[b, s])
                for m in range(nm):
                    out[b, m] += ww * field[m, c]


class Projector:
    """Smoothing of :mod:`millfmu.dem.coupling.projection` for one grid.
    ``smoothing_length_m`` [m]: L, the kernel's variance per axis being 2 L^2 (0: no
    smoothing), reached by ``method`` (:data:`millfmu.dem.coupling.settings.SMOOTHINGS`;
    ``steps``: split_implicit's backward-Euler steps)."""

    def __init__(self, grid, smoothing_length_m: float, eps_min: float = 0.35,
                 method: str = "explicit_diffusion", steps: int = 4):
        self.grid = grid
        self.L = float(smoothing_length_m)
        self.eps_min = float(eps_min)
        g = grid
        nr, nt, nz = g.shape
        self.fluid = (g.solid == FLUID)
        self.vol_cells = np.broadcast_to(g.cell_volume_m3[:, None, None], g.shape).copy()
        self.rc = np.ascontiguousarray(g.r_centres_m)
        self.rtab, self.rh = radial_table(self.rc)
        # explicit diffusion sweeps: per-sweep face coefficients alpha = kappa dtau A / h
        # [m3] between fluid cells, on the "+" face of each cell (r, theta, z)
        if method not in SMOOTHINGS:
            raise ValueError(f"smoothing = {method!r}: allowed {list(SMOOTHINGS)}")
        cr, ct, cz = g.face_conductances_m()
        fl = self.fluid
        self._ar = np.zeros(g.shape)
        self._at = np.zeros(g.shape)
        self._az = np.zeros(g.shape)
        self._ar[:-1] = np.where(fl[:-1] & fl[1:], cr[:, None, None], 0.0)
        if nt > 1:
            self._at[:] = np.where(fl & np.roll(fl, -1, axis=1), ct[:, None, None], 0.0)
        self._az[:] = np.where(fl & np.roll(fl, -1, axis=2), cz[:, None, None], 0.0)
        # stability and positivity: sum of a cell's coefficients <= V / 2 per sweep
        conn = self._ar + np.roll(self._ar, 1, axis=0) * (np.arange(nr) > 0)[:, None, None] + \
            self._at + np.roll(self._at, 1, axis=1) + self._az + np.roll(self._az, 1, axis=2)
        with np.errstate(divide="ignore"):
            k_max = 0.5 / float(np.max(np.where(fl, conn / self.vol_cells, 0.0)))
        #: per-axis variance of the kernel [m2]: 2 L^2, as for a Helmholtz filter of length L
        self.variance_m2 = 2.0 * self.L ** 2
        self.sweeps = int(math.ceil(self.variance_m2 / (2.0 * k_max))) if self.L > 0 else 0
        kappa = self.variance_m2 / (2.0 * self.sweeps) if self.sweeps else 0.0
        self.method = method
        self._implicit = None
        if method == "split_implicit" and self.L > 0:
            from millfmu.dem.coupling.split_implicit_smoothing import SplitImplicitSmoother

            # the face coefficients of one unit of kappa dtau (before the sweeps' scaling)
            self._implicit = SplitImplicitSmoother(g.shape, g.cell_volume_m3, self._ar,
                                                   self._at, self._az, self.variance_m2,
                                                   steps)
        for a in (self._ar, self._at, self._az):
            a *= kappa
        self._tmp = None
        self._vol_r = np.ascontiguousarray(g.cell_volume_m3)

    # ---- smoothing ----------------------------------------------------------------------
    def smooth_totals(self, tot, ncols=None):
        """Smooth cell totals (m, ncells_grid) in place (conservative diffusion), the first
        ``ncols`` fields (default all)."""
        return self._smooth(tot, True, ncols)

    def smooth_values(self, val, ncols=None):
        """Smooth intensive cell values (m, ncells_grid) in place, the first ``ncols``
        fields: the transpose of :meth:`smooth_totals`."""
        return self._smooth(val, False, ncols)

    def _smooth(self, a, totals, ncols):
        if self._implicit is not None:
            self._implicit.smooth(a, totals, a.shape[0] if ncols is None else int(ncols))
        elif self.sweeps:
            a4 = a.reshape((a.shape[0],) + self.grid.shape)
            if self._tmp is None or self._tmp.shape != a4.shape:
                self._tmp = np.zeros(a4.shape)
            diffuse(a4, self._vol_r, self._ar, self._at, self._az, self.sweeps, totals,
                    self._tmp, a.shape[0] if ncols is None else int(ncols))
        return a


@kernel
def diffuse(q, vol, ar, at, az, sweeps, totals, tmp, ncols):
    """``sweeps`` explicit diffusion steps on the first ``ncols`` fields of q
    (m, n_r, n_t, n_z) with the "+"-face coefficients ar, at, az [m3] (0 at walls and
    solids) and cell volumes vol (n_r,). totals: q holds extensive totals, the flux
    alpha (q_a/V_a - q_b/V_b) moves between a and b (sums conserved); else q holds intensive
    values and each cell moves by sum alpha (q_b - q_a) / V_a (the transpose).

    The fields are independent: one thread per field, each field's sweeps in the same
    order as one thread would make them (the same results on any thread count). With theta
    cells this is the coupled step's largest part (the accelerator slice with 12 theta
    cells: 59 % of a coupling interval on one thread, about 95 sweeps of 6 fields).

    Along a row (fixed i, j) the cell being visited and the next one are carried in
    registers: each receives the same additions in the same order as through memory (the
    same bits), and the next cell's value need not wait for the store of the face flux just
    added to it. The row's last cell, whose +z face wraps to its first, goes through
    memory."""
    for c in prange(ncols):
        diffuse_field(c, q, vol, ar, at, az, sweeps, totals, tmp)


@inlined
def diffuse_field(c, q, vol, ar, at, az, sweeps, totals, tmp):
    """Field c of :func:`diffuse` (its sweeps, on the calling thread)."""
    nr, nt, nz = ar.shape
    for _ in range(sweeps):
        # tmp: densities (totals) or values at the start of the sweep; q accumulates
        for i in range(nr):
            f = 1.0 / vol[i] if totals else 1.0
            for j in range(nt):
                for k in range(nz):
                    tmp[c, i, j, k] = q[c, i, j, k] * f
        for i in range(nr):
            ia = 1.0 if totals else 1.0 / vol[i]
            ib = 1.0 if totals or i + 1 >= nr else 1.0 / vol[i + 1]
            for j in range(nt):
                jp = j + 1 if j + 1 < nt else 0
                # v: cell k, with everything the faces before it gave it; vn: cell k + 1
                v = q[c, i, j, 0]
                for k in range(nz - 1):
                    t0 = tmp[c, i, j, k]
                    vn = q[c, i, j, k + 1]
                    al = az[i, j, k]
                    if al != 0.0:
                        f = al * (t0 - tmp[c, i, j, k + 1])
                        v -= f * ia
                        vn += f * ia
                    al = ar[i, j, k]
                    if al != 0.0:
                        f = al * (t0 - tmp[c, i + 1, j, k])
                        v -= f * ia
                        q[c, i + 1, j, k] += f * ib
                    if nt > 1:
                        al = at[i, j, k]
                        if al != 0.0:
                            f = al * (t0 - tmp[c, i, jp, k])
                            v -= f * ia
                            q[c, i, jp, k] += f * ia
                    q[c, i, j, k] = v
                    v = vn
                k = nz - 1
                q[c, i, j, k] = v
                t0 = tmp[c, i, j, k]
                al = az[i, j, k]
                if al != 0.0:
                    f = al * (t0 - tmp[c, i, j, 0])
                    q[c, i, j, k] -= f * ia
                    q[c, i, j, 0] += f * ia
                al = ar[i, j, k]
                if al != 0.0:
                    f = al * (t0 - tmp[c, i + 1, j, k])
                    q[c, i, j, k] -= f * ia
                    q[c, i + 1, j, k] += f * ib
                if nt > 1:
                    al = at[i, j, k]
                    if al != 0.0:
                        f = al * (t0 - tmp[c, i, jp, k])
                        q[c, i, j, k] -= f * ia
                        q[c, i, jp, k] += f * ia
