"""The one set of numba flags shared by every DEM kernel, and the threading layer.

Only the kernel modules import this file, and only when a DEM run is requested, so that
``import millfmu.dem`` stays free of numba.

- ``FLAGS``: options common to all kernels (cached compilation, no Python objects,
  fastmath off so that the contact laws are evaluated as written, in IEEE order, and a
  run repeats bit for bit on the same thread count).
- ``kernel``: decorator for loops over all beads; these use ``prange`` over chunks of beads.
- ``device``: decorator for the small scalar helpers that kernels call inside a chunk
  (the same flags without ``parallel``, because a parallel region must not nest).
- ``contact``: ``device`` for the helpers called once per contact in the force loop
  (contact law, pair and wall response), inlined into the loop by numba: as calls they
  made the force loop on the bench bed 28 % slower.
- ``serial``: the same flags for serial drivers and bookkeeping (binning, wrapping).

Threading layer: ``workqueue`` unless NUMBA_THREADING_LAYER is set. numba picks TBB by
default where libtbb is installed, and its TBB layer (numba 0.68, libtbb 2021/2022) keeps
about 7 kB per parallel launch and makes every launch slower than the one before: a DEM
run launches two or three per step, so its cost grew with the square of its length (a
0.4 s disc_slice run had not finished after 29 minutes, 0.2 s took 65 s). OpenMP's
layer busy-waits, which halves the throughput on a shared machine. workqueue has neither
problem; it cannot launch from several Python threads at once (run one DEM per process,
as the tables' process pool and Dask workers with one thread do).
"""

import os

import numba

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

FLAGS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy",
             boundscheck=False)

kernel = numba.njit(parallel=True, **FLAGS)
device = numba.njit(inline="never", **FLAGS)
contact = numba.njit(inline="always", **FLAGS)
serial = numba.njit(**FLAGS)


def gpu_kernel(fn):
    """numba.cuda kernel (the GPU path, millfmu.dem.gpu). numba.cuda is imported only here,
    when the GPU path is used; NUMBA_ENABLE_CUDASIM=1 runs the kernels on the CPU."""
    from numba import cuda

    return cuda.jit(cache=True)(fn)


def gpu_device(cpu_fn, **twins):
    """The CUDA device twin of a CPU ``device`` function, compiled from the same Python
    source (``py_func``): one formula, two targets. ``twins`` maps the names of the device
    functions it calls to their CUDA twins (its globals otherwise name the CPU ones)."""
    import types

    from numba import cuda

    fn = cpu_fn.py_func
    if twins:
        fn = types.FunctionType(fn.__code__, dict(fn.__globals__, **twins), fn.__name__,
                                fn.__defaults__, fn.__closure__)
    return cuda.jit(device=True)(fn)
