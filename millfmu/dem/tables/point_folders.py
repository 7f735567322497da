"""The folders of table points being run (:mod:`.point_work`): their names, lock and
description, read without the DEM, so that the cache (:mod:`.cache`) can clear stale ones
without importing the DEM's run."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

try:  # POSIX; elsewhere a point's folder is not locked
    import fcntl
except ImportError:  # pragma: no cover - not on the platforms the tests run on
    fcntl = None

#: the folder of a point store that holds the points being run
RUNNING_DIR = "running"
#: a point folder's description: its key's content (JSON)
META = "meta.json"
#: a point folder's start record (JSON), written before the run begins
START = "start.json"
LOCK = "lock"


def hold(fh) -> bool:
    """Hold the open lock file ``fh`` for this process without waiting (flock): False where
    another process holds it; True where the platform has no flock (nothing is locked)."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def held(path: Path) -> bool:
    """Whether a process holds the point folder ``path`` (runs its point now)."""
    if fcntl is None:
        return False
    try:
        with open(path / LOCK, "a+") as fh:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        return False
    except OSError:
        return True


def clear_running(folder, only_stale: bool, kernel_version: str) -> list[str]:
    """Remove the folders of points being run in the point store ``folder`` (all, or those
    of another DEM kernel version or without a readable description), skipping any that a
    process holds; returns 'running/KEY' for each removed folder."""
    removed = []
    root = Path(folder) / RUNNING_DIR
    if not root.is_dir():
        return removed
    for path in sorted(p for p in root.iterdir() if p.is_dir()):
        if only_stale:
            try:
                if json.loads((path / META).read_text())["kernel_version"] == kernel_version:
                    continue
            except (OSError, ValueError, KeyError, TypeError):
                # a folder made a moment ago has no description yet
                if time.time() - path.stat().st_mtime < 3600.0:
                    continue
        if fcntl is not None:
            try:
                with open(path / LOCK, "a+") as fh:
                    fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                    shutil.rmtree(path, ignore_errors=True)
            except OSError:
                continue  # a build runs this point now
        else:
            shutil.rmtree(path, ignore_errors=True)
        removed.append(f"{RUNNING_DIR}/{path.name}")
    return removed
