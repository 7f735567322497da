"""The neighbour search's binning (engine.kernels.bin_entries) against a
stable sort by cell in numpy: the same cells, the same order within each cell, on one and
on two threads."""

import math

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from millfmu.dem.engine import kernels as K  # noqa: E402


def _reference(ej, es, ex, lo, cs, ncx, ncy, ncz, lz):
    csz = lz / ncz
    cid = np.empty(ex.shape[0], np.int64)
    for e in range(ex.shape[0]):
        ix = min(max(int((ex[e, 0] - lo[0]) / cs), 0), ncx - 1)
        iy = min(max(int((ex[e, 1] - lo[1]) / cs), 0), ncy - 1)
        zz = ex[e, 2] - lz * math.floor(ex[e, 2] / lz)
        iz = min(int(zz / csz), ncz - 1)
        cid[e] = (ix * ncy + iy) * ncz + iz
    ncell = ncx * ncy * ncz
    order = np.argsort(cid, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(cid, minlength=ncell))])
    cmax = np.full(ncell, -1, np.int64)
    np.maximum.at(cmax, cid, ej)
    return start, ej[order], es[order], ex[order].T, cmax


@pytest.mark.parametrize("ne", [0, 1, 5, 3000, 20000])
@pytest.mark.parametrize("threads", [1, 2])
def test_binning_is_a_stable_sort_by_cell_on_any_thread_count(ne, threads):
    rng = np.random.default_rng(ne)
    lz = 0.01
    ex = np.column_stack([rng.uniform(-0.02, 0.02, ne), rng.uniform(-0.02, 0.02, ne),
                          rng.uniform(-0.5 * lz, 1.5 * lz, ne)])
    ej = rng.integers(0, max(ne, 1), ne).astype(np.int64)
    es = rng.integers(-1, 2, ne).astype(np.int8)
    cs = 0.002
    lo = np.array([-0.02 - 1e-9, -0.02 - 1e-9])
    ncx = ncy = int(0.04 / cs) + 1
    ncz = int(lz / cs)
    prev = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        got = K.bin_entries(ej, es, ex, lo, cs, ncx, ncy, ncz, lz)
    finally:
        numba.set_num_threads(prev)
    ref = _reference(ej, es, ex, lo, cs, ncx, ncy, ncz, lz)
    for g, r in zip(got, ref):
        assert g.dtype == r.dtype or g.dtype.kind == r.dtype.kind
        np.testing.assert_array_equal(g, r)
