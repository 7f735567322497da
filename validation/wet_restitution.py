"""The DEM's wet collisions by Legendre et al. (2006)'s restitution against the coupled
table's lubrication law, at the table's anchor and the trend points (issue 58's wet-damping
candidate).

The coupled table's DEM loses a collision's energy to the liquid by seed 001's lubrication
force between close beads, which rebounds more than measured immersed collisions above
St 11 and leaves wall contacts dry (``python -m validation.wet_collisions``). This study
runs the table's anchor (disc slice, 10-degree sector without gravity, coupled liquid,
10 m/s, 80 %, 0.8 mm glass beads) and the trend points (6 and 14 m/s; 0.6 and 1.2 mm beads;
zirconia's 6040 kg/m3) by both laws, ``[fluid] wet_collisions = "legendre2006"`` (a
restitution e_dry exp(-35 / St) per contact from its approach, lubrication off;
:mod:`millfmu.dem.engine.legendre2006`) and the table's ``"lubrication"``, by the protocol
of :mod:`validation.bead_stiffness` (started turning at 0.1 of the stirrer's angular
velocity, 0.8 s spin-up, 0.2 s recorded, seed 1), and compares the collisions the detailed
model reads and the limestone pair's trends, f_Mat refitted at each law's anchor, with the
simple model's; with the yeast pair's runs at its own reference, 8 m/s (run only when named:
``--point "v_t 8" --point "d 0.6 mm, 8 m/s" ...``), the yeast pair's trends too, its burst
energy refitted at each law's reference run.

From a checkout's root:

    python -m validation.wet_restitution run --out DIR [--threads N] [--law LAW] [--point P]
    python -m validation.wet_restitution table --out DIR [--json validation/runs/wet_restitution.json]
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

from validation import bead_stiffness as B
from validation.run_summary import write_json

#: the anchor (None) and the trend points of validation.bead_stiffness
POINTS = (None, "v_t 6", "v_t 14", "d 0.6 mm", "d 1.2 mm", "rho 6040")
#: The yeast pair's reference is 8 m/s: the runs its trends read, by trend (the reference
#: "anchor" and the points of its bead diameter and density at 8 m/s; tip speed 6 and 14 m/s
#: are the limestone pair's runs)
YEAST_RUNS = {"anchor": "v_t 8", "v_t 6": "v_t 6", "v_t 14": "v_t 14", "d 0.6 mm": "d 0.6 mm, 8 m/s",
              "d 1.2 mm": "d 1.2 mm, 8 m/s", "rho 6040": "rho 6040, 8 m/s"}
#: the runs the yeast pair adds
YEAST_POINTS = tuple(p for p in YEAST_RUNS.values() if p not in POINTS)
#: the DEM's laws of wet collisions, each run into its own subfolder
LAWS = ("lubrication", "legendre2006")
SPIN_UP_S = 0.8
RECORD_S = 0.2
SUMMARY = Path(__file__).resolve().parent / "runs" / "wet_restitution.json"


def scene_for(point: str | None, law: str = "legendre2006"):
    """The bead-stiffness study's scene at ``point`` (Y as the table's) by the wet-collision
    law ``law``."""
    base = B.scene_for(1.0, SPIN_UP_S, RECORD_S, point)
    if law == "lubrication":
        return base
    fluid = replace(base.fluid, lubrication=False, wet_collisions=law)
    return replace(base, fluid=fluid, name=base.name + "_" + law)


def run_cases(out_dir, threads=None, progress=True, laws=LAWS, points=POINTS):
    """Run the anchor and the trend points by each law into ``DIR/<law>``, skipping runs
    that have a stats.json."""
    from millfmu.dem.run import run_scene

    for law in laws:
        for point in points:
            d = B.case_dir(Path(out_dir) / law, 1.0, point)
            if not (d / "stats.json").exists():
                run_scene(scene_for(point, law), d, progress=progress, threads=threads)


def _label(point):
    return "anchor" if point is None else point


def summarize(out_dir) -> dict:
    """Readings of each law's runs, the published curve's over the lubrication law's, and
    the limestone pair's trends by both laws."""
    points = [p for p in POINTS if p is not None]
    runs = {law: {_label(p): B._readings(B.case_dir(Path(out_dir) / law, 1.0, p), 1.0) for p in POINTS}
            for law in LAWS}
    wet, lub = runs["legendre2006"], runs["lubrication"]
    ratios = {k: {key: wet[k][key] / lub[k][key] if lub[k][key] > 0 else None
                  for key in B.CHAMBER_KEYS} for k in wet}
    tr = {law: B.trends(Path(out_dir) / law, [1.0], points) for law in LAWS}
    have = all((B.case_dir(Path(out_dir) / law, 1.0, p) / "stats.json").exists() for law in LAWS for p in YEAST_POINTS)
    yeast = yeast_trends(out_dir) if have else None
    return {"note": ("coupled table's anchor (10 m/s, 80 %, 0.8 mm) and trend points by the DEM's two "
                     "wet-collision laws: the lubrication force (the table's) and Legendre et al. "
                     "(2006)'s restitution per contact (lubrication off); chamber readings (1/(m3 s), "
                     "W/m3), their ratios, and the limestone S(10 um) over its anchor"),
            "command": "python -m validation.wet_restitution run --out DIR, then python -m "
                       "validation.wet_restitution table --out DIR --json validation/runs/wet_restitution.json",
            "protocol": {"spin_up_s": SPIN_UP_S, "record_s": RECORD_S, "initial_rotation": B.INITIAL_ROTATION,
                         "sector_deg": 10.0, "gravity_m_per_s2": [0.0, 0.0, 0.0]},
            "runs": runs, "ratio_to_lubrication": ratios,
            "trends": {"simple": tr["lubrication"]["simple"],
                       **{law: tr[law]["detailed"]["1"]["relative_rate"] for law in LAWS},
                       "f_mat_kg_per_J_m": {law: tr[law]["detailed"]["1"]["f_mat_kg_per_J_m"] for law in LAWS}},
            **({"yeast_trends": yeast} if yeast is not None else {})}


def yeast_trends(out_dir) -> dict:
    """The yeast pair's disruption rate at each trend point over its reference (8 m/s, 80 %,
    0.8 mm glass) by the simple model and by the detailed model on each law's runs, its burst
    energy refitted at the reference run so that the reference rate is the shipped detailed
    model's (as validation.trends_causes refits), with the refitted burst energies [J] and
    how much of the reference rate each law's reference run reaches at most (every stress
    breaking a cell: ``reach_at_p1``). Where that is below 1 no burst energy fits
    (``burst_median_J`` None) and the trends keep the shipped one."""
    from validation import trends_causes as tc

    ps = next(p for p in tc.setups() if p.w_feed is not None)  # yeast: the feed's disruption rate
    dm = ps.detailed
    runs = {k: p for k, p in YEAST_RUNS.items() if k != "anchor"}
    target, simple = B.simple_trend(ps, runs)  # as validation.trends_causes refits the cells' pair
    out = {"simple": simple, "burst_median_J": {}, "reach_at_p1": {}}
    for law in LAWS:
        const, out[law], src0 = B.detailed_trend(ps, target, Path(out_dir) / law, 1.0, YEAST_RUNS["anchor"], runs)
        out["burst_median_J"][law] = None if math.isnan(const) else const
        every = replace(dm.material, **{ps.constant: getattr(dm.material, ps.constant) * 1e-12})
        out["reach_at_p1"][law] = tc.rate(dm, every, src0, ps.op_detailed, ps) / target
    return out


#: the points' names on the page
NAMES = {"anchor": "anchor", "v_t 6": "6 m/s", "v_t 14": "14 m/s", "d 0.6 mm": "0.6 mm beads",
         "d 1.2 mm": "1.2 mm beads", "rho 6040": "6040 kg/m3"}


def page_tables(s: dict) -> str:
    """The two tables of the rates page: the published curve's chamber readings over the
    lubrication law's, and the limestone S(10 um) over its anchor by the simple model and
    both laws, with each law's change over the simple model's."""
    r = s["ratio_to_lubrication"]
    cols = list(r)
    out = ["| the published curve over the table's law | " + " | ".join(NAMES[c] for c in cols) + " |",
           "|---" * (1 + len(cols)) + "|"]
    for key, name in (("frequency_per_m3_s", "collisions per volume"),
                      ("above_limestone_threshold_per_m3_s", "collisions with SE_tn above 2.7e-9 J"),
                      ("power_W_per_m3", "collision power")):
        out.append(f"| {name} | " + " | ".join(f"{r[c][key]:.2f}" for c in cols) + " |")
    out += ["", *_trend_rows("limestone S(10 um) over its anchor", s["trends"])]
    return "\n".join(out)


def yeast_page_table(s: dict) -> str:
    """The rates page's table of the yeast pair's disruption rate over its reference by the
    simple model and both laws ("" where the summary has no yeast runs)."""
    y = s.get("yeast_trends")
    return "" if y is None else "\n".join(_trend_rows("yeast disruption rate over its reference (8 m/s)", y))


def _trend_rows(title: str, t: dict) -> list:
    """A pair's trend table: the simple model's change at each point, each law's detailed
    change with its ratio to the simple model's in brackets."""
    pts = list(t["simple"])
    out = [f"| {title} | " + " | ".join(NAMES[p] for p in pts) + " |", "|---" * (1 + len(pts)) + "|",
           "| simple model | " + " | ".join(f"{t['simple'][p]:.3g}" for p in pts) + " |"]
    for law, name in (("lubrication", "detailed, the table's law (over the simple model's)"),
                      ("legendre2006", "detailed, the published curve (over the simple model's)")):
        out.append(f"| {name} | " + " | ".join(f"{t[law][p]:.3g} ({t[law][p] / t['simple'][p]:.2f})"
                                                for p in pts) + " |")
    return out


def markdown(s: dict) -> str:
    keys = (("frequency_per_m3_s", "collisions per volume"),
            ("above_limestone_threshold_per_m3_s", "collisions above 2.7e-9 J"),
            ("above_yeast_burst_per_m3_s", "collisions above 2.8e-10 J"),
            ("limestone_breaking_per_m3_s", "collisions breaking a 3 um limestone particle"),
            ("power_W_per_m3", "collision power"))
    cols = list(s["ratio_to_lubrication"])
    lines = ["| wet restitution over the lubrication law | " + " | ".join(cols) + " |",
             "|---" * (1 + len(cols)) + "|"]
    for key, name in keys:
        lines.append(f"| {name} | " + " | ".join(
            "n/a" if s["ratio_to_lubrication"][c][key] is None else f"{s['ratio_to_lubrication'][c][key]:.2f}"
            for c in cols) + " |")
    t = s["trends"]
    lines += ["", *_plain_rows("limestone S(10 um) over its anchor", t)]
    lines.append(f"\nf_Mat refitted at the anchor [kg/(J m)]: lubrication {t['f_mat_kg_per_J_m']['lubrication']:.4g}, "
                 f"legendre2006 {t['f_mat_kg_per_J_m']['legendre2006']:.4g}")
    y = s.get("yeast_trends")
    if y is not None:
        lines += ["", *_plain_rows("yeast disruption rate over its reference (8 m/s)", y)]
        fit = {law: "none reaches it" if y["burst_median_J"][law] is None else f"{y['burst_median_J'][law]:.3g}"
               for law in LAWS}
        lines.append("burst energy refitted at the reference [J]: " + ", ".join(
            f"{law} {fit[law]} (at most {y['reach_at_p1'][law]:.2f} of the reference rate)" for law in LAWS))
    return "\n".join(lines)


def _plain_rows(title: str, t: dict) -> list:
    """A pair's trends for the terminal: the simple model's and each law's rate over its
    reference at each point."""
    pts = list(t["simple"])
    return [f"| {title} | " + " | ".join(pts) + " |", "|---" * (1 + len(pts)) + "|",
            *(f"| {law} | " + " | ".join(f"{t[law][p]:.3g}" for p in pts) + " |" for law in ("simple", *LAWS))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.wet_restitution", description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=("run", "table"))
    ap.add_argument("--out", required=True, help="folder of the runs")
    ap.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    ap.add_argument("--json", help="table: also write the run summary to this file")
    ap.add_argument("--law", choices=LAWS, action="append", help="run: only this law (repeatable)")
    ap.add_argument("--point", choices=["anchor", *POINTS[1:], *YEAST_POINTS], action="append",
                    help="run: only this point (repeatable; the yeast pair's points at 8 m/s run only when named)")
    args = ap.parse_args(argv)
    if args.action == "run":
        pts = POINTS if not args.point else [None if p == "anchor" else p for p in args.point]
        run_cases(args.out, threads=args.threads, laws=args.law or LAWS, points=pts)
    try:
        s = summarize(args.out)
    except FileNotFoundError as e:
        print(f"python -m validation.wet_restitution: {e}", file=sys.stderr)
        return 2
    print(markdown(s))
    if args.json:
        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
