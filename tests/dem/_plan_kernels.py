"""Two small cached kernels, one calling the other, for the compile plan's tests (imported
by name in the compiling processes)."""

import numba
import numpy as np


@numba.njit(cache=True)
def inner(a, flag):
    s = 0.0
    for x in a:
        s += x * x if flag else x
    return s


@numba.njit(cache=True)
def outer(a, b):
    return inner(a, np.bool_(True)) + inner(b[0], np.bool_(False))
