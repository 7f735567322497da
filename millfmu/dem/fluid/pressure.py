"""Pressure (projection) equation of the VANS solver.

The predictor treats the beads' drag implicitly; the projection then corrects
u = u* - dt / (rho eps_f) grad(phi), so that the eps-weighted face fluxes meet continuity,
sum_f eps_f A_f u_f = -V d(eps)/dt. The void fraction cancels from the face coefficients:
the equation is sum over a cell's faces of (A_f / h_f) (phi_nb - phi_c) =
(rho / dt) (net outflow of eps u* + V d(eps)/dt), a constant-coefficient finite-volume
Laplacian on the fluid cells (the void fraction enters only the right-hand side and the
correction). One factorisation of it therefore serves the whole run, in the axisymmetric
and the 3-D mode (by default a symmetric L D L^T, ``direct_ldl``; a sparse LU,
``direct_lu``, or an FFT in theta, ``theta_fft``, by name); each solve is direct (residual
at round-off, checked in the tests). The pure-Neumann/periodic null space is removed by
pinning one cell after making the right-hand side consistent (its volume-weighted mean
removed: round-off and a clipped void fraction would otherwise leave it unsolvable).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from millfmu.dem.fluid.settings import DEFAULT_PRESSURE_SOLVER, PRESSURE_SOLVERS
from millfmu.dem.fluid.grid import FLUID, CylGrid


def coupling_entries(rows: list, cols: list, vals: list, a, b, cond) -> None:
    """Append to the (rows, cols, vals) triplets the conductance ``cond`` [m] between the
    unknowns ``a`` and ``b`` (index arrays, -1 for solid cells, whose pairs are skipped):
    a symmetric -Laplacian's four entries per face."""
    m = (a >= 0) & (b >= 0)
    a, b, c = a[m], b[m], np.broadcast_to(cond, m.shape)[m]
    rows.extend([a, b, a, b])
    cols.extend([b, a, a, b])
    vals.extend([-c, -c, c, c])


class PressureSolver:
    """Direct solver of the projection equation on a CylGrid's fluid cells. ``method``
    (:data:`PRESSURE_SOLVERS`): ``direct_lu``, one sparse LU of the whole operator;
    ``theta_fft``, an FFT in theta and one LU per mode
    (:mod:`millfmu.dem.fluid.theta_fft_pressure`: grids whose solids do not vary with
    theta; the same solution to round-off, a fraction of the cost on 3D grids);
    ``direct_ldl``, a symmetric factor L D L^T on a minimum-degree ordering solved by a
    numba kernel (:mod:`millfmu.dem.fluid.ldl_pressure`: the same solution to round-off, a
    third of direct_lu's factor and time on an axisymmetric sector; the default,
    :data:`DEFAULT_PRESSURE_SOLVER`)."""

    def __init__(self, grid: CylGrid, method: str = DEFAULT_PRESSURE_SOLVER):
        if method not in PRESSURE_SOLVERS:
            raise ValueError(f"pressure_solver = {method!r}: allowed {list(PRESSURE_SOLVERS)}")
        self.method = method
        self.grid = grid
        g = grid
        nr, nt, nz = g.shape
        fluid = g.solid == FLUID
        self.fluid = fluid
        idx = np.full(g.shape, -1, np.int64)
        self.n = int(fluid.sum())
        idx[fluid] = np.arange(self.n)
        self.volume = np.broadcast_to(g.cell_volume_m3[:, None, None], g.shape)[fluid]
        self._index_cells()
        rows, cols, vals = [], [], []

        def couple(a, b, cond):
            coupling_entries(rows, cols, vals, a, b, cond)

        cr, ct, cz = g.face_conductances_m()
        ii, jj, kk = np.meshgrid(np.arange(1, nr), np.arange(nt), np.arange(nz), indexing="ij")
        couple(idx[ii - 1, jj, kk], idx[ii, jj, kk], cr[:, None, None])
        ii, jj, kk = np.meshgrid(np.arange(nr), np.arange(nt), np.arange(nz), indexing="ij")
        if nt > 1:
            couple(idx[ii, jj, kk], idx[ii, (jj + 1) % nt, kk], ct[:, None, None])
        couple(idx[ii, jj, kk], idx[ii, jj, (kk + 1) % nz], cz[:, None, None])
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        v = np.concatenate(vals)
        #: -Laplacian (symmetric positive semi-definite) [m]
        self.matrix = sp.csc_matrix((v, (r, c)), shape=(self.n, self.n))
        keep = (r != 0) & (c != 0)  # pin unknown 0
        pinned = sp.csc_matrix((np.concatenate([v[keep], [1.0]]),
                                (np.concatenate([r[keep], [0]]),
                                 np.concatenate([c[keep], [0]]))), shape=(self.n, self.n))
        self._pinned = pinned
        self._fft = None
        if method == "theta_fft":
            from millfmu.dem.fluid.theta_fft_pressure import ThetaFftPressure

            self._fft = ThetaFftPressure(grid)
        self._lu = self._factor()
        self.solves = 0
        self.last_residual = 0.0

    def __getstate__(self):
        # SuperLU cannot be pickled (a run's checkpoint): factorised again on loading, the
        # same matrix by the same ordering, so the solves are the same to the bit
        d = dict(self.__dict__)
        d.pop("_lu")
        return d

    def __setstate__(self, d):
        self.__dict__.update(d)
        self.__dict__.setdefault("_fft", None)  # a checkpoint of earlier sources
        self.__dict__.setdefault("method", "direct_lu")
        if "_cells" not in d:
            self._index_cells()
        self._lu = self._factor()

    def _index_cells(self):
        # the fluid cells by their flat indices (the boolean mask's order): a solve gathers
        # and scatters by them, cheaper than a mask pass on a sector's 1,344 cells
        self._cells = np.flatnonzero(self.fluid.ravel())
        self._volume_sum = self.volume.sum()

    def _factor(self):
        if self._fft is not None:
            return None
        if self.method == "direct_ldl":
            from millfmu.dem.fluid.ldl_pressure import LdlFactor

            return LdlFactor(self._pinned)
        return spla.splu(self._pinned, permc_spec="COLAMD")

    def solve(self, b_cells: np.ndarray, check: bool = False) -> np.ndarray:
        """phi (cells, 0 in solids) with sum_f (A_f/h_f) (phi_nb - phi_c) = b_cells."""
        if self.method == "direct_ldl" and not check:
            self.solves += 1
            return self._lu.project(b_cells, self._cells, self.volume, self._volume_sum,
                                    self.grid.shape)
        b = b_cells.reshape(-1).take(self._cells)
        b = b - self.volume * (b.sum() / self._volume_sum)
        rhs = -b
        if self._fft is not None:
            x = self._fft.solve(rhs)
        else:
            rhs[0] = 0.0  # the pinned unknown (the others' equations imply its own)
            x = self._lu.solve(rhs)
        if check:
            res = self.matrix @ x + b
            self.last_residual = float(np.linalg.norm(res) / max(np.linalg.norm(b), 1e-300))
        out = np.zeros(self.grid.shape)
        out.reshape(-1)[self._cells] = x
        self.solves += 1
        return out
