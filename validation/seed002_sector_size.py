"""Is seed 002's 60-degree sector wide enough? The campaign's case at 1200 rpm, 80 %
(physical method, model B, from rest, 1.0 s of spin-up, 0.5 s recorded in 0.1 s windows, no
gravity) on a 90-degree sector (three vane pitches) against the campaign's 60 degrees (two
vane pitches), each from two random bead placements (the scene's ``seed``), so that what the
width changes stands beside what a realization changes.

One vane pitch (30 degrees) against two changed SEV_1's mean stress intensity by 40 % and
SE_cs,sum by 43 %, with zone speeds within 0.1 % (docs/validation-seed002.md). The campaign's
own case (60 degrees, placement 1) is read from ``validation/runs/seed002_sector.json``;
this study runs the other three (:data:`RUNS`).

    python -m validation.seed002_sector_size run --out DIR --threads 1
    python -m validation.seed002_sector_size compare --out DIR

``compare`` keeps the runs' compact statistics (:func:`validation.seed002.compact`) and
windows, with the comparison, in ``validation/runs/seed002_sector_size.json`` and prints
the table. A study: nothing in the package imports it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from validation import seed002 as S2
from validation.run_summary import keep_and_show, read_windows

#: the case: the campaign's reference point
CASE = (1200.0, 0.8)
#: the wider sector [degrees]: three vane pitches
SECTOR_DEG = 90.0
#: the campaign the narrower sector's case (placement 1) is read from
CAMPAIGN = "physical, model B"
#: (sector [degrees], bead placement seed) of the runs this study makes
RUNS = ((SECTOR_DEG, 1), (S2.SECTOR_DEG, 2), (SECTOR_DEG, 2))
#: every column of the comparison: the kept campaign case and the runs, by width
COLUMNS = ((S2.SECTOR_DEG, 1), (S2.SECTOR_DEG, 2), (SECTOR_DEG, 1), (SECTOR_DEG, 2))
#: what it keeps of each 0.1 s window per zone (``windows.csv``; units: -, -)
WINDOW_KEYS = ("filling", "speed_over_tip_speed")
#: what this study keeps
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed002_sector_size.json"


def case_dir(out_dir, sector_deg: float, seed: int) -> Path:
    rpm, fill = CASE
    return Path(out_dir) / f"s{sector_deg:g}_seed{seed}_n{rpm:g}_f{round(fill * 100)}"


def scene(sector_deg: float, seed: int):
    """The campaign's case (:func:`validation.seed002.scene_for`) on ``sector_deg`` degrees
    with the beads placed by ``seed``."""
    import dataclasses

    return dataclasses.replace(S2.scene_for(*CASE, sector_deg=sector_deg), seed=int(seed))


def run(out_dir, threads=None, progress: bool = True) -> list:
    """Run each of :data:`RUNS` that has no stats.json yet into :func:`case_dir`; returns
    the folders."""
    from millfmu.dem.run import run_scene

    out = []
    for deg, seed in RUNS:
        d = case_dir(out_dir, deg, seed)
        if not (d / "stats.json").exists():
            run_scene(scene(deg, seed), d, progress=progress, threads=threads, window_s=S2.WINDOW_S)
        out.append(d)
    return out


def _q(st):
    return st["flow"]["seed002"]


#: (label, unit, value of a compact run) the comparison reads
QUANTITIES = tuple(
    [(f"local filling {z}", "-", lambda st, z=z: S2._zone(st, z)["filling"]) for z in S2.ZONE_NAMES]
    + [(f"bead speed / tip speed {z}", "-", lambda st, z=z: S2._zone(st, z)["speed_over_tip_speed"])
       for z in S2.ZONE_NAMES]
    + [(f"SN_g {z}", "1/(m3 s)", lambda st, z=z: _q(st)["zones"][z]["SN_g_per_m3_s"]) for z in S2.ZONE_NAMES]
    + [(f"SI {z}", "J", lambda st, z=z: _q(st)["zones"][z]["SI_j"]) for z in S2.ZONE_NAMES]
    + [(f"SE_cs {z}", "W/m3", lambda st, z=z: _q(st)["zones"][z]["SE_cs_w_per_m3"]) for z in S2.ZONE_NAMES]
    + [("SN_g of the chamber", "1/(m3 s)", lambda st: _q(st)["total"]["SN_g_per_m3_s"]),
       ("SE_cs,sum", "W", lambda st: _q(st)["total"]["SE_ts_sum_w"] / _q(st)["total"]["ts_share"]),
       ("SE_ts,sum / SE_cs,sum", "-", lambda st: _q(st)["total"]["ts_share"]),
       ("efficiency SE_cs,sum / SE_net", "-", lambda st: _q(st)["total"]["efficiency"])])


def kept_case(path=None) -> dict:
    """The campaign's case on its own sector: compact statistics from the seed 002 summary."""
    doc = json.loads(Path(path or S2.SUMMARY).read_text())
    camp = doc["campaigns"][CAMPAIGN]
    return camp["runs"][S2._case_label(*CASE)]["stats"]


def _label(deg, seed) -> str:
    return f"{deg:g} deg, placement {seed}"


def _rel(a: float, b: float):
    return (b / a - 1.0) if a else None


def comparison(stats: dict) -> list:
    """Each of :data:`QUANTITIES` in every run (``stats``: {(sector, seed): compact
    stats}), with the placements' spread at each width (second over first, - 1) and the
    wide sector's mean over the narrow one's (- 1); None where a divisor is 0."""
    n, w = S2.SECTOR_DEG, SECTOR_DEG
    out = []
    for name, unit, fn in QUANTITIES:
        v = {k: float(fn(st)) for k, st in stats.items()}
        mn, mw = 0.5 * (v[(n, 1)] + v[(n, 2)]), 0.5 * (v[(w, 1)] + v[(w, 2)])
        out.append({"quantity": name, "unit": unit,
                    "values": {_label(*k): v[k] for k in COLUMNS},
                    "placement_narrow": _rel(v[(n, 1)], v[(n, 2)]),
                    "placement_wide": _rel(v[(w, 1)], v[(w, 2)]),
                    "wide_over_narrow": _rel(mn, mw)})
    return out


def keep(out_dir, path=SUMMARY) -> Path:
    """Keep the runs (compact statistics, windows) and the comparison in ``path``.
    FileNotFoundError where a run has not finished."""
    stats, runs = {COLUMNS[0]: kept_case()}, {}
    for deg, seed in RUNS:
        d = case_dir(out_dir, deg, seed)
        p = d / "stats.json"
        if not p.exists():
            raise FileNotFoundError(f"{d}: no stats.json (run it: python -m validation.seed002_sector_size "
                                    f"run --out {out_dir})")
        stats[(deg, seed)] = S2.compact(json.loads(p.read_text()))
        runs[_label(deg, seed)] = {"sector_deg": deg, "seed": seed, "stats": stats[(deg, seed)],
                                   "windows": read_windows(d, WINDOW_KEYS)}
    doc = {"note": ("seed 002's campaign case at 1200 rpm, 80 % (physical, model B, the campaign's "
                    f"protocol) on {S2.SECTOR_DEG:g} and {SECTOR_DEG:g} degrees, each from two bead "
                    f"placements; the {_label(*COLUMNS[0])} run is the campaign's, kept in "
                    "seed002_sector.json; units as there"),
           "case": S2._case_label(*CASE), "sector_deg": {"narrow": S2.SECTOR_DEG, "wide": SECTOR_DEG},
           "command": ("python -m validation.seed002_sector_size run --out DIR --threads 1, then "
                       "python -m validation.seed002_sector_size compare --out DIR"),
           "runs": runs, "comparison": comparison(stats)}
    out = Path(path)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def _pct(x) -> str:
    return "-" if x is None else f"{x:+.1%}"


def markdown(doc: dict) -> str:
    """The kept comparison as a markdown table."""
    n, w = doc["sector_deg"]["narrow"], doc["sector_deg"]["wide"]
    cols = [_label(*k) for k in COLUMNS]
    lines = [f"| {doc['case']} | " + " | ".join(cols) + f" | placements, {n:g} deg | placements, {w:g} deg | "
             f"{w:g} / {n:g} deg - 1 (means) |", "|---" * (4 + len(cols)) + "|"]
    for q in doc["comparison"]:
        lines.append(f"| {q['quantity']} [{q['unit']}] | " + " | ".join(f"{q['values'][c]:.4g}" for c in cols)
                     + f" | {_pct(q['placement_narrow'])} | {_pct(q['placement_wide'])} | "
                     f"{_pct(q['wide_over_narrow'])} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.seed002_sector_size",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "compare"))
    p.add_argument("--out", required=True, help="folder of the run")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    args = p.parse_args(argv)
    if args.action == "run":
        for d in run(args.out, threads=args.threads):
            print(f"wrote {d}")
        return 0
    return keep_and_show(keep, args.out, markdown)


if __name__ == "__main__":
    sys.exit(main())
