"""A line before the first DEM run with the installed kernel sources: numba compiles the
DEM's kernels then (a minute or more), and without a word a user takes that for a hang.

numba caches the compiled kernels in :func:`millfmu.dem.engine._jit.kernel_cache_dir`, a
folder keyed by the kernel sources; an index file (``*.nbi``) there means they were
compiled before and load in seconds. Measured on 2 cores with numba's cache emptied
(docs/dem-performance.md, "The first run's compilation"): a short coupled disc sector
(``millfmu dem run disc_slice --sector-deg 10 --no-gravity --fluid coupled --spin-up 0.002
--record 0.002 --threads 2``) 152 s, of which the parts in :data:`PARTS`; the same sector
with ``--fluid none`` 31 s.

While a cold cache compiles, each kernel that takes :data:`SAY_ABOVE_S` or more to compile
is named on stderr when it is done, with its time (:func:`watch_compiles`).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

#: Compile times [s] measured on 2 cores (see the module docstring), by what runs.
SECONDS = {"dem": 30, "coupled": 150}
#: What a first coupled run compiles, each part's compile time [s] measured on 2 cores
#: (the coupled sector of the module docstring); the DEM alone compiles the first.
PARTS = (("the DEM's contacts, neighbour lists and steps", 28),
         ("the liquid's step and its exchange with the beads", 110),
         ("the compiled run of coupled intervals", 12))
#: a kernel whose own compilation takes this long [s] or longer is named when it is done
SAY_ABOVE_S = 5.0
#: the listener of :func:`watch_compiles` where one is registered (one per process)
_watching = []


def kernel_cache_is_cold() -> Path | None:
    """The kernel cache folder where no kernel of the installed sources has been compiled
    yet, else None. Imports numba (the caller is about to run the DEM)."""
    from .engine._jit import kernel_cache_dir

    d = kernel_cache_dir()
    try:
        if any(d.rglob("*.nbi")):
            return None
    except OSError:
        pass
    return d


def _say(log):
    return log or (lambda m: print(m, file=sys.stderr, flush=True))


def say_if_compiling(coupled: bool, log=None) -> bool:
    """Say on stderr (or ``log``) that the DEM's kernels compile first, what compiles, how
    long that takes and where they are kept, where the cache is cold; then name each long
    compilation when it is done (:func:`watch_compiles`). True where it said so."""
    d = kernel_cache_is_cold()
    if d is None:
        return False
    what = "with the coupled liquid" if coupled else "of the DEM"
    parts = PARTS if coupled else PARTS[:1]
    each = ", ".join(f"{name} about {s:.0f} s" for name, s in parts)
    line = (f"millfmu: compiling the kernels {what} for this machine first (about "
            f"{SECONDS['coupled' if coupled else 'dem']} s on 2 cores: {each}; numba, once "
            f"for these sources): later runs load them from {d} in seconds")
    _say(log)(line)
    watch_compiles(log)
    return True


def watch_compiles(log=None) -> None:
    """From now on in this process, name on stderr (or ``log``) each kernel whose own
    compilation (without the kernels it calls, which are named themselves) took
    :data:`SAY_ABOVE_S` or more, with its time [s], when it is done: on a cold cache the
    first coupled run compiles for minutes, and these lines show what and how far."""
    from numba.core import event

    if _watching:
        return
    say = _say(log)
    stack = []  # [start, seconds of the callees' compilations] per open compilation

    class Said(event.Listener):
        def on_start(self, ev):
            stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev):
            t0, inner = stack.pop()
            took = time.perf_counter() - t0
            if stack:
                stack[-1][1] += took
            own = took - inner
            if own >= SAY_ABOVE_S:
                f = ev.data["dispatcher"].py_func
                name = f"{f.__module__.removeprefix('millfmu.dem.')}.{f.__qualname__}"
                say(f"millfmu: compiled {name} in {own:.0f} s")

    _watching.append(Said())
    event.register("numba:compile", _watching[0])
