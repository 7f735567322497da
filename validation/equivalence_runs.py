"""The runs behind :mod:`millfmu.dem.tables.equivalence`: the table's scene at the
work-precision operating point, once per thread count, with the installed DEM sources, as
reference realizations of the table's version or as a change judged against them.

Kept apart from :mod:`millfmu.dem.tables.equivalence`, which the cache reads for the kernel
version and which therefore imports neither the cache nor the DEM: these runs need both.
They are run from a checkout's root when the DEM's sources change (the installed package
only reads the evidence they write):

    python -m validation.equivalence_runs --reference --write   # the table's own sources
    python -m validation.equivalence_runs --threads 1 2 --change "fused multiply-adds" --write
    python -m validation.equivalence_runs --show
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from millfmu.dem.tables import equivalence as E
from millfmu.dem.tables.equivalence import (GATED, WORK_PRECISION_PATH, Z_LIMIT, EquivalenceError,
                                            read_evidence, rejudge, sampling_sigma)
from millfmu.machine import machine


def _plain(fields: dict) -> dict:
    """Check fields (:func:`millfmu.dem.tables.build._check_fields`) as JSON lists, None where not finite."""
    return {k: [float(x) if math.isfinite(float(x)) else None for x in v]
            for k, v in fields.items()}


def _run_one(scene: dict, point: dict, threads: int) -> dict:
    # a process of its own (spawned): each run sets its numba thread count, which numba
    # caps at NUMBA_NUM_THREADS (default: the cores), read when numba is first imported,
    # here below: a realization on more threads than cores is still another realization
    if int(os.environ.get("NUMBA_NUM_THREADS") or 0) < threads:
        os.environ["NUMBA_NUM_THREADS"] = str(max(threads, os.cpu_count() or 1))
    from millfmu.dem.tables.build import _check_fields
    from millfmu.dem.tables.cache import kernel_source_hash
    from millfmu.dem.tables.dem_builder import DemBuilder

    r = DemBuilder(threads=threads)(scene, point)
    return dict(threads=threads, source_hash=kernel_source_hash(),
                wall_time_s=round(float(r["wall_time_s"]), 1), values=_plain(_check_fields(r)))


def operating_point(table, summary: dict) -> dict:
    """The work-precision study's operating point as a full point of ``table`` (grid axes
    tip speed and filling; one-at-a-time axes at their references)."""
    from millfmu.dem.tables.build import _full_point

    op = summary.get("operating_point") or {}
    name = (table.manifest.get("scene") or {}).get("name")
    if op.get("scene") != name:
        raise EquivalenceError(f"the work-precision study is of scene {op.get('scene')!r}; "
                               f"this table's scene is {name!r}, whose sampling noise was not "
                               f"measured: judge against the coupled table")
    point = {k: float(op[k]) for k in ("tip_speed_m_per_s", "filling") if k in op}
    if len(point) != 2:
        raise EquivalenceError(f"work-precision summary: operating_point {op!r} names no "
                               f"tip_speed_m_per_s and filling")
    return _full_point(table, point)


def run_equivalence(table_ref: str = "coupled", threads=(1, 2), change: str = "",
                    reference: bool = False, evidence_path=None, summary_path=None,
                    z_limit: float = Z_LIMIT, run_one=None) -> dict:
    """Run the table's scene at the work-precision operating point with the installed DEM
    sources, once per entry of ``threads`` (distinct counts, in parallel processes).

    ``reference``: the sources must be the table's kernel version (to the bit,
    :data:`millfmu.dem.tables.cache.SAME_DEM_AS`); the runs are more realizations of it (``kind``
    "reference"). Otherwise the sources must differ and the runs are judged
    (:func:`millfmu.dem.tables.equivalence.judge`) against the table's point and the recorded reference runs (``kind``
    "change", with ``judgement``). Writes nothing
    (:func:`millfmu.dem.tables.equivalence.record` does).
    ``run_one(scene, point, threads)``: instead of the DEM, in this process (tests)."""
    from millfmu.dem.tables.build import _check_fields
    from millfmu.dem.tables.cache import SAME_DEM_AS, kernel_source_hash
    from millfmu.stress_tables.table import read_table_ref

    threads = [int(t) for t in threads]
    if not threads or len(set(threads)) != len(threads) or min(threads) < 1:
        raise EquivalenceError(f"threads = {threads}: give distinct counts >= 1 (one run "
                               f"per count; a count repeated repeats its run to the bit)")
    table = read_table_ref(table_ref)
    version = table.manifest.get("kernel_version")
    sp = Path(summary_path) if summary_path is not None else WORK_PRECISION_PATH
    if not sp.is_file():
        raise EquivalenceError(f"{sp}: no work-precision study (its operating point and "
                               f"sampling law are what the runs are judged at and by)")
    summary = json.loads(sp.read_text())["summary"]
    law = summary.get("recording_law") or {}
    record_s = float(((table.manifest.get("resolution") or {}).get("dem") or {})["record_s"])
    point = operating_point(table, summary)
    h = kernel_source_hash()
    same = SAME_DEM_AS.get(h, h) == version
    if reference and not same:
        raise EquivalenceError(f"--reference: the installed DEM sources ({h[:19]}...) are "
                               f"not table {table_ref}'s kernel version ({version[:19]}...): "
                               f"reference runs need that version's sources")
    if not reference and same:
        raise EquivalenceError(f"the installed DEM sources ({h[:19]}...) are table "
                               f"{table_ref}'s kernel version to the bit: nothing to judge "
                               f"(--reference adds realizations of it)")
    ref = None
    if not reference:
        ref = read_evidence(evidence_path).get("reference")
        if ref is None:
            raise EquivalenceError("no reference runs recorded: run 'python -m "
                                   "validation.equivalence_runs --reference --write' with the "
                                   "table's own sources first (their spread is the noise a "
                                   "change is judged by)")
        if ref["kernel_version"] != version or ref["table_key"] != table.manifest.get("key"):
            raise EquivalenceError(f"the recorded reference is of table key "
                                   f"{ref['table_key']} version {ref['kernel_version']}, not "
                                   f"of table {table_ref}")
    zones = list(table.zone_names)
    scene = table.spec().scene
    if run_one is not None:
        runs = [run_one(scene, point, t) for t in threads]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        if sum(threads) > (os.cpu_count() or 1) and "OMP_WAIT_POLICY" not in os.environ \
                and "GOMP_SPINCOUNT" not in os.environ:
            # more threads than cores: idle threads sleep at once instead of spinning on
            # the cores the other runs need (the spawned workers inherit this)
            os.environ["OMP_WAIT_POLICY"] = "passive"
        # spawned, not forked: GNU OpenMP is not fork safe (see build.run_points)
        with ProcessPoolExecutor(max_workers=len(threads),
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            futs = [pool.submit(_run_one, scene, point, t) for t in threads]
            runs = [f.result() for f in futs]
    measured_on = machine()
    for r in runs:
        r["measured_on"] = measured_on
    if reference:
        tv = _plain(_check_fields(table.lookup(point).values))
        sigma = {f: [sampling_sigma(law, st, z, record_s) for z in zones]
                 for f, st in GATED.items()}
        return dict(kind="reference", table=table_ref, table_key=table.manifest.get("key"),
                    kernel_version=version, point=point, record_s=record_s, zones=zones,
                    sigma=sigma, table_values=tv, runs=runs)
    out = dict(kind="change", source_hash=h, accepted_as=version, change=change,
               z_limit=z_limit, runs=runs)
    out["judgement"] = {k: v for k, v in rejudge(out, ref).items() if k != "comparisons"}
    return out


# --- the command: python -m validation.equivalence_runs ----------------------------------

def parser() -> argparse.ArgumentParser:
    """The command's options."""
    q = argparse.ArgumentParser(
        prog="python -m validation.equivalence_runs",
        description="Accept a change of the DEM's sources that alters only round-off (another "
        "order of a sum, fused multiply-adds): it gives other trajectories and so other "
        "numbers, but the same statistics. At the operating point of the work-precision "
        "study, --reference runs the table's own sources once per thread count (each count "
        "splits the 10-degree sector's beads differently: another realization) and records "
        "them beside the table's point; without it, the changed sources run there and each "
        "statistic per zone is scored, (mean of the runs - mean of the reference) / "
        "(s sqrt(1/n + 1/m)), s the larger of the realizations' pooled standard deviation "
        "and the study's sampling sigma. With --write, a change that passes is added to "
        "millfmu/data/dem_equivalence.json, and its sources then take the table's kernel "
        "version. Not for changes of the physics: those need a rebuilt table. Run from a "
        "checkout's root.")
    q.add_argument("table", nargs="?", default="coupled", help="the table judged against "
                   "(default: coupled, the default scene's)")
    q.add_argument("--threads", type=int, nargs="+", default=[1, 2], metavar="N",
                   help="one run per thread count, in parallel processes (distinct counts; "
                        "default: 1 2)")
    q.add_argument("--change", default="", help="what the change is (kept with the "
                   "evidence)")
    q.add_argument("--reference", action="store_true", help="the installed sources are the "
                   "table's version: add their runs to the reference realizations (the noise "
                   "a change is judged by)")
    q.add_argument("--write", action="store_true", help="record the reference runs, or a "
                   "passing change, in the evidence file")
    q.add_argument("--evidence", metavar="FILE.json", help="the evidence file (default: "
                   "millfmu/data/dem_equivalence.json)")
    q.add_argument("--show", action="store_true", help="instead: print the recorded "
                   "reference and the accepted changes with their recomputed scores")
    q.add_argument("--record-spread", action="store_true", help="instead: record the "
                   "reference realizations' spread in the table's manifest (the realization "
                   "part of a lookup's stated error; --reference --write records it too)")
    return q


def _show(evidence) -> int:
    """Print the recorded reference and each accepted change with its recomputed scores."""
    data = E.read_evidence(evidence)
    ref = data.get("reference")
    if ref is None:
        print("no reference runs recorded")
        return 0
    for line in E.reference_lines(ref):
        print(line)
    if not data["accepted"]:
        print("no accepted changes")
    for e in data["accepted"]:
        print(f"{e['source_hash'][:19]}... accepted as {e['accepted_as'][:19]}... "
              f"({e.get('change') or 'no description'})")
        for line in E.change_lines(e, ref):
            print("  " + line)
    return 0


def main(argv=None) -> int:
    """``python -m validation.equivalence_runs [TABLE] [...]``: 0 (recorded, accepted or
    shown), 1 (a change not accepted) or 2 with the reason on stderr."""
    from millfmu.stress_tables.spec import TableError

    args = parser().parse_args(argv)
    try:
        if args.show:
            return _show(args.evidence)
        if args.record_spread:
            print(f"recorded the realizations' spread in "
                  f"{E.write_realization_spread(args.table, args.evidence)}")
            return 0
        res = run_equivalence(args.table, args.threads, args.change,
                              reference=args.reference, evidence_path=args.evidence)
        if res["kind"] == "reference":
            shown = dict(res)
            if args.write:
                E.record(res, args.evidence)
                shown = E.read_evidence(args.evidence)["reference"]
                E.write_realization_spread(args.table, args.evidence)
            for line in E.reference_lines(shown):
                print(line)
            print("recorded" if args.write else "not recorded (--write records)")
            return 0
        for line in E.change_lines(res, E.read_evidence(args.evidence)["reference"]):
            print(line)
        if not res["judgement"]["passed"]:
            print("not accepted: nothing written" if args.write else "not accepted")
            return 1
        if args.write:
            p = E.record(res, args.evidence)
            print(f"accepted: {res['source_hash']} recorded in {p} as {res['accepted_as']}")
        return 0
    except (E.EquivalenceError, TableError) as e:
        print(f"python -m validation.equivalence_runs: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
