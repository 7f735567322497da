"""The DEM's wet collisions by Legendre et al. (2006)'s restitution against the coupled
table's lubrication law, at the table's anchor and the trend points (issue 58's wet-damping
candidate).

The coupled table's DEM loses a collision's energy to the liquid by seed 001's lubrication
force between close beads, which rebounds more than measured immersed collisions above
St 11 and leaves wall contacts dry (``python -m validation.wet_collisions``). This study
runs the table's anchor (disc slice, 10-degree sector without gravity, coupled liquid,
10 m/s, 80 %, 0.8 mm glass beads) and the trend points (14 m/s; 1.2 mm beads) with
``[fluid] wet_collisions = "legendre2006"`` (a restitution e_dry exp(-35 / St) per contact
from its approach, lubrication off; :mod:`millfmu.dem.engine.legendre2006`), by the
protocol of :mod:`validation.bead_stiffness` (started turning at 0.1 of the stirrer's
angular velocity, 0.8 s spin-up, 0.2 s recorded, seed 1), and compares them with that
study's runs of the table's law (its factor 1, the shipped summary
``validation/runs/bead_stiffness.json``; another realization of the same protocol): the
collisions the detailed model reads, and the limestone pair's trends, f_Mat refitted at
each law's anchor.

From a checkout's root:

    python -m validation.wet_restitution run --out DIR [--threads N]
    python -m validation.wet_restitution table --out DIR [--json validation/runs/wet_restitution.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

from validation import bead_stiffness as B

#: the anchor (None) and the trend points of validation.bead_stiffness
POINTS = (None, "v_t 14", "d 1.2 mm")
SPIN_UP_S = 0.8
RECORD_S = 0.2
SUMMARY = Path(__file__).resolve().parent / "runs" / "wet_restitution.json"
REFERENCE = Path(__file__).resolve().parent / "runs" / "bead_stiffness.json"


def scene_for(point: str | None):
    """The bead-stiffness study's scene at ``point`` (Y as the table's) with the wet
    restitution per contact instead of the lubrication force."""
    base = B.scene_for(1.0, SPIN_UP_S, RECORD_S, point)
    fluid = replace(base.fluid, lubrication=False, wet_collisions="legendre2006")
    return replace(base, fluid=fluid, name=base.name + "_legendre2006")


def run_cases(out_dir, threads=None, progress=True):
    """Run the anchor and the trend points, skipping runs that have a stats.json."""
    from millfmu.dem.run import run_scene

    for point in POINTS:
        d = B.case_dir(out_dir, 1.0, point)
        if not (d / "stats.json").exists():
            run_scene(scene_for(point), d, progress=progress, threads=threads)


def summarize(out_dir, reference=REFERENCE) -> dict:
    """Readings of the wet-restitution runs, their ratios to the table's law's runs (the
    bead-stiffness summary's factor 1), and the limestone pair's trends by both laws."""
    ref = json.loads(Path(reference).read_text())
    points = [p for p in POINTS if p is not None]
    runs = {"anchor": B._readings(B.case_dir(out_dir, 1.0), 1.0)}
    base = {"anchor": ref["runs"]["1"]}
    for p in points:
        runs[p] = B._readings(B.case_dir(out_dir, 1.0, p), 1.0)
        base[p] = ref["point_runs"][p]["1"]
    ratios = {k: {key: runs[k][key] / base[k][key] if base[k][key] > 0 else None
                  for key in B.CHAMBER_KEYS} for k in runs}
    tr = B.trends(out_dir, [1.0], points)
    return {"note": ("coupled table's anchor (10 m/s, 80 %, 0.8 mm) and trend points with the wet "
                     "restitution of Legendre et al. (2006) per contact (lubrication off), against "
                     "the table's lubrication law (validation/runs/bead_stiffness.json, factor 1): "
                     "chamber readings (1/(m3 s), W/m3) and the limestone S(10 um) over its anchor"),
            "command": "python -m validation.wet_restitution run --out DIR, then python -m "
                       "validation.wet_restitution table --out DIR --json validation/runs/wet_restitution.json",
            "protocol": {"spin_up_s": SPIN_UP_S, "record_s": RECORD_S, "initial_rotation": B.INITIAL_ROTATION,
                         "sector_deg": 10.0, "gravity_m_per_s2": [0.0, 0.0, 0.0]},
            "runs": runs, "ratio_to_lubrication": ratios,
            "trends": {"simple": tr["simple"],
                       "lubrication": ref["trends"]["detailed"]["1"]["relative_rate"],
                       "legendre2006": tr["detailed"]["1"]["relative_rate"],
                       "f_mat_kg_per_J_m": {"lubrication": ref["trends"]["detailed"]["1"]["f_mat_kg_per_J_m"],
                                            "legendre2006": tr["detailed"]["1"]["f_mat_kg_per_J_m"]}}}


def markdown(s: dict) -> str:
    keys = (("frequency_per_m3_s", "collisions per volume"),
            ("above_limestone_threshold_per_m3_s", "collisions above 2.7e-9 J"),
            ("above_yeast_burst_per_m3_s", "collisions above 2.8e-10 J"),
            ("limestone_breaking_per_m3_s", "collisions breaking a 3 um limestone particle"),
            ("power_W_per_m3", "collision power"))
    cols = list(s["runs"])
    lines = ["| wet restitution over the lubrication law | " + " | ".join(cols) + " |",
             "|---" * (1 + len(cols)) + "|"]
    for key, name in keys:
        lines.append(f"| {name} | " + " | ".join(
            "n/a" if s["ratio_to_lubrication"][c][key] is None else f"{s['ratio_to_lubrication'][c][key]:.2f}"
            for c in cols) + " |")
    t = s["trends"]
    pts = list(t["simple"])
    lines += ["", "| limestone S(10 um) over its anchor | " + " | ".join(pts) + " |",
              "|---" * (1 + len(pts)) + "|"]
    for law in ("simple", "lubrication", "legendre2006"):
        lines.append(f"| {law} | " + " | ".join(f"{t[law][p]:.3g}" for p in pts) + " |")
    lines.append(f"\nf_Mat refitted at the anchor [kg/(J m)]: lubrication {t['f_mat_kg_per_J_m']['lubrication']:.4g}, "
                 f"legendre2006 {t['f_mat_kg_per_J_m']['legendre2006']:.4g}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.wet_restitution", description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=("run", "table"))
    ap.add_argument("--out", required=True, help="folder of the runs")
    ap.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    ap.add_argument("--json", help="table: also write the run summary to this file")
    args = ap.parse_args(argv)
    if args.action == "run":
        run_cases(args.out, threads=args.threads)
    try:
        s = summarize(args.out)
    except FileNotFoundError as e:
        print(f"python -m validation.wet_restitution: {e}", file=sys.stderr)
        return 2
    print(markdown(s))
    if args.json:
        Path(args.json).write_text(json.dumps(s, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
