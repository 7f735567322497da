"""Building a table: a builder (``builder(scene, point) -> fields``, e.g. the DEM's
:class:`~millfmu.dem.tables.dem_builder.DemBuilder`) run at every grid point, serially, in a
local process pool or on a Dask cluster, and the results stacked into a :class:`Table`.

Imports no numba: the builder loads the DEM in the processes that run grid points.
"""

from __future__ import annotations

import contextlib
import os
import time
from typing import Callable

import numpy as np

from .spec import DRIFT_FIELDS, FIELDS, TableError, TableSpec
from .table import Table


def assemble(spec: TableSpec, results: list[dict]) -> Table:
    """Stack per-point builder results (grid order, see :meth:`TableSpec.points`)."""
    if len(results) != len(spec.points()):
        raise TableError(f"assemble: {len(results)} results for {len(spec.points())} points")
    zn = tuple(results[0]["zone_names"])
    for r in results:
        if tuple(r["zone_names"]) != zn:
            raise TableError(f"assemble: zone names differ between points: {zn} vs "
                             f"{tuple(r['zone_names'])}")
    shape = spec.shape
    data = {k: np.stack([np.asarray(r[k], float) for r in results]).reshape(
        shape + np.asarray(results[0][k]).shape) for k in FIELDS}
    if all("drift" in r for r in results):
        data["recording_drift"] = np.array(
            [[r["drift"][f] for f in DRIFT_FIELDS] for r in results], float).reshape(
            shape + (len(DRIFT_FIELDS), len(zn)))
    refs = {k: np.array([float(r[k]) for r in results]).reshape(shape)
            for k in ("e_ref_J", "omega_rad_s", "n_gb_per_m3")}
    t = Table(axes={k: np.asarray(v, float) for k, v in spec.grid.items()}, zone_names=zn,
              data=data, refs=refs)
    t.check_shapes()
    return t


def run_points(spec: TableSpec, builder: Callable, executor: str = "processes",
               workers: int | None = None, scheduler: str | None = None,
               progress: bool = True) -> list[dict]:
    """Evaluate ``builder(scene, point)`` at every grid point; results in grid order.

    executor: ``serial``; ``processes`` (a local process pool of ``workers`` processes,
    default all cores); ``dask`` (a Dask LocalCluster on 127.0.0.1 with ``workers``
    single-threaded worker processes, or the existing cluster at ``scheduler``, e.g.
    ``tcp://host:8786``, when given). A tqdm bar counts finished grid points.
    """
    points = spec.points()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(points), unit="point", desc=f"table {spec.key()[:10]}")
    results: list = [None] * len(points)
    try:
        if scheduler is not None or executor == "dask":
            _run_dask(spec, builder, points, results, workers, scheduler, bar)
        elif executor == "serial" or len(points) == 1:
            for i, p in enumerate(points):
                results[i] = builder(spec.scene, p)
                if bar is not None:
                    bar.update(1)
        elif executor == "processes":
            from concurrent.futures import ProcessPoolExecutor, as_completed
            n = min(workers or os.cpu_count() or 1, len(points))
            with ProcessPoolExecutor(max_workers=n) as pool:
                futs = {pool.submit(builder, spec.scene, p): i for i, p in enumerate(points)}
                for f in as_completed(futs):
                    results[futs[f]] = f.result()
                    if bar is not None:
                        bar.update(1)
        else:
            raise TableError(f"executor = {executor!r}: allowed 'serial', 'processes', 'dask'")
    finally:
        if bar is not None:
            bar.close()
    return results


def _run_dask(spec, builder, points, results, workers, scheduler, bar):
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise TableError("executor 'dask' / --scheduler: needs the packages dask and "
                         "distributed (pip install dask distributed)") from None
    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            client = stack.enter_context(Client(scheduler))
        else:
            cluster = stack.enter_context(LocalCluster(
                n_workers=min(workers or os.cpu_count() or 1, len(points)),
                threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None))
            client = stack.enter_context(Client(cluster))
        futs = client.map(builder, [spec.scene] * len(points), points, pure=False)
        where = {f.key: i for i, f in enumerate(futs)}
        for f in as_completed(futs):
            results[where[f.key]] = f.result()
            if bar is not None:
                bar.update(1)


def build_table(spec: TableSpec, builder: Callable, **run_kw) -> Table:
    """Run the builder over the grid and assemble the table (not cached)."""
    t0 = time.perf_counter()
    results = run_points(spec, builder, **run_kw)
    table = assemble(spec, results)
    table.manifest = {"build_wall_time_s": time.perf_counter() - t0}
    st = stationarity_summary(results, table.zone_names)
    if st is not None:
        table.manifest["stationarity"] = st
    return table


def stationarity_summary(results: list[dict], zone_names) -> dict | None:
    """Largest |drift| over the grid points per field and zone (None without drift data)."""
    if not all("drift" in r for r in results):
        return None
    out = {"measure": "relative change from the first to the second half of each grid "
                      "point's recording, largest magnitude over the grid points"}
    for f in DRIFT_FIELDS:
        arr = np.abs(np.array([r["drift"][f] for r in results], float))
        out[f] = {z: round(float(np.nanmax(arr[:, k])), 4) for k, z in enumerate(zone_names)}
    return out
