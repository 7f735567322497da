"""Seed 001's full slice by seed 001's own protocol (2 s of spin-up, 1 s recorded with 50
samples) at 10 m/s, 80 %, and how its zones settle over the spin-up.

The full-slice column of docs/validation-seed001.md runs the campaign's shorter protocol:
1.0 s of spin-up from 0.1 of the stirrer's rotation, 0.3 s recorded. Its two cold runs of
this case end that spin-up with V1 at a local filling of 0.48 and 0.57. Started warm from
the settled 10-degree sector (:mod:`validation.full_slice_warm`), the full slice keeps the
sector's V1 at 0.40 over 0.5 s. Which of these beds seed 001's 2 s reach is what this
study measures:

- ``run``: the column's scene (:func:`validation.seed001.full_slice_scene`) with seed
  001's protocol: from rest, 2.0 s of spin-up, 1.0 s recorded with a sample every 0.02 s,
  in 0.1 s windows; 600,000 steps, about 6 h on 2 idle cores. It runs in a child process with a
  checkpoint every 300 s of wall time, and goes on from the checkpoint when started again.
  At each checkpoint the parent keeps the beads' positions and velocities in
  ``DIR/snapshots/snap_<step>.npz`` (13 MB each): the spin-up's course, which the run's
  own statistics (recording only) do not hold.
- ``trace``: each snapshot's local filling and mean bead speed over tip speed per zone, by
  the run statistics' own formulas (:func:`millfmu.dem.analysis.stats.compute_stats`, one
  sample each), then the recording's 0.1 s windows once the run has finished; keeps them
  with the run's compact statistics (:func:`validation.seed001.compact`) in
  ``validation/runs/seed001_full_paper.json`` and prints the table.

    python -m validation.full_slice_paper run --out DIR --threads 2
    python -m validation.full_slice_paper trace --out DIR

A study: nothing in the package imports it.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from pathlib import Path

import numpy as np

from validation import seed001 as S
from validation.run_summary import keep_and_show, read_windows

#: the case: seed 001's reference point, the one the cold and warm full slices ran
CASE = S.PAPER_CASE
#: seed 001's protocol (section 2): 2 s before the analysis, 1 s recorded with 50 samples,
#: the beads started from rest
SPIN_UP_S = 2.0
RECORD_S = 1.0
SAMPLE_EVERY_S = 0.02
INITIAL_ROTATION = 0.0
#: [s of wall time] between checkpoints, each giving a snapshot of the spin-up
CHECKPOINT_EVERY_S = 300.0
#: [s of wall time] between the parent's looks for a new checkpoint
POLL_S = 20.0
#: what this study keeps (seed 001's table takes the case from it once the run has finished)
SUMMARY = S.FULL_PAPER_SUMMARY


def scene():
    """The full slice at :data:`CASE` by seed 001's protocol."""
    return S.full_slice_scene(*CASE).with_overrides(
        spin_up_s=SPIN_UP_S, record_s=RECORD_S, sample_every_s=SAMPLE_EVERY_S,
        initial_rotation=INITIAL_ROTATION)


def case_dir(out_dir) -> Path:
    """The run's folder in ``out_dir``."""
    return S.paper_case_dir(out_dir)


def _child(d: str, sc, threads, checkpoint_every_s: float) -> None:
    """The run in the child process: ``sc`` from its start, or (None) from the checkpoint;
    it holds the folder's lock while it runs (exit code 3 where another process holds it)."""
    from millfmu.dem.run import resume_run, run_scene
    from millfmu.dem.tables.point_folders import hold

    lock = open(Path(d) / S.FULL_LOCK, "a+")
    if not hold(lock):
        sys.exit(3)
    if sc is not None:
        run_scene(sc, d, threads=threads, window_s=S.WINDOW_S, checkpoint_every_s=checkpoint_every_s,
                  progress=sys.stderr.isatty())
    else:
        resume_run(d, threads=threads, progress=sys.stderr.isatty())


def snapshot(d) -> Path | None:
    """Keep the beads' positions [m], velocities [m/s] and radii [m] of the run's
    checkpoint in ``d`` as ``d/snapshots/snap_<step>.npz`` (with t_s, the time [s]);
    None where the folder has no checkpoint."""
    from millfmu.dem.run import CHECKPOINT, DemRunError, load_checkpoint

    d = Path(d)
    if not (d / CHECKPOINT).exists():
        return None
    try:
        state = load_checkpoint(d)
    except DemRunError:  # replaced while being read: the next look takes the new one
        return None
    sim, done = state["sim"], int(state["loop"]["done"])
    out = d / "snapshots" / f"snap_{done:07d}.npz"
    out.parent.mkdir(exist_ok=True)
    tmp = out.with_name(out.name + ".tmp.npz")
    np.savez(tmp, t_s=done * sim.dt_s, step=done, x=sim.x, v=sim.v, rad=sim.rad)
    os.replace(tmp, out)
    return out


def run(out_dir, threads=None, sc=None, checkpoint_every_s: float = CHECKPOINT_EVERY_S,
        poll_s: float = POLL_S) -> Path:
    """Run (or go on with) the case (``sc``, default :func:`scene`) into :func:`case_dir`
    in a child process, keeping a snapshot at each checkpoint (written every
    ``checkpoint_every_s`` [s of wall time], looked for every ``poll_s`` [s]); says each on
    stderr; returns the folder."""
    from millfmu.dem.run import CHECKPOINT
    from millfmu.dem.tables.point_folders import hold

    d = case_dir(out_dir)
    if (d / "stats.json").exists():
        return d
    d.mkdir(parents=True, exist_ok=True)
    # a run whose parent was stopped goes on in its child: never two runs on one folder
    with open(d / S.FULL_LOCK, "a+") as lock:
        if not hold(lock):
            raise RuntimeError(f"{d}: run by another process (it holds {S.FULL_LOCK})")
    fresh = not (d / CHECKPOINT).exists()
    child = multiprocessing.get_context("spawn").Process(
        target=_child, args=(str(d), (sc or scene()) if fresh else None, threads, checkpoint_every_s))
    child.start()
    seen = (d / CHECKPOINT).stat().st_mtime if not fresh else None
    while child.is_alive():
        child.join(poll_s)
        p = d / CHECKPOINT
        m = p.stat().st_mtime if p.exists() else None
        if m is not None and m != seen:
            kept = snapshot(d)
            if kept is not None:
                seen = m
                print(f"{kept.name}: t = {float(np.load(kept)['t_s']):.3f} s", file=sys.stderr, flush=True)
    if child.exitcode == 3:
        raise RuntimeError(f"{d}: run by another process (it holds {S.FULL_LOCK})")
    if child.exitcode != 0:
        raise RuntimeError(f"{d}: the run stopped with exit code {child.exitcode}; "
                           "start it again to go on from its checkpoint")
    return d


def zone_state(sc, x, v, rad) -> dict:
    """{zone: (local filling [-], mean bead speed / tip speed [-])} of one state of the
    beads (positions [m], velocities [m/s], radii [m]), by the run statistics' formulas."""
    from millfmu.dem.analysis.stats import compute_stats
    from millfmu.dem.mills import zones_for

    st = compute_stats(
        scene=sc.name, zones=zones_for(sc), events=np.zeros((0, 7)),
        ev_cols=dict(type=0, x=1, y=2, z=3, setn=4, sets=5, serot=6),
        sample_x=[x], sample_v=[v], radii_m=rad, record_s=1.0,
        tip_speed_m_per_s=sc.tip_speed_m_per_s, omega_rad_per_s=sc.omega_rad_per_s,
        torque_on_stirrer_nm=0.0, ke_t_s=np.zeros(0), ke_j=np.zeros(0), spin_up_s=0.0,
        dt_s=sc.dt_s, filling=sc.filling, bulk_porosity=sc.bulk_porosity)
    return {z.name: (z.filling, z.speed_over_tip_speed) for z in st.zones}


def first_layer(sc, sample_x, sample_v) -> dict:
    """The first bead layer's mean angular velocity over the stirrer's [-] over the samples
    (positions [m], velocities [m/s]) by the run statistics' formula and layer
    (:data:`millfmu.dem.analysis.flow_structure.FIRST_LAYER_DIAMETERS`), and the bead
    samples it averages."""
    from millfmu.dem.analysis import flow_structure as FS

    ratio, n = FS.first_layer_angular_velocity(sample_x, sample_v, sc.geometry, sc.omega_rad_per_s,
                                               FS.FIRST_LAYER_DIAMETERS * sc.bead_diameter_m)
    return {"angular_velocity_ratio": ratio, "bead_samples": n}


def trace(out_dir) -> list:
    """The spin-up's course: per snapshot its time [s], per zone its local filling and mean
    bead speed / tip speed, and its first bead layer (:func:`first_layer`), in time order."""
    sc = scene()
    rows = []
    for p in sorted((case_dir(out_dir) / "snapshots").glob("snap_*.npz")):
        if p.name.endswith(".tmp.npz"):
            continue
        a = np.load(p)
        zs = zone_state(sc, a["x"], a["v"], a["rad"])
        rows.append({"t_s": float(a["t_s"]),
                     "zones": {z: {"filling": f, "speed_over_tip_speed": s} for z, (f, s) in zs.items()},
                     "first_layer": first_layer(sc, [a["x"]], [a["v"]])})
    return rows


def window_first_layers(d, record_s: float) -> list:
    """The first bead layer (:func:`first_layer`) of each recording window of a finished
    run in ``d`` that recorded ``record_s`` [s], from its kept samples
    (``bead_samples.npz``, evenly spaced), the windows' samples taken in order as the run
    cuts them."""
    a = np.load(Path(d) / "bead_samples.npz")
    x, v = a["x_m"].astype(float), a["v_m_per_s"].astype(float)
    per = max(1, round(S.WINDOW_S * len(x) / record_s))
    sc = scene()
    return [first_layer(sc, x[i:i + per], v[i:i + per]) for i in range(0, len(x), per)]


def keep(out_dir, path=SUMMARY) -> Path:
    """Keep the trace, and the run's windows and compact statistics where it has finished,
    in ``path``."""
    from validation.full_slice_warm import WINDOW_KEYS

    d = case_dir(out_dir)
    st = S.load_dir(d)
    vt, fill = CASE
    doc = {"note": ("seed 001's full slice (whole disc slice, gravity across the axis, coupled) at "
                    f"{S.case_label(vt, fill)} by seed 001's protocol; the spin-up's course from "
                    "snapshots of the run's checkpoints (one sample each), the recording's windows "
                    "and compact statistics as in seed001_sector.json (units: s, -, 1/(m3 s), W, J)"),
           "protocol": {"spin_up_s": SPIN_UP_S, "record_s": RECORD_S, "sample_every_s": SAMPLE_EVERY_S,
                        "initial_rotation": INITIAL_ROTATION, "window_s": S.WINDOW_S},
           "command": ("python -m validation.full_slice_paper run --out DIR --threads 2, then "
                       "python -m validation.full_slice_paper trace --out DIR"),
           "case": S.case_label(vt, fill), "tip_speed_m_per_s": vt, "filling": fill,
           "trace": trace(out_dir),
           "finished": st is not None}
    if st is not None:
        doc["windows"] = read_windows(d, WINDOW_KEYS)
        for w, fl in zip(doc["windows"], window_first_layers(d, st["record_s"]), strict=True):
            w["first_layer"] = fl
        doc["stats"] = S.compact(st)
    p = Path(path)
    p.write_text(json.dumps(doc, indent=1) + "\n")
    return p


#: [s] the page's table shows the course at this spacing (the first snapshot at or after
#: each multiple)
SHOWN_EVERY_S = 0.1


def shown(trace: list, every_s: float = SHOWN_EVERY_S) -> list:
    """The snapshots the table shows: the first at or after each multiple of ``every_s``
    [s], and the last."""
    out, mark = [], 0.0
    for r in trace:
        if r["t_s"] >= mark - 1e-9:
            out.append(r)
            mark = (int(r["t_s"] / every_s + 1e-9) + 1) * every_s
    if trace and out[-1] is not trace[-1]:
        out.append(trace[-1])
    return out


def markdown(doc: dict) -> str:
    """The kept course as a markdown table: per shown snapshot (:func:`shown`) and
    recording window each zone's local filling and mean bead speed / tip speed, and the
    first bead layer's angular velocity over the disc's."""
    rows = shown(doc["trace"])
    zones = list(rows[0]["zones"]) if rows else ["V1", "V2", "V3", "V4"]
    lines = ["| t [s] | " + " | ".join(f"filling {z}" for z in zones) + " | "
             + " | ".join(f"speed / tip {z}" for z in zones) + " | first layer / disc |",
             "|" + "---|" * (2 + 2 * len(zones))]

    def cells(label, r):
        return (f"| {label} | " + " | ".join(f"{r['zones'][z]['filling']:.3f}" for z in zones) + " | "
                + " | ".join(f"{r['zones'][z]['speed_over_tip_speed']:.4f}" for z in zones)
                + f" | {r['first_layer']['angular_velocity_ratio']:.3f} |")

    for r in rows:
        lines.append(cells(f"{r['t_s']:.3f}", r))
    for w in doc.get("windows", []):
        t = w["t_start_s"]
        lines.append(cells(f"{t:.1f}-{t + S.WINDOW_S:.1f} (window)", w))
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m validation.full_slice_paper",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "trace"))
    p.add_argument("--out", required=True, help="folder of the run")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    if args.action == "run":
        t0 = time.time()
        try:
            d = run(args.out, threads=args.threads)
        except RuntimeError as e:
            print(e, file=sys.stderr)
            return 1
        print(f"wrote {d} ({time.time() - t0:.0f} s)")
        return 0
    d = case_dir(args.out)
    if not (d / "snapshots").is_dir() and not (d / "stats.json").exists():
        print(f"{d}: no snapshots and no finished run (python -m "
              f"validation.full_slice_paper run --out {args.out})", file=sys.stderr)
        return 1
    return keep_and_show(keep, args.out, markdown)


if __name__ == "__main__":
    sys.exit(main())
