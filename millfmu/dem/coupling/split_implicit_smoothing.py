"""Smoothing of the beads' fields by split implicit diffusion (``smoothing = "split_implicit"``).

The same diffusion as :class:`millfmu.dem.coupling.projection.Projector`'s explicit sweeps
(densities q/V among the fluid cells, the same face coefficients, zero flux through walls
and solids, periodic in theta and z), taken to the same per-axis variance 2 L^2 in
``steps`` backward-Euler steps, each split by direction (r, theta, z: one tridiagonal,
or for the periodic directions cyclic tridiagonal, solve per grid line). As in Sun & Xiao
(2015, "Diffusion-based coarse graining in hybrid continuum-discrete solvers",
Int. J. Multiphase Flow 72, 233-247), the implicit steps are stable at any step size, so
the cost does not grow with (L / cell size)^2 as the explicit sweeps' count does (86 sweeps
for the accelerator slice's 2 d over 0.5 mm cells).

Properties, each checked in ``tests/dem/test_smoothing.py``:

- totals are conserved to round-off: each factor V (V - L_d)^-1, with L_d the direction's
  graph Laplacian (symmetric, zero row sums), keeps sum(q);
- nothing turns negative: V - L_d is a symmetric M-matrix, whose inverse is non-negative;
- a backward-Euler step of the discrete diffusion adds exactly 2 kappa dtau to the variance
  per axis on a uniform periodic line, as an explicit one does: ``steps`` steps reach 2 L^2;
- the values' smoothing is the exact transpose of the totals' (the factors transposed,
  in reverse order), so that the exchange between beads and liquid stays exact.

The kernel's shape differs from the explicit sweeps' (which approach the heat kernel, a
Gaussian): one step is a product of 1D Helmholtz filters (exp(-|x|/L) per axis, Lethe's
filter of length L), whose peak is sqrt(pi) = 1.77 times a Gaussian's of the same variance
per axis (5.6 times in 3D: more of a dense bed's cells clipped at eps_min); more steps
approach the Gaussian (``steps = 4``, the default: 1.11 times per axis, 1.36 in 3D). The
steps are chosen with ``fluid.coupled.smoothing_steps``.
"""

import numpy as np
from numba import prange

from millfmu.dem.engine._jit import kernel, serial


@serial
def factor_lines(starts, stride, m, periodic, vol, alpha, e_line, cp, invden, zc, smb, smg):
    """Factorise each line's matrix V + L (diagonal V + the faces' alpha, off-diagonals
    -alpha; ``alpha[c]``: the face between cell c and the next along the line, the last
    one's the wrap when ``periodic``). Writes, per cell: ``e_line`` (the coupling to the
    next cell in the line), ``cp`` and ``invden`` (Thomas's modified super-diagonal and
    inverse pivots); per line, at its first cell: the Sherman-Morrison vector ``zc`` and
    scalars ``smb`` (w / b0), ``smg`` (1 / (1 + v.z)); smg = 0 where the line is not cyclic
    (no wrap face, or fewer than 3 cells)."""
    for s in range(starts.size):
        c0 = starts[s]
        w = alpha[c0 + (m - 1) * stride] if periodic else 0.0
        for k in range(m):
            c = c0 + k * stride
            e_line[c] = alpha[c] if k < m - 1 else 0.0
        if periodic and m == 2:  # both faces join the same two cells
            e_line[c0] += w
            w = 0.0
        # the diagonal: V + the faces on both sides (the wrap face on the first and last)
        b0 = 0.0
        for k in range(m):
            c = c0 + k * stride
            b = vol[c] + e_line[c]
            if k > 0:
                b += e_line[c - stride]
            if periodic and m > 2 and (k == 0 or k == m - 1):
                b += w
            if k == 0:
                b0 = b
                if w != 0.0:
                    b *= 2.0  # b0 - gamma with gamma = -b0 (Numerical Recipes' cyclic)
            if k == m - 1 and w != 0.0:
                b += w * w / b0  # b_m-1 - alpha beta / gamma
            den = b if k == 0 else b - e_line[c - stride] * e_line[c - stride] * \
                invden[c - stride]
            # stored: 1 / den and cp = -e / den (a symmetric tridiagonal)
            invden[c] = 1.0 / den
            cp[c] = -e_line[c] * invden[c]
        smg[c0] = 0.0
        smb[c0] = 0.0
        if w != 0.0:
            # A' z = u, u = (gamma, 0, ..., alpha) = (-b0, 0, ..., -w)
            for k in range(m):
                c = c0 + k * stride
                u = -b0 if k == 0 else (-w if k == m - 1 else 0.0)
                prev = zc[c - stride] if k > 0 else 0.0
                ek = e_line[c - stride] if k > 0 else 0.0
                zc[c] = (u + ek * prev) * invden[c]
            for k in range(m - 2, -1, -1):
                c = c0 + k * stride
                zc[c] -= cp[c] * zc[c + stride]
            smb[c0] = w / b0
            smg[c0] = 1.0 / (1.0 + zc[c0] + smb[c0] * zc[c0 + (m - 1) * stride])


@kernel
def solve_lines(q, ncols, starts, stride, m, vol, e_line, cp, invden, zc, smb, smg, totals):
    """One direction's factor on the first ``ncols`` fields of q (m_fields, ncells):
    totals: q <- V (V + L)^-1 q; values: q <- (V + L)^-1 V q (its transpose). One thread
    per field, the lines in the same order on any thread count."""
    for f in prange(ncols):
        for s in range(starts.size):
            c0 = starts[s]
            # forward: y_k = (r_k + e_k-1 y_k-1) / den_k
            prev = 0.0
            for k in range(m):
                c = c0 + k * stride
                r = q[f, c] if totals else q[f, c] * vol[c]
                if k > 0:
                    r += e_line[c - stride] * prev
                prev = r * invden[c]
                q[f, c] = prev
            # back: x_k = y_k - cp_k x_k+1
            nxt = q[f, c0 + (m - 1) * stride]
            for k in range(m - 2, -1, -1):
                c = c0 + k * stride
                nxt = q[f, c] - cp[c] * nxt
                q[f, c] = nxt
            if smg[c0] != 0.0:
                fact = (q[f, c0] + smb[c0] * q[f, c0 + (m - 1) * stride]) * smg[c0]
                for k in range(m):
                    c = c0 + k * stride
                    q[f, c] -= fact * zc[c]
            if totals:
                for k in range(m):
                    c = c0 + k * stride
                    q[f, c] *= vol[c]


class SplitImplicitSmoother:
    """Split implicit diffusion on a grid of shape (nr, nt, nz) with the "+"-face
    coefficients ar, at, az [m3] of one unit of kappa dtau (0 at walls and solids; at's and
    az's last faces wrap round), cell volumes ``vol_r`` (nr,) [m3], per-axis variance
    ``variance_m2`` [m2] reached in ``steps`` steps."""

    def __init__(self, shape, vol_r, ar, at, az, variance_m2: float, steps: int):
        nr, nt, nz = shape
        self.steps = int(steps)
        scale = variance_m2 / (2.0 * self.steps)
        vol = np.ascontiguousarray(np.broadcast_to(
            np.asarray(vol_r, float)[:, None, None], shape).ravel())
        self.vol = vol
        idx = np.arange(nr * nt * nz).reshape(shape)
        # each direction: (first cells of its lines, stride, cells per line, periodic, alpha)
        dirs = [(idx[0].ravel(), nt * nz, nr, False, ar)]
        if nt > 1:
            dirs.append((idx[:, 0, :].ravel(), nz, nt, True, at))
        if nz > 1:
            dirs.append((idx[:, :, 0].ravel(), 1, nz, True, az))
        self.dirs = []
        for starts, stride, m, periodic, a in dirs:
            n = vol.size
            arr = [np.zeros(n) for _ in range(6)]
            factor_lines(np.ascontiguousarray(starts, np.int64), stride, m, periodic, vol,
                         np.ascontiguousarray(a.ravel() * scale), *arr)
            self.dirs.append((np.ascontiguousarray(starts, np.int64), stride, m, *arr))

    def smooth(self, q, totals: bool, ncols: int):
        """Smooth the first ``ncols`` rows of q (m, ncells) in place: totals (conserved) or
        intensive values (the transpose)."""
        order = self.dirs if totals else self.dirs[::-1]
        for _ in range(self.steps):
            for starts, stride, m, e_line, cp, invden, zc, smb, smg in order:
                solve_lines(q, ncols, starts, stride, m, self.vol, e_line, cp, invden, zc,
                            smb, smg, totals)
        return q
