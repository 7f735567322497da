"""millfmu tables build|status|verify|check|clear: the stress-energy lookup tables' cache.

The main CLI calls :func:`register` with its subparsers object. Nothing here imports numba;
the DEM loads only in the processes that build grid points.

Examples::

    millfmu tables build --scene disc_slice --tip-speed 6,10,14 --filling 0.6,0.8
    millfmu tables build ... --bead-diameter 0.0005,0.0008,0.0012 --one-at-a-time bead-diameter
    millfmu tables build ... --scheduler tcp://10.0.0.5:8786     # an existing Dask cluster
    millfmu tables status
    millfmu tables verify --default
    millfmu tables clear --stale

A change of the DEM's sources that alters only round-off is accepted as the tables' kernel
version by runs made from a checkout (``python -m validation.equivalence_runs``); the cache
reads the evidence they write (:mod:`millfmu.dem.tables.equivalence`).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import shlex
import sys
from pathlib import Path

#: CLI option -> (grid axis, help)
GRID_OPTIONS = {
    "--tip-speed": ("tip_speed_m_per_s", "stirrer tip speeds [m/s]"),
    "--filling": ("filling", "grinding-media fillings [-]"),
    "--bead-diameter": ("bead_diameter_m", "bead diameters [m]"),
    "--bead-density": ("bead_density_kg_per_m3", "bead densities [kg/m3]"),
    "--viscosity": ("viscosity_Pa_s", "fluid viscosities [Pa s]"),
}
#: CLI option -> (scene section, key, help) for run settings written into the scene content
RUN_OPTIONS = {
    "--sector-deg": ("mill", "sector_deg", "simulated sector, 360/k degrees (k >= 4); "
                     "needs --no-gravity"),
    "--spin-up": ("run", "spin_up_s", "spin-up time excluded from the statistics [s]"),
    "--record": ("run", "record_s", "recording time [s]"),
    "--sample-every": ("run", "sample_every_s", "sampling interval [s]"),
    "--dt": ("run", "dt_s", "DEM time step [s]"),
    "--initial-rotation": ("run", "initial_rotation", "beads and coupled fluid start turning "
                           "at this fraction of the stirrer's angular velocity [-]"),
}


def _to_stderr(msg: str) -> None:
    print(msg, file=sys.stderr)


def _floats(text: str) -> list:
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated numbers, "
                                         f"e.g. 6,10,14") from None
    if not vals:
        raise argparse.ArgumentTypeError(f"{text!r}: no values")
    return vals


def _axis_names(text: str) -> list:
    """CLI names (bead-diameter) or axis names (bead_diameter_m) -> axis names."""
    by_opt = {opt[2:]: axis for opt, (axis, _) in GRID_OPTIONS.items()}
    axes = {axis for axis, _ in GRID_OPTIONS.values()}
    out = []
    for name in (x.strip() for x in text.split(",") if x.strip()):
        axis = by_opt.get(name, name if name in axes else None)
        if axis is None:
            raise argparse.ArgumentTypeError(
                f"{name!r}: not an axis; allowed: {', '.join(by_opt)}")
        out.append(axis)
    return out


def _across(text: str) -> tuple:
    """``AXIS[=V1,V2,..]:GRID-AXIS=V1,V2,..[:GRID-AXIS=..]`` -> (axis name, {grid axis name:
    values}, with the axis's own values under its name where given: only those run across)."""
    parts = [x.strip() for x in text.split(":")]
    if len(parts) < 2 or not all(parts):
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected AXIS[=V1,V2,..]:GRID-AXIS=V1,V2,.., e.g. "
            f"bead-density:tip-speed=6,10,14:filling=0.5,0.8,0.9")
    def one(name):
        names = _axis_names(name)
        if len(names) != 1:
            raise argparse.ArgumentTypeError(f"{name!r} in {text!r}: expected one axis name")
        return names[0]

    name, eq, vals = parts[0].partition("=")
    axis, sub = one(name), {}
    if eq:
        sub[axis] = _floats(vals)
    for part in parts[1:]:
        name, eq, vals = part.partition("=")
        if not eq:
            raise argparse.ArgumentTypeError(f"{part!r} in {text!r}: expected GRID-AXIS=V1,V2,..")
        grid_axis = one(name)
        if grid_axis in sub:
            raise argparse.ArgumentTypeError(f"{text!r}: {name} given twice")
        sub[grid_axis] = _floats(vals)
    return axis, sub


def _cache_opt(q) -> None:
    q.add_argument("--cache-dir", metavar="DIR", help="tables cache folder (default: "
                   "$MILLFMU_CACHE_DIR, else $XDG_CACHE_HOME/millfmu/tables, else "
                   "~/.cache/millfmu/tables)")


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``tables`` command group to an argparse subparsers object."""
    p = subparsers.add_parser("tables", help="stress-energy lookup tables: build, status, "
                              "verify, check, clear", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="tables_command", metavar="{build,status,verify,check,clear}")
    sub.required = True
    _register_build(sub)

    s = sub.add_parser("status", help="list cache entries: ok, stale or bad")
    _cache_opt(s)
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(func=_status)

    v = sub.add_parser("verify", help="verify cache entries, table files, the default table")
    _cache_opt(v)
    v.add_argument("paths", nargs="*", help="cache entry folders, shipped tables' names (default, coupled, "
                   "prescribed, accelerator) or PREFIX of PREFIX.npz/.json (default: every cache entry)")
    v.add_argument("--default", action="store_true", help="verify the shipped default table")
    v.set_defaults(func=_verify)

    _register_check(sub)

    c = sub.add_parser("clear", help="remove cache entries")
    _cache_opt(c)
    c.add_argument("--stale", action="store_true", help="remove only stale and bad entries")
    c.set_defaults(func=_clear)
    return p


def _register_build(sub) -> None:
    b = sub.add_parser("build", help="build (or find) the table of a DEM scene and grid")
    b.add_argument("--scene", default="disc_slice",
                   help="shipped DEM scene name or a .toml path (default disc_slice)")
    for opt, (axis, h) in GRID_OPTIONS.items():
        b.add_argument(opt, type=_floats, dest=f"grid_{axis}", metavar="V1,V2,..",
                       help=f"grid of {h} (default: the scene's value only)")
    for opt, (sec, key, h) in RUN_OPTIONS.items():
        b.add_argument(opt, type=float, dest=f"run_{sec}_{key}", metavar="X", help=h)
    b.add_argument("--one-at-a-time", type=_axis_names, metavar="OPT1,OPT2,..",
                   help="axes (e.g. bead-diameter,bead-density) varied one at a time from the "
                        "scene's operating point instead of over the whole grid; their values "
                        "must include the scene's")
    b.add_argument("--across", type=_across, action="append", metavar="AXIS[=V1,..]:GRID-AXIS=V1,V2,..",
                   help="run a one-at-a-time axis at each of its values across a sub-grid of grid "
                        "axes, where its effect depends on them, e.g. "
                        "bead-density:tip-speed=6,10,14:filling=0.5,0.8,0.9 (repeatable); "
                        "AXIS=V1,V2 runs only those of its values across (consecutive ones, the "
                        "scene's among them), the others at the anchor alone")
    b.add_argument("--no-gravity", action="store_true", help="switch gravity off")
    b.add_argument("--fluid", choices=("coupled", "prescribed", "none"),
                   help="fluid model of the DEM runs (default: the scene's [fluid] mode; "
                        "disc_slice: coupled)")
    _cache_opt(b)
    b.add_argument("--executor", choices=("processes", "dask", "serial"), default="processes",
                   help="where grid points run: a local process pool (default), a Dask "
                        "LocalCluster on 127.0.0.1, or one after the other")
    b.add_argument("--workers", type=int, help="parallel grid points (default: all cores)")
    b.add_argument("--scheduler", metavar="ADDRESS",
                   help="submit grid points to an existing Dask distributed scheduler, "
                        "e.g. tcp://host:8786 (needs dask and distributed)")
    b.add_argument("--threads", type=_threads, help="numba threads per DEM run (default: 1 when "
                   "grid points run in parallel, all cores when serial)")
    b.add_argument("--force", action="store_true", help="rebuild even a good cache entry")
    b.add_argument("--warm", action="store_true",
                   help="start each point to run warm from the nearest settled state of a point "
                        "with the same beads stored when the build starts (or shipped), within "
                        "the range warm starts were measured in, with a 0.2 s spin-up "
                        "(docs/tables.md, warm starts); each point's start is recorded in the "
                        "manifest (point_starts). Default: every point cold, from a fresh bed "
                        "with the scene's spin-up, as the shipped tables are built")
    b.add_argument("--export", metavar="PREFIX", help="also write PREFIX.npz and "
                   "PREFIX.json (e.g. millfmu/data/coupled_table)")
    b.add_argument("--builder", metavar="MODULE:NAME", help="builder callable instead of "
                   "the DEM: NAME(scene_dict, point) -> fields (alternative simulators)")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    b.set_defaults(func=_build)


def _register_check(sub) -> None:
    k = sub.add_parser("check", help="run the DEM at one point and compare the table's "
                       "lookup there with it (interpolation; one-at-a-time separability)")
    k.add_argument("table", help="a shipped table's name (default, coupled, accelerator) or "
                   "PREFIX of PREFIX.npz/PREFIX.json")
    for opt, (axis, h) in GRID_OPTIONS.items():
        k.add_argument(opt, type=float, dest=f"at_{axis}", metavar="X",
                       help=f"{axis} at the point (default: the table scene's value; for a "
                            f"one-at-a-time axis its reference)")
    k.add_argument("--threads", type=_threads, help="numba threads of the DEM run (default: all "
                   "cores)")
    k.add_argument("--builder", metavar="MODULE:NAME", help="builder callable instead of "
                   "the DEM (the one the table was built with)")
    k.add_argument("--write", action="store_true", help="record the result in the table's "
                   "manifest (separability_check or interpolation_check) and write the "
                   "table's files again")
    k.add_argument("--from", dest="from_manifest", metavar="MANIFEST.json",
                   help="instead of running the DEM, compare the table with the runs of the "
                        "checks recorded in another manifest of the same scene and settings "
                        "(e.g. the table's manifest before a rebuild or refinement)")
    k.set_defaults(func=_check)


def _threads(text: str) -> int:
    """--threads: 1 to the threads numba may start (:func:`millfmu.dem.cli.thread_count`)."""
    from millfmu.dem.cli import thread_count

    return thread_count(text)


def _load_builder(text: str | None, threads):
    from millfmu.dem.analysis.precision import manifest_entry
    from millfmu.dem.tables.dem_builder import DemBuilder
    from millfmu.stress_tables.spec import TableError

    if not text:
        return DemBuilder(threads=threads, work_precision=manifest_entry)
    mod, _, name = text.partition(":")
    try:
        return getattr(importlib.import_module(mod), name)
    except (ImportError, AttributeError, ValueError) as e:
        raise TableError(f"--builder {text!r}: cannot be loaded ({e}); give MODULE:NAME") \
            from None


def _warm(builder):
    """``--warm``: the DEM builder starting its points warm (:mod:`millfmu.dem.tables.warm_start`);
    refused by name for another builder, which keeps no settled states."""
    from dataclasses import replace

    from millfmu.dem.tables.dem_builder import DemBuilder
    from millfmu.dem.tables.warm_start import WARM_SPIN_UP_S
    from millfmu.stress_tables.spec import TableError

    if not isinstance(builder, DemBuilder):
        raise TableError(f"--warm: the builder {getattr(builder, '__name__', type(builder).__name__)} keeps no "
                         f"settled states; allowed with the DEM's builder (no --builder) only")
    return replace(builder, warm_spin_up_s=WARM_SPIN_UP_S)


def _build(args) -> int:
    from millfmu.dem import tables as T
    from millfmu.dem.scene import DemSceneError

    grid = {axis: getattr(args, f"grid_{axis}") for _, (axis, _) in GRID_OPTIONS.items()
            if getattr(args, f"grid_{axis}") is not None}
    oat = {}
    for axis in args.one_at_a_time or ():
        if axis not in grid:
            opt = next(o for o, (a, _) in GRID_OPTIONS.items() if a == axis)
            print(f"millfmu tables build: --one-at-a-time {axis}: give its values with {opt}",
                  file=sys.stderr)
            return 2
        oat[axis] = grid.pop(axis)
    over: dict = {}
    for _, (sec, key, _) in RUN_OPTIONS.items():
        v = getattr(args, f"run_{sec}_{key}")
        if v is not None:
            over.setdefault(sec, {})[key] = v
    if args.no_gravity:
        over.setdefault("run", {})["gravity_m_per_s2"] = [0.0, 0.0, 0.0]
    if args.fluid:
        over.setdefault("fluid", {})["mode"] = args.fluid
    try:
        if not grid:
            raise T.TableError(("no grid given: " if not oat else "--one-at-a-time needs a "
                                "grid axis besides: ") + "name at least one of " +
                               ", ".join(GRID_OPTIONS))
        parallel = args.executor != "serial" or args.scheduler
        threads = args.threads if args.threads is not None else (1 if parallel else None)
        builder = _load_builder(args.builder, threads)
        if args.warm:
            builder = _warm(builder)
        across = dict(args.across or ())
        twice = sorted({a for a, _ in args.across or () if [b for b, _ in args.across].count(a) > 1})
        if twice:
            raise T.TableError(f"--across {', '.join(twice)}: given more than once; give each axis's "
                               f"sub-grid in one --across")
        spec = T.dem_spec(args.scene, grid, over, one_at_a_time=oat, across=across)
        if args.builder:
            spec = dataclasses.replace(spec, builder_id=T.builder_id_of(builder))
        table = T.get_table(spec, builder, cache_dir=args.cache_dir, force=args.force,
                            log=_to_stderr, executor=args.executor, workers=args.workers,
                            scheduler=args.scheduler, progress=not args.no_progress)
    except (T.TableError, DemSceneError) as e:
        print(f"millfmu tables build: {e}", file=sys.stderr)
        return 2
    entry = T.entry_dir(spec, args.cache_dir)
    m = table.manifest
    def across_text(k):
        sub = spec.across.get(k, {})
        n = math.prod(len(x) for a, x in sub.items() if a != k)
        return "" if not sub else (f", {len(sub[k])} of them across {n} grid points" if k in sub
                                   else f" across {n} grid points")

    extra = "".join(f" + {len(v)} {k} values one at a time{across_text(k)}" for k, v in oat.items())
    print(f"table {spec.key()} ({' x '.join(map(str, spec.shape))} points{extra}, "
          f"{(entry / T.TABLE_FILE).stat().st_size} bytes): {entry}")
    if m.get("build_wall_time_s"):
        print(f"build wall time {m['build_wall_time_s']:.1f} s")
    if "points_run" in m:
        cost = (f"; the points took {m['points_wall_time_s']:.0f} s where they ran"
                if m.get("points_wall_time_s") is not None else "")
        print(f"points: {m['points_run']} run, {m['points_reused']} reused from the cache"
              f"{cost}")
    starts = m.get("point_starts")
    if starts:
        cold = len(starts["points"]) - starts["warm"]
        print(f"point starts: {starts['warm']} warm, {cold} cold (manifest point_starts)")
    if args.export:
        table.manifest = dict(table.manifest, resolution=T.resolution_of(spec),
                              rebuild_command=_command(args))
        npz, man = table.export(args.export)
        print(f"exported {npz} ({npz.stat().st_size} bytes), {man}")
    return 0


def _command(args) -> str:
    """The ``millfmu tables build`` command that rebuilds this table (grid, scene and run
    settings; not the executor, which does not change the result)."""
    cmd = ["millfmu", "tables", "build", "--scene", args.scene]
    for opt, (axis, _) in GRID_OPTIONS.items():
        v = getattr(args, f"grid_{axis}")
        if v is not None:
            cmd += [opt, ",".join(f"{x:g}" for x in v)]
    if args.one_at_a_time:
        by_axis = {axis: opt[2:] for opt, (axis, _) in GRID_OPTIONS.items()}
        cmd += ["--one-at-a-time", ",".join(by_axis[a] for a in args.one_at_a_time)]
        for axis, sub in args.across or ():
            own = f"={','.join(f'{x:g}' for x in sub[axis])}" if axis in sub else ""
            cmd += ["--across", ":".join([by_axis[axis] + own] + [
                f"{by_axis[a]}={','.join(f'{x:g}' for x in v)}" for a, v in sub.items() if a != axis])]
    for opt, (sec, key, _) in RUN_OPTIONS.items():
        v = getattr(args, f"run_{sec}_{key}")
        if v is not None:
            cmd += [opt, f"{v:g}"]
    if args.no_gravity:
        cmd.append("--no-gravity")
    if args.fluid:
        cmd += ["--fluid", args.fluid]
    if args.builder:
        cmd += ["--builder", args.builder]
    if getattr(args, "warm", False):
        cmd.append("--warm")
    if args.export:
        cmd += ["--export", str(args.export)]
    return shlex.join(cmd)


def _status(args) -> int:
    from millfmu.dem import tables as T

    try:
        entries = T.cache_entries(args.cache_dir)
    except T.TableError as e:
        print(f"millfmu tables status: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(entries, indent=1))
        return 0
    root = T.resolve_cache_dir(args.cache_dir)
    print(f"cache {root}: {len(entries)} entries")
    for e in entries:
        shape = "x".join(map(str, e.get("shape", []))) or "?"
        print(f"  {e['key'][:16]}  {e['state']:5s}  {e.get('scene', '?'):12s} "
              f"{shape:>8s}  {e['bytes']:>9d} B  {e['reason']}")
    _points_status(root / T.POINTS_DIR, T.dem_kernel_version())
    return 0


def _points_status(folder: Path, kernel_version: str) -> None:
    """The point store's finished points, and those a build runs now or left stopped with a
    checkpoint (each with the command that shows how far it is)."""
    from .point_work import running_points

    stored = sorted(folder.glob("*.json")) if folder.is_dir() else []
    mine = 0
    for f in stored:
        try:
            mine += json.loads(f.read_text())["key_content"]["kernel_version"] == kernel_version
        except (OSError, ValueError, KeyError, TypeError):
            pass
    run = running_points(folder)
    if not stored and not run:
        return
    print(f"points {folder}: {len(stored)} finished ({mine} of the installed DEM version)")
    for r in run:
        v = r["values"]
        what = ("?" if v is None else f"{v['tip_speed_m_per_s']:g} m/s, filling {v['filling']:g}, beads "
                f"{v['bead_diameter_m'] * 1e3:g} mm {v['bead_density_kg_per_m3']:g} kg/m3")
        age = r["checkpoint_age_s"]
        state = ("running" if r["running"] else "stopped") + (
            f", checkpoint {age / 60:.0f} min ago" if age is not None else ", no checkpoint yet")
        other = "" if r["kernel_version"] in (None, kernel_version) else " (another DEM version: tables clear --stale)"
        print(f"  {what}: {state}{other}")
        if age is not None:
            print(f"    millfmu dem progress {r['path']}")


def _verify(args) -> int:
    from millfmu.dem import tables as T

    bad = 0
    checked = 0
    targets = list(args.paths)
    if args.default:
        try:
            t = T.read_default_table()
            older = "" if t.manifest["kernel_version"] == T.dem_kernel_version() else " (older than the installed DEM)"
            print(f"default table: ok ({' x '.join(map(str, t.shape))} points, scene "
                  f"{t.manifest['scene'].get('name')}, kernel {t.manifest['kernel_version'][:19]}{older})")
        except T.TableError as e:
            print(f"default table: BAD: {e}")
            bad += 1
        checked += 1
    if not targets and not args.default:
        try:
            entries = T.cache_entries(args.cache_dir)
        except T.TableError as e:
            print(f"millfmu tables verify: {e}", file=sys.stderr)
            return 2
        for e in entries:
            print(f"{e['key'][:16]}: {e['state']} {e['reason']}")
            bad += e["state"] == "bad"
            checked += 1
    for p in targets:
        try:
            if Path(p).is_dir():
                T.read_table(p)
            else:  # a shipped table's name (default, coupled, ...) or PREFIX
                npz, man = T.table_ref_files(p)
                T.read_table(npz=npz, manifest_path=man)
            print(f"{p}: ok")
        except T.TableError as e:
            print(f"{p}: BAD: {e}")
            bad += 1
        checked += 1
    print(f"{checked} checked, {bad} bad")
    return 1 if bad else 0


def _check(args) -> int:
    from millfmu.dem import tables as T
    from millfmu.dem.scene import DemSceneError
    from millfmu.dem.tables.build import check_point

    point = {axis: getattr(args, f"at_{axis}") for _, (axis, _) in GRID_OPTIONS.items()
             if getattr(args, f"at_{axis}") is not None}
    if args.from_manifest:
        if point or args.builder:
            print("millfmu tables check: --from compares recorded runs; give no point and no "
                  "--builder with it", file=sys.stderr)
            return 2
        return _recheck(args)
    try:
        table = T.read_table_ref(args.table)
        builder = _load_builder(args.builder, args.threads)
        res = check_point(table, point, builder)
    except (T.TableError, DemSceneError) as e:
        print(f"millfmu tables check: {e}", file=sys.stderr)
        return 2
    _print_check(args.table, res)
    if args.write:
        _record(args.table, [res])
    return 0


def _record(name: str, results: list) -> None:
    """Record check results in the manifest of table ``name`` and write its files again."""
    from millfmu.dem import tables as T
    from millfmu.dem.tables.build import record_check

    # read again: another check may have recorded its point while this one ran
    table = T.read_table_ref(name)
    for res in results:
        table.manifest = record_check(table, res)
    npz, man = table.export(T.table_ref_prefix(name))
    print(f"recorded {len(results)} checks in {man}" if len(results) > 1 else
          f"recorded in {man}")


def _recheck(args) -> int:
    """``tables check TABLE --from OLD.json``: the checks recorded in OLD.json compared with
    TABLE's lookup, without running the DEM (:func:`~millfmu.dem.tables.build.recheck`)."""
    from millfmu.dem import tables as T
    from millfmu.dem.tables.build import recheck

    try:
        old = json.loads(Path(args.from_manifest).read_text())
        table = T.read_table_ref(args.table)
    except (OSError, ValueError, T.TableError) as e:
        why = f"cannot be read ({e.strerror})" if isinstance(e, OSError) and e.strerror else \
            f"not a manifest (JSON: {e})" if isinstance(e, ValueError) and not isinstance(e, T.TableError) else str(e)
        print(f"millfmu tables check: --from {args.from_manifest}: {why}", file=sys.stderr)
        return 2
    if not isinstance(old, dict) or old.get("scene") != table.manifest.get("scene"):
        print(f"millfmu tables check: --from {args.from_manifest}: its scene and run settings "
              f"are not the table's, so its runs are no samples of it", file=sys.stderr)
        return 2
    results = []
    for key in ("interpolation_check", "separability_check"):
        for res in (old.get(key) or {}).get("points", []):
            try:
                results.append(recheck(table, res, old.get("kernel_version")))
            except T.TableError as e:  # OutsideGridError is one
                print(f"skipped the {key.split('_')[0]} check at {res.get('point')}: {e}")
    if not results:
        print(f"millfmu tables check: --from {args.from_manifest}: no recorded check lies "
              f"within the table", file=sys.stderr)
        return 2
    for res in results:
        _print_check(args.table, res)
    if args.write:
        _record(args.table, results)
    return 0


def _print_check(name: str, res: dict) -> None:
    from millfmu.dem import tables as T

    run = (f"run {res['wall_time_s']:.0f} s" if res.get("wall_time_s") is not None else "run")
    if res.get("run_from"):
        run += ", recorded by an earlier table's check"
    print(f"table {name} at {res['point']} ({run}): relative "
          f"difference of the lookup [and of the grid alone] against the run")
    print(f"  {'quantity':26s} " + " ".join(f"{z:>22s}" for z in res["zones"]))

    def fmt(x):
        return "-" if x is None else f"{x:+.3f}"

    for k in T.CHECK_FIELDS:
        e = res[k]
        cells = [f"{fmt(a)} [{fmt(b)}]" if "grid_only_rel_diff" in e else fmt(a)
                 for a, b in zip(e["lookup_rel_diff"],
                                 e.get("grid_only_rel_diff", e["lookup_rel_diff"]))]
        print(f"  {k:26s} " + " ".join(f"{c:>22s}" for c in cells))


def _clear(args) -> int:
    from millfmu.dem import tables as T

    try:
        removed = T.clear_cache(args.cache_dir, only_not_ok=args.stale)
    except T.TableError as e:
        print(f"millfmu tables clear: {e}", file=sys.stderr)
        return 2
    print(f"removed {len(removed)} entries from {T.resolve_cache_dir(args.cache_dir)}")
    return 0


def main(argv=None) -> int:
    """Run ``tables`` subcommands on their own (``python -m millfmu.dem.tables.cli``)."""
    ap = argparse.ArgumentParser(prog="millfmu")
    register(ap.add_subparsers(dest="command"))
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
