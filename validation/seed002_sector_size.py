"""Is seed 002's 60-degree sector wide enough? The campaign's case at 1200 rpm, 80 %
(physical method, model B, from rest, 1.0 s of spin-up, 0.5 s recorded in 0.1 s windows, no
gravity) on a 90-degree sector (three vane pitches) against the same case on the campaign's
60 degrees (two vane pitches), kept in ``validation/runs/seed002_sector.json``.

One vane pitch (30 degrees) against two changed SEV_1's mean stress intensity by 40 % and
SE_cs,sum by 43 %, with zone speeds within 0.1 % (docs/validation-seed002.md): the pitch
constrains the packed layer at the wall. Three pitches show whether two have converged.

    python -m validation.seed002_sector_size run --out DIR --threads 1
    python -m validation.seed002_sector_size compare --out DIR

``compare`` keeps the 90-degree run's compact statistics (:func:`validation.seed002.compact`)
and its windows, with the comparison, in ``validation/runs/seed002_sector_size.json`` and
prints the table. A study: nothing in the package imports it.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

from validation import seed002 as S2

#: the case: the campaign's reference point
CASE = (1200.0, 0.8)
#: the wider sector [degrees]: three vane pitches
SECTOR_DEG = 90.0
#: the campaign the narrower sector's case is read from
CAMPAIGN = "physical, model B"
#: what this study keeps
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed002_sector_size.json"


def case_dir(out_dir) -> Path:
    rpm, fill = CASE
    return Path(out_dir) / f"s{SECTOR_DEG:g}_n{rpm:g}_f{round(fill * 100)}"


def run(out_dir, threads=None, progress: bool = True) -> Path:
    """Run the case on :data:`SECTOR_DEG` degrees into :func:`case_dir` (by the campaign's
    protocol, :func:`validation.seed002.scene_for`); returns the folder."""
    from millfmu.dem.run import run_scene

    d = case_dir(out_dir)
    if not (d / "stats.json").exists():
        run_scene(S2.scene_for(*CASE, sector_deg=SECTOR_DEG), d, progress=progress, threads=threads,
                  window_s=S2.WINDOW_S)
    return d


def _zone(st, z):
    return next(x for x in st["zones"] if x["name"] == z)


def _q(st):
    return st["flow"]["seed002"]


#: (label, unit, value of a compact run) the comparison reads
QUANTITIES = tuple(
    [(f"local filling {z}", "-", lambda st, z=z: _zone(st, z)["filling"]) for z in S2.ZONE_NAMES]
    + [(f"bead speed / tip speed {z}", "-", lambda st, z=z: _zone(st, z)["speed_over_tip_speed"])
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


def comparison(wide: dict, narrow: dict) -> list:
    """Each of :data:`QUANTITIES` on the campaign's sector and on :data:`SECTOR_DEG`
    degrees, with the relative difference (None where the narrow value is 0)."""
    out = []
    for name, unit, fn in QUANTITIES:
        a, b = float(fn(narrow)), float(fn(wide))
        out.append({"quantity": name, "unit": unit, "narrow": a, "wide": b,
                    "relative_difference": (b / a - 1.0) if a else None})
    return out


def _windows(d: Path) -> list:
    """Per 0.1 s window (``windows.csv``) each zone's local filling and speed / tip speed."""
    out = {}
    with open(d / "windows.csv", newline="") as f:
        for row in csv.DictReader(f):
            w = out.setdefault(float(row["t_start_s"]), {"t_start_s": float(row["t_start_s"]), "zones": {}})
            w["zones"][row["zone"]] = {k: float(row[k]) for k in ("filling", "speed_over_tip_speed")}
    return [out[t] for t in sorted(out)]


def keep(out_dir, path=SUMMARY) -> Path:
    """Keep the wide run (compact statistics, windows) and the comparison in ``path``.
    FileNotFoundError where the run has not finished."""
    d = case_dir(out_dir)
    p = d / "stats.json"
    if not p.exists():
        raise FileNotFoundError(f"{d}: no stats.json (run it: python -m validation.seed002_sector_size "
                                f"run --out {out_dir})")
    wide = S2.compact(json.loads(p.read_text()))
    narrow_deg = json.loads(Path(S2.SUMMARY).read_text())["protocol"]["sector_deg"]
    doc = {"note": ("seed 002's campaign case at 1200 rpm, 80 % (physical, model B, the campaign's "
                    f"protocol) on {SECTOR_DEG:g} degrees against the kept case on {narrow_deg:g}; units "
                    "as in seed002_sector.json"),
           "case": S2._case_label(*CASE), "sector_deg": {"narrow": narrow_deg, "wide": SECTOR_DEG},
           "command": ("python -m validation.seed002_sector_size run --out DIR --threads 1, then "
                       "python -m validation.seed002_sector_size compare --out DIR"),
           "stats": wide, "windows": _windows(d), "comparison": comparison(wide, kept_case())}
    out = Path(path)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def markdown(doc: dict) -> str:
    """The kept comparison as a markdown table."""
    n, w = doc["sector_deg"]["narrow"], doc["sector_deg"]["wide"]
    lines = [f"| {doc['case']} | {n:g} degrees | {w:g} degrees | {w:g} / {n:g} - 1 |", "|---|---|---|---|"]
    for q in doc["comparison"]:
        rd = q["relative_difference"]
        lines.append(f"| {q['quantity']} [{q['unit']}] | {q['narrow']:.4g} | {q['wide']:.4g} | "
                     + ("-" if rd is None else f"{rd:+.1%}") + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.seed002_sector_size",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "compare"))
    p.add_argument("--out", required=True, help="folder of the run")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    args = p.parse_args(argv)
    if args.action == "run":
        print(f"wrote {run(args.out, threads=args.threads)}")
        return 0
    try:
        kept = keep(args.out)
    except FileNotFoundError as e:
        print(e, file=sys.stderr)
        return 1
    print(markdown(json.loads(kept.read_text())))
    print(f"kept in {kept}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
