"""Checkpointed table points: a DEM point that a build (or an on-demand point) runs beside a
point store keeps its run's checkpoint, so that a build stopped in the middle of a point (a
killed process, a machine that sleeps or reboots) goes on from there when it is run again,
instead of from the point's start.

A point of the coupled table with 0.5 mm beads runs for about an hour on one core. Each DEM
point of a build with a point store runs in its own folder ``<store>/running/<key>/`` (:func:`work_key`:
sha256 over the point's scene, the DEM kernel version and how the point is run) and keeps
the DEM's checkpoint there (:mod:`millfmu.dem.run`) every :data:`POINT_CHECKPOINT_EVERY_S`
of wall time, with the point's start record (``start.json``: warm or cold, from which
state). A point whose folder holds a checkpoint goes on from it with the start it began
with, and its result is that of the run that was not stopped, to the digit (the DEM's
resume: ``tests/dem/test_checkpoint.py``); it says so on stderr. The folder is removed
when the point's run has ended.

A checkpoint that cannot be used (unreadable, another layout, made by DEM sources that do
not give the same results) is said on stderr and the point starts again. Without a store,
or where another process holds the folder (its ``lock``, taken with ``flock``), the point
runs in a temporary folder without checkpoints. ``millfmu tables clear
--stale`` removes the folders of other DEM kernel versions
(:func:`.point_folders.clear_running`).
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from ...stress_tables.files import canonical_json, sha256_bytes, write_replacing
from .point_folders import LOCK, META, RUNNING_DIR, START, held, hold

#: [s of wall time] how often a point's run writes its checkpoint: at most this much of a
#: point's run is lost when a build is stopped (a coupled 0.5 mm point's checkpoint holds
#: 30-45 MB, most of it the recorded samples, and takes about a second to write)
POINT_CHECKPOINT_EVERY_S = 600.0


def work_key(scene_at_point: dict, kernel_version: str, how: dict) -> dict:
    """The content of a point folder's key: the scene the point runs, the DEM kernel version
    and ``how`` (what else decides the run: its windows, the warm start's spin-up)."""
    return json.loads(canonical_json({"scene": scene_at_point, "kernel_version": kernel_version,
                                      "how": how}))


class PointWork:
    """The folder one point's run works in (:func:`point_work`): ``folder``, whether it
    keeps checkpoints (``checkpointed``), and after :meth:`run` the wall time [s] the run
    had taken before it was stopped (``wall_before_s``; 0 for a run that was not)."""

    def __init__(self, folder: Path, checkpointed: bool, label: str):
        self.folder = Path(folder)
        self.checkpointed = checkpointed
        self.label = label
        self.wall_before_s = 0.0

    def run(self, run_new, resume):
        """The point's statistics and start record: ``resume(folder, start, state)`` (returns
        the statistics; ``state``: the checkpoint as read) where the folder holds a usable
        checkpoint, else ``run_new(folder, checkpoint_every_s, on_start)`` (returns
        (statistics, start))."""
        got = self._checkpoint() if self.checkpointed else None
        if got is not None:
            start, state = got
            return resume(self.folder, start, state), start

        def on_start(start: dict):
            if self.checkpointed:
                write_replacing(self.folder / START, json.dumps(start).encode(), prefix=".tmp-start-")

        every = POINT_CHECKPOINT_EVERY_S if self.checkpointed else None
        return run_new(self.folder, every, on_start)

    def _checkpoint(self):
        """(start record, checkpoint state) of the folder's checkpoint where it can be used
        (said on stderr), else None: none there, or one that cannot be read or was made by
        DEM sources that give other results (said, and the folder emptied)."""
        from millfmu.dem import run as R

        from .warm_start import point_checkpoint

        if not (self.folder / R.CHECKPOINT).exists():
            return None
        try:
            start = json.loads((self.folder / START).read_text())
            state = point_checkpoint(self.folder)
            loop, scene = state["loop"], state["scene"]
            done_s, total_s = loop["done"] * scene.dt_s, scene.spin_up_s + scene.record_s
        except (OSError, ValueError, KeyError, TypeError, AttributeError, R.DemRunError) as e:
            print(f"millfmu: table point {self.label}: the checkpoint in {self.folder} is not "
                  f"used ({e}); the point starts again", file=sys.stderr, flush=True)
            _empty(self.folder)
            return None
        self.wall_before_s = float(loop.get("wall_s", 0.0))
        print(f"millfmu: table point {self.label} goes on from its checkpoint ({done_s:.4g} of "
              f"{total_s:.4g} s simulated, {self.wall_before_s:.0f} s run before)", file=sys.stderr, flush=True)
        return start, state


def _empty(folder: Path) -> None:
    """Remove what a point's folder holds except its description and lock."""
    for p in folder.iterdir():
        if p.name in (META, LOCK):
            continue
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)


@contextmanager
def point_work(store, content: dict, label: str):
    """The :class:`PointWork` of the point whose key content is ``content``
    (:func:`work_key`) in the point store ``store`` (None: a temporary folder, no
    checkpoints). The folder is removed when the block ends, unless it ends by an exception
    with a checkpoint in the folder (kept for the next run of the build)."""
    folder = _claim(store, content) if store is not None else None
    if folder is None:
        with tempfile.TemporaryDirectory(prefix="millfmu-table-point-") as tmp:
            yield PointWork(Path(tmp), False, label)
        return
    path, fh = folder
    from millfmu.dem.run import CHECKPOINT

    done = False
    try:
        yield PointWork(path, True, label)
        done = True
    finally:
        if done or not (path / CHECKPOINT).exists():
            shutil.rmtree(path, ignore_errors=True)
        if fh is not None:
            fh.close()  # releases the lock


def _claim(store, content: dict):
    """(folder, open lock file) of the point in ``store``, made where missing and locked for
    this process; None where it cannot be made or another process holds it."""
    key = sha256_bytes(canonical_json(content).encode())
    path = Path(store) / RUNNING_DIR / key
    try:
        path.mkdir(parents=True, exist_ok=True)
        fh = open(path / LOCK, "a+")
    except OSError as e:
        print(f"millfmu: a table point's folder {path} cannot be made ({e}); the point runs "
              f"without checkpoints", file=sys.stderr, flush=True)
        return None
    if not hold(fh):
        fh.close()
        print(f"millfmu: another process runs the table point of {path}; this one runs it "
              f"apart, without checkpoints", file=sys.stderr, flush=True)
        return None
    meta = path / META
    if not meta.exists():
        write_replacing(meta, canonical_json(content).encode(), prefix=".tmp-meta-")
    return path, fh


def running_points(folder) -> list[dict]:
    """The points of the point store ``folder`` that a build runs now or left stopped with a
    checkpoint: per folder its ``path``, the point's ``values`` (tip speed [m/s], filling
    [-], bead diameter [m] and density [kg/m3] of its scene), its DEM ``kernel_version``,
    whether a process runs it now (``running``) and the wall time [s] since its last
    checkpoint was written (``checkpoint_age_s``, None without one)."""
    from millfmu.dem.run import CHECKPOINT

    root = Path(folder) / RUNNING_DIR
    out = []
    for path in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else ():
        try:
            meta = json.loads((path / META).read_text())
            sc = meta["scene"]
            values = {"tip_speed_m_per_s": sc["mill"]["tip_speed_m_per_s"], "filling": sc["beads"]["filling"],
                      "bead_diameter_m": sc["beads"]["diameter_m"],
                      "bead_density_kg_per_m3": sc["beads"]["density_kg_per_m3"]}
            kv = meta["kernel_version"]
        except (OSError, ValueError, KeyError, TypeError):
            values, kv = None, None
        ck = path / CHECKPOINT
        age = time.time() - ck.stat().st_mtime if ck.exists() else None
        out.append({"path": str(path), "values": values, "kernel_version": kv, "running": held(path),
                    "checkpoint_age_s": age})
    return out
