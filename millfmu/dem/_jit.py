"""The one set of numba flags shared by every DEM kernel.

Only the kernel modules import this file, and only when a DEM run is requested, so that
``import millfmu.dem`` stays free of numba.

- ``FLAGS``: options common to all kernels (cached compilation, no Python objects,
  fastmath off so that the contact laws are evaluated as written, in IEEE order, and a
  run repeats bit for bit on the same thread count).
- ``kernel``: decorator for loops over all beads; these use ``prange`` over chunks of beads.
- ``device``: decorator for the small scalar helpers that kernels call inside a chunk
  (the same flags without ``parallel``, because a parallel region must not nest).
- ``serial``: the same flags for serial drivers and bookkeeping (binning, wrapping).
"""

import numba

FLAGS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy",
             boundscheck=False)

kernel = numba.njit(parallel=True, **FLAGS)
device = numba.njit(inline="never", **FLAGS)
serial = numba.njit(**FLAGS)
