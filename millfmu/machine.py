"""Where a study or benchmark ran: one description for every study (the report, the DEM
work-precision study), so that their records compare."""

from __future__ import annotations

import os
import platform
import time


def machine() -> dict:
    """Platform, CPU count, load, Python, numpy, scipy (numba where installed), date."""
    import numpy
    import scipy

    m = dict(platform=platform.platform(), processor=platform.processor() or platform.machine(),
             cpus=os.cpu_count(), python=platform.python_version(), numpy=numpy.__version__,
             scipy=scipy.__version__, date_utc=time.strftime("%Y-%m-%d %H:%M:%SZ", time.gmtime()))
    try:
        import importlib.metadata as md

        m["numba"] = md.version("numba")
    except Exception:  # not installed: the DEM section says so
        pass
    if hasattr(os, "getloadavg"):
        m["load_average_1min"] = round(os.getloadavg()[0], 2)
    return m
