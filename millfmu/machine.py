"""Where a study or benchmark ran: one description for every study (the report, the DEM
work-precision study), so that their records compare."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import time
from pathlib import Path


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


def source_commit() -> str:
    """The short git commit of the millfmu sources where they are a git checkout, else
    "unknown" (an installed wheel)."""
    here = Path(__file__).resolve().parent
    try:
        r = subprocess.run(["git", "-C", str(here), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                           timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else "unknown"


def write_record(path, command: str, figures: dict, unit: str, aim: dict | None = None, host: str = "",
                 note: str = "") -> Path:
    """A benchmark's figures as one JSON record (commit, host, date, command, figures, aim,
    unit, note, and :func:`machine`), written whole: to a temporary file beside ``path`` and
    then renamed, so that a failed write leaves the old file. ``host``: the machine in
    words (``machine()`` records the platform either way)."""
    path = Path(path)
    cpu = platform.processor() or platform.machine()
    rec = {"commit": source_commit(), "host": host or f"{os.cpu_count()} cores, {cpu}",
           "date": datetime.date.today().isoformat(), "command": command, "figures": figures}
    if aim:
        rec["aim"] = aim
    rec["unit"] = unit
    if note:
        rec["note"] = note
    rec["machine"] = machine()
    tmp = path.with_name(f".{path.name}.part")
    tmp.write_text(json.dumps(rec, indent=2) + "\n")
    tmp.replace(path)
    return path
