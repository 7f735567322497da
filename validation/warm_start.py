"""How short a warm start's spin-up may be: a new point of the coupled table started from the
settled state of the table's anchor (:mod:`millfmu.dem.tables.warm_start`) against the same
point started cold, relative to the table's stated error there.

    python -m validation.warm_start run --out DIR      # the runs (resumable: done runs are kept)
    python -m validation.warm_start table --out DIR    # the comparison and the wall-time ratios
    python -m validation.warm_start run --out DIR --spin-ups 0.8 --one-thread-spin-up 0 --cold-seeds 2,3
    python -m validation.warm_start run --out DIR --anchor-density 6040 --spin-ups 0.2,0.4 --one-thread-spin-up 0
    python -m validation.warm_start run --out DIR12 --tip-speed 12 --bead-density 2510 --spin-ups 0.2 \
        --one-thread-spin-up 0

The runs, each through the table builder (:class:`~millfmu.dem.tables.dem_builder.DemBuilder`,
the table's scene and settings): the anchor (0.8 mm glass, 10 m/s, 80 %) cold, its settled
state kept; the new point (by default steel beads, 7,800 kg/m3, at the anchor's speed and
filling) cold on 2 and on 1 thread (two realizations: the thread count splits the beads
into as many chunks), and warm from the anchor's state with each spin-up of ``--spin-ups``
on 2 threads and with ``--one-thread-spin-up`` on 1. Wall times are compared as ratios to
the cold run on as many threads, measured in the same session (a shared machine's load
changes the seconds, less their ratio).

Per zone the table prints the relative difference of each run from the cold run on 2
threads for the collision frequency, the collision power, the median SE_tn and the local
filling, beside the table's stated error at the point (:meth:`~millfmu.stress_tables.
stress_source.TableStressSource.relative_error` of the coupled table extended by the cold
run, carrying the shipped table's realization spread and checks; for the collision power and
the filling, which the model states no error for, the lookup's 2 sigma and the
work-precision expected error), the cold realizations' spread (those run, and the shipped
table's run where the point is one of its nodes) and a summary: each run's largest
difference from the cold realizations' mean over the stated error. Each run's result, its
wall time, its stepping time and the machine's load are kept in ``DIR/runs/NAME.json``, the
comparison in ``DIR/warm_start.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ZONES = ("V1", "V2", "V3", "V4")
QUANTITIES = ("collision_frequency", "collision_power", "se_median", "filling")


def _plain(obj):
    from millfmu.dem.tables.build import _plain as p

    return p(obj)


def _table():
    from millfmu.stress_tables.table import read_table_ref

    return read_table_ref("coupled")


def _points(density: float, tip_speed: float) -> tuple[dict, dict]:
    t = _table()
    anchor = {**t.spec().anchor(), **{k: float(v) for k, v in t.one_at_a_time_ref.items()}}
    new = dict(anchor, bead_density_kg_per_m3=float(density), tip_speed_m_per_s=float(tip_speed))
    return anchor, new


def _run(out: Path, name: str, point: dict, threads: int, seed: int | None = None, **builder_kw) -> dict:
    """One point through the DEM builder, its result kept in ``out/runs/name.json`` (a run
    already there is not run again); ``seed``: the scene's bed placement seed instead of its
    own (another cold realization)."""
    from millfmu.dem.tables.dem_builder import DemBuilder

    path = out / "runs" / f"{name}.json"
    if path.exists():
        return json.loads(path.read_text())
    t = _table()
    b = DemBuilder(threads=threads, **builder_kw)
    print(f"{time.strftime('%H:%M:%S')} run {name}: {point}, {threads} thread(s)", file=sys.stderr, flush=True)
    scene = t.spec().scene
    if seed is not None:
        scene = json.loads(json.dumps(scene))
        scene["run"]["seed"] = int(seed)
    # the run's own stepping time beside the builder's wall time (set-up, statistics and
    # outputs the rest)
    import millfmu.dem.run as R

    plain, timing = R.run_scene, {}

    def timed(*a, **k):
        t0 = time.perf_counter()
        st = plain(*a, **k)
        timing.update(run_scene_s=time.perf_counter() - t0, stepping_s=float(st.counts["wall_time_s"]))
        return st

    R.run_scene = timed
    try:
        r = b(scene, point)
    finally:
        R.run_scene = plain
    rec = dict(timing=timing, name=name, point=point, threads=threads, seed=seed, result=_plain(r),
               load_average=os.getloadavg())
    states = [p for p in Path(builder_kw.get("state_dir") or out / "none").glob("*.state.npz")
              if p.name not in builder_kw.get("warm_from", ())]
    if states:
        rec["state_bytes"] = max(p.stat().st_size for p in states)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rec, indent=1))
    print(f"{time.strftime('%H:%M:%S')} {name}: {r['wall_time_s']:.0f} s", file=sys.stderr, flush=True)
    return rec


def run(out: Path, density: float, tip_speed: float, spin_ups, one_thread_spin_up: float | None,
        anchor_density: float | None = None, cold_seeds=()) -> None:
    """The runs into ``out/runs`` (module docstring). ``anchor_density``: start the warm runs
    from a cold run of the anchor with this bead density instead of the table's (run names
    ``anchor<density>_cold_2t`` and ``warm_from<density>_<spin-up>_2t``); ``one_thread_spin_up``
    None: no runs on 1 thread."""
    anchor, new = _points(density, tip_speed)
    tag = ""
    if anchor_density is not None and anchor_density != anchor["bead_density_kg_per_m3"]:
        anchor = dict(anchor, bead_density_kg_per_m3=float(anchor_density))
        tag = f"{anchor_density:g}"
    anchor_states = out / "states" / f"anchor{tag}"
    _run(out, f"anchor{tag}_cold_2t", anchor, 2, state_dir=str(anchor_states))
    names = tuple(sorted(p.name for p in anchor_states.glob("*.state.npz")))
    if len(names) != 1:
        raise SystemExit(f"{anchor_states}: expected the anchor's state, found {names}")
    _run(out, "cold_2t", new, 2, state_dir=str(out / "states" / "cold_2t"))

    def warm(su, threads):
        # the builder reads the states it may start from in its state_dir: the anchor's is
        # copied into a folder of the run's own, where the run keeps its state too
        name = f"warm_{'from' + tag + '_' if tag else ''}{su:g}_{threads}t"
        folder = out / "states" / name
        folder.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(anchor_states / names[0], folder / names[0])
        _run(out, name, new, threads, warm_spin_up_s=su, state_dir=str(folder), warm_from=names)

    for su in spin_ups:
        warm(su, 2)
    if one_thread_spin_up is not None:
        _run(out, "cold_1t", new, 1)
        warm(one_thread_spin_up, 1)
    for seed in cold_seeds:
        _run(out, f"cold_seed{seed}_2t", new, 2, seed=seed)


def _fields(r: dict) -> dict:
    from millfmu.stress_tables.spec import COMPONENTS, QUANTILE_NAMES

    q = np.asarray(r["se_quantiles_norm"], float)
    return {"collision_frequency": np.asarray(r["collision_frequency_norm"], float),
            "collision_power": np.asarray(r["collision_power_norm"], float),
            "se_median": q[COMPONENTS.index("tn"), :, QUANTILE_NAMES.index("q50")],
            "filling": np.asarray(r["filling_local"], float)}


def stated_error(cold_result: dict, point: dict) -> dict:
    """The stated relative error per zone at ``point`` of the coupled table extended by the
    cold run there (the shipped manifest's realization spread, checks and work-precision
    entry carried over): collision frequency and median SE_tn as the model states them;
    for the collision power and the local filling, which the model states no error for, the
    lookup's bound (2 sigma) plus the work-precision expected error."""
    from millfmu.dem.tables.build import assemble, unstack
    from millfmu.dem.tables.on_demand import extended_axes
    from millfmu.stress_tables.spec import TableSpec
    from millfmu.stress_tables.stress_source import TableStressSource

    t = _table()
    old = t.spec()
    grid, oat = extended_axes(old, point)
    spec = TableSpec(scene=old.scene, grid=grid, kernel_version=old.kernel_version,
                     builder_id=old.builder_id, one_at_a_time=oat)
    have = {json.dumps(p, sort_keys=True): r for p, r in unstack(old, t)}
    res = [have.get(json.dumps(p, sort_keys=True), cold_result) for p in spec.points()]
    ext = assemble(spec, res)
    ext.manifest = {**{k: t.manifest[k] for k in ("scene", "work_precision", "realization_spread",
                                                  "interpolation_check", "separability_check")
                       if k in t.manifest}}
    lk = ext.lookup(point)
    b = TableStressSource(ext).relative_error(lk)
    wp = ((t.manifest.get("work_precision") or {}).get("choice") or {}).get("expected_error") or {}

    def other(field, wp_key):
        v = np.abs(np.asarray(lk.values[field], float))
        return lk.bound(field) / v + np.array([float((wp.get(wp_key) or {}).get(z, 0.0)) for z in ZONES])

    return {"collision_frequency": np.asarray(b["collision_frequency"], float),
            "se_median": np.asarray(b["se_median"], float),
            "collision_power": other("collision_power_norm", "collision_power"),
            "filling": other("filling_local", "filling")}


def _table_node(point: dict) -> dict | None:
    """The shipped table's fields at ``point`` where it is one of its points, else None."""
    t = _table()
    if t._node_of(point) is None:
        return None
    return _fields(t.lookup(point).values)


def _rel(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(b) > 0, (a - b) / b, np.nan)


def table(out: Path) -> dict:
    runs = {p.stem: json.loads(p.read_text()) for p in sorted((out / "runs").glob("*.json"))}
    cold = runs.get("cold_2t")
    if cold is None:
        raise SystemExit(f"{out}: no cold_2t run yet (python -m validation.warm_start run --out {out})")
    ref = _fields(cold["result"])
    b = stated_error(cold["result"], cold["point"])
    rows = {}
    for name, r in runs.items():
        if name.startswith("anchor"):
            continue
        f = _fields(r["result"])
        rel = {q: _rel(f[q], ref[q]) for q in QUANTITIES}
        rows[name] = {"threads": r["threads"], "start": r["result"].get("start"),
                      "wall_time_s": r["result"]["wall_time_s"],
                      "rel_diff": {q: [None if not math.isfinite(x) else round(float(x), 4) for x in rel[q]]
                                   for q in QUANTITIES},
                      "over_stated": max(float(np.nanmax(np.abs(rel[q]) / b[q])) for q in QUANTITIES),
                      "over_stated_cf_se": max(float(np.nanmax(np.abs(rel[q]) / b[q]))
                                               for q in ("collision_frequency", "se_median")),
                      "state_bytes": r.get("state_bytes")}
    # the cold realizations: their mean and standard deviation per zone, and each run's
    # difference from that mean in units of it
    colds = [_fields(r["result"]) for n, r in runs.items() if n.startswith("cold")]
    node = _table_node(cold["point"])
    if node is not None:
        colds.append(node)
    spread = None
    if len(colds) >= 2:
        mean = {q: np.mean([c[q] for c in colds], axis=0) for q in QUANTITIES}
        sd = {q: np.std([c[q] for c in colds], axis=0, ddof=1) for q in QUANTITIES}
        spread = {"realizations": len(colds),
                  "relative_sd": {q: [round(float(x), 4) for x in np.abs(sd[q] / mean[q])] for q in QUANTITIES}}
        for name, r in runs.items():
            if name in rows:
                f = _fields(r["result"])
                rel_m = {q: _rel(f[q], mean[q]) for q in QUANTITIES}
                rows[name]["rel_diff_from_cold_mean"] = {
                    q: [None if not math.isfinite(x) else round(float(x), 4) for x in rel_m[q]] for q in QUANTITIES}
                rows[name]["over_stated_from_cold_mean_cf_se"] = max(
                    float(np.nanmax(np.abs(rel_m[q]) / b[q])) for q in ("collision_frequency", "se_median"))
                with np.errstate(divide="ignore", invalid="ignore"):
                    z = {q: (f[q] - mean[q]) / sd[q] for q in QUANTITIES}
                rows[name]["from_cold_mean_over_sd"] = {q: [None if not math.isfinite(x) else round(float(x), 2)
                                                            for x in z[q]] for q in QUANTITIES}
    if node is not None:
        rel = {q: _rel(node[q], ref[q]) for q in QUANTITIES}
        rows["table_node"] = {"threads": None, "start": {"start": "cold (the shipped table's run)", "spin_up_s": 1.5},
                              "wall_time_s": None,
                              "rel_diff": {q: [None if not math.isfinite(x) else round(float(x), 4) for x in rel[q]]
                                           for q in QUANTITIES},
                              "over_stated": max(float(np.nanmax(np.abs(rel[q]) / b[q])) for q in QUANTITIES),
                              "over_stated_cf_se": max(float(np.nanmax(np.abs(rel[q]) / b[q]))
                                                       for q in ("collision_frequency", "se_median"))}
    walls = {n: r["result"]["wall_time_s"] for n, r in runs.items()}
    ratios = {}
    for n, w in walls.items():
        th = runs[n]["threads"]
        base = walls.get(f"cold_{th}t")
        if base:
            ratios[n] = round(w / base, 3)
    res = {"point": cold["point"],
           "stated_error": {q: [round(float(x), 4) for x in b[q]] for q in QUANTITIES},
           "cold_realizations": spread,
           "runs": rows, "wall_time_s": {n: round(w, 1) for n, w in walls.items()},
           "wall_ratio_to_cold_same_threads": ratios}
    (out / "warm_start.json").write_text(json.dumps(res, indent=1))
    _print(res)
    return res


def _print(res: dict) -> None:
    print(f"point {res['point']}")
    print("stated error at the point (relative, V1/V2/V3/V4):")
    for q in QUANTITIES:
        print(f"  {q:20s} " + " / ".join(f"{x:.1%}" for x in res["stated_error"][q]))
    cr = res.get("cold_realizations")
    if cr:
        print(f"relative standard deviation of the {cr['realizations']} cold realizations (V1/V2/V3/V4):")
        for q in QUANTITIES:
            print(f"  {q:20s} " + " / ".join("-" if x is None else f"{x:.1%}" for x in cr["relative_sd"][q]))
    print("relative difference from the cold run on 2 threads (V1/V2/V3/V4), largest |diff| / stated;"
          " in [ ]: from the mean of the cold realizations over their standard deviation:")
    for name, r in res["runs"].items():
        st = r["start"] or {}
        frm = f" from {st['from']}" if st.get("from") else ""
        print(f"{name} ({st.get('start')}{frm}, spin-up {st.get('spin_up_s')} s, {r['threads']} thread(s)): "
              f"largest |diff| / stated {r['over_stated']:.2f} (collision frequency and median SE_tn: "
              f"{r['over_stated_cf_se']:.2f})")
        for q in QUANTITIES:
            z = (r.get("from_cold_mean_over_sd") or {}).get(q)
            zs = ("   [" + " / ".join("-" if x is None else f"{x:+.1f}" for x in z) + "]") if z else ""
            print(f"  {q:20s} " + " / ".join("-" if x is None else f"{x:+.1%}" for x in r["rel_diff"][q]) + zs)
    if cr:
        print(f"summary: largest |difference| from the mean of the {cr['realizations']} cold realizations over the "
              "stated error (collision frequency, median SE_tn), and the local filling's difference (V1/V2/V3/V4):")
        for name, r in res["runs"].items():
            if "over_stated_from_cold_mean_cf_se" in r:
                fill = " / ".join("-" if x is None else f"{x:+.1%}" for x in r["rel_diff_from_cold_mean"]["filling"])
                print(f"  {name:24s} {r['over_stated_from_cold_mean_cf_se']:.2f}   filling {fill}")
    print("wall times [s]: " + ", ".join(f"{n} {w:.0f}" for n, w in res["wall_time_s"].items()))
    print("ratio to the cold run on as many threads: " +
          ", ".join(f"{n} {x:.2f}" for n, x in res["wall_ratio_to_cold_same_threads"].items()))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.warm_start", description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=("run", "table"))
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--bead-density", type=float, default=7800.0, help="the new point's bead density [kg/m3]")
    p.add_argument("--tip-speed", type=float, default=10.0, help="the new point's tip speed [m/s]")
    p.add_argument("--spin-ups", default="0.1,0.2,0.4", help="warm spin-ups [s] run on 2 threads")
    p.add_argument("--one-thread-spin-up", type=float, default=0.2,
                   help="the warm spin-up [s] run on 1 thread, beside a cold run on 1 thread (0: neither)")
    p.add_argument("--cold-seeds", default="", help="further cold realizations on 2 threads, each from a bed "
                   "placed with one of these seeds (the scene's is 1)")
    p.add_argument("--anchor-density", type=float, default=None,
                   help="start the warm runs from the anchor point with this bead density [kg/m3], run cold "
                        "first (default: the table's anchor, 2,510 kg/m3)")
    a = p.parse_args(argv)
    if a.what == "run":
        run(a.out, a.bead_density, a.tip_speed, [float(x) for x in a.spin_ups.split(",") if x],
            a.one_thread_spin_up or None, a.anchor_density, [int(x) for x in a.cold_seeds.split(",") if x])
    table(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
