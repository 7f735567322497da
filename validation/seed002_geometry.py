"""Which of seed 002's unstated dimensions would let the beads circulate? Seed 002 gives
its mill's dimensions in its figure 1 only; the rotor's rim, channel and axial pitch of
millfmu's accelerator slice are derived (accelerator_slice.toml), and the liquid is laminar
where the paper ran k-epsilon. On that slice the beads pack at the chamber wall and the
inner ring empties (docs/validation-seed002.md): the return leg between the rotors swirls
too fast for its beads' weight to be carried back to the eye by the rotor's head.

Each probe changes one of these against the shipped slice, at the campaign's reference case
(1200 rpm, 80 %, physical method, model B, from rest, 1.0 s of spin-up, 0.5 s recorded, no
gravity) on one vane pitch (30 degrees: zone speeds within 0.1 % and fillings within 0.02
of the campaign's 60 degrees, at half the cost; docs/validation-seed002-sector.md), the
shipped slice run beside them on the same pitch:

- ``rim 26 mm``: the rotor's rim at 26 mm instead of 22.2 (R read as the nomenclature's
  "distance between stirrer shaft and stirrer tip" rather than the chamber's radial length);
  a larger rotor's head, (r_rim^2 - r_eye^2), against the return leg's weight;
- ``channel 5 mm``: the rotor's channel 5 mm high in its 6 mm thickness (0.5 mm shrouds)
  instead of 3 mm, so that it carries more beads;
- ``pitch 20 mm``: 20 mm between rotors instead of 13 mm, a longer return leg whose swirl
  the chamber wall brakes over more of its length;
- ``k-epsilon``: the liquid by standard k-epsilon with wall functions, as seed 002 ran it,
  instead of laminar (rotor Reynolds number 103 at 1200 rpm).

What decides (computed by :func:`verdicts` from the kept summary): whether the beads
circulate, R < 1 (:func:`millfmu.dem.mills.accelerator.return_leg`: the return leg's buoyant
weight over the rotor's head), and whether seed 002's row 1 holds (the fastest bead bin at
Z'/R >= 0.69 and the beads near the shaft faster than at the wall,
:func:`validation.seed002._profile_peak`).

    python -m validation.seed002_geometry run --out DIR --threads 1
    python -m validation.seed002_geometry summarize --out DIR

``summarize`` keeps the probes' compact statistics (:func:`validation.seed002.compact`), the
rotor's throughflow and the return leg in ``validation/runs/seed002_geometry.json`` and prints
the table. A study: nothing in the package imports it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from validation import seed002 as S2
from validation.run_summary import keep_and_show

#: the case: the campaign's reference point (rpm [1/min], filling [-])
CASE = (1200.0, 0.8)
#: one vane pitch [degrees]
SECTOR_DEG = 30.0
#: probe name -> scene-file values it changes (validation.seed002.scene_for's ``changes``)
PROBES = {
    "shipped slice": {},
    "rim 26 mm": {"mill.rotor_radius_m": 0.026},
    "channel 5 mm": {"mill.channel_height_m": 0.005},
    "pitch 20 mm": {"mill.rotor_pitch_m": 0.020},
    "k-epsilon": {"fluid.coupled.turbulence": "k_epsilon"},
}
#: what it keeps of the return leg (units: -, -, -, -, -)
RETURN_LEG_KEYS = ("k_beads", "k_liquid", "solids_fraction", "R", "k_for_R_1")
#: what this study keeps
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed002_geometry.json"


def case_dir(out_dir, probe: str) -> Path:
    if probe not in PROBES:
        raise ValueError(f"probe {probe!r}: allowed {list(PROBES)}")
    return Path(out_dir) / probe.replace(" ", "_").replace("-", "")


def scene(probe: str):
    """The campaign's reference case on :data:`SECTOR_DEG` with the probe's changes."""
    if probe not in PROBES:
        raise ValueError(f"probe {probe!r}: allowed {list(PROBES)}")
    return S2.scene_for(*CASE, sector_deg=SECTOR_DEG, changes=PROBES[probe])


def run(out_dir, probes=None, threads=None, progress: bool = True) -> list:
    """Run each probe (default all of :data:`PROBES`) that has no stats.json yet; returns
    the folders."""
    from millfmu.dem.run import run_scene

    out = []
    for probe in probes or PROBES:
        d = case_dir(out_dir, probe)
        if not (d / "stats.json").exists():
            run_scene(scene(probe), d, progress=progress, threads=threads, window_s=S2.WINDOW_S)
        out.append(d)
    return out


def probe_summary(st: dict, probe: str) -> dict:
    """What the study keeps of a run's stats.json: the compact statistics, the rotor's
    throughflow [m3/s, full circle], the return leg, the budget's closure and the scene
    values the probe changed."""
    q = st["flow"]["seed002"]
    rl = q["return_leg"]
    return {"changes": PROBES[probe],
            "tip_speed_m_per_s": st["tip_speed_m_per_s"],
            "beads": st["beads"],
            "stats": S2.compact(st),
            "rotor_throughflow_m3_per_s": q["rotor_throughflow_m3_per_s"],
            "return_leg": {k: rl[k] for k in RETURN_LEG_KEYS},
            "budget_closure_rel": st["flow"]["angular_momentum_budget"]["closure_rel"]}


def summarize(out_dir, path=SUMMARY) -> Path:
    """Keep every probe that has finished in ``path`` (FileNotFoundError naming the first
    that has not)."""
    probes = {}
    for probe in PROBES:
        p = case_dir(out_dir, probe) / "stats.json"
        if not p.exists():
            raise FileNotFoundError(f"{p.parent}: no stats.json (run it: python -m "
                                    f"validation.seed002_geometry run --out {out_dir})")
        probes[probe] = probe_summary(json.loads(p.read_text()), probe)
    doc = {"note": ("seed 002's campaign case at 1200 rpm, 80 % (physical, model B, the campaign's "
                    f"protocol) on one vane pitch ({SECTOR_DEG:g} degrees), the shipped slice and one "
                    "unstated dimension or the turbulence changed at a time; the rotor's throughflow "
                    "[m3/s] over the full circle; the return leg as "
                    "millfmu.dem.mills.accelerator.return_leg; other units as seed002_sector.json"),
           "case": S2._case_label(*CASE), "sector_deg": SECTOR_DEG,
           "protocol": {"spin_up_s": S2.SPIN_UP_S, "record_s": S2.RECORD_S, "window_s": S2.WINDOW_S,
                        "sample_every_s": S2.SAMPLE_S},
           "command": ("python -m validation.seed002_geometry run --out DIR --threads 1, then "
                       "python -m validation.seed002_geometry summarize --out DIR"),
           "probes": probes}
    out = Path(path)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def verdicts(doc: dict) -> dict:
    """Per probe: ``circulates`` (the return leg's R < 1), ``row_1`` (seed 002's row 1 on
    this one case: fastest bin at Z'/R >= 0.69 and speed near the shaft over speed at the
    wall > 1), the fastest bin's Z'/R and that ratio (NaN: no beads beyond Z'/R 0.85)."""
    out = {}
    for probe, p in doc["probes"].items():
        z, ratio = S2._profile_peak(p["stats"])
        out[probe] = {"circulates": p["return_leg"]["R"] is not None and p["return_leg"]["R"] < 1.0,
                      "row_1": bool(z >= 0.69 and math.isfinite(ratio) and ratio > 1.0),
                      "fastest_z_over_r": z, "shaft_over_wall": ratio}
    return out


def markdown(doc: dict) -> str:
    """The kept probes as a markdown table, one row a probe."""
    v = verdicts(doc)
    head = ("| probe | beads | local filling SEV_1 / SEV_2 / SEV_3 / SEV_4 | speed / tip SEV_1-4 | "
            "rotor throughflow [L/min] | return leg k beads / liquid | R | beads circulate (R < 1) | "
            "fastest bin Z'/R; shaft / wall | row 1 |")
    lines = [head, "|---" * 10 + "|"]
    for probe, p in doc["probes"].items():
        zones = p["stats"]["zones"]
        rl = p["return_leg"]
        pv = v[probe]
        ratio = "no beads beyond 0.85" if not math.isfinite(pv["shaft_over_wall"]) else \
            f"{pv['shaft_over_wall']:.2f}"
        lines.append(f"| {probe} | {p['beads']} | " + " / ".join(f"{z['filling']:.2f}" for z in zones)
                     + " | " + " / ".join(f"{z['speed_over_tip_speed']:.3f}" for z in zones)
                     + f" | {p['rotor_throughflow_m3_per_s'] * 6e4:.3g} | {rl['k_beads']:.3f} / "
                     f"{rl['k_liquid']:.3f} | {rl['R']:.2f} | {'yes' if pv['circulates'] else 'no'} | "
                     f"{pv['fastest_z_over_r']:.2f}; {ratio} | {'holds' if pv['row_1'] else 'missed'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.seed002_geometry",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "summarize", "table"))
    p.add_argument("--out", help="folder of the runs (needed by run and summarize)")
    p.add_argument("--probe", action="append", choices=tuple(PROBES),
                   help="run: only this probe (repeat for several; default all)")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    args = p.parse_args(argv)
    if args.action == "table":
        print(markdown(json.loads(SUMMARY.read_text())))
        return 0
    if not args.out:
        print(f"{args.action}: --out DIR is needed (the folder of the runs)", file=sys.stderr)
        return 2
    if args.action == "run":
        for d in run(args.out, probes=args.probe, threads=args.threads):
            print(f"wrote {d}")
        return 0
    return keep_and_show(summarize, args.out, markdown)


if __name__ == "__main__":
    sys.exit(main())
