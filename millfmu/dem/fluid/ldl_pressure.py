"""The projection's pressure equation solved by a symmetric factorisation
(``pressure_solver = "direct_ldl"``): P A P^T = L D L^T on an ordering of minimum degree.

The operator of :class:`millfmu.dem.fluid.pressure.PressureSolver` (the finite-volume
-Laplacian on the fluid cells with its first unknown pinned) is symmetric positive
definite. SuperLU factorises it here with the minimum-degree ordering of A + A^T and
diagonal pivots only (its symmetric mode), so that U = D L^T: only L's strictly lower part
and 1/D are kept, and a numba kernel (:func:`millfmu.dem.fluid.step_kernels.ldl_solve`)
solves. Why: on the 10-degree disc sector's 1,344 cells L holds 15,573 entries against
51,532 in L + U of ``direct_lu`` (COLAMD), and a solve inside the coupled run, where the
factor comes back from memory after the DEM's steps, takes about a third of SuperLU's
time. The solution is direct_lu's to round-off (1.6e-13 of its largest value on the
sector; tests/dem/test_fluid.py). It is the default solver
(:data:`millfmu.dem.fluid.settings.DEFAULT_PRESSURE_SOLVER`): its round-off differs from
``direct_lu``'s, with which the shipped coupled table was built, and ``millfmu tables
equivalence`` accepts it as that table's kernel version on the statistics' evidence
(docs/tables.md).

Imports no numba until a solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from millfmu.dem.fluid.grid import GridError


class LdlFactor:
    """L D L^T of a symmetric positive definite sparse matrix ``a`` (SuperLU, minimum
    degree on A + A^T, diagonal pivots); :meth:`solve` returns x with a x = rhs."""

    def __init__(self, a):
        a = sp.csc_matrix(a)
        lu = spla.splu(a, permc_spec="MMD_AT_PLUS_A",
                       options=dict(SymmetricMode=True, DiagPivotThresh=0.0))
        if not np.array_equal(lu.perm_r, lu.perm_c):
            raise GridError("pressure_solver 'direct_ldl': the factorisation pivoted off the "
                            "diagonal (the operator is not symmetric positive definite); "
                            "use 'direct_lu'")
        lower = sp.tril(lu.L, k=-1).tocsc()
        lower.sort_indices()
        d = lu.U.diagonal()
        if not np.all(d > 0.0):
            raise GridError("pressure_solver 'direct_ldl': a pivot is not positive (the "
                            "operator is not positive definite); use 'direct_lu'")
        self.indptr = lower.indptr.astype(np.int64)
        self.indices = lower.indices.astype(np.int64)
        self.values = np.ascontiguousarray(lower.data)
        self.inv_d = 1.0 / d
        # row k of the permuted system is row order[k] of a (perm_r maps a's rows to it)
        self.order = np.empty_like(lu.perm_r, dtype=np.int64)
        self.order[lu.perm_r] = np.arange(lu.perm_r.size)
        # work arrays of a solve (no allocation per solve on the coupled run's hot path)
        self._work = np.zeros(a.shape[0])
        self._rhs = np.zeros(a.shape[0])
        self._x = np.zeros(a.shape[0])
        #: entries kept: L's strictly lower part
        self.entries = int(lower.nnz)

    def project(self, b_cells: np.ndarray, cells: np.ndarray, volume: np.ndarray,
                volume_sum: float, shape) -> np.ndarray:
        """The pressure equation's solution on a grid of ``shape`` (0 in solids) for the
        right-hand side b_cells, whose volume-weighted mean over the fluid cells (flat
        indices ``cells``, volumes ``volume`` [m3] summing to volume_sum) is removed first;
        the first fluid cell pinned: :meth:`PressureSolver.solve` in one numba call."""
        from millfmu.dem.fluid.step_kernels import ldl_project

        out = np.empty(shape)
        ldl_project(np.ascontiguousarray(b_cells, dtype=float).reshape(-1), cells, volume,
                    volume_sum, self.indptr, self.indices, self.values, self.inv_d,
                    self.order, self._rhs, self._work, self._x, out.reshape(-1))
        return out

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        from millfmu.dem.fluid.step_kernels import ldl_solve

        out = np.empty(rhs.shape[0])
        ldl_solve(self.indptr, self.indices, self.values, self.inv_d, self.order,
                  np.ascontiguousarray(rhs, dtype=float), self._work, out)
        return out
