"""The one set of numba flags shared by every DEM kernel, and the threading layer.

Only the kernel modules import this file, and only when a DEM run is requested, so that
``import millfmu.dem`` stays free of numba.

- ``FLAGS``: options common to all kernels (cached compilation, no Python objects,
  fastmath off so that the contact laws are evaluated as written, in IEEE order, and a
  run repeats bit for bit on the same thread count). The cache lives in a folder keyed
  by the bytes of every kernel file (:func:`kernel_cache_dir`), not beside each module.
- ``kernel``: decorator for loops over all beads; these use ``prange`` over chunks of beads
  (and, in the liquid, over rows of cells).
- ``device``: decorator for the small scalar helpers that kernels call inside a chunk
  (the same flags without ``parallel``, because a parallel region must not nest).
- ``contact``: ``device`` for the helpers called once per contact in the force loop
  (contact law, pair and wall response), inlined into the loop by numba: as calls they
  cost the force loop on the bench bed about a quarter more time.
- ``serial``: the same flags for serial drivers and bookkeeping (binning, wrapping).
- ``set_chunksize``: numba's parallel chunk size set from jitted code, cached (the
  coupling's compiled run of intervals switches it between the liquid and the DEM).
- ``inlined``: ``contact``'s inlining for the liquid's per-node and per-edge helpers
  (gradients, edge viscosities, wall functions, fluxes) and the exchange's per-bead ones
  (stencil, drag law): as calls returning tuples they make the edge-stress kernel several
  times slower and the beads' deposit pass 1.6 times.

Threading layer: OpenMP (numba's ``omp`` layer), else ``workqueue``, unless
NUMBA_THREADING_LAYER or NUMBA_THREADING_LAYER_PRIORITY is set; numba settles the layer
at a process's first parallel launch or thread-count setting, so the package sets its
thread counts only through :func:`use_threads`. Why (the DEM launches two or three
parallel loops per step, a 10-degree disc sector's step takes about 0.4 ms):
- TBB, numba's default where libtbb is installed, keeps memory per parallel launch and
  makes every launch slower than the one before: a run's cost grows with the square of its
  length. Never chosen.
- workqueue costs about 100 us per launch (two handshakes with each thread): the fallback.
- OpenMP's idle threads spin GOMP_SPINCOUNT=1000 times (tens of microseconds) after a
  launch, then sleep, unless GOMP_SPINCOUNT or OMP_WAIT_POLICY is set: a sleeping thread
  takes about 45 us to wake, a spinning one about 1 us, and threads that spin without end
  take the cores of a second run beside them. OMP_WAIT_POLICY=passive sleeps at once.
- One thread per process (the tables' builds) runs no team, so the layers do not differ.
GNU OpenMP is not fork safe: a process that has run a parallel kernel must not fork a
child that runs one (numba stops such a child). The tables' process pool therefore spawns
its workers; Dask's workers are spawned too. Neither layer can launch from several Python
threads at once (run one DEM per process).
"""

import hashlib
import os
import shutil
import tempfile
import time
from pathlib import Path

import numba
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

#: the threading layers in the order numba tries them (it wants all three named;
#: workqueue always loads, so TBB is never reached)
LAYER_PRIORITY = ("omp", "workqueue", "tbb")
if "NUMBA_THREADING_LAYER" not in os.environ and \
        "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    # in the environment too: numba re-reads its configuration from the environment when a
    # NUMBA_ variable has changed (at the next compilation), which would put TBB first again
    os.environ["NUMBA_THREADING_LAYER_PRIORITY"] = " ".join(LAYER_PRIORITY)
    numba.config.THREADING_LAYER_PRIORITY = list(LAYER_PRIORITY)
    numba.config.THREADING_LAYER = "default"
# read by the OpenMP runtime when it loads, at the first parallel launch: idle threads spin
# SPIN_COUNT times (GNU OpenMP, tens of microseconds), then sleep; either variable set by
# the user wins
SPIN_COUNT = 1000
if "OMP_WAIT_POLICY" not in os.environ and "GOMP_SPINCOUNT" not in os.environ:
    os.environ["GOMP_SPINCOUNT"] = str(SPIN_COUNT)


@intrinsic
def set_chunksize(typingctx, n):
    """numba's parallel chunk size for the parallel loops that follow (``n`` >= 0; 0:
    numba's equal static blocks), called in jitted code; returns the size before. It calls
    the threading layer's own ``set_parallel_chunksize`` by its symbol, which the layer
    registers when it loads (:func:`use_threads` loads it): numba's jitted
    ``set_parallel_chunksize`` calls it through a ctypes pointer instead, and numba does
    not cache a function that holds one."""
    def codegen(context, builder, signature, args):
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i32, [i32]),
                                            "set_parallel_chunksize")
        old = builder.call(fn, [builder.trunc(args[0], i32)])
        return builder.zext(old, ir.IntType(64))

    return types.int64(n), codegen


@intrinsic
def nonneg(typingctx, i):
    """``i``, with the compiler told that it is not negative (``llvm.assume``), for an
    array index known to be >= 0 (a chunk, bead, pair or entry index). numba's indexing
    adds the length to a negative index (Python's wraparound): a select per index and
    array, which the compiler can drop only where it proves the index non-negative, and
    in a vectorised loop the selected addresses made every load a gather. Passing a
    negative value is undefined behaviour: only for indices that cannot be negative."""
    if not isinstance(i, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        v = args[0]
        if not signature.args[0].signed:
            return v  # never negative (a prange's index)
        fn = builder.module.declare_intrinsic(
            "llvm.assume", fnty=ir.FunctionType(ir.VoidType(), [ir.IntType(1)]))
        builder.call(fn, [builder.icmp_signed(">=", v, ir.Constant(v.type, 0))])
        return v

    return i(i), codegen


def use_threads(n: int) -> None:
    """numba's thread count for the parallel loops that follow: the one way the package
    sets it. The layer is chosen at the first launch or thread-count setting in a process
    and cannot change afterwards; importing this module first is what puts OpenMP before
    TBB: a count set with numba's own call before any kernel module is imported would run
    every later kernel on TBB."""
    numba.set_num_threads(int(n))

FLAGS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy",
             boundscheck=False)

#: the folders whose modules hold the kernels (and this file): their sources key the cache
KERNEL_DIRS = ("engine", "fluid", "coupling")
#: a kernel cache folder not written for this many days is removed when a new one is made
CACHE_KEEP_DAYS = 30


def sources_key(dem: Path | None = None) -> str:
    """sha256 (16 hex digits) over the names and bytes of every module in
    :data:`KERNEL_DIRS` of the package folder ``dem`` (default millfmu/dem)."""
    dem = Path(__file__).resolve().parent.parent if dem is None else Path(dem)
    h = hashlib.sha256()
    for d in KERNEL_DIRS:
        for f in sorted((dem / d).glob("*.py")):
            h.update(f"{d}/{f.name}\0".encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _prune(base: Path, keep: Path) -> None:
    """Remove the other kernel cache folders under base not written for CACHE_KEEP_DAYS
    (older sources' compiled code); never fails."""
    limit = time.time() - CACHE_KEEP_DAYS * 86400.0
    try:
        for d in base.glob("millfmu-kernels-*"):
            if d == keep or not d.is_dir():
                continue
            newest = max((f.stat().st_mtime for f in d.rglob("*")), default=0.0)
            if max(newest, d.stat().st_mtime) < limit:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


def kernel_cache_dir() -> Path:
    """Where the kernels' compiled code is cached: a folder named after the kernel sources'
    key (:func:`sources_key`) under NUMBA_CACHE_DIR where the user set it, else under
    $XDG_CACHE_HOME (~/.cache)/millfmu.

    Why not numba's own place beside each module: numba checks a cached function against its
    own file's time stamp only, so a function whose callee in another file changed (the
    fluid's predictor in step_kernels.py calling vans_kernels.py's stress kernels) loads its
    old compiled code, callee and all, and runs the old arithmetic without a word. Keyed by
    every kernel file's bytes, a change anywhere compiles everything afresh."""
    base = numba.config.CACHE_DIR or os.environ.get("XDG_CACHE_HOME") or ""
    if base:
        base = Path(base).expanduser()
    else:
        try:
            base = Path.home() / ".cache"
        except RuntimeError:  # no home folder known (a service account)
            base = Path(tempfile.gettempdir())
    if not numba.config.CACHE_DIR:
        base = base / "millfmu"
    return base / f"millfmu-kernels-{sources_key()}"


_CACHE_DIR = kernel_cache_dir()
if not _CACHE_DIR.exists():
    _prune(_CACHE_DIR.parent, _CACHE_DIR)


def _cached(decorate):
    """decorate(fn) with numba's cache in :data:`_CACHE_DIR` (numba reads its CACHE_DIR
    when a cached function is made; restored after, so that other numba code in the
    process keeps its own place). A folder that cannot be made leaves numba's fallbacks."""
    def wrap(fn):
        prev = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(_CACHE_DIR)
        try:
            return decorate(fn)
        finally:
            numba.config.CACHE_DIR = prev
    return wrap


kernel = _cached(numba.njit(parallel=True, **FLAGS))
device = _cached(numba.njit(inline="never", **FLAGS))
contact = _cached(numba.njit(inline="always", **FLAGS))
inlined = contact
serial = _cached(numba.njit(**FLAGS))


def gpu_kernel(fn):
    """numba.cuda kernel (the GPU path, millfmu.dem.engine.gpu). numba.cuda is imported only here,
    when the GPU path is used; NUMBA_ENABLE_CUDASIM=1 runs the kernels on the CPU."""
    from numba import cuda

    return _cached(cuda.jit(cache=True))(fn)


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
