"""The DEM as a table builder: :class:`DemBuilder` runs millfmu's DEM at a grid point and
normalizes its statistics into table fields; :func:`dem_scene_at_point` chooses the DEM cell a
point runs in (a wider sector where its beads do not fit the scene's); :func:`dem_spec` makes
the specification of a DEM table from a scene file; :func:`rebuild_including` builds a table
whose grid covers a point outside the old one.

The DEM (and numba) loads only inside :class:`DemBuilder` calls, not on import.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable

import numpy as np

from ..scene import load_scene_dict, scene_from_dict
from .cache import dem_kernel_version, get_table
from .cells import dem_cells, dem_scene_at_point
from .point_work import point_work, work_key
from .warm_start import resume_point, run_point, start_of, warm_candidates
from ...stress_tables.spec import (COMPONENTS, DEM_BUILDER_ID, DRIFT_FIELDS, QUANTILE_NAMES, TableError,
                   TableSpec, e_ref_J, n_gb_per_m3, norm_log10_edges,
                   scene_at_point)
from ...stress_tables.table import STATED_ERROR_ENTRIES, Table


def rebin_density(dem_edges_J: np.ndarray, density_per_decade: np.ndarray,
                  e_ref: float) -> np.ndarray:
    """Number density over log10(SE) on the DEM's bins -> density over log10(SE / E_ref)
    on :func:`norm_log10_edges` [1/decade]. The density is taken constant within a DEM bin
    (the cumulative distribution linear in log10 SE); mass beyond the normalized range goes
    to the end bins, as the DEM statistics do with theirs."""
    u = np.log10(np.asarray(dem_edges_J, float)) - math.log10(e_ref)
    dens = np.asarray(density_per_decade, float)
    mass = dens * np.diff(u)
    total = mass.sum()
    U = norm_log10_edges()
    if total <= 0.0:
        return np.zeros(U.size - 1)
    cdf = np.concatenate([[0.0], np.cumsum(mass)]) / total
    F = np.interp(U, u, cdf, left=0.0, right=1.0)
    w = np.diff(F)
    w[0] += F[0]
    w[-1] += 1.0 - F[-1]
    return w / np.diff(U)


def normalize_stats(stats, scene) -> dict:
    """Per-point table fields from DEM statistics (:class:`millfmu.dem.analysis.stats.DemStats`) of
    a run of ``scene`` (:class:`millfmu.dem.scene.DemScene`, placement 'filling')."""
    d, rho = scene.bead_diameter_m, scene.material.density_kg_per_m3
    eref = e_ref_J(d, rho, scene.tip_speed_m_per_s)
    omega = scene.omega_rad_per_s
    ngb = n_gb_per_m3(scene.filling, scene.bulk_porosity, d)
    vols = np.array([z.volume_m3 for z in stats.zones])
    edges = np.asarray(stats.se_bin_edges_j)
    out = {
        "zone_names": [z.name for z in stats.zones],
        "volume_fraction": vols / vols.sum(),
        "filling_local": np.array([z.filling for z in stats.zones]),
        "speed_over_tip_speed": np.array([z.speed_over_tip_speed for z in stats.zones]),
        "collision_frequency_norm": np.array([z.collision_frequency_per_m3_s
                                              for z in stats.zones]) / (omega * ngb),
        "collision_power_norm": np.array([z.collision_power_w for z in stats.zones])
        / (vols * eref * omega * ngb),
        "collision_count": np.array([z.collision_count for z in stats.zones], float),
        "se_density": np.array([[rebin_density(edges, z.se[c].density_per_decade, eref)
                                 for z in stats.zones] for c in COMPONENTS]),
        "se_quantiles_norm": np.array([[[np.nan if z.se[c].quantiles_j[q] is None
                                         else z.se[c].quantiles_j[q] / eref
                                         for q in QUANTILE_NAMES] for z in stats.zones]
                                       for c in COMPONENTS]),
        "e_ref_J": eref, "omega_rad_per_s": omega, "n_gb_per_m3": ngb,
    }
    return out


@dataclass(frozen=True)
class DemBuilder:
    """Builder of one grid point: runs millfmu's DEM (:func:`millfmu.dem.run.run_scene`) on
    the scene with the point's values and returns the normalized fields. ``threads``: numba
    threads per run (1 when grid points run in parallel). ``work_precision``: what the
    table's manifest states as its work-precision entry (see
    :func:`~.spec.manifest_for`), handed in by the caller: the tables CLI gives the shipped
    study's :func:`millfmu.dem.analysis.precision.manifest_entry`. ``warm_spin_up_s``: a
    point with the same beads as a point whose settled state is among ``warm_from`` (file
    names in ``state_dir``) or shipped with the package starts from the nearest with this
    spin-up; None, or ``warm_from`` None: every point starts cold (:mod:`.warm_start`).
    ``state_dir``: where each point's settled state is kept (None: nowhere); a build sets
    it and ``warm_from`` (:meth:`with_states`)."""

    threads: int | None = None
    work_precision: object = field(default=None, compare=False)
    warm_spin_up_s: float | None = None
    state_dir: str | None = field(default=None, compare=False)
    warm_from: tuple | None = field(default=None, compare=False)
    builder_id = DEM_BUILDER_ID

    def before_points(self, spec) -> None:
        """Before a build runs points on this machine: compile the DEM's kernels where the
        cache is cold, once and in several processes (:mod:`millfmu.dem.first_compile`),
        rather than in each worker of the build at the same time."""
        from ..first_compile import compile_if_cold

        compile_if_cold(coupled=(spec.scene.get("fluid") or {}).get("mode") == "coupled")

    def with_states(self, folder, reuse: bool = True) -> DemBuilder:
        """This builder keeping its points' settled states in ``folder`` (a build's point
        store) and, where it starts points warm and ``reuse``, starting them from the states
        there now and the shipped ones (not from those its own points write while the build
        runs, so that a build's points do not depend on the order in which they finish)."""
        from dataclasses import replace

        from .warm_start import STATE_SUFFIX

        folder = Path(folder)
        names = None
        if reuse and self.warm_spin_up_s is not None:
            names = tuple(sorted(p.name for p in folder.glob("*" + STATE_SUFFIX))) if folder.is_dir() else ()
        return replace(self, state_dir=str(folder), warm_from=names)

    def __call__(self, scene: dict, point: dict) -> dict:
        at = dem_scene_at_point(scene, point)
        s = scene_from_dict(at)
        if s.placement != "filling":
            raise TableError(f"scene {s.name}: beads.placement = {s.placement!r}; tables "
                             f"need placement 'filling'")
        # Two windows, the halves of the recording: their difference shows whether the
        # recorded state is stationary (manifest "stationarity").
        window_s = 0.5 * s.record_s
        kv = dem_kernel_version()
        kw = dict(threads=self.threads, kernel_version=kv)
        content = work_key(at, kv, {"window_s": window_s, "warm_spin_up_s": self.warm_spin_up_s})
        label = ", ".join(f"{k} {v:g}" for k, v in point.items())
        t0 = time.perf_counter()
        # in the point store's folder with checkpoints where there is a store (.point_work);
        # a warm start from a stored point's settled state where it may (.warm_start)
        with point_work(self.state_dir, content, label) as work:
            stats, start = work.run(
                lambda out, every, on_start: run_point(
                    s, at, out, window_s=window_s, checkpoint_every_s=every, on_start=on_start,
                    **kw, **self.start_kw()),
                lambda out, start, state: resume_point(out, at, start, state, state_dir=self.state_dir, **kw))
            out = normalize_stats(stats, s)
            out["drift"] = recording_drift(work.folder / "windows.csv", out["zone_names"])
        out["wall_time_s"] = time.perf_counter() - t0 + work.wall_before_s
        out["start"] = start
        return out

    def unbuildable(self, scene: dict, point: dict) -> str | None:
        """Why the DEM cannot run ``point`` (its beads do not fit the scene's cell at the
        point's filling and bead size, nor any wider sector of :func:`dem_scene_at_point`),
        else None: asked before a build starts, so that it is refused before its cost is said
        and before any point runs."""
        cell, widest = dem_cells(scene, point)
        if cell.dem is None or cell.fits:
            return None
        s, g = widest.dem, widest.dem.geometry
        wider = (f" in a sector of {g.sector_deg:g} degrees, the widest it may take"
                 if widest is not cell else "")
        return (f"the DEM scene {s.name} ({s.kind}, a cell {g.height_m * 1e3:g} mm high between radii "
                f"{g.shaft_radius_m * 1e3:g} and {g.chamber_radius_m * 1e3:g} mm) holds at most {widest.capacity} "
                f"beads of {s.bead_diameter_m * 1e3:g} mm placed without overlap{wider}, and a filling of "
                f"{s.filling:g} needs {widest.need}: the table cannot be extended to this bead size at this filling")

    def start_kw(self) -> dict:
        """How :func:`~.warm_start.run_point` starts this builder's points and keeps their
        states: ``state_dir``, ``candidates`` (None where every point starts cold) and
        ``warm_spin_up_s``."""
        return {"state_dir": self.state_dir, "warm_spin_up_s": self.warm_spin_up_s,
                "candidates": warm_candidates(self.state_dir, self.warm_from)
                if self.warm_spin_up_s is not None else None}

    def start_of(self, scene: dict, point: dict) -> tuple[str, str | None]:
        """How this builder would start ``point``: ("warm", None) where it starts points warm
        and a stored state with the point's beads lies within the measured range
        (:func:`~.warm_start.start_of`), else ("cold", why), ``why`` None or why the states
        at hand are too far."""
        if self.warm_spin_up_s is None or self.warm_from is None:
            return "cold", None
        return start_of(dem_cells(scene, point)[0].scene, self.state_dir, self.warm_from)

    def relative_cost(self, scene: dict, point: dict) -> float:
        """Expected run time of the point, up to a constant: bead count (filling / d^3) times
        DEM steps ((spin-up + recording) / dt), the spin-up a warm start's where the point
        would start warm (:meth:`start_of`). A build runs the costliest points first, so that
        a long point (small beads) does not start last and leave the other workers idle while
        it runs. A point run in a wider sector than the scene's (:func:`dem_scene_at_point`)
        has as many times more beads."""
        warm = self.warm_spin_up_s is not None and self.start_of(scene, point)[0] == "warm"
        return _cost(scene, point, self.warm_spin_up_s if warm else None)

    def cost_as_started(self, scene: dict, point: dict, start: dict) -> float:
        """:meth:`relative_cost` of a point that ran with the start ``start`` (its record:
        :func:`~.warm_start.cold_record`, :func:`~.warm_start.warm_record`): a warm one at
        its spin-up, for the calibration on a table whose points started warm."""
        warm = isinstance(start, dict) and start.get("start") == "warm"
        return _cost(scene, point, start.get("spin_up_s") if warm else None)

    def measured_seconds_per_cost(self, table: Table) -> float | None:
        """Seconds per unit of :meth:`relative_cost` for points of ``table`` from runs of the
        installed DEM on this builder's threads (:data:`MEASURED_SPEED`), where they were runs
        of its scene with the DEM kernel version installed now; else None (the table's own
        build calibrates)."""
        return measured_seconds_per_cost(table, threads=self.threads)

    def with_threads(self, threads: int) -> DemBuilder:
        """This builder with ``threads`` numba threads per point where it was given none (a
        build running several points at once shares the cores out,
        :func:`~.build.builder_sharing_cores`); the results do not depend on it."""
        from dataclasses import replace

        return self if self.threads is not None else replace(self, threads=int(threads))


#: What a coupled point's step costs besides its beads (the liquid on its grid, which does
#: not grow with the beads, and the step's fixed work), as a share of the bead cost of the
#: scene's own point (its filling and bead diameter in its own sector) [-]. Fitted to two
#: cold points of the coupled table's scene run alone on one thread, t = steps (a N + b):
#: the steel point (0.8 mm, 6,536 beads, 10 m/s, 80 %) 403 s, 1.4 mm beads at 80 % in a
#: 12-degree cell (1,464 beads) 121 s; b / a = 720 beads' worth, 0.11 of the 6,536.
COUPLED_FIXED_SHARE = 0.11


def _cost(scene: dict, point: dict, spin_up_s: float | None = None) -> float:
    """:meth:`DemBuilder.relative_cost` of ``point`` run with the spin-up ``spin_up_s`` [s]
    (None: the scene's; a longer one than the scene's is not run): the bead count's measure
    filling / d^3 (times the sector where the point runs wider than the scene), plus for a
    coupled liquid :data:`COUPLED_FIXED_SHARE` of the scene's own point's, times the
    steps."""
    cell = dem_cells(scene, point)[0]
    s = cell.dem if cell.dem is not None else scene_from_dict(cell.scene)
    wider = s.geometry.sector_deg / float(scene.get("mill", {}).get("sector_deg", 360.0))
    spin_up = s.spin_up_s if spin_up_s is None else min(s.spin_up_s, float(spin_up_s))
    beads = s.filling / s.bead_diameter_m**3 * wider
    if s.fluid_mode == "coupled":
        own = scene_from_dict(scene)
        beads += COUPLED_FIXED_SHARE * own.filling / own.bead_diameter_m**3
    return beads * (spin_up + s.record_s) / s.dt_s


#: The installed DEM's speed, measured: points of the coupled table's scene
#: (``scene_sha256``: of its canonical JSON), each run alone on a 2-core machine with 2
#: numba threads, as an on-demand build runs one new point, and with one (as each of two
#: points run at once), with the sources of ``source_hash`` (DEM kernel version
#: ``kernel_version``): the steel point (0.8 mm, 7,800 kg/m3, 10 m/s, 80 %) cold and warm
#: from the shipped anchor state (``python -m validation.warm_start run --out DIR
#: --spin-ups 0.2``; docs/tables.md). The coupled table's ``points_wall_time_s`` was
#: recorded by the sources that built it, which have the kernel version of these (the same
#: results: the cache's SAME_DEM_AS and accepted round-off changes) but ran the glass
#: anchor point in 894 and 965 s on 1 and 2 threads (millfmu/data/dem_equivalence.json):
#: calibrated on it, the steel point was estimated at 18 min cold and 6 min warm against
#: the 280 and 103 s it took. Used where the installed kernel version is ``kernel_version``
#: (runs of later sources of the same version measure their own speed, not this one:
#: measure again when they change it).
_STEEL = {"tip_speed_m_per_s": 10.0, "filling": 0.8, "bead_diameter_m": 0.8e-3,
          "bead_density_kg_per_m3": 7800.0}
MEASURED_SPEED = {
    "scene_sha256": "sha256:216aecd5347f34fcc9a8338d251a6dd9c72d9926aba20694e21e9a665c3012aa",
    "kernel_version": "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "source_hash": "sha256:ccfe999eeb245cff904badce12eca5351083bf878c6f2247a5f5f24bda20361f",
    "threads": 2, "cpus": 2,
    "runs": ({"point": _STEEL, "spin_up_s": 1.5, "wall_time_s": 280.0},
             {"point": _STEEL, "spin_up_s": 0.2, "wall_time_s": 103.0},
             # the same two on one thread (docs/tables.md, "What it costs")
             {"point": _STEEL, "spin_up_s": 1.5, "wall_time_s": 403.0, "threads": 1},
             {"point": _STEEL, "spin_up_s": 0.2, "wall_time_s": 145.0, "threads": 1}),
}


def measured_seconds_per_cost(table: Table, measured: dict | None = None,
                              threads: int | None = None) -> float | None:
    """Seconds per unit of :meth:`DemBuilder.relative_cost` from ``measured`` (default
    :data:`MEASURED_SPEED`): its runs' summed wall time over their summed cost, where
    ``table``'s scene is the one it measured and the installed DEM kernel version is its;
    else None. ``threads``: the runs on that many threads (a run without ``threads`` ran on
    ``measured["threads"]``) where there are some, else those on ``measured["threads"]``
    (None: all cores, as it measured)."""
    from ...stress_tables.files import canonical_json, sha256_bytes
    from . import cache

    m = MEASURED_SPEED if measured is None else measured
    scene = table.manifest.get("scene")
    if not isinstance(scene, dict) or "sha256:" + sha256_bytes(canonical_json(scene).encode()) != m["scene_sha256"]:
        return None
    if cache.dem_kernel_version() != m["kernel_version"]:
        return None
    def on(n):
        return [r for r in m["runs"] if r.get("threads", m["threads"]) == n]

    runs = (on(threads) if threads is not None else []) or on(m["threads"])
    cost = sum(_cost(scene, r["point"], r["spin_up_s"]) for r in runs)
    wall = sum(float(r["wall_time_s"]) for r in runs)
    return wall / cost if cost > 0 else None


def recording_drift(windows_csv, zone_names) -> dict:
    """Relative change [-] of each of :data:`DRIFT_FIELDS` per zone from the first to the
    last window of a DEM run's ``windows.csv``: (last - first) / mean of the two."""
    import csv

    with open(windows_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    starts = sorted({float(r["t_start_s"]) for r in rows})
    first = {r["zone"]: r for r in rows if float(r["t_start_s"]) == starts[0]}
    last = {r["zone"]: r for r in rows if float(r["t_start_s"]) == starts[-1]}
    out = {}
    for f in DRIFT_FIELDS:
        vals = []
        for z in zone_names:
            a, b = float(first[z][f]), float(last[z][f])
            m = 0.5 * (a + b)
            vals.append((b - a) / m if math.isfinite(m) and m > 0.0 else float("nan"))
        out[f] = vals
    return out


def dem_spec(scene_name_or_path: str, grid: dict, overrides: dict | None = None,
             one_at_a_time: dict | None = None, across: dict | None = None) -> TableSpec:
    """Spec for a DEM table: the scene file's content (TOML -> dict) with ``overrides``
    (section -> {key: value}, e.g. {"run": {"spin_up_s": 0.05}}) merged in, validated;
    ``one_at_a_time``: axes varied one at a time from the scene's point, ``across``: those
    of them run across a sub-grid of the grid axes (:class:`TableSpec`)."""
    d = load_scene_dict(scene_name_or_path)
    for sec, kv in (overrides or {}).items():
        d.setdefault(sec, {}).update(kv)
    spec = TableSpec(scene=d, grid=grid, kernel_version=dem_kernel_version(),
                     one_at_a_time=one_at_a_time or {}, across=across or {})
    gp = spec.grid_points()
    # validate the grid's corners and every point off the grid early
    for p in [gp[0], gp[-1]] + spec.points()[len(gp):]:
        _validate_scene_dict(scene_at_point(d, p))
    return spec


def _validate_scene_dict(d: dict):
    scene_from_dict(d)


def rebuild_including(table: Table, point: dict, builder: Callable | None = None,
                      cache_dir=None, progress: bool = True, on_stale: str = "refuse",
                      log: Callable[[str], None] | None = None, **run_kw) -> Table:
    """Build (or find in the cache) a table like ``table`` whose grid also covers ``point``:
    each axis (grid or one-at-a-time) whose value lies outside gets that value as a new end
    node. Only the points not in the cache's point store are run (the table's own points
    and those of the shipped tables of the same scene and kernel are put there first).
    ``builder``: default the DEM (:class:`DemBuilder`).

    Before anything runs, one line (``log``, default stderr) says what the build runs and
    costs; where the installed DEM's kernel version is not the table's, ``on_stale``
    decides (:mod:`.on_demand`): 'refuse' raises :class:`~.on_demand.StaleTableError`
    naming the cost of the full rebuild, 'rebuild' runs every point with the installed
    DEM, 'accept' keeps the table's points and runs only the new ones."""
    from . import on_demand as od

    if log is None:
        def log(msg):
            print(f"millfmu: {msg}", file=sys.stderr, flush=True)
    if builder is None:
        # The extended table has the same DEM settings: it keeps the old one's entry.
        builder = od.default_builder(table)
    workers = run_kw.get("workers") or (1 if run_kw.get("executor") == "serial" else None)
    od.unbuildable(table, point, builder)  # before the cost is said or anything runs
    old_v = table.spec().kernel_version
    new_v = od.installed_kernel_version(table)
    if new_v != old_v:
        line = od.stale_line(table, point, on_stale, builder, cache_dir, workers)
        log(line)
        if on_stale == "refuse":
            raise od.StaleTableError(line)
    kv = old_v if on_stale == "accept" else new_v
    pl = od.plan(table, point, builder, kv, cache_dir, workers)
    # what the table's stated error reads besides its grid (the checks against the DEM at
    # points off its nodes, the spread of independent realizations) holds for the extended
    # table as well: same scene, settings and DEM; left out, its stated error would shrink
    extra = {k: table.manifest[k] for k in STATED_ERROR_ENTRIES if k in table.manifest}
    if kv != new_v:
        extra["on_demand"] = {
            "kernel_accepted": "the points of the table extended ran with the kernel version "
                               "of this table; the points run for the extension with the "
                               "installed DEM's (on_stale = 'accept')",
            "installed_kernel_version": new_v, "points_run_with_installed": pl.todo}
    name = (table.manifest.get("scene") or {}).get("name", "?")
    if pl.todo:
        log(f"table {name}: building a table that covers {_point_text(table, point)}: {pl.line()}")
        od.confirm_build(pl, f"the build of table {name} extended to {_point_text(table, point)}")
    run_kw.setdefault("seconds_per_cost", pl.seconds_per_cost)
    return get_table(pl.spec, builder, cache_dir=cache_dir, progress=progress, seed_from=(table,),
                     manifest_extra=extra, **run_kw)


def _point_text(table: Table, point: dict) -> str:
    spec = table.spec()
    out = []
    for ax, vals in (*spec.grid.items(), *spec.one_at_a_time.items()):
        if ax in point and not vals[0] <= float(point[ax]) <= vals[-1]:
            out.append(f"{ax} = {float(point[ax]):g}")
    return ", ".join(out) or "the point"
