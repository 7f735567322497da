"""The first coupled DEM run on a machine whose numba cache holds no kernel of the installed
sources, against the same run compiling in one process, in one session; and the second run.

Each measure is the wall time of ``millfmu dem run`` (the command below) in a new process
with NUMBA_CACHE_DIR set to an empty folder: first with MILLFMU_COMPILE_PROCESSES=1 (the
kernels compiled one after another in the run's process), then as a user's first run
(compiled from the shipped plan in as many processes as the cores,
:mod:`millfmu.dem.first_compile`), then the same command again on that cache, then on a new
empty cache with the fused exchange (MILLFMU_FUSED_EXCHANGE=1: what a long run compiles,
the short run's form before it took the exchange by calls). Prints the figures and their
ratios; ``--out FILE`` writes them as JSON (the README's row). About 8
minutes on 2 cores. ``--report-out FILE`` measures ``millfmu report --quick`` instead, with
empty kernel and table caches (NUMBA_CACHE_DIR, MILLFMU_CACHE_DIR) and again on them, and
writes that (about 2.5 minutes).

Usage, from a checkout: ``python -m benchmarks.first_dem_run [--out FILE | --report-out
FILE] [--host TEXT]``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ARGS = ["disc_slice", "--sector-deg", "10", "--no-gravity", "--fluid", "coupled", "--spin-up",
        "0.002", "--record", "0.002", "--threads", "2"]
COMMAND = "millfmu dem run disc_slice --out DIR " + " ".join(ARGS[1:])


def timed_run(cache: Path, out: Path, **env) -> tuple[float, str]:
    """(wall time [s], stderr) of one ``millfmu dem run`` in a new process."""
    e = dict(os.environ, NUMBA_CACHE_DIR=str(cache), **env)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "millfmu", "dem", "run", *ARGS, "--out", str(out),
                        "--no-progress"], env=e, capture_output=True, text=True)
    took = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"the run failed ({r.returncode}):\n{r.stderr}")
    return took, r.stderr


def report_times() -> dict:
    """Wall times [s] of ``millfmu report --quick`` on empty kernel and table caches, then
    again on them."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        env = dict(os.environ, NUMBA_CACHE_DIR=str(t / "nb"), MILLFMU_CACHE_DIR=str(t / "tables"))
        for name, folder in (("fresh_wall_s", "r1"), ("second_wall_s", "r2")):
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "millfmu", "report", "--quick", "--out",
                                str(t / folder)], env=env, capture_output=True, text=True)
            out[name] = round(time.perf_counter() - t0, 1)
            if r.returncode:
                raise SystemExit(f"millfmu report --quick failed ({r.returncode}):\n{r.stderr[-3000:]}")
    return out


def measure() -> dict:
    from millfmu.dem.first_compile import FUSED_ENV, processes_here

    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        one, _ = timed_run(t / "cache1", t / "r1", MILLFMU_COMPILE_PROCESSES="1")
        first, err = timed_run(t / "cache2", t / "r2")
        second, _ = timed_run(t / "cache2", t / "r3")
        fused, _ = timed_run(t / "cache3", t / "r4", **{FUSED_ENV: "1"})
    return {"first_run_wall_s": round(first, 1), "second_run_wall_s": round(second, 2),
            "first_run_one_process_wall_s": round(one, 1),
            "one_process_over_first": round(one / first, 2),
            "first_run_fused_wall_s": round(fused, 1),
            "fused_over_first": round(fused / first, 2),
            "compiling_processes": processes_here(),
            "said": [x for x in err.splitlines() if x.startswith("millfmu: compil")]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.first_dem_run", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="write the figures to this JSON file")
    ap.add_argument("--report-out", help="measure millfmu report --quick instead; write it here (JSON)")
    ap.add_argument("--host", default="", help="the machine, in words, for the JSON")
    a = ap.parse_args(argv)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip() or "0000000"
    if a.report_out:
        f = report_times()
        print(f"millfmu report --quick: {f['fresh_wall_s']} s on empty caches, {f['second_wall_s']} s again")
        Path(a.report_out).write_text(json.dumps({
            "commit": commit, "host": a.host, "date": datetime.date.today().isoformat(),
            "command": "millfmu report --quick --out DIR",
            "made_by": "python -m benchmarks.first_dem_run --report-out FILE",
            "figures": f, "aim": {"fresh_wall_s": 120},
            "unit": "wall time of millfmu report --quick with empty kernel and table caches (fresh) and "
                    "again (second); the installation not counted",
            "note": "fresh: NUMBA_CACHE_DIR and MILLFMU_CACHE_DIR set to empty folders; second: the same "
                    "command again"}, indent=2) + "\n")
        return 0
    f = measure()
    said = f.pop("said")
    print("\n".join(said))
    print(f"first run {f['first_run_wall_s']} s in {f['compiling_processes']} compiling processes, "
          f"{f['first_run_one_process_wall_s']} s in one ({f['one_process_over_first']}x), "
          f"second run {f['second_run_wall_s']} s; with the fused exchange compiled first (as a "
          f"long run does) {f['first_run_fused_wall_s']} s ({f['fused_over_first']}x)")
    if a.out:
        Path(a.out).write_text(json.dumps({
            "commit": commit, "host": a.host, "date": datetime.date.today().isoformat(),
            "command": COMMAND, "made_by": "python -m benchmarks.first_dem_run --out FILE",
            "figures": f, "aim": {"first_run_wall_s": 90},
            "unit": "wall time of the short coupled DEM run [s], numba's kernel cache empty (first: "
                    "compiled in the processes the cores allow; one process: "
                    "MILLFMU_COMPILE_PROCESSES=1; fused: MILLFMU_FUSED_EXCHANGE=1, the fused "
                    "exchange compiled and taken as by a long run) and filled by the first (second)",
            "note": "each run a new process with NUMBA_CACHE_DIR set to an empty folder, one after "
                    "the other in one session"}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
