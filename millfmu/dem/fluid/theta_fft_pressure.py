"""The projection's pressure equation solved by a Fourier transform in theta
(``pressure_solver = "theta_fft"``), for grids whose solids do not vary with theta.

:class:`millfmu.dem.fluid.pressure.PressureSolver` factorises the whole operator
(finite-volume -Laplacian on the fluid cells, periodic in theta and z) once. On a 3D grid
that factor fills in badly: the disc full slice's 43 k fluid cells (40 x 32 x 42) give
68 M non-zeros in L + U, a 15 s factorisation and 63 ms per solve, more than half of what
the liquid and the exchange add to a coupling interval.

Where every theta column holds the same solids (a disc mill or the accelerator, whose
vanes are driven velocity nodes and not solid cells; not stationary baffles), the operator is block-circulant in theta: the theta
faces' conductance c_i = dr dz / (r_i dtheta) depends on the radius only and the theta
cells are uniform. A real FFT along theta then splits it into nt // 2 + 1 independent 2D
(r, z) problems, A_rz + c_i lambda_m with lambda_m = 2 - 2 cos(2 pi m / nt), each
factorised once (the 2D sector's size: 1,344 unknowns for the disc). The m = 0 problem is
singular like the whole (constants): its first unknown is pinned, and the solution is
shifted so that the first fluid cell holds 0, the gauge of the direct solver. The two agree
to round-off (tests/dem/test_theta_fft_pressure.py), for a compatible right-hand side (the
solver removes the volume-weighted mean first).

Imports no numba.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from millfmu.dem.fluid.grid import FLUID, CylGrid, GridError
from millfmu.dem.fluid.pressure import coupling_entries


def theta_invariant(grid: CylGrid) -> bool:
    """True where the grid has theta cells and every theta column holds the same solids."""
    s = grid.solid
    return s.shape[1] > 1 and bool(np.all(s == s[:, :1, :]))


class ThetaFftPressure:
    """-Laplacian x = rhs on the fluid cells of ``grid`` (C order of (r, theta, z)), by FFT
    in theta and one sparse LU per Fourier mode; GridError where the solids vary with
    theta or there is one theta cell."""

    def __init__(self, grid: CylGrid):
        g = grid
        nr, nt, nz = g.shape
        if nt < 2:
            raise GridError("pressure_solver 'theta_fft' needs theta cells (n_theta >= 2); "
                            "with one theta cell the direct solver is the 2D one already")
        if not theta_invariant(g):
            raise GridError("pressure_solver 'theta_fft' needs the same solids in every "
                            "theta column (no baffles); use 'direct_lu'")
        fluid = g.solid == FLUID
        f2 = fluid[:, 0, :]
        n2 = int(f2.sum())
        idx = np.full((nr, nz), -1, np.int64)
        idx[f2] = np.arange(n2)
        cr, ct, cz = g.face_conductances_m()
        rows, cols, vals = [], [], []

        # the r and z faces' conductances as the direct solver's (one theta column)
        def couple(a, b, cond):
            coupling_entries(rows, cols, vals, a, b, cond)

        ii, kk = np.meshgrid(np.arange(1, nr), np.arange(nz), indexing="ij")
        couple(idx[ii - 1, kk], idx[ii, kk], cr[:, None])
        ii, kk = np.meshgrid(np.arange(nr), np.arange(nz), indexing="ij")
        couple(idx[ii, kk], idx[ii, (kk + 1) % nz], cz[:, None])
        a_rz = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))), shape=(n2, n2))
        ct = np.broadcast_to(ct[:, None], (nr, nz))[f2]
        lam = 2.0 - 2.0 * np.cos(2.0 * np.pi * np.arange(nt // 2 + 1) / nt)
        self._lus = []
        for m, lm in enumerate(lam):
            am = (a_rz + sp.diags(ct * lm)).tocsc()
            if m == 0:  # singular (constants): pin the first unknown
                am = am.tolil()
                am[0, :] = 0.0
                am[:, 0] = 0.0
                am[0, 0] = 1.0
                am = am.tocsc()
            self._lus.append((am, None))
        self.nt = nt
        self.n = int(fluid.sum())
        # the fluid unknown (C order of (r, theta, z)) of 2D cell q at theta cell j: [q, j]
        idx3 = np.full(g.shape, -1, np.int64)
        idx3[fluid] = np.arange(self.n)
        self._perm = np.ascontiguousarray(idx3.transpose(0, 2, 1)[f2])
        self._factor()

    def _factor(self):
        self._lus = [(am, spla.splu(am, permc_spec="COLAMD")) for am, _ in self._lus]

    def __getstate__(self):
        # SuperLU cannot be pickled (a run's checkpoint): factorised again on loading
        d = dict(self.__dict__)
        d["_lus"] = [(am, None) for am, _ in self._lus]
        return d

    def __setstate__(self, d):
        self.__dict__.update(d)
        self._factor()

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """x with (-Laplacian) x = rhs (fluid unknowns; rhs summing to zero) and x[0] = 0."""
        bh = np.fft.rfft(rhs[self._perm], axis=1)
        xh = np.empty_like(bh)
        for m, (_, lu) in enumerate(self._lus):
            b = np.column_stack([bh[:, m].real, bh[:, m].imag])
            if m == 0:
                b[0] = 0.0  # the pinned unknown's equation: implied by the others
            y = lu.solve(b)
            xh[:, m] = y[:, 0] + 1j * y[:, 1]
        x2 = np.fft.irfft(xh, n=self.nt, axis=1)
        x = np.empty(self.n)
        x[self._perm] = x2
        return x - x[0]
