"""Seed 001's full slice started warm: the whole disc slice with gravity (seed 001's own
configuration) from the settled 10-degree sector, against the same case started cold.

A full-slice case started cold takes 1.3 s of coupled motion (1.0 s of spin-up, 0.3 s
recorded), 2.5-4 hours on 2 cores. Its beads spend most of that spin-up reaching the
bed the 10-degree sector reaches too: without gravity the sector is the full slice's bed
but for what gravity adds. This study starts the full slice from the settled sector instead,
as the coupled table's new points start from its anchor (:mod:`millfmu.dem.tables.warm_start`):

- the state: the coupled table's shipped anchor (``millfmu/data/coupled_anchor.state.npz``:
  the campaign's scene, 10 m/s, 80 %, 10-degree sector without gravity, after 1.9 s of
  coupled motion), its velocities scaled to the case's tip speed
  (:func:`~millfmu.dem.tables.warm_start.scaled`);
- its beads repeated around the axis, 36 copies turned by 10 degrees each (positions,
  velocities, spins; the liquid's velocity and pressure gradient at each bead are
  cylindrical components and stay as they are), the liquid's axisymmetric fields repeated
  over the full slice's 32 theta cells;
- the beads the full slice holds beyond 36 sectors' (235,305 against 235,296 at 80 %:
  the filling's count is not a multiple of 36) placed at rest in free space of the bed
  (:func:`add_beads`, out of contact with every bead and wall);
- then ``--spin-up`` [s] with gravity (the scene's, across the axis) and the campaign's
  recording (0.3 s, a sample every 0.01 s, 0.1 s windows).

    python -m validation.full_slice_warm run --out DIR [--case 10:0.8] [--spin-up 0.3] --threads 2
    python -m validation.full_slice_warm compare --out DIR

``run`` goes on from the case's checkpoint where it has one. ``compare`` puts the warm run
beside the shipped cold run of the same case (``full_slice`` of
``validation/runs/seed001_sector.json``): every quantity seed 001's statements read, their
difference, and each statement's verdict at the case from either run (computed by
:func:`validation.seed001.deviation_rows`); it keeps the warm run's compact statistics and
the comparison in ``validation/runs/seed001_full_warm.json``. A study: nothing in the
package imports it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from validation import seed001 as S
from validation.run_summary import read_windows

#: the state the full slice starts from: the coupled table's anchor (the campaign's scene
#: in the 10-degree sector without gravity, 10 m/s, 80 %)
ANCHOR = Path(__file__).resolve().parents[1] / "millfmu" / "data" / "coupled_anchor.state.npz"
#: spin-up [s] after the warm start, with gravity
SPIN_UP_S = 0.2
#: an added bead's centre lies at least this many bead diameters from every bead's centre,
#: its surface at least this many less one from the shaft, the chamber wall and the disc's
#: faces (it starts at rest, out of contact)
ADD_CLEARANCE = 1.05
#: what this study keeps
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed001_full_warm.json"
#: the seed of the added beads' positions
SEED = 1


def case_dir(out_dir, vt: float, fill: float) -> Path:
    return Path(out_dir) / f"w360_v{vt:g}_f{round(100 * fill)}"


def replicate(arrays: dict, sector_deg: float, n_theta: int) -> dict:
    """The state of a rotationally periodic sector of ``sector_deg`` [degrees] repeated
    around the axis (z) to the whole circle: 360 / sector_deg copies of the beads, copy k
    turned by k sector_deg (positions [m], velocities [m/s], spins [rad/s]); per-bead
    cylindrical fields (``fluid_at_bead``) repeated as they are; the liquid's fields, one
    theta cell in the sector, repeated over ``n_theta`` theta cells. ValueError where the
    sector does not divide the circle or the liquid is not axisymmetric."""
    copies = 360.0 / sector_deg
    if abs(copies - round(copies)) > 1e-9:
        raise ValueError(f"sector_deg = {sector_deg!r}: 360 is not a multiple of it")
    copies = int(round(copies))
    out = {}
    for key in ("x_m", "v_m_per_s", "w_rad_per_s"):
        a = np.asarray(arrays[key], np.float64)
        parts = []
        for k in range(copies):
            t = math.radians(k * sector_deg)
            c, s = math.cos(t), math.sin(t)
            b = a.copy()
            b[:, 0] = c * a[:, 0] - s * a[:, 1]
            b[:, 1] = s * a[:, 0] + c * a[:, 1]
            parts.append(b)
        out[key] = np.concatenate(parts)
    if "fluid_at_bead" in arrays:
        out["fluid_at_bead"] = np.tile(np.asarray(arrays["fluid_at_bead"], np.float64), (copies, 1))
    for key, a in arrays.items():
        if key.startswith("liquid_"):
            a = np.asarray(a, np.float64)
            if a.ndim != 3 or a.shape[1] != 1:
                raise ValueError(f"{key}: shape {a.shape}, not one theta cell")
            out[key] = np.repeat(a, n_theta, axis=1)
    return out


def add_beads(arrays: dict, count: int, geometry, radius_m: float, seed: int = SEED) -> dict:
    """``count`` beads added at rest to the state ``arrays`` (whole circle) at random free
    places: centre at least :data:`ADD_CLEARANCE` diameters from every bead (its axial
    periodic images too), surface at least ADD_CLEARANCE - 1 diameters from the shaft, the
    chamber wall and the disc (its faces inside the disc's radius). Their liquid values at
    the bead are the nearest bead's. Returns a new state."""
    from scipy.spatial import cKDTree

    from millfmu.dem.analysis.flow_structure import fold_zeta

    if count <= 0:
        return dict(arrays)
    g = geometry
    d = 2.0 * radius_m
    clear = ADD_CLEARANCE * d
    x = np.asarray(arrays["x_m"], np.float64)
    lz = g.height_m
    tree = cKDTree(np.concatenate([x, x + [0, 0, lz], x - [0, 0, lz]]))
    rng = np.random.default_rng(seed)
    new = []
    tries = 0
    while len(new) < count:
        tries += 1
        if tries > 200000:
            raise RuntimeError(f"no free place for {count - len(new)} more beads")
        r = rng.uniform(g.shaft_radius_m + radius_m + clear - d, g.chamber_radius_m - radius_m - clear + d)
        t = rng.uniform(0.0, 2.0 * math.pi)
        z = rng.uniform(0.0, lz)
        zeta = fold_zeta(z, g.disc_z_m, lz)
        if r < g.disc_radius_m + radius_m + clear - d and abs(zeta) < 0.5 * g.disc_thickness_m + radius_m + clear - d:
            continue
        p = np.array([r * math.cos(t), r * math.sin(t), z])
        if tree.query(p)[0] < clear:
            continue
        if any(np.linalg.norm(p - q) < clear for q in new):
            continue
        new.append(p)
    new = np.array(new)
    out = dict(arrays)
    out["x_m"] = np.concatenate([x, new])
    for key in ("v_m_per_s", "w_rad_per_s"):
        out[key] = np.concatenate([np.asarray(arrays[key], np.float64), np.zeros((count, 3))])
    if "fluid_at_bead" in arrays:
        near = cKDTree(x).query(new)[1]
        fab = np.asarray(arrays["fluid_at_bead"], np.float64)
        out["fluid_at_bead"] = np.concatenate([fab, fab[near]])
    return out


def warm_arrays(scene, state_path=ANCHOR):
    """(arrays, start record) of the full slice ``scene`` from the sector state at
    ``state_path``: scaled to the scene's tip speed, repeated around the axis, the beads
    the scene's filling holds beyond the copies added (:func:`add_beads`)."""
    from millfmu.dem.mills.geometry import bead_count_for_filling
    from millfmu.dem.tables.warm_start import read_state, scaled

    arrays, meta = read_state(state_path)
    sc = meta["scene"]
    sector = float(sc["mill"]["sector_deg"])
    v0 = float(sc["mill"]["tip_speed_m_per_s"])
    if abs(float(sc["beads"]["filling"]) - scene.filling) > 1e-12:
        raise ValueError(f"{state_path}: filling {sc['beads']['filling']}, the case's {scene.filling}: "
                         "a warm start keeps the sector's beads")
    ratio = scene.tip_speed_m_per_s / v0
    rep = replicate(scaled(arrays, ratio), sector, scene.coupling.n_theta)
    n = bead_count_for_filling(scene.geometry, scene.filling, scene.bead_diameter_m, scene.bulk_porosity)
    added = n - len(rep["x_m"])
    if added < 0:
        raise ValueError(f"the copies hold {len(rep['x_m'])} beads, the case {n}")
    full = add_beads(rep, added, scene.geometry, 0.5 * scene.bead_diameter_m)
    start = {"start": "warm, from the settled sector repeated around the axis",
             "state": state_path.name if isinstance(state_path, Path) else str(state_path),
             "state_scene": {"sector_deg": sector, "tip_speed_m_per_s": v0,
                             "filling": float(sc["beads"]["filling"]),
                             "gravity_m_per_s2": sc["run"].get("gravity_m_per_s2"),
                             "coupled_motion_s": float(sc["run"]["spin_up_s"]) + float(sc["run"]["record_s"])},
             "speed_scale": ratio, "copies": int(round(360.0 / sector)), "beads_added_at_rest": added,
             "spin_up_s": scene.spin_up_s}
    return full, start


def run_case(out_dir, vt: float = 10.0, fill: float = 0.8, spin_up_s: float = SPIN_UP_S,
             threads=None, progress: bool = True) -> Path:
    """Run the full slice at ``vt`` [m/s], ``fill`` [-] warm into :func:`case_dir` (from its
    checkpoint where it has one); returns the folder."""
    from millfmu.dem.run import CHECKPOINT, resume_run, run_scene
    from millfmu.dem.tables.warm_start import _loop, warm_simulation

    d = case_dir(out_dir, vt, fill)
    if (d / "stats.json").exists():
        return d
    d.mkdir(parents=True, exist_ok=True)
    if (d / CHECKPOINT).exists():
        print(f"{d}: going on from its checkpoint", file=sys.stderr, flush=True)
        resume_run(d, progress=progress, threads=threads)
        return d
    scene = S.full_slice_scene(vt, fill).with_overrides(spin_up_s=float(spin_up_s))
    arrays, start = warm_arrays(scene)
    (d / "warm_start.json").write_text(json.dumps(start, indent=1) + "\n")
    sim, cpl = warm_simulation(scene, arrays, threads)
    run_scene(scene, d, progress=progress, threads=threads, window_s=S.WINDOW_S,
              checkpoint_every_s=S.FULL_CHECKPOINT_EVERY_S,
              _state=dict(sim=sim, cpl=cpl, loop=_loop(scene, sim)))
    return d


def _zone(st, name, key):
    return S.zone(st, name)[key]


#: What the comparison reads of a run's compact statistics (:func:`validation.seed001.compact`):
#: (label, unit, value)
QUANTITIES = tuple(
    [(f"bead speed / tip speed {z}", "-", lambda st, z=z: _zone(st, z, "speed_over_tip_speed"))
     for z in ("V1", "V2", "V3", "V4")]
    + [(f"collision density {z}", "1/(m3 s)", lambda st, z=z: _zone(st, z, "collision_frequency_per_m3_s"))
       for z in ("V1", "V2", "V3", "V4")]
    + [(f"collision power {z}", "W", lambda st, z=z: _zone(st, z, "collision_power_w"))
       for z in ("V1", "V2", "V3", "V4")]
    + [(f"median SE_tn {z}", "J", lambda st, z=z: S.zone(st, z)["se"]["tn"]["quantiles_j"]["q50"])
       for z in ("V1", "V2", "V3", "V4")]
    + [("first bead layer / disc angular velocity", "-",
        lambda st: st["flow"]["first_bead_layer_angular_velocity_ratio"]),
       ("collision frequency peak from the wall", "m",
        lambda st: st["maps"]["frequency_peak"]["from_wall_m"]),
       ("collision power peak from the disc's rim", "m",
        lambda st: st["maps"]["power_peak"]["from_rim_m"])])


def _summary_with(summary_doc: dict, label: str, vt: float, fill: float, stats: dict) -> dict:
    """The summary ``summary_doc`` with its full slice holding only ``stats`` at the case."""
    doc = json.loads(json.dumps(summary_doc))
    full = doc.setdefault("full_slice", {})
    full["runs"] = {label: {"tip_speed_m_per_s": vt, "filling": fill, "stats": stats}}
    return doc


def comparison(warm: dict, vt: float = 10.0, fill: float = 0.8, summary=None) -> dict:
    """The warm run's compact statistics ``warm`` beside the cold run of the same case that
    the seed 001 summary ``summary`` (default the shipped one) keeps: each of
    :data:`QUANTITIES` (warm, cold, relative difference) and each statement's full-slice
    cell from either run (:func:`validation.seed001.deviation_rows`, the full slice holding
    that one case) with whether it holds there. ValueError where the summary has no cold
    run of the case."""
    path = Path(summary) if summary is not None else S.SUMMARY
    doc = json.loads(path.read_text())
    cold = S.summary_stats(path, full_slice=True).get((vt, fill))
    label = S.case_label(vt, fill)
    if cold is None:
        raise ValueError(f"{path}: no cold full-slice run at {label}")
    quantities = []
    for name, unit, fn in QUANTITIES:
        w, c = float(fn(warm)), float(fn(cold))
        quantities.append({"quantity": name, "unit": unit, "warm": w, "cold": c,
                           "relative_difference": (w - c) / c if c else None})
    cells = {}
    with tempfile.TemporaryDirectory() as tmp:
        for which, st in (("warm", warm), ("cold", cold)):
            p = Path(tmp) / f"{which}.json"
            p.write_text(json.dumps(_summary_with(doc, label, vt, fill, st)))
            cells[which] = S.deviation_rows(summary=p)
    statements = []
    for rw, rc in zip(cells["warm"], cells["cold"]):
        statements.append({"statement": rw["statement"], "warm": rw["full"], "cold": rc["full"],
                           "warm_state": rw["full_state"], "cold_state": rc["full_state"]})
    judged = [s for s in statements if s["cold_state"] != "not judged" or s["warm_state"] != "not judged"]
    same = sum(s["warm_state"] == s["cold_state"] for s in judged)
    return {"case": label, "quantities": quantities, "statements": statements,
            "statements_judged": len(judged), "statements_same": same}


def keep(out_dir, vt: float, fill: float, path=SUMMARY) -> Path:
    """Keep the warm run of the case in ``out_dir`` (its compact statistics and how it
    started) in ``path``, beside the runs kept there before. FileNotFoundError where
    the run has not finished."""
    d = case_dir(out_dir, vt, fill)
    st = S.load_dir(d)
    if st is None:
        raise FileNotFoundError(f"{d}: no stats.json (run it: python -m validation.full_slice_warm "
                                f"run --out {out_dir} --case {vt:g}:{fill:g})")
    start = json.loads((d / "warm_start.json").read_text())
    p = Path(path)
    doc = json.loads(p.read_text()) if p.exists() else {}
    runs = dict(doc.get("runs", {}))
    runs[S.case_label(vt, fill)] = {"tip_speed_m_per_s": vt, "filling": fill, "start": start,
                                    "stats": S.compact(st), "windows": read_windows(d, WINDOW_KEYS)}
    doc = {"note": ("seed 001's full slice (whole disc slice, gravity across the axis, coupled) "
                    "started warm from the settled 10-degree sector repeated around the axis; "
                    "compact statistics as in seed001_sector.json (units: m3, 1/(m3 s), W, J)"),
           "protocol": {"spin_up_s_after_the_start": start["spin_up_s"], "record_s": S.RECORD_S,
                        "window_s": S.WINDOW_S, "sample_every_s": 0.01,
                        "sector_deg": S.FULL_SECTOR_DEG, "theta_cells": S.FULL_THETA_CELLS,
                        "gravity_m_per_s2": "the scene's"},
           "command": ("python -m validation.full_slice_warm run --out DIR --case V:F --threads 2, "
                       "then python -m validation.full_slice_warm compare --out DIR"),
           "runs": runs}
    p.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return p


#: what :func:`keep` keeps of each 0.1 s window per zone (``windows.csv``; units: -, -,
#: 1/(m3 s), J)
WINDOW_KEYS = ("filling", "speed_over_tip_speed", "collision_frequency_per_m3_s", "se_tn_q50_j")


def windows_markdown(windows: list) -> str:
    """The kept windows as a markdown table: per zone its local filling and median SE_tn
    in each window."""
    zones = list(windows[0]["zones"])
    head = "| window [s] | " + " | ".join(f"filling {z}" for z in zones) + " | " + \
        " | ".join(f"median SE_tn {z} [J]" for z in zones) + " |"
    lines = [head, "|" + "---|" * (1 + 2 * len(zones))]
    for w in windows:
        t = w["t_start_s"]
        lines.append(f"| {t:.1f}-{t + S.WINDOW_S:.1f} | "
                     + " | ".join(f"{w['zones'][z]['filling']:.3f}" for z in zones) + " | "
                     + " | ".join(f"{w['zones'][z]['se_tn_q50_j']:.3g}" for z in zones) + " |")
    return "\n".join(lines)


def _kept(path, field: str) -> dict:
    """{(tip speed, filling): run[field]} of the kept warm runs in ``path``, {} where none."""
    p = Path(path)
    if not p.exists():
        return {}
    doc = json.loads(p.read_text())
    return {(r["tip_speed_m_per_s"], r["filling"]): r[field] for r in doc.get("runs", {}).values()}


def kept_windows(path=SUMMARY) -> dict:
    """{(tip speed, filling): windows} of the kept warm runs
    (:func:`validation.run_summary.read_windows` of :data:`WINDOW_KEYS`)."""
    return _kept(path, "windows")


def kept_runs(path=SUMMARY) -> dict:
    """{(tip speed, filling): compact stats} of the kept warm runs, {} where none."""
    return _kept(path, "stats")


def markdown(cmp: dict) -> str:
    """The comparison as two markdown tables (quantities; statements)."""
    lines = [f"| {cmp['case']} | warm | cold | warm / cold - 1 |", "|---|---|---|---|"]
    for q in cmp["quantities"]:
        rd = q["relative_difference"]
        lines.append(f"| {q['quantity']} [{q['unit']}] | {q['warm']:.4g} | {q['cold']:.4g} | "
                     + ("-" if rd is None else f"{rd:+.1%}") + " |")
    lines += ["", "| statement | warm | cold |", "|---|---|---|"]
    for s in cmp["statements"]:
        lines.append(f"| {s['statement']} | {s['warm_state']} | {s['cold_state']} |")
    lines.append("")
    lines.append(f"The same at {cmp['statements_same']} of the {cmp['statements_judged']} statements "
                 "either run judges.")
    return "\n".join(lines)


def compare_main(out_dir, vt: float, fill: float) -> int:
    try:
        kept = keep(out_dir, vt, fill)
    except FileNotFoundError as e:
        print(e, file=sys.stderr)
        return 1
    warm = kept_runs(kept)[(vt, fill)]
    try:
        cmp = comparison(warm, vt, fill)
    except ValueError as e:
        print(e, file=sys.stderr)
        return 1
    print(markdown(cmp))
    print()
    print(windows_markdown(kept_windows(kept)[(vt, fill)]))
    print(f"kept in {kept}")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m validation.full_slice_warm",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("action", choices=("run", "compare"))
    p.add_argument("--out", required=True, help="folder of the runs")
    p.add_argument("--case", default="10:0.8",
                   help="TIP_SPEED:FILLING, a case whose cold run the summary keeps (default 10:0.8)")
    p.add_argument("--spin-up", type=float, default=SPIN_UP_S,
                   help=f"spin-up after the warm start [s] (default {SPIN_UP_S})")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        (vt, fill), = S.parse_cases([args.case])
    except ValueError as e:
        print(e, file=sys.stderr)
        return 2
    if not args.spin_up > 0.0 or not math.isfinite(args.spin_up):
        print(f"--spin-up {args.spin_up!r}: a duration above 0 s", file=sys.stderr)
        return 2
    if args.action == "run":
        d = run_case(args.out, vt, fill, args.spin_up, threads=args.threads)
        print(f"wrote {d}")
        return 0
    return compare_main(args.out, vt, fill)


if __name__ == "__main__":
    raise SystemExit(main())
