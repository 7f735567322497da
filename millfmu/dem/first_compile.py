"""A line before the first DEM run with the installed kernel sources: numba compiles the
DEM's kernels then (minutes), and without a word a user takes that for a hang.

numba caches the compiled kernels in :func:`millfmu.dem.engine._jit.kernel_cache_dir`, a
folder keyed by the kernel sources; an index file (``*.nbi``) there means they were
compiled before and load in seconds. Measured on 2 cores (numba's cache emptied): the DEM
alone (``millfmu dem run annulus --fluid none``) 58 s until its first step, a short coupled
disc slice 273-295 s.
"""

from __future__ import annotations

import sys
from pathlib import Path

#: Compile times [min] measured on 2 cores (see the module docstring), by what runs.
MINUTES = {"dem": 1, "coupled": 5}


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


def say_if_compiling(coupled: bool, log=None) -> bool:
    """Say on stderr (or ``log``) that the DEM's kernels compile first, how long that takes
    and where they are kept, where the cache is cold; True where it said so."""
    d = kernel_cache_is_cold()
    if d is None:
        return False
    what = "with the coupled liquid" if coupled else "of the DEM"
    line = (f"millfmu: compiling the kernels {what} for this machine first (about "
            f"{MINUTES['coupled' if coupled else 'dem']} min on 2 cores; numba, once for these sources): later runs "
            f"load them from {d} in seconds")
    (log or (lambda m: print(m, file=sys.stderr, flush=True)))(line)
    return True
