"""Building a table: a builder (``builder(scene, point) -> fields``, e.g. the DEM's
:class:`~millfmu.dem.tables.dem_builder.DemBuilder`) run at every grid point, serially, in a
local process pool or on a Dask cluster, and the results stacked into a :class:`Table`.

Each finished point is kept in a point store (:class:`PointStore`, ``<cache>/points``),
named by what decides its numbers (builder, kernel version, the scene at the point), so an
interrupted build resumes where it stopped and tables that share a point (a grid and its
one-at-a-time axes, a grid extended by :func:`rebuild_including`) run it once.

Imports no numba: the builder loads the DEM in the processes that run grid points.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from pathlib import Path
from collections.abc import Callable

import numpy as np

from ...stress_tables.files import canonical_json, sha256_bytes, write_replacing
from ...stress_tables.spec import (COMPONENTS, DEM_BUILDER_ID, DRIFT_FIELDS, EARLIER_FORMAT, FIELDS, FORMAT_VERSION,
                                   QUANTILE_NAMES, TableError, TableSpec, scene_at_point)
from ...stress_tables.table import FIXED_AXIS_RTOL, Table
from ...unit_names import modernize, to_earlier
from .cells import dem_scene_at_point


def point_scene(spec: TableSpec, point: dict) -> dict:
    """The scene a point of ``spec`` runs: the scene with the point's values put in
    (:func:`~millfmu.stress_tables.spec.scene_at_point`), and for the DEM builder in the cell
    that holds the point's beads (:func:`~.cells.dem_scene_at_point`: a wider sector
    where they do not fit the scene's, else the scene at the point as it is)."""
    if spec.builder_id != DEM_BUILDER_ID:
        return scene_at_point(spec.scene, point)
    return dem_scene_at_point(spec.scene, point)


class PointStore:
    """Finished grid points on disk: ``<folder>/<key>.json``, the key the sha256 of the
    canonical JSON of (format, builder id, kernel version, the scene the point runs,
    :func:`point_scene`). A file is written to a temporary name, fsync'ed and renamed, so a reader sees
    a whole point or none; a file that does not parse or whose content is not its key's is
    ignored (the point is run again)."""

    def __init__(self, folder, reuse: bool = True):
        self.folder = Path(folder)
        #: False: every point is run again (and stored), e.g. for ``--force``.
        self.reuse = reuse

    @staticmethod
    def key_content(spec: TableSpec, point: dict) -> dict:
        return {"format": FORMAT_VERSION, "builder": spec.builder_id,
                "kernel_version": spec.kernel_version,
                "scene": point_scene(spec, point)}

    def key(self, spec: TableSpec, point: dict) -> str:
        return sha256_bytes(canonical_json(self.key_content(spec, point)).encode())

    @classmethod
    def earlier_key_content(cls, spec: TableSpec, point: dict) -> dict:
        """The key content the earlier format gave the point (its names in the earlier
        spelling: :mod:`millfmu.unit_names`)."""
        return dict(to_earlier(cls.key_content(spec, point)), format=EARLIER_FORMAT)

    def get(self, spec: TableSpec, point: dict) -> dict | None:
        """The stored result of the point, or None; a point stored in the earlier format is
        read with its names in the current spelling."""
        if not self.reuse:
            return None
        for content in (self.key_content(spec, point), self.earlier_key_content(spec, point)):
            content = json.loads(canonical_json(content))
            path = self.folder / f"{sha256_bytes(canonical_json(content).encode())}.json"
            try:
                d = json.loads(path.read_text())
            except (OSError, ValueError):
                continue
            if isinstance(d, dict) and d.get("key_content") == content:
                r = d.get("result")
                return modernize(r) if content["format"] == EARLIER_FORMAT else r
        return None

    def put(self, spec: TableSpec, point: dict, result: dict) -> bool:
        """Store a point's result; False (with a warning) where it cannot be written (a
        full disk, a result that is not JSON): the build goes on without it."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            text = json.dumps({"key_content": self.key_content(spec, point),
                               "result": _plain(result)}, sort_keys=True)
            write_replacing(self.folder / f"{self.key(spec, point)}.json", text.encode(),
                            prefix=".tmp-point-")
            return True
        except (OSError, TypeError, ValueError) as e:
            warnings.warn(f"point store {self.folder}: point {point} not kept ({e}); the "
                          f"build goes on, a resume would run it again", stacklevel=2)
            return False


    def seed(self, table: Table) -> int:
        """Put the points a finished table holds (its grid and one-at-a-time points, as the
        builder returned them: :func:`unstack`) into the store where it has none; returns how
        many were added. Their keys are those of the table's own specification (builder,
        kernel version, scene at the point), so a build of another grid over the same scene
        and kernel finds them and runs only what is missing; a table of another kernel adds
        points no current build asks for."""
        if not self.reuse:
            return 0
        spec = table.spec()
        added = 0
        for point, result in unstack(spec, table):
            if self.get(spec, point) is None and self.put(spec, point, result):
                added += 1
        return added


def unstack(spec: TableSpec, table: Table) -> list:
    """(point, result) per point of ``spec`` from a table built by it: the inverse of
    :func:`assemble` (FIELDS, zone names, references, and the recording drift where kept;
    the run's wall time is not kept in a table)."""
    zn = list(table.zone_names)

    def one(t: Table, idx) -> dict:
        r = {k: np.asarray(t.data[k][idx]) for k in FIELDS}
        r["zone_names"] = zn
        r.update({k: float(t.refs[k][idx]) for k in ("e_ref_J", "omega_rad_per_s", "n_gb_per_m3")})
        if "recording_drift" in t.data:
            d = np.asarray(t.data["recording_drift"][idx])
            r["drift"] = {f: d[j] for j, f in enumerate(DRIFT_FIELDS)}
        return r

    out = []
    shape = spec.shape
    for i, point in enumerate(spec.grid_points()):
        out.append((point, one(table, np.unravel_index(i, shape))))
    for name in spec.one_at_a_time:
        for at_anchor, _, pts in spec.sides(name):
            side = (table.one_at_a_time_anchor if at_anchor else table.one_at_a_time)[name]
            for j, p in enumerate(pts):
                out.append((p, one(side, np.unravel_index(j, side.shape))))
    return out


def _plain(obj):
    """A builder's result as JSON values (arrays as nested lists, NaN kept as NaN)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def assemble(spec: TableSpec, results: list[dict]) -> Table:
    """Stack per-point builder results (in the order of :meth:`TableSpec.points`): the grid
    points into the table, the anchor and one-at-a-time points into its side tables
    (``Table.one_at_a_time``: 1-D along the axis at the anchor, each holding the scene's
    value from the anchor's result; over the axis and its ``across`` sub-grid where the spec
    names one, the scene's value there from the grid's results; an axis run partly across
    has both, ``Table.one_at_a_time_anchor`` the one at the anchor)."""
    points = spec.points()
    if len(results) != len(points):
        raise TableError(f"assemble: {len(results)} results for {len(points)} points")
    zn = tuple(results[0]["zone_names"])
    for r in results:
        if tuple(r["zone_names"]) != zn:
            raise TableError(f"assemble: zone names differ between points: {zn} vs "
                             f"{tuple(r['zone_names'])}")
    n = len(spec.grid_points())
    t = _stack(spec.grid, results[:n], zn)
    if spec.one_at_a_time:
        by_point = {json.dumps(p, sort_keys=True): r for p, r in zip(points, results)}
        for name in spec.one_at_a_time:
            for at_anchor, axes, pts in spec.sides(name):
                rs = [by_point[json.dumps(p, sort_keys=True)] for p in pts]
                (t.one_at_a_time_anchor if at_anchor else t.one_at_a_time)[name] = _stack(axes, rs, zn)
            t.one_at_a_time_ref[name] = spec.scene_value(name)
        t.anchor = spec.anchor()
    return t


def _stack(grid: dict, results: list[dict], zn: tuple) -> Table:
    shape = tuple(len(v) for v in grid.values())
    data = {k: np.stack([np.asarray(r[k], float) for r in results]).reshape(
        shape + np.asarray(results[0][k]).shape) for k in FIELDS}
    if all("drift" in r for r in results):
        data["recording_drift"] = np.array(
            [[r["drift"][f] for f in DRIFT_FIELDS] for r in results], float).reshape(
            shape + (len(DRIFT_FIELDS), len(zn)))
    refs = {k: np.array([float(r[k]) for r in results]).reshape(shape)
            for k in ("e_ref_J", "omega_rad_per_s", "n_gb_per_m3")}
    t = Table(axes={k: np.asarray(v, float) for k, v in grid.items()}, zone_names=zn,
              data=data, refs=refs)
    t.check_shapes()
    return t


def stored_results(spec: TableSpec, point_store: PointStore | None) -> list:
    """Each point's result from the point store, None where it has none (all None without
    a store), in the order of :meth:`TableSpec.points`."""
    points = spec.points()
    if point_store is None:
        return [None] * len(points)
    return [point_store.get(spec, p) for p in points]


def order_by_cost(spec: TableSpec, builder: Callable, points: list, todo: list) -> list:
    """The indices ``todo`` with the costliest points first, where the builder estimates
    its points' cost (``builder.relative_cost(scene, point)``); else unchanged. Running
    the longest first keeps the workers busy to the end of a build (a 0.5 mm bead point
    costs about 5 anchor points: started last, it could run alone for most of its time)."""
    cost = getattr(builder, "relative_cost", None)
    if cost is None:
        return list(todo)
    c = {i: float(cost(spec.scene, points[i])) for i in todo}
    return sorted(todo, key=lambda i: -c[i])  # stable: grid order among equal costs


def duration(s: float | None) -> str:
    """Seconds in words: '40 s', '12 min', '4.5 h' ('unknown' for None)."""
    if s is None:
        return "unknown"
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def seconds_per_cost(table: Table, builder) -> float | None:
    """Seconds per unit of ``builder.relative_cost``: from runs of the installed builder
    where it has measured them for this table's points (``builder.measured_seconds_per_cost
    (table)``, the DEM's: :data:`~.dem_builder.MEASURED_SPEED`), else from what the table's
    points took (manifest ``points_wall_time_s`` over the summed cost of its points, each
    point that started warm at the cost of its start where the builder says it,
    ``builder.cost_as_started(scene, point, start)`` with the point's record of the
    manifest's ``point_starts``); None where neither says."""
    measured = getattr(builder, "measured_seconds_per_cost", None)
    spc = measured(table) if measured is not None else None
    if spc is not None:
        return spc
    wall = table.manifest.get("points_wall_time_s")
    cost = getattr(builder, "relative_cost", None)
    if not isinstance(wall, (int, float)) or not wall > 0 or cost is None:
        return None
    spec = table.spec()
    costs = relative_costs(builder, spec.scene, spec.points())
    # a point that started warm (the manifest's point_starts) cost the steps of its start
    as_started = getattr(builder, "cost_as_started", None)
    starts = {json.dumps(p.get("point"), sort_keys=True): p
              for p in (table.manifest.get("point_starts") or {}).get("points", []) if isinstance(p, dict)}
    if costs is not None and as_started is not None and starts:
        try:
            costs = [float(as_started(spec.scene, p, starts[k])) if (k := json.dumps(p, sort_keys=True)) in starts
                     else c for p, c in zip(spec.points(), costs)]
        except (ValueError, KeyError, TypeError):
            costs = None
    total = sum(costs) if costs is not None else 0.0
    return float(wall) / total if total > 0 else None


def relative_costs(builder, scene: dict, points: list) -> list | None:
    """``builder.relative_cost`` of each point; None where the builder has no estimate or
    cannot make one for this scene (e.g. the DEM's for a scene that is not a DEM scene)."""
    cost = getattr(builder, "relative_cost", None)
    if cost is None:
        return None
    try:
        return [float(cost(scene, p)) for p in points]
    except (ValueError, KeyError, TypeError):
        return None


class BuildProgress:
    """Where a build stands, in words: points done of the total, the share of the build's
    cost that the running point(s) hold, and an estimated time left.

    ``costs``: the builder's relative cost of each point to run (index -> cost; None where
    the builder gives none: then no share and no time). Seconds per cost unit come from the
    points finished in this build (their ``wall_time_s`` where the builder records it, else
    the time since they started), before the first one from ``seconds_per_cost`` (e.g. the
    manifest of the table being extended, :func:`~.on_demand.seconds_per_cost`). The time
    left is that of the points not finished, less what the running ones have run, shared by
    ``workers`` but never less than the longest one left: max(sum / workers, largest).
    ``clock``: seconds (a test's fake clock)."""

    def __init__(self, total: int, done: int, costs: dict | None, seconds_per_cost=None,
                 workers: int = 1, clock: Callable[[], float] = time.monotonic):
        self.total, self.done = int(total), int(done)
        self.costs = dict(costs) if costs is not None else None
        self.prior = seconds_per_cost
        self.workers = max(1, int(workers))
        self.clock = clock
        self.running: dict = {}  # index -> start time
        self.finished: set = set()
        self._cost_done = 0.0
        self._wall_done = 0.0

    def start(self, i):
        self.running[i] = self.clock()

    def finish(self, i, wall_s: float | None = None):
        t0 = self.running.pop(i, None)
        if wall_s is None and t0 is not None:
            wall_s = self.clock() - t0
        self.finished.add(i)
        self.done += 1
        if self.costs is not None and wall_s is not None and self.costs.get(i, 0.0) > 0.0:
            self._cost_done += self.costs[i]
            self._wall_done += float(wall_s)

    def seconds_per_cost(self) -> float | None:
        if self._cost_done > 0.0:
            return self._wall_done / self._cost_done
        return self.prior

    def share(self, i) -> float | None:
        """Point i's share of the build's cost (the points this build runs)."""
        if self.costs is None:
            return None
        total = sum(self.costs.values())
        return self.costs[i] / total if total > 0 else None

    def eta_s(self) -> float | None:
        spc = self.seconds_per_cost()
        if self.costs is None or spc is None:
            return None
        now = self.clock()
        left = [max(0.0, c * spc - (now - self.running[i] if i in self.running else 0.0))
                for i, c in self.costs.items() if i not in self.finished]
        if not left:
            return 0.0
        return max(sum(left) / min(self.workers, len(left)), max(left))

    def text(self) -> str:
        out = f"{self.done}/{self.total} points"
        if self.running and self.costs is not None:
            sh = sum(self.share(i) or 0.0 for i in self.running)
            n = len(self.running)
            out += (f", running {n} point{'s' if n > 1 else ''} of {sh:.0%} of the build's "
                    f"cost")
        eta = self.eta_s()
        if eta is not None:
            out += f", about {duration(eta)} left"
        return out


#: Seconds between refreshes of a build's progress line while points run [s].
PROGRESS_REFRESH_S = 10.0


def run_points(spec: TableSpec, builder: Callable, executor: str = "processes",
               workers: int | None = None, scheduler: str | None = None,
               progress: bool = True, point_store: PointStore | None = None,
               stored: list | None = None, seconds_per_cost: float | None = None) -> list[dict]:
    """Evaluate ``builder(scene, point)`` at every grid point; results in grid order.

    executor: ``serial``; ``processes`` (a local process pool of ``workers`` processes,
    default all cores); ``dask`` (a Dask LocalCluster on 127.0.0.1 with ``workers``
    single-threaded worker processes, or the existing cluster at ``scheduler``, e.g.
    ``tcp://host:8786``, when given). A tqdm bar counts finished grid points.
    ``point_store``: points found there are not run again, and each point is put there as
    soon as it finishes (so that a build cut off resumes); ``stored``: what
    :func:`stored_results` gave, when the caller has read the store already. The bar says
    what :class:`BuildProgress` says (share of the cost running, time left; before the
    first point finishes from ``seconds_per_cost``, where given).
    """
    points = spec.points()
    if executor not in ("serial", "processes", "dask"):
        raise TableError(f"executor = {executor!r}: allowed 'serial', 'processes', 'dask'")
    results = list(stored) if stored is not None else stored_results(spec, point_store)
    todo = order_by_cost(spec, builder, points,
                         [i for i, r in enumerate(results) if r is None])
    cost = getattr(builder, "relative_cost", None)
    n_workers = 1 if (executor == "serial" and scheduler is None) else points_at_once(workers, len(todo))
    prog = BuildProgress(len(points), len(points) - len(todo),
                         {i: float(cost(spec.scene, points[i])) for i in todo} if cost else None,
                         seconds_per_cost, n_workers)
    bar, ticking = _progress_bar(spec, len(points), len(points) - len(todo), prog) \
        if progress else (None, None)
    points_done = _PointsDone(spec, points, results, point_store, prog, todo, bar)
    try:
        _run_todo(spec, builder, points, todo, points_done, executor, workers, scheduler,
                  n_workers)
    finally:
        if ticking is not None:
            ticking.set()
        if bar is not None:
            bar.close()
    if points_done.errors:
        i, e = points_done.errors[0]
        errors = points_done.errors
        more = f" ({len(errors) - 1} more failed)" if len(errors) > 1 else ""
        finished = sum(r is not None for r in results)
        kept = (f"; the {finished} finished points are kept for a resume"
                if point_store is not None else "")
        raise TableError(f"grid point {points[i]}: {type(e).__name__}: {e}{more}{kept}") \
            from e
    return results


def _progress_bar(spec: TableSpec, total: int, initial: int, prog: BuildProgress):
    """A tqdm bar of a build's points and the event that stops its ticking: a point can
    run for an hour, so a thread refreshes the bar's line (the time left counts down)
    every PROGRESS_REFRESH_S between finished points."""
    import threading

    from tqdm import tqdm
    bar = tqdm(total=total, initial=initial, unit="point", desc=f"table {spec.key()[:10]}")
    ticking = threading.Event()

    def tick():
        while not ticking.wait(PROGRESS_REFRESH_S):
            bar.set_postfix_str(prog.text(), refresh=True)

    threading.Thread(target=tick, daemon=True).start()
    return bar, ticking


class _PointsDone:
    """What :func:`run_points` does as points start and finish: the results in grid
    order, the point store, the progress and the failures (``errors``: (index,
    exception))."""

    def __init__(self, spec, points, results, point_store, prog, todo, bar):
        self.spec, self.points, self.results = spec, points, results
        self.point_store, self.prog, self.bar = point_store, prog, bar
        self.queue = list(todo)  # not started, in the order the executors start them
        self.errors = []

    def started(self, k=1):
        for _ in range(k):
            if self.queue:
                self.prog.start(self.queue.pop(0))
        if self.bar is not None:
            self.bar.set_postfix_str(self.prog.text(), refresh=True)

    def __call__(self, i, f):
        """Store the outcome of point i (``f()`` returns its result or raises); a failed
        point is remembered and the others go on, so that they are stored for a resume."""
        try:
            r = f()
        except Exception as e:  # noqa: BLE001 - re-raised by run_points, after the others
            self.errors.append((i, e))
            return
        self.results[i] = r
        if self.point_store is not None:
            self.point_store.put(self.spec, self.points[i], r)
        w = r.get("wall_time_s") if isinstance(r, dict) else None
        self.prog.finish(i, float(w) if isinstance(w, (int, float)) else None)
        if self.bar is not None:
            self.bar.update(1)
        self.started(1)  # a worker took the next point


def _run_todo(spec, builder, points, todo, done: _PointsDone, executor, workers, scheduler,
              n_workers) -> None:
    """Run the points ``todo`` by ``executor`` (see :func:`run_points`), each outcome to
    ``done``."""
    if not todo:
        return
    if scheduler is not None or executor == "dask":
        done.started(n_workers)
        _run_dask(spec, builder, points, todo, done, workers, scheduler)
    elif executor == "serial" or len(todo) == 1:
        done.started(1)
        for i in todo:
            done(i, lambda: builder(spec.scene, points[i]))
            if done.errors:
                break  # one after the other: stop at the first failure
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed
        n = points_at_once(workers, len(todo))
        builder = builder_sharing_cores(builder, n)
        # spawned, not forked: a forked child of a process that has run the DEM's
        # OpenMP kernels cannot run them (GNU OpenMP is not fork safe)
        with ProcessPoolExecutor(max_workers=n,
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            futs = {pool.submit(builder, spec.scene, points[i]): i for i in todo}
            done.started(n)
            for f in as_completed(futs):
                done(futs[f], f.result)


def points_at_once(workers: int | None, n_points: int) -> int:
    """How many points a local build runs at once: ``workers`` (default all cores), at most
    the points to run, at least one."""
    return max(1, min(workers or os.cpu_count() or 1, n_points))


def builder_sharing_cores(builder, workers: int):
    """``builder`` for ``workers`` points running at once on this machine: where it takes a
    thread count and was given none (all cores per point), the cores shared out, at least
    one each (``builder.with_threads``). Each point on all cores oversubscribes them: on 2
    cores, 2 points with 2 threads each wait for each other's threads at every parallel
    loop."""
    with_threads = getattr(builder, "with_threads", None)
    if with_threads is None or workers <= 1:
        return builder
    return with_threads(max(1, (os.cpu_count() or 1) // workers))


def _run_dask(spec, builder, points, todo, done, workers, scheduler):
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise TableError("executor 'dask' / --scheduler: needs the packages dask and "
                         "distributed (pip install dask distributed)") from None
    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            client = stack.enter_context(Client(scheduler))
        else:
            import dask

            # worker-saturation 1.0: a worker holds only the task it runs, the others wait
            # at the scheduler in todo's order (costliest first); with the default 1.1 a
            # worker also holds the next one, which waits behind a long point while the
            # other workers run cheaper ones
            n = points_at_once(workers, len(todo))
            builder = builder_sharing_cores(builder, n)
            with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
                cluster = stack.enter_context(LocalCluster(
                    n_workers=n,
                    threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address=None))
            client = stack.enter_context(Client(cluster))
        # the scheduler starts mapped tasks in the order given (todo: costliest first); an
        # existing cluster (scheduler) keeps that order where its worker-saturation is 1.0
        futs = client.map(builder, [spec.scene] * len(todo), [points[i] for i in todo],
                          pure=False)
        where = {f.key: i for i, f in zip(todo, futs)}
        for f in as_completed(futs):
            done(where[f.key], f.result)


def build_table(spec: TableSpec, builder: Callable, **run_kw) -> Table:
    """Run the builder over the grid and assemble the table (not cached)."""
    t0 = time.perf_counter()
    stored = stored_results(spec, run_kw.get("point_store"))
    reused = sum(r is not None for r in stored)
    before = getattr(builder, "before_points", None)
    if before is not None and reused < len(stored) and not run_kw.get("scheduler"):
        before(spec)  # the DEM's kernels compiled here once, not by every local worker
    results = run_points(spec, builder, stored=stored, **run_kw)
    table = assemble(spec, results)
    point_s = [r.get("wall_time_s") for r in results]
    table.manifest = {"build_wall_time_s": time.perf_counter() - t0,
                      "points_run": len(results) - reused, "points_reused": reused}
    if all(isinstance(x, (int, float)) for x in point_s):
        # what the points cost where they ran, this build's or an earlier one's
        table.manifest["points_wall_time_s"] = float(sum(point_s))
    st = stationarity_summary(results, table.zone_names)
    if st is not None:
        table.manifest["stationarity"] = st
    cells = wider_cells(spec)
    if cells is not None:
        table.manifest["cells"] = cells
    starts = point_starts(spec, results)
    if starts is not None:
        table.manifest["point_starts"] = starts
    return table


def wider_cells(spec: TableSpec) -> dict | None:
    """The points of ``spec`` that run in another sector than the scene's (DEM points whose
    beads do not fit it, :func:`~.cells.dem_scene_at_point`) and that sector, for the
    manifest; None where every point runs in the scene's own."""
    if spec.builder_id != DEM_BUILDER_ID:
        return None
    own = (spec.scene.get("mill") or {}).get("sector_deg", 360.0)
    wide = []
    for p in spec.points():
        deg = (point_scene(spec, p).get("mill") or {}).get("sector_deg", 360.0)
        if deg != own:
            wide.append({"point": p, "sector_deg": deg})
    if not wide:
        return None
    return {"note": f"points whose beads do not fit the scene's {own:g}-degree sector at their filling ran in "
                    f"the narrowest wider sector that holds them (millfmu.dem.tables.cells."
                    f"dem_scene_at_point); the zone statistics are per chamber volume",
            "points": wide}


def point_starts(spec: TableSpec, results: list[dict]) -> dict | None:
    """How the points started, where their results say (the DEM builder's ``start``: cold,
    or warm from another point's settled state with a shorter spin-up,
    :mod:`~millfmu.dem.tables.warm_start`); None where no result says."""
    pts = [dict(point=p, **r["start"]) for p, r in zip(spec.points(), results)
           if isinstance(r.get("start"), dict)]
    if not pts:
        return None
    return {"measure": "how each point's DEM run started: 'cold' from a fresh bed with the scene's "
                       "spin-up, 'warm' from the settled state of the point whose values 'from' names "
                       "(the beads' and the liquid's velocities scaled by speed_scale, the tip speeds' "
                       "ratio) with the spin-up spin_up_s; why_cold: why a point started cold although "
                       "a state with its beads was at hand (beyond the range warm starts were measured "
                       "in); points not listed were taken from tables "
                       "that did not record it and started cold",
            "warm": sum(p["start"] == "warm" for p in pts), "points": pts}


def stationarity_summary(results: list[dict], zone_names) -> dict | None:
    """Largest |drift| over the points per field and zone (None without drift data)."""
    if not all("drift" in r for r in results):
        return None
    out = {"measure": "relative change from the first to the second half of each "
                      "point's recording, largest magnitude over the points (grid and "
                      "one-at-a-time)"}
    for f in DRIFT_FIELDS:
        arr = np.abs(np.array([r["drift"][f] for r in results], float))
        out[f] = {z: round(float(np.nanmax(arr[:, k])), 4) for k, z in enumerate(zone_names)}
    return out


# ---- checking a table against a run at a point -------------------------------------------
#: Per-zone quantities a point check compares: the table's fields, and the median of the
#: normal impact energy SE_tn / E_ref.
CHECK_FIELDS = ("speed_over_tip_speed", "filling_local", "collision_frequency_norm",
                "se_tn_q50_norm")


def _check_fields(values: dict) -> dict:
    out = {k: np.asarray(values[k], float) for k in CHECK_FIELDS[:-1]}
    q = np.asarray(values["se_quantiles_norm"], float)
    out["se_tn_q50_norm"] = q[COMPONENTS.index("tn"), :, QUANTILE_NAMES.index("q50")]
    return out


def _rel(a, b) -> list:
    """(a - b) / b per zone, None where b is zero or missing (4 significant digits)."""
    out = []
    for x, y in zip(np.ravel(a), np.ravel(b)):
        ok = np.isfinite(x) and np.isfinite(y) and y != 0.0
        out.append(float(f"{(x - y) / y:.4g}") if ok else None)
    return out


def check_point(table: Table, point: dict, builder: Callable) -> dict:
    """Run ``builder`` at ``point`` and compare the table's lookup there with the run.

    ``point``: axis -> value; axes left out take the scene's value (grid axes) or their
    reference (one-at-a-time axes). Per zone and quantity of :data:`CHECK_FIELDS`: the
    run's value, the relative difference of the lookup (``lookup_rel_diff``) and, where
    the table has one-at-a-time axes, of the grid alone with those axes at their references
    (``grid_only_rel_diff``): how much the one-at-a-time scaling (its separability
    assumption) gains or loses there. Returns a JSON-ready dict (``point``, ``zones``, one
    entry per quantity, ``wall_time_s`` of the run, and for the DEM builder
    ``run_kernel_version``, the installed DEM's: a check measures the table's error only
    where it is the table's)."""
    if "scene" not in table.manifest:
        raise TableError("check: the table's manifest names no scene to run")
    spec = table.spec()
    full = _full_point(table, point)
    table.lookup(full)  # outside the table: OutsideGridError, before the run
    t0 = time.perf_counter()
    run = builder(spec.scene, full)
    wall = time.perf_counter() - t0
    out = {"point": full, "zones": list(table.zone_names), "wall_time_s": round(wall, 1)}
    if getattr(builder, "builder_id", None) == spec.builder_id and spec.builder_id == DEM_BUILDER_ID:
        from .cache import dem_kernel_version

        out["run_kernel_version"] = dem_kernel_version()
    return _compare(table, out, _check_fields(run))


def _full_point(table: Table, point: dict) -> dict:
    """``point`` with every axis of the table: grid axes left out take the scene's value
    (or the axis's only node), one-at-a-time axes left out their reference."""
    known = set(table.axes) | set(table.one_at_a_time)
    unknown = sorted(set(point) - known)
    if unknown:
        raise TableError(f"check: axes {unknown} are not the table's; it has {sorted(known)}")
    full = {}
    for name, ax in table.axes.items():
        full[name] = float(point[name]) if name in point else (
            float(ax[0]) if len(ax) == 1 else table.spec().scene_value(name))
    refs = {k: float(v) for k, v in table.one_at_a_time_ref.items()}
    full.update({k: float(point.get(k, v)) for k, v in refs.items()})
    return full


def _compare(table: Table, out: dict, want: dict) -> dict:
    """``out`` with, per quantity of :data:`CHECK_FIELDS`, the run's values ``want[k]``
    (per zone; NaN or None where missing; recorded to 4 significant digits) and the
    relative differences of the lookup at ``out["point"]`` (and of the grid alone) against
    them."""
    full = out["point"]
    refs = {k: float(v) for k, v in table.one_at_a_time_ref.items()}
    got = _check_fields(table.lookup(full).values)
    base = _check_fields(table.lookup({**full, **refs}).values) if refs else None
    for k in CHECK_FIELDS:
        w = np.array([np.nan if v is None else v for v in np.ravel(want[k])], float)
        e = {"run": [float(f"{v:.4g}") if np.isfinite(v) else None for v in w],
             "lookup_rel_diff": _rel(got[k], w)}
        if base is not None:
            e["grid_only_rel_diff"] = _rel(base[k], w)
        out[k] = e
    return out


def recheck(table: Table, result: dict, run_kernel_version: str | None = None) -> dict:
    """A check recorded against another table (``result``, as :func:`check_point` gave it)
    compared with this table's lookup at its point, without running the DEM again: the
    run's values are the recorded ones (4 significant digits). For a table rebuilt or
    refined on the same scene and settings, whose checks' runs stay valid samples of it.
    ``run_kernel_version``: the DEM kernel version the run had (the old table's), kept in
    the entry unless the check was itself carried over and names its run's version.
    Raises OutsideGridError where this table does not cover the point."""
    # axes the check's point leaves out (e.g. one the table did not have when the check was
    # recorded) are filled as check_point fills them
    full = _full_point(table, result["point"])
    if list(result.get("zones", ())) != list(table.zone_names):
        raise TableError(f"recheck: the check's zones {result.get('zones')} are not the "
                         f"table's {list(table.zone_names)}")
    out = {"point": full, "zones": list(table.zone_names),
           "wall_time_s": result.get("wall_time_s"),
           "run_from": "an earlier table's check (the DEM not run again)"}
    kv = result.get("run_kernel_version", run_kernel_version)
    if kv is not None:
        out["run_kernel_version"] = kv
    return _compare(table, out, {k: result[k]["run"] for k in CHECK_FIELDS})


def record_check(table: Table, result: dict) -> dict:
    """The table's manifest with ``result`` (:func:`check_point`) among its checks:
    ``separability_check`` where a one-at-a-time axis is off its reference, else
    ``interpolation_check``; a check at the same point is replaced."""
    # FIXED_AXIS_RTOL: the lookup's rule for "at the reference".
    off = any(not math.isclose(result["point"][k], v, rel_tol=FIXED_AXIS_RTOL)
              for k, v in table.one_at_a_time_ref.items())
    key = "separability_check" if off else "interpolation_check"
    measure = ("one-at-a-time values run away from the anchor: relative difference of the "
               "table's lookup (lookup_rel_diff) and of the grid alone without the "
               "one-at-a-time scaling (grid_only_rel_diff) against the run, per zone"
               if off else "points off the grid's nodes: relative difference of the "
               "table's lookup (lookup_rel_diff) against the run, per zone")
    m = json.loads(json.dumps(table.manifest))
    entry = m.get(key) or {"measure": measure, "points": []}
    same = [p for p in entry["points"] if p.get("point") == result["point"]]
    entry["points"] = [p for p in entry["points"] if p not in same] + [result]
    m[key] = entry
    return m
