"""The numba intrinsics of millfmu.dem.engine._jit that the kernels rely on."""

import numba
import numpy as np
import pytest

from millfmu.dem.engine._jit import nonneg


@numba.njit
def _take(a, i):
    return a[nonneg(i)]


@numba.njit
def _sum_run(a, e0, e1):
    # the neighbour search's form: a run of entries indexed from a declared offset
    s = 0.0
    for t in range(e1 - e0):
        s += a[nonneg(e0 + t)]
    return s


@pytest.mark.parametrize("dtype", [np.int8, np.int32, np.int64, np.uint32, np.uint64])
def test_nonneg_passes_the_index_through(dtype):
    a = np.arange(10.0) * 1.5
    for i in (0, 3, 9):
        assert _take(a, dtype(i)) == a[i]
    assert _sum_run(a, 2, 7) == a[2:7].sum()


def test_nonneg_refuses_what_is_not_an_integer():
    @numba.njit
    def f(x):
        return nonneg(x)

    with pytest.raises(numba.core.errors.TypingError):
        f(1.5)
