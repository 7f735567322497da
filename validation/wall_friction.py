"""Which contacts seed 001's first bead layer hangs on: the bead-disc (bead-wall) friction
against the bead-bead friction.

Seed 001 finds the first bead layer at the disc turning at 0.20-0.26 of the disc's angular
velocity and says (section 4) that this value depends on the friction coefficient; its
Table 1 gives one friction (0.3) and one rolling friction (0.10) for every contact. Our
runs put the layer at 0.15-0.17, and raising the one friction raised it (0.182 at 0.6,
0.400 at 1.0; ``validation/runs/seed001_friction.json``). This study raises the walls'
and the beads' coefficients apart (``[beads] wall_friction``, ``wall_rolling_friction``),
each case otherwise the reference protocol of that summary: the coupled 10-degree disc
sector without gravity at 10 m/s and 80 %, started at 0.1 of the stirrer's rotation, 0.565 s
of spin-up, 0.3 s recorded with a sample every 0.01 s in 0.1 s windows, one thread.
The cases are variants of seed 001's method (it has one coefficient for both): shown
beside its table, never counted.

    python -m validation.wall_friction run --out DIR [--case LABEL ...]
    python -m validation.wall_friction summarize --out DIR

``run`` runs the cases not finished in ``DIR`` one after the other (5-7 minutes each on one
core beside a 2-thread run); ``summarize`` keeps what ``millfmu dem compare`` shows of each finished case
in ``validation/runs/seed001_wall_friction.json``. A study: nothing in the package imports
it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

#: label -> the [beads] keys a case sets (beyond seed 001's Table 1 in disc_slice.toml)
CASES = {
    "Table 1 (0.3 and 0.10 at every contact)": {},
    "walls 0.6": {"wall_friction": 0.6},
    "walls 1.0": {"wall_friction": 1.0},
    "beads 1.0, walls 0.3": {"friction": 1.0, "wall_friction": 0.3},
    "walls without rolling friction": {"wall_rolling_friction": 0.0},
}
#: the reference protocol (validation/runs/seed001_friction.json)
PROTOCOL = dict(tip_speed_m_per_s=10.0, filling=0.8, sector_deg=10.0,
                gravity_m_per_s2=(0.0, 0.0, 0.0), spin_up_s=0.565, record_s=0.3,
                sample_every_s=0.01, initial_rotation=0.1)
WINDOW_S = 0.1
THREADS = 1
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed001_wall_friction.json"
COMMAND = ("millfmu dem run disc_slice.toml with [beads] {keys} --out DIR --tip-speed 10 "
           "--filling 0.8 --sector-deg 10 --no-gravity --spin-up 0.565 --record 0.3 "
           "--sample-every 0.01 --initial-rotation 0.1 --windows 0.1 --threads 1")


def case_scene(label: str):
    """The scene of case ``label``: disc_slice with the case's [beads] keys, by the
    reference protocol."""
    from millfmu.dem.scene import load_scene_dict, scene_from_dict

    if label not in CASES:
        raise ValueError(f"case {label!r}: allowed {list(CASES)}")
    d = load_scene_dict("disc_slice")
    d["beads"].update(CASES[label])
    return scene_from_dict(d).with_overrides(**PROTOCOL)


def case_dir(out_dir, label: str) -> Path:
    return Path(out_dir) / ("case_" + "".join(c if c.isalnum() else "_" for c in label).strip("_").lower())


def command(label: str) -> str:
    keys = ", ".join(f"{k} = {v:g}" for k, v in CASES[label].items()) or "as shipped"
    return COMMAND.format(keys=keys)


def run(out_dir, labels=None, say=None) -> list[Path]:
    """Run the cases ``labels`` (default all) not finished in ``out_dir``; returns their
    folders."""
    from millfmu.dem.run import run_scene

    say = say or (lambda m: print(m, file=sys.stderr, flush=True))
    done = []
    for label in labels or list(CASES):
        sc = case_scene(label)
        d = case_dir(out_dir, label)
        if not (d / "stats.json").exists():
            say(f"{label}: running into {d}")
            run_scene(sc, d, threads=THREADS, window_s=WINDOW_S, progress=False)
        done.append(d)
    return done


def summarize(out_dir, path=SUMMARY) -> Path:
    """Keep the finished cases of ``out_dir`` (:func:`validation.run_summary.summary`) in
    ``path``; FileNotFoundError naming the cases not run."""
    from validation.run_summary import summary, write_json

    missing = [lab for lab in CASES if not (case_dir(out_dir, lab) / "stats.json").exists()]
    if missing:
        raise FileNotFoundError(f"{out_dir}: cases not run: {missing} (python -m "
                                f"validation.wall_friction run --out {out_dir})")
    doc = summary({lab: case_dir(out_dir, lab) for lab in CASES},
                  {lab: command(lab) for lab in CASES},
                  note=("Seed 001's first bead layer against the bead-wall and the bead-bead "
                        "friction apart (variants: seed 001 has one coefficient for both); "
                        "the coupled 10 degree disc sector without gravity at 10 m/s and 80 %, "
                        "the reference protocol of seed001_friction.json; python -m "
                        "validation.wall_friction run --out DIR, then summarize --out DIR"))
    write_json(path, doc)
    return Path(path)


#: (column, quantity of the summary, seed 001's band or None) of the table
COLUMNS = (("first layer / disc", "first bead layer / disc angular velocity", "layer"),
           ("speed / tip V1", "bead speed / tip speed V1", "V1"),
           ("speed / tip V2", "bead speed / tip speed V2", "V2"),
           ("speed / tip V3", "bead speed / tip speed V3", "V3"),
           ("median SE_tn V2 [J]", "median SE_tn V2", None),
           ("power number", "power number", None),
           ("liquid's share of the stirrer torque", "stirrer torque: fluid shear share", None))


def band(key):
    """Seed 001's (lo, hi) for a column's band key (validation.seed001)."""
    from validation import seed001 as S

    return S.FIRST_LAYER_BAND if key == "layer" else S.SPEED_BANDS[key]


def markdown(doc: dict) -> str:
    """The kept cases as a table: the first layer, the zone speeds, V2's median SE_tn, the
    power number and the liquid's share of the stirrer torque; a figure within seed 001's
    band (its tolerance, :func:`validation.seed001.within_band`) is marked, and the last
    column counts them."""
    from validation import seed001 as S

    lines = ["| case | " + " | ".join(c for c, _, _ in COLUMNS) + " | within seed 001's bands |",
             "|" + "---|" * (len(COLUMNS) + 2)]
    for label, run in doc["runs"].items():
        v = run["values"]
        cells, held = [], []
        for col, q, key in COLUMNS:
            x = v[q]
            txt = f"{x:.3g}"
            if key is not None and S.within_band(x, *band(key)):
                txt += " (in band)"
                held.append(col.split(" / ")[0] if key == "layer" else key)
            cells.append(txt)
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {len(held)} of 4"
                     + (f": {', '.join(held)}" if held else "") + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.wall_friction",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "summarize"))
    p.add_argument("--out", required=True, help="folder of the runs")
    p.add_argument("--case", action="append", metavar="LABEL", help=f"one of {list(CASES)}")
    args = p.parse_args(argv)
    try:
        if args.action == "run":
            for d in run(args.out, args.case):
                print(d)
        else:
            kept = summarize(args.out)
            print(markdown(json.loads(kept.read_text())))
    except (ValueError, FileNotFoundError) as e:
        print(e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
