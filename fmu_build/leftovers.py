"""Temporary files and folders of ``millfmu build-fmu`` named after the process that made
them, so that the next build removes those a killed build left behind (and never those of
a build that still runs)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from millfmu.runner import pid_alive


def tag(prefix: str) -> str:
    """``prefix`` + this process's id + ``_``: the start of a temporary name."""
    return f"{prefix}{os.getpid()}_"


def clean(folder: str | Path, prefix: str) -> list[Path]:
    """Remove the entries ``<prefix><pid>_*`` of ``folder`` whose process no longer runs."""
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for p in entries:
        if not p.name.startswith(prefix):
            continue
        pid = p.name[len(prefix):].split("_", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid() or pid_alive(int(pid)):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            try:
                p.unlink()
            except OSError:
                continue
        removed.append(p)
    return removed


def temp_dir(prefix: str, dir=None) -> tempfile.TemporaryDirectory:
    """A TemporaryDirectory named after this process, after removing the stale ones."""
    clean(dir or tempfile.gettempdir(), prefix)
    return tempfile.TemporaryDirectory(prefix=tag(prefix), dir=dir)
