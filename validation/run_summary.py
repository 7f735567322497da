"""Small summaries of DEM run folders, kept in the repository beside the pages they back.

``python -m validation.run_summary --out FILE.json LABEL=DIR ... [--note TEXT]`` reads each
folder's ``stats.json`` and keeps what ``millfmu dem compare`` shows (zone speeds, fillings,
collision densities, median SE_tn, the first bead layer, the power number, ...), as numbers
with their units, per run; raw contacts are not kept. ``--command LABEL=TEXT`` records the
command that made a run. The summary is what a page's verdicts are computed from.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from millfmu.dem.analysis.compare import QUANTITIES, CompareError, load_run


def summary(runs: dict, commands: dict | None = None, note: str = "") -> dict:
    """{label: DIR} -> {"note", "quantities": {label: unit}, "runs": {label: {"command",
    "values": {quantity: value}}}}; a value the run does not have is None."""
    out = {"note": note, "quantities": {q: unit for q, _f, unit, _rel in QUANTITIES}, "runs": {}}
    for label, folder in runs.items():
        st = load_run(folder)
        values = {}
        for q, f, _unit, _rel in QUANTITIES:
            try:
                values[q] = f(st)
            except (KeyError, TypeError, ZeroDivisionError):
                values[q] = None
        out["runs"][label] = {"command": (commands or {}).get(label, ""), "values": values}
    return out


def read_windows(d, keys) -> list:
    """A run folder's recording window by window (its ``windows.csv``): per window its
    start [s] and per zone the columns ``keys`` (e.g. local filling, speed / tip speed),
    in time order; whether the zones still drift over the recording."""
    import csv

    out = {}
    with open(Path(d) / "windows.csv", newline="") as f:
        for row in csv.DictReader(f):
            w = out.setdefault(float(row["t_start_s"]), {"t_start_s": float(row["t_start_s"]), "zones": {}})
            w["zones"][row["zone"]] = {k: float(row[k]) for k in keys}
    return [out[t] for t in sorted(out)]


def write_json(path, doc: dict) -> None:
    """Write a run summary to ``path`` as indented JSON and say so on stdout."""
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {path}")


def keep_and_show(keep, out_dir, markdown) -> int:
    """A study's ``summarize`` step on its command line: keep its summary from the runs in
    ``out_dir`` (``keep(out_dir)`` returns the file it wrote), print the summary's table
    (``markdown(doc)``) and where it is kept; 0, or 1 with the reason on stderr where
    the runs are missing (``keep`` raises FileNotFoundError)."""
    try:
        kept = keep(out_dir)
    except FileNotFoundError as e:
        print(e, file=sys.stderr)
        return 1
    print(markdown(json.loads(Path(kept).read_text())))
    print(f"kept in {kept}")
    return 0


def _pairs(items, what) -> dict:
    out = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        if not sep or not k:
            raise ValueError(f"{what} {it!r}: write LABEL=VALUE")
        out[k] = v
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.run_summary", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", metavar="LABEL=DIR", help="a finished 'millfmu dem run' folder")
    ap.add_argument("--out", required=True, help="the summary's JSON file")
    ap.add_argument("--command", action="append", metavar="LABEL=TEXT", help="the command that made run LABEL")
    ap.add_argument("--note", default="", help="what the runs test")
    args = ap.parse_args(argv)
    try:
        doc = summary(_pairs(args.runs, "run"), _pairs(args.command, "--command"), args.note)
    except (ValueError, CompareError) as e:
        print(f"python -m validation.run_summary: {e}", file=sys.stderr)
        return 2
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out} ({len(doc['runs'])} runs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
