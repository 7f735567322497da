"""Beads <-> fluid grid: what the beads put on the grid, and what the grid gives back.

Three linear steps, each conserving totals; interpolation back to the beads applies the
transposes in reverse order, so that whatever the fluid loses to the beads through the
exchange terms the beads gain exactly (to round-off):

1. Deposit (cloud in cell): a bead's quantity goes to the (up to 8) cell centres around it
   with trilinear weights in (r, theta, z); weights on solid cells are dropped and the rest
   renormalised, so that each bead deposits exactly its total. Interpolation reads the
   same cells with the same weights.
2. Smoothing (a Helmholtz filter, as Lethe smooths its void fraction): densities q/V are
   filtered by (I - L^2 Lap) q_s = q with zero flux through walls and solids, i.e. totals by
   T_s = V H^-1 T with H = V - L^2 G (G the finite-volume Laplacian of the fluid cells).
   H 1 = V 1, so the totals are conserved; H is an M-matrix, so nothing turns negative;
   intensive fields are smoothed by the transpose H^-1 V. The smoothing length L [m] is a
   physical length (default one bead diameter; the kernel's standard deviation per axis is
   sqrt(2) L), so the void fraction does not depend on the cell size when cells are smaller
   than a bead. One sparse LU factorisation of H serves the whole run.
3. Cells -> velocity nodes: each cell's total goes half to each of its two faces of a
   component (all of it to the free one when the other is a wall or solid face); a node's
   value is read back as the cells' mean of their faces with the same weights.

The void fraction per cell is 1 - (smoothed bead volume) / V, clipped to
[eps_min, 1] (clipping is counted). The void fraction on a velocity node is the volume-
weighted mean of the cells beside it.
"""

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from millfmu.dem._jit import serial
from millfmu.dem.fluid.grid import FLUID


@serial
def bead_stencils(x, rc, rmin, rmax, dth, nt, dz, nz, lz, solid, idx, w):
    """Trilinear cell stencils of beads at Cartesian x [m] (n, 3): idx (n, 8) flat cell
    indices, w (n, 8) weights summing to 1 over fluid cells. Also returns r [m], theta
    [rad] (in [0, nt dth)) and z [m] (in [0, lz)) per bead."""
    n = x.shape[0]
    nr = rc.size
    rr = np.empty(n)
    tt = np.empty(n)
    zz = np.empty(n)
    for b in range(n):
        r = math.sqrt(x[b, 0] ** 2 + x[b, 1] ** 2)
        th = math.atan2(x[b, 1], x[b, 0])
        sec = nt * dth
        th -= sec * math.floor(th / sec)
        z = x[b, 2] - lz * math.floor(x[b, 2] / lz)
        rr[b] = r
        tt[b] = th
        zz[b] = z
        # radial: cell centres around r (non-uniform spacing), clamped at the walls
        if r <= rc[0]:
            i0 = 0
            fr = 0.0
        elif r >= rc[nr - 1]:
            i0 = nr - 2
            fr = 1.0
        else:
            lo = 0
            hi = nr - 1
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if rc[mid] <= r:
                    lo = mid
                else:
                    hi = mid
            i0 = lo
            fr = (r - rc[i0]) / (rc[i0 + 1] - rc[i0])
        if nt > 1:
            t = th / dth - 0.5
            j0f = math.floor(t)
            ft = t - j0f
            j0 = int(j0f) % nt
        else:
            j0 = 0
            ft = 0.0
        t = z / dz - 0.5
        k0f = math.floor(t)
        fz = t - k0f
        k0 = int(k0f) % nz
        s = 0.0
        m = 0
        for a in range(2):
            wa = fr if a else 1.0 - fr
            ia = i0 + a
            for bb in range(2):
                wb = ft if bb else 1.0 - ft
                jb = (j0 + bb) % nt
                for c in range(2):
                    wc = fz if c else 1.0 - fz
                    kc = (k0 + c) % nz
                    ww = wa * wb * wc
                    if solid[ia, jb, kc] != 0:
                        ww = 0.0
                    idx[b, m] = (ia * nt + jb) * nz + kc
                    w[b, m] = ww
                    s += ww
                    m += 1
        if s > 0.0:
            for m in range(8):
                w[b, m] /= s
        else:
            # no fluid cell around the bead's stencil (cannot happen for a bead in the
            # fluid): put it in the cell that holds its centre
            ic = 0
            while ic < nr - 1 and rc[ic] + 0.5 * (rc[ic + 1] - rc[ic]) < r:
                ic += 1
            for m in range(8):
                w[b, m] = 0.0
            idx[b, 0] = (ic * nt + int(th / dth) % nt) * nz + int(z / dz) % nz
            w[b, 0] = 1.0
    return rr, tt, zz


@serial
def deposit(idx, w, q, out):
    """out[cell, m] += sum over beads of w q[bead, m] (totals per cell)."""
    out[:, :] = 0.0
    for b in range(idx.shape[0]):
        for s in range(8):
            ww = w[b, s]
            if ww != 0.0:
                c = idx[b, s]
                for m in range(q.shape[1]):
                    out[c, m] += ww * q[b, m]


@serial
def gather(idx, w, field, out):
    """out[bead, m] = sum over the stencil of w field[cell, m]."""
    for b in range(idx.shape[0]):
        for m in range(field.shape[1]):
            out[b, m] = 0.0
        for s in range(8):
            ww = w[b, s]
            if ww != 0.0:
                c = idx[b, s]
                for m in range(field.shape[1]):
                    out[b, m] += ww * field[c, m]


@serial
def cells_to_nodes(tot, kind, axis, out):
    """Split cell totals tot (nr, nt, nz) onto the nodes of one velocity component with
    node kinds ``kind``: axis 0 r-faces (out (nr+1, nt, nz)), 1 theta faces, 2 z-faces
    (out (nr, nt, nz)). Half to each free face, all to the free one if the other is fixed."""
    nr, nt, nz = tot.shape
    out[:, :, :] = 0.0
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                t = tot[i, j, k]
                if t == 0.0:
                    continue
                if axis == 0:
                    la, lb = (i, j, k), (i + 1, j, k)
                elif axis == 1:
                    la, lb = (i, (j - 1) % nt, k), (i, j, k)
                else:
                    la, lb = (i, j, (k - 1) % nz), (i, j, k)
                fa = kind[la] == 0
                fb = kind[lb] == 0
                if fa and fb:
                    out[la] += 0.5 * t
                    out[lb] += 0.5 * t
                elif fa:
                    out[la] += t
                elif fb:
                    out[lb] += t


@serial
def nodes_to_cells(val, kind, axis, solid, out):
    """Transpose of :func:`cells_to_nodes` for intensive node values: each fluid cell
    receives the weighted mean of its two faces with the split weights."""
    nr, nt, nz = out.shape
    for i in range(nr):
        for j in range(nt):
            for k in range(nz):
                out[i, j, k] = 0.0
                if solid[i, j, k] != 0:
                    continue
                if axis == 0:
                    la, lb = (i, j, k), (i + 1, j, k)
                elif axis == 1:
                    la, lb = (i, (j - 1) % nt, k), (i, j, k)
                else:
                    la, lb = (i, j, (k - 1) % nz), (i, j, k)
                fa = kind[la] == 0
                fb = kind[lb] == 0
                if fa and fb:
                    out[i, j, k] = 0.5 * (val[la] + val[lb])
                elif fa:
                    out[i, j, k] = val[la]
                elif fb:
                    out[i, j, k] = val[lb]


class Projector:
    """Deposit, smoothing and node splits of :mod:`millfmu.dem.coupling.projection` for one
    grid. ``smoothing_length_m`` [m]: the Helmholtz filter length L (0: no smoothing)."""

    def __init__(self, grid, smoothing_length_m: float, eps_min: float = 0.35):
        self.grid = grid
        self.L = float(smoothing_length_m)
        self.eps_min = float(eps_min)
        g = grid
        nr, nt, nz = g.shape
        self.fluid = (g.solid == FLUID)
        self.index = np.full(g.shape, -1, np.int64)
        nf = int(self.fluid.sum())
        self.index[self.fluid] = np.arange(nf)
        self.vol = np.broadcast_to(g.cell_volume_m3[:, None, None], g.shape)[self.fluid].copy()
        self.vol_cells = np.broadcast_to(g.cell_volume_m3[:, None, None], g.shape).copy()
        self.rc = np.ascontiguousarray(g.r_centres_m)
        self._lu = None
        if self.L > 0.0:
            rf, rc = g.r_faces_m, g.r_centres_m
            dth, dz = g.dtheta_rad, g.dz_m
            rows, cols, vals = [], [], []
            idx = self.index

            def couple(a, b, cond):
                m = (a >= 0) & (b >= 0)
                a, b, c = a[m], b[m], np.broadcast_to(cond, a.shape)[m] if np.ndim(cond) else \
                    np.full(int(m.sum()), cond)
                rows.extend([a, b, a, b])
                cols.extend([b, a, a, b])
                vals.extend([-c, -c, c, c])

            ii, jj, kk = np.meshgrid(np.arange(1, nr), np.arange(nt), np.arange(nz),
                                     indexing="ij")
            cond_r = (rf[1:nr] * dth * dz / (rc[1:] - rc[:-1]))[:, None, None]
            couple(idx[ii - 1, jj, kk], idx[ii, jj, kk], np.broadcast_to(cond_r, ii.shape))
            ii, jj, kk = np.meshgrid(np.arange(nr), np.arange(nt), np.arange(nz),
                                     indexing="ij")
            if nt > 1:
                cond_t = (g.dr_m * dz / (rc * dth))[:, None, None]
                couple(idx[ii, jj, kk], idx[ii, (jj + 1) % nt, kk],
                       np.broadcast_to(cond_t, ii.shape))
            cond_z = (g.cell_volume_m3 / dz / dz)[:, None, None]
            couple(idx[ii, jj, kk], idx[ii, jj, (kk + 1) % nz], np.broadcast_to(cond_z, ii.shape))
            G = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))), shape=(nf, nf))
            H = sp.diags(self.vol) + self.L ** 2 * G
            self._lu = spla.splu(H.tocsc())

    # ---- smoothing ----------------------------------------------------------------------
    def smooth_totals(self, tot):
        """Smooth cell totals (ncells_grid, m) in place: T_s = V H^-1 T on the fluid cells."""
        if self._lu is None:
            return tot
        f = self.fluid.ravel()
        t = tot[f]
        tot[f] = self.vol[:, None] * self._lu.solve(np.ascontiguousarray(t))
        return tot

    def smooth_values(self, val):
        """Smooth intensive cell values (ncells_grid, m) in place: v_s = H^-1 V v."""
        if self._lu is None:
            return val
        f = self.fluid.ravel()
        v = val[f]
        val[f] = self._lu.solve(np.ascontiguousarray(self.vol[:, None] * v))
        return val
