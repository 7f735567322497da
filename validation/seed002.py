"""Seed 002 side by side: the statements of He et al. (2022) on the accelerator mill against
millfmu's accelerator slice with the coupled fluid.

From a checkout's root, ``python -m validation.seed002 run --out DIR`` runs the cases
(accelerator_slice, 60 degree sector without gravity (SECTOR_DEG); 800, 1000, 1200, 1400 rpm
at 80 % filling and 60, 70, 80, 90 % at 1200 rpm) into ``DIR/n<rpm>_f<filling %>``;
``python -m validation.seed002 table --out DIR`` reads their ``stats.json`` and prints one
row per statement: the paper's, ours, the verdict. ``python -m validation.seed002 summarize
--out DIR --label NAME`` keeps what the table reads of a campaign's runs (zone statistics,
no contacts) in ``validation/runs/seed002_sector.json``; ``python -m validation.seed002
table`` computes the table from that summary. Statements are counted on the paper's
configuration and start: a campaign with stationary baffles (``--baffles``; seed 002's mill
has none) or a primed start (``--primed``; seed 002 starts from rest) is a variant, shown
in its own column and never counted as a match. ``--full-slice`` runs the paper's own slice
(360 degrees, gravity across the axis) instead of the sector; one case of it is judged on
that case, shown and not counted as a match of a statement made over the cases.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from millfmu.dem.mills.accelerator import ZONE_NAMES

#: (rotor speed [rpm], filling [-]) of seed 002's cases
SPEEDS = (800.0, 1000.0, 1200.0, 1400.0)
FILLINGS = (0.6, 0.7, 0.8, 0.9)
CASES = tuple([(n, 0.8) for n in SPEEDS] + [(1200.0, f) for f in FILLINGS if f != 0.8])

#: protocol: a 60 degree sector (two vane pitches) without gravity, the beads and liquid
#: from rest; spin-up before the recording and the recording [s], windows of WINDOW_S
#: for the stationarity check, samples every SAMPLE_S (seed 002: 20 per second). At
#: 1200 rpm and 80 % a 30 degree sector (one vane pitch) gave the same zone speeds (0.1 %),
#: fillings (0.02) and stress numbers (within 8 %), but collision energies in SEV_1 25-40 %
#: lower (SE_cs,sum -30 %), steady over its windows: 30 degrees constrain the packed layer
#: at the wall. 90 degrees (three pitches) change the figures by less than a second random
#: placement of the beads does, but for SEV_1's collision density (-9 %;
#: validation.seed002_sector_size, docs/validation-seed002-sector.md).
SECTOR_DEG = 60.0
SPIN_UP_S = 1.0
RECORD_S = 0.5
WINDOW_S = 0.1
SAMPLE_S = 0.05


def case_dir(out_dir, rpm: float, filling: float) -> Path:
    return Path(out_dir) / f"n{rpm:g}_f{round(filling * 100)}"


#: seed 002's spin-up and recording [s] (section 2.3: "Data analysis started after a
#: processing time of 2 s"; SN_g and the energies evaluated over 1 s)
PAPER_PROTOCOL = {"spin_up_s": 2.0, "record_s": 1.0}

#: How a campaign computes and counts (``seed002 run --method``):
#: - ``physical``: the accelerator slice's own coupling (volume-averaged liquid, model B,
#:   exchange every 5e-5 s); contacts counted at every event;
#: - ``paper``: seed 002's numerics: a dilute discrete phase model (no void fraction in the
#:   liquid, drag only, CFD step 0.01 s; :mod:`millfmu.dem.coupling.dpm`) with the drag law
#:   it adopted, Koch and Hill's at the beads' void fraction; its spin-up (2 s) and
#:   recording (1 s) (:data:`PAPER_PROTOCOL`); contacts counted at its 20 frames per second
#:   (``flow.seed002.snapshots``);
#: - ``paper-SN``: as ``paper`` with an isolated sphere's drag (Schiller-Naumann) and the
#:   campaigns' shorter protocol;
#: - ``physical-A``: as ``physical`` with model A (the beads feel the liquid's pressure
#:   gradient: the swirl's radial pressure gradient pushes them inwards with rho_f / rho_b
#:   of their centrifugal force, which model B leaves out), the gradient of the interval
#:   just solved (``pressure_gradient = "this_interval"``: with the previous interval's the
#:   packed wall layer's compaction and pressure oscillate and the run blows up at 0.83 s).
METHODS = {"physical": dict(scheme="vans", counting="events"),
           "paper": dict(scheme="dpm", counting="snapshots", dpm_drag="koch_hill2001",
                         protocol=PAPER_PROTOCOL),
           "paper-SN": dict(scheme="dpm", counting="snapshots"),
           "physical-A": dict(scheme="vans", model="A", counting="events",
                              pressure_gradient="this_interval")}
#: seed 002's CFD step [s]
PAPER_CFD_STEP_S = 0.01


def protocol_of(method: str) -> dict:
    """Spin-up and recording [s] of a campaign by ``method``: its own where
    :data:`METHODS` gives one (seed 002's for ``paper``), else the campaigns' shorter
    :data:`SPIN_UP_S` and :data:`RECORD_S`."""
    return dict(METHODS[method].get("protocol") or {"spin_up_s": SPIN_UP_S, "record_s": RECORD_S})


#: seed 002's highest local stress number [1/(m3 s)]: "more than 15 x 10^8" at 1400 rpm and
#: 80 % (section 3.4, figure 13b), the top of its colour scale
PAPER_PEAK_SN_G = 1.5e9
#: primed start: bead-free liquid time before the beads go in [s] (at 1200 rpm the rotor's
#: bead-free throughflow changed by less than 0.05 % from 0.15 to 0.4 s)
PRIMED_S = 0.3


#: stationary baffles between the rotors (``seed002 run --baffles``), pin-mill style: one
#: radial plate per 60 degrees on the chamber wall, 2 mm thick (2.5 bead diameters), from
#: the wall in to r = 16 mm (2 mm outside the eye, so the eye stays free: Z'/R 0.7, the
#: smooth zone's edge), 4 mm high in the 7 mm gap between two rotors (1.5 mm, about two
#: bead diameters, to either rotor's face); at 32.5 degrees, the centre of a theta column
#: of the liquid. Assumed: seed 002's mill has none; they test whether a slower return leg
#: (R < 1) lets the beads circulate.
BAFFLES = dict(baffle_count=6, baffle_thickness_m=0.002, baffle_inner_radius_m=0.016,
               baffle_height_m=0.004, baffle_angle_deg=32.5)
#: theta cells of the liquid per 60 degrees with baffles: 5-degree columns, the baffle's
#: 1.4 mm (r = 16 mm) to 2.6 mm (wall) wide, about the plate's 2 mm
BAFFLE_THETA_CELLS_PER_60_DEG = 12

#: seed 002's own configuration (``seed002 run --full-slice``): the whole 360-degree slice with
#: gravity across the mill's axis, as ``validation/scenes/accelerator_full_gravity.toml``;
#: the liquid in one theta cell
FULL_SLICE = {"sector_deg": 360.0, "gravity_m_per_s2": (0.0, -9.81, 0.0)}
#: seed 002 figure 8b's maximum "at about Rpa = 60 degrees": by its figure 9 the beads moving
#: up the rising side are slowed by gravity's tangential part (largest at Rpa = 0, level with
#: the axis; zero at +-90, below and above it) and gather between the bottom (+90) and the
#: level (0), so 60 degrees is 30 degrees past the bottom in the direction of rotation: 210
#: degrees of the azimuth that ``flow.circumferential`` counts from the top with the rotation
PAPER_MAX_AZIMUTH_DEG = 210.0
#: a circumferential maximum counts where its 30-degree bin exceeds the bins' mean by more
#: than this (two full-slice realizations, 1 and 16 liquid theta cells, kept every bin within
#: 1 % of the mean) and its centre lies within a bin of PAPER_MAX_AZIMUTH_DEG
CIRC_MAX_OVER_MEAN = 1.02


def scene_for(rpm: float, filling: float, sector_deg: float | None = None,
              method: str = "physical", primed: bool = False, baffles: bool = False,
              full_slice: bool = False, changes: dict | None = None):
    """The accelerator slice at ``rpm`` [1/min] and ``filling`` [-] with the protocol,
    computed by ``method`` (:data:`METHODS`), with a primed start or from rest, with the
    stationary :data:`BAFFLES` or without; ``full_slice``: the paper's whole slice with
    gravity (:data:`FULL_SLICE`) instead of the sector without. ``changes``: scene-file
    values put in before the scene is validated, {"table.key": value} (``"mill.rotor_radius_m"``,
    ``"fluid.coupled.turbulence"``), for studies of the dimensions seed 002 does not state."""
    from millfmu.dem.scene import load_scene_dict, scene_from_dict

    if method not in METHODS:
        raise ValueError(f"method = {method!r}: allowed {list(METHODS)}")
    d = load_scene_dict("accelerator_slice")
    for dotted, value in (changes or {}).items():
        *tables, key = dotted.split(".")
        t = d
        for name in tables:
            t = t.setdefault(name, {})
        t[key] = value
    c = d["fluid"].setdefault("coupled", {})
    if METHODS[method]["scheme"] == "dpm":
        c.pop("vans_model", None)
        c.update(scheme="dpm", cfd_step_s=PAPER_CFD_STEP_S)
        if "dpm_drag" in METHODS[method]:
            c["dpm_drag"] = METHODS[method]["dpm_drag"]
    elif "model" in METHODS[method]:
        c["vans_model"] = METHODS[method]["model"]
        if "pressure_gradient" in METHODS[method]:
            c["pressure_gradient"] = METHODS[method]["pressure_gradient"]
    if full_slice and (baffles or sector_deg is not None):
        raise ValueError("full_slice: the paper's whole slice, without baffles or another sector")
    sector_deg = FULL_SLICE["sector_deg"] if full_slice else SECTOR_DEG if sector_deg is None \
        else sector_deg
    gravity = FULL_SLICE["gravity_m_per_s2"] if full_slice else (0.0, 0.0, 0.0)
    if baffles:
        d["mill"].update(BAFFLES)
        d["mill"]["sector_deg"] = sector_deg
        c["n_theta"] = int(round(BAFFLE_THETA_CELLS_PER_60_DEG * sector_deg / 60.0))
    base = scene_from_dict(d)
    tip = rpm * 2.0 * math.pi / 60.0 * base.geometry.disc_radius_m
    return base.with_overrides(tip_speed_m_per_s=tip, filling=filling, sector_deg=sector_deg,
                               gravity_m_per_s2=gravity, **protocol_of(method),
                               sample_every_s=SAMPLE_S,
                               primed_s=PRIMED_S if primed else 0.0)


def campaign_of(out_dir) -> dict:
    """The method, start, baffles and slice of the campaign in ``out_dir``
    (``campaign.json``; a folder without one holds a campaign of the physical method from
    rest on the sector, made before the file; keys a file lacks take those defaults)."""
    have = {"method": "physical", "primed": False, "baffles": False, "full_slice": False}
    if isinstance(out_dir, Shipped):
        return dict(have, **out_dir.campaign)
    p = Path(out_dir) / "campaign.json"
    if p.exists():
        have.update(json.loads(p.read_text()))  # made before baffles: none
    return have


def variant_of(out_dir) -> str | None:
    """What the campaign in ``out_dir`` adds to seed 002's mill and start, or None on the
    paper's configuration and start. Seed 002's mill has no baffles (section 2.2: three
    acceleration rotors in an outer chamber), and its runs start from rest (section 2.3:
    once every bead was generated, the stirrer started), so a baffled campaign or a primed
    start is a variant: its verdicts are shown, never counted as a match of the paper's
    statements."""
    c = campaign_of(out_dir)
    return " and ".join(name for name, on in (("baffles", c.get("baffles")),
                                              ("primed start", c.get("primed"))) if on) or None


def run_campaign(out_dir, cases=CASES, threads=None, progress=True, method="physical",
                 primed=False, baffles=False, full_slice=False):
    """Run the cases that have no stats.json yet (the protocol above), by ``method``, on
    the sector or (``full_slice``) the paper's whole slice with gravity; a folder holds one
    campaign: another method, start or slice there is refused."""
    from millfmu.dem.run import run_scene

    if method not in METHODS:
        raise ValueError(f"method = {method!r}: allowed {list(METHODS)}")
    out = Path(out_dir)
    want = {"method": method, "primed": bool(primed), "baffles": bool(baffles),
            "full_slice": bool(full_slice)}
    if (out / "campaign.json").exists() or any(out.glob("n*_f*/stats.json")):
        have = campaign_of(out)
        if have != want:
            raise ValueError(f"{out}: holds a campaign of {have}, not {want}; use another "
                             f"folder")
    out.mkdir(parents=True, exist_ok=True)
    (out / "campaign.json").write_text(json.dumps(want))
    for rpm, fill in cases:
        d = case_dir(out_dir, rpm, fill)
        if (d / "stats.json").exists():
            continue
        run_scene(scene_for(rpm, fill, method=method, primed=primed, baffles=baffles,
                            full_slice=full_slice), d,
                  progress=progress,
                  threads=threads, window_s=WINDOW_S)


#: Builder id of a table assembled from the campaign's runs (not the DemBuilder: the runs'
#: windows are WINDOW_S long, not the halves of the recording, and they keep their outputs).
#: It names the module where this campaign lived before (millfmu.dem.studies): the id is
#: part of the table's key, which a move of the code must not change.
CAMPAIGN_BUILDER_ID = "millfmu.dem.studies.seed002.campaign_runs"


def protocol_overrides(sector_deg: float | None = None) -> dict:
    """The protocol as scene overrides (section -> {key: value}), as ``tables build`` takes
    them."""
    sector_deg = SECTOR_DEG if sector_deg is None else sector_deg
    return {"mill": {"sector_deg": sector_deg},
            "run": {"spin_up_s": SPIN_UP_S, "record_s": RECORD_S, "sample_every_s": SAMPLE_S,
                    "gravity_m_per_s2": [0.0, 0.0, 0.0]}}


def export_table(out_dir, prefix, filling: float = 0.8):
    """The stress-energy table of the campaign's runs at ``filling`` over the rotor speeds
    (tip-speed axis), written to PREFIX.npz / PREFIX.json with a manifest that names the
    runs, the protocol and the commands that rebuild it. Returns the Table."""
    from millfmu.dem.analysis.stats import DemStats
    from millfmu.dem.scene import scene_from_dict
    from millfmu.dem.scene import load_scene_dict
    from millfmu.dem.analysis.precision import manifest_entry
    from millfmu.dem.tables.build import assemble, stationarity_summary
    from millfmu.dem.tables.cache import dem_kernel_version
    from millfmu.dem.tables.dem_builder import normalize_stats, recording_drift
    from millfmu.stress_tables.spec import (TableError, TableSpec, manifest_for,
                                            scene_at_point)

    camp = campaign_of(out_dir)
    if camp != {"method": "physical", "primed": False, "baffles": False, "full_slice": False}:
        # the table's scene and rebuild command are the physical campaign's from rest
        raise TableError(f"{out_dir}: holds a campaign of {camp}; a table is exported from "
                         f"the physical campaign from rest without baffles ('python -m "
                         f"validation.seed002 run --out DIR')")
    base = load_scene_dict("accelerator_slice")
    for sec, kv in protocol_overrides().items():
        base.setdefault(sec, {}).update(kv)
    base["beads"]["filling"] = filling
    r_rim = base["mill"]["rotor_radius_m"]
    tips = [n * 2.0 * math.pi / 60.0 * r_rim for n in SPEEDS]
    spec = TableSpec(scene=base, grid={"tip_speed_m_per_s": tips},
                     kernel_version=dem_kernel_version(), builder_id=CAMPAIGN_BUILDER_ID)
    results, walls = [], 0.0
    for n, point in zip(SPEEDS, spec.points()):
        d = case_dir(out_dir, n, filling)
        if not (d / "stats.json").exists():
            raise TableError(f"{d}: no stats.json; run 'python -m validation.seed002 run "
                             f"--out {out_dir}' first")
        stats = DemStats.from_json((d / "stats.json").read_text())
        sc = scene_from_dict(scene_at_point(base, point))
        if abs(stats.tip_speed_m_per_s - sc.tip_speed_m_per_s) > 1e-9 * sc.tip_speed_m_per_s or \
                abs(stats.record_s - sc.record_s) > 1e-6 or \
                abs(stats.spin_up_s - sc.spin_up_s) > 1e-6 or \
                abs(stats.sector_deg - sc.geometry.sector_deg) > 1e-9:
            raise TableError(f"{d}: its run (tip speed {stats.tip_speed_m_per_s} m/s, spin-up "
                             f"{stats.spin_up_s} s, record {stats.record_s} s, sector "
                             f"{stats.sector_deg} deg) is not the protocol's")
        r = normalize_stats(stats, sc)
        r["drift"] = recording_drift(d / "windows.csv", r["zone_names"])
        results.append(r)
        walls += float(stats.counts.get("wall_time_s", 0.0))
    table = assemble(spec, results)
    table.manifest = {"build_wall_time_s": walls}
    st = stationarity_summary(results, table.zone_names)
    if st is not None:
        table.manifest["stationarity"] = st
    res = {"grid_points": len(SPEEDS), "shape": [len(SPEEDS)],
           "dem": {"sector_deg": SECTOR_DEG, "spin_up_s": SPIN_UP_S, "record_s": RECORD_S,
                   "sample_every_s": SAMPLE_S, "dt_s": base["run"]["dt_s"],
                   "fluid": base["fluid"]["mode"]},
           "note": (f"assembled from the seed 002 campaign's runs at {filling:g} filling "
                    f"({', '.join(f'{n:g}' for n in SPEEDS)} rpm); drift: first against last "
                    f"window of {WINDOW_S} s")}
    table.manifest = manifest_for(spec, table, {
        "resolution": res,
        "rebuild_command": (f"python -m validation.seed002 run --out DIR && python -m "
                            f"validation.seed002 table --out DIR --export-table {prefix}")},
        work_precision=manifest_entry)
    table.export(prefix)
    return table


#: What the deviation table reads of a run's stats.json: per zone, and of seed 002's
#: quantities per zone and in total (by every contact event and at the frames)
ZONE_KEYS = ("name", "filling", "speed_over_tip_speed")
Q_ZONE_KEYS = ("SN_g_per_m3_s", "SE_cs_w_per_m3", "SI_j")
Q_TOTAL_KEYS = ("SN_g_per_m3_s", "SE_ts_sum_w", "SE_tn_sum_w", "ts_share", "efficiency")
#: The shipped summary of the campaigns on seed 002's mill, from which the page's columns of
#: those campaigns are computed
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed002_sector.json"


def _counted_part(q: dict) -> dict:
    return {"zones": {z: {k: q["zones"][z][k] for k in Q_ZONE_KEYS} for z in ZONE_NAMES},
            "total": {k: q["total"][k] for k in Q_TOTAL_KEYS}}


def compact(st: dict) -> dict:
    """The part of a run's stats that :func:`deviation_rows` reads: per zone the local filling
    and speed, seed 002's quantities per zone and in total by both countings, the radial
    speed profile; no contacts or maps (units: 1/(m3 s), W/m3, J, W, -)."""
    q = st["flow"]["seed002"]
    out = _counted_part(q)
    prof = q["radial_speed_profile"]
    out["radial_speed_profile"] = {k: prof[k] for k in ("z_over_r", "speed_over_tip_speed")}
    snap = q.get("snapshots_20_per_s") or q.get("snapshots")
    if snap is not None:
        out["snapshots_20_per_s"] = _counted_part(snap)
    flow = {"seed002": out}
    circ = st["flow"].get("circumferential")
    if circ:  # a full slice with gravity: where the beads sit round the circle
        flow["circumferential"] = {k: circ[k] for k in ("azimuth_bin_deg", "samples", "per_bin_over_mean",
                                                        "rising_over_falling_half")}
    return {"zones": [{k: z[k] for k in ZONE_KEYS} for z in st["zones"]], "flow": flow}


def _case_label(rpm: float, filling: float) -> str:
    return f"{rpm:g} rpm, {round(filling * 100)} %"


def summarize(out_dir, label: str | None = None, path=None) -> Path:
    """Add the campaign in ``out_dir`` (its cases' :func:`compact` stats, its method, start,
    baffles and the command that made it) to the summary at ``path`` (default
    :data:`SUMMARY`) under ``label`` (default the method's name), replacing a campaign of
    that label; ValueError for a folder without runs."""
    camp = campaign_of(out_dir)
    runs = {}
    for rpm, fill in CASES:
        st = _load(out_dir, rpm, fill)
        if st is not None:
            runs[_case_label(rpm, fill)] = {"rpm": rpm, "filling": fill, "stats": compact(st)}
    if not runs:
        raise ValueError(f"{out_dir}: no case has a stats.json; run 'python -m validation.seed002 "
                         f"run --out {out_dir}' first")
    label = label or _label(out_dir)
    opts = (f" --method {camp['method']}" if camp["method"] != "physical" else "") + \
        (" --primed" if camp.get("primed") else "") + (" --baffles" if camp.get("baffles") else "") + \
        (" --full-slice" if camp.get("full_slice") else "")
    quoted = f'"{label}"' if "'" in label else f"'{label}'"
    p = Path(path) if path is not None else SUMMARY
    doc = json.loads(p.read_text()) if p.exists() else {}
    doc["note"] = ("seed 002's cases on the 60-degree accelerator sector without gravity (a campaign "
                   "with full_slice: the whole 360-degree slice with gravity), per campaign: per case "
                   "what the deviation table reads (zone filling and speed [-]; SN_g [1/(m3 s)], "
                   "SE_cs [W/m3], SI [J] per zone; totals [1/(m3 s), W, -]; the radial speed profile; "
                   "a full slice's beads per 30 degrees over their mean)")
    doc["protocol"] = {"sector_deg": SECTOR_DEG, "spin_up_s": SPIN_UP_S, "record_s": RECORD_S,
                       "window_s": WINDOW_S, "sample_every_s": SAMPLE_S,
                       "gravity_m_per_s2": [0.0, 0.0, 0.0], "threads": 1,
                       "note": "the campaigns' protocol; spin-up and recording [s] of each "
                               "campaign in its own 'protocol'"}
    doc.setdefault("campaigns", {})[label] = {
        "campaign": camp,
        "protocol": protocol_of(camp["method"]),
        "command": f"python -m validation.seed002 run --out DIR{opts} --threads 1, then python -m "
                   f"validation.seed002 summarize --out DIR --label {quoted}",
        "runs": runs}
    p.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return p


def _summary_doc(path=None) -> dict:
    p = Path(path if path is not None else SUMMARY)
    if not p.exists():
        raise ValueError(f"{p}: no summary; make it with 'python -m validation.seed002 summarize "
                         f"--out DIR' from a campaign's runs")
    return json.loads(p.read_text())


class Shipped:
    """A campaign of the shipped summary (:data:`SUMMARY`), read where a run folder is:
    :func:`deviation_rows` and :func:`deviation_table` take it in place of a folder."""

    def __init__(self, label: str, path=None):
        doc = _summary_doc(path)
        if label not in doc.get("campaigns", {}):
            raise ValueError(f"campaign {label!r}: not in the shipped summary; it has "
                             f"{sorted(doc.get('campaigns', {}))}")
        self.label = label
        entry = doc["campaigns"][label]
        self.campaign = dict(entry["campaign"])
        self.stats = {(r["rpm"], r["filling"]): r["stats"] for r in entry["runs"].values()}

    def __str__(self):
        return f"the shipped summary's campaign {self.label!r}"


def shipped_labels(path=None) -> list[str]:
    """The campaigns the shipped summary holds, in its order."""
    return list(_summary_doc(path)["campaigns"])


def _has(out_dir, rpm, fill) -> bool:
    if isinstance(out_dir, Shipped):
        return (rpm, fill) in out_dir.stats
    return (case_dir(out_dir, rpm, fill) / "stats.json").exists()


def _load(out_dir, rpm, fill):
    if isinstance(out_dir, Shipped):
        return out_dir.stats.get((rpm, fill))
    p = case_dir(out_dir, rpm, fill) / "stats.json"
    return json.loads(p.read_text()) if p.exists() else None


def _fmt(x, nd=3):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else \
        f"{x:.{nd}g}"


def _zone(st, name):
    for z in st["zones"]:
        if z["name"] == name:
            return z
    raise KeyError(name)


def _q(st):
    return st["flow"]["seed002"]


def counted(st, counting: str) -> dict:
    """Seed 002's stress quantities of a run's stats (dict) by ``counting``: ``events``
    (every contact event) or ``snapshots`` (the contacts present at 20 frames per second,
    else at the run's samples)."""
    q = _q(st)
    if counting == "events":
        return q
    if counting != "snapshots":
        raise ValueError(f"counting = {counting!r}: allowed 'events', 'snapshots'")
    snap = q.get("snapshots_20_per_s") or q.get("snapshots")
    if snap is None:
        raise ValueError("a run without snapshot counts (made before they were recorded); "
                         "run it again")
    return snap


def _order(vals: dict) -> str:
    """'max SEV_1, min SEV_3' of a dict zone -> value."""
    ok = {k: v for k, v in vals.items() if v is not None}
    return f"max {max(ok, key=ok.get)}, min {min(ok, key=ok.get)}"


def _profile_peak(st):
    """(Z'/R of the fastest bin, speed ratio near the shaft / at the wall) of the radial
    bead speed profile."""
    p = _q(st)["radial_speed_profile"]
    z = np.array(p["z_over_r"])
    v = np.array([np.nan if x is None else x for x in p["speed_over_tip_speed"]])
    k = int(np.nanargmax(v))
    inner, outer = v[z > 0.85], v[z < 0.15]
    if not np.isfinite(inner).any() or not np.isfinite(outer).any():
        return float(z[k]), float("nan")  # no beads there
    return float(z[k]), float(np.nanmean(inner) / np.nanmean(outer))


def _peak_text(st) -> str:
    z, ratio = _profile_peak(st)
    return f"Z'/R {z:.2f}, " + (f"ratio {ratio:.2f}" if math.isfinite(ratio) else
                                "no beads beyond Z'/R 0.85")


def deviation_rows(out_dir, counting: str | None = None, partial: bool = False) -> list[dict]:
    """One dict per statement of seed 002: statement, paper, ours, verdict. ``counting``:
    the stress quantities from every contact event (``events``) or from the contacts
    present at frames (``snapshots``: 20 per second where recorded); default that of the
    campaign's method (:data:`METHODS`). ``partial``: a campaign of some cases (a variant
    run at one point): each statement judged on the cases it has, saying which."""
    runs = {k: _load(out_dir, *k) for k in CASES}
    counting = counting or METHODS[campaign_of(out_dir)["method"]]["counting"]

    def cq(st):
        return counted(st, counting)
    at80 = [(n, 0.8) for n in SPEEDS]
    at1200 = [(1200.0, f) for f in FILLINGS]
    rows = []

    def label(k):
        return f"{k[0]:.0f} rpm {round(k[1] * 100)} %"

    def add(statement, paper, fn, keys, accept, why=""):
        vals = [(k, fn(runs[k])) for k in keys if runs.get(k) is not None]
        ours = "; ".join(f"{label(k)}: {v if isinstance(v, str) else _fmt(v)}"
                         for k, v in vals) or "not run"
        got = [v for _, v in vals]
        verdict = "not run" if not got else ("matches" if accept(got, vals) else "missed")
        if got and len(got) < len(keys):
            verdict = (f"{verdict} at {', '.join(label(k) for k, _ in vals)}" if partial and
                       fn is not None and _per_case(accept) else
                       f"incomplete ({len(got)} of {len(keys)} cases run)")
        rows.append(dict(statement=statement, paper=paper, ours=ours,
                         verdict=verdict + (f" ({why})" if why and got else "")))

    def zone_vals(st, field):
        return {z: _zone(st, z)[field] for z in ZONE_NAMES}

    def q_vals(st, field):
        return {z: cq(st)["zones"][z][field] for z in ZONE_NAMES}

    add("highest bead speed near the shaft: Z'/R of the fastest bin (0 wall, 1 shaft) and "
        "speed near the shaft (Z'/R > 0.85) over speed at the wall (Z'/R < 0.15) (section "
        "3.1, figures 3a, 4a)", "fastest at Z'/R ~ 0.9; ratio > 1 (accelerating from wall to "
        "shaft)",
        _peak_text, list(CASES),
        lambda got, vals: all(_profile_peak(runs[k])[0] >= 0.69 and
                              _profile_peak(runs[k])[1] > 1.0 for k, _ in vals),
        "all cases: fastest bin beyond Z'/R 0.69 and ratio > 1")
    add("local filling at 80 %: lowest in SEV_3, highest in SEV_1 (section 3.2, figure 6a)",
        "max SEV_1, min SEV_3", lambda st: _order(zone_vals(st, "filling")), at80,
        lambda got, vals: all(g == "max SEV_1, min SEV_3" for g in got))
    fills = [runs.get(k) for k in at80[:3]]
    if all(f is not None for f in fills):
        ch = {z: max(_zone(f, z)["filling"] for f in fills) -
              min(_zone(f, z)["filling"] for f in fills) for z in ZONE_NAMES}
        worst = max(ch, key=ch.get)
        rows.append(dict(statement="local filling at 80 % unchanged from 800 to 1200 rpm "
                                   "(figure 6a): largest change of a zone's local filling",
                         paper="unchanged", ours=f"{ch[worst]:.3f} ({worst}); " + ", ".join(
                             f"{z} {ch[z]:.3f}" for z in ZONE_NAMES),
                         verdict=("matches" if ch[worst] <= 0.05 else "missed") +
                         " (within 0.05)"))
    add("beads fastest in SEV_3 and SEV_4, slowest in SEV_1 (section 3.3, figure 11)",
        "SEV_3, SEV_4 > SEV_2 > SEV_1",
        lambda st: ", ".join(f"{z} {v:.3f}" for z, v in
                             zone_vals(st, "speed_over_tip_speed").items()), list(CASES),
        lambda got, vals: all(
            min(_zone(runs[k], "SEV_3")["speed_over_tip_speed"],
                _zone(runs[k], "SEV_4")["speed_over_tip_speed"]) >
            _zone(runs[k], "SEV_2")["speed_over_tip_speed"] >
            _zone(runs[k], "SEV_1")["speed_over_tip_speed"] for k, _ in vals))
    add("stress number SN_g highest in SEV_1, lowest in SEV_3, in all cases (section 3.4, "
        "figure 13)", "max SEV_1, min SEV_3", lambda st: _order(q_vals(st, "SN_g_per_m3_s")),
        list(CASES), lambda got, vals: all(g == "max SEV_1, min SEV_3" for g in got))
    add("total SN_g rising with filling at 1200 rpm (section 3.4) [1/(m3 s)]", "rising",
        lambda st: cq(st)["total"]["SN_g_per_m3_s"], at1200,
        _across_cases(lambda got, vals: len(got) == len(at1200) and all(np.diff(got) > 0)))
    add("collision stress energy SE_cs peaks in SEV_1 in all cases (section 3.4, figure 14)",
        "max SEV_1", lambda st: _order(q_vals(st, "SE_cs_w_per_m3")), list(CASES),
        lambda got, vals: all(g.startswith("max SEV_1") for g in got))
    add("SE_cs follows SN_g more than SI: spread over the zones of log10 SN_g against log10 "
        "SI (standard deviations; section 3.4)", "SN_g's spread larger",
        lambda st: "SN_g {:.2f}, SI {:.2f}".format(*_spreads(cq(st))), list(CASES),
        lambda got, vals: all(_spreads(cq(runs[k]))[0] > _spreads(cq(runs[k]))[1]
                                  for k, _ in vals))
    add("SE_ts about an order of magnitude above SE_tn (section 3.4, figure 15): SE_ts,sum "
        "/ SE_tn,sum", "about 10",
        lambda st: cq(st)["total"]["SE_ts_sum_w"] / max(cq(st)["total"]["SE_tn_sum_w"],
                                                        1e-300),
        list(CASES), lambda got, vals: all(10 ** 0.5 <= g <= 10 ** 1.5 for g in got),
        "within half a decade of 10")
    add("SE_ts,sum / SE_cs,sum above 80 % in every case (section 3.4, figure 16)", "> 0.8",
        lambda st: cq(st)["total"]["ts_share"], list(CASES),
        lambda got, vals: all(g > 0.8 for g in got))
    add("efficiency SE_cs,sum / SE_net at most 0.45 % (section 3.5, figure 17)", "<= 0.0045",
        lambda st: cq(st)["total"]["efficiency"], list(CASES),
        lambda got, vals: all(g <= 0.0045 for g in got))
    eff = {k: cq(runs[k])["total"]["efficiency"] for k in CASES if runs.get(k) is not None}
    best_fill = max((k for k in at1200 if k in eff), key=eff.get, default=None)
    best_rpm = max((k for k in at80 if k in eff), key=eff.get, default=None)
    if best_fill is not None and best_rpm is not None:
        ran = sum(k in eff for k in set(at1200) | set(at80))
        need = len(set(at1200) | set(at80))
        rows.append(dict(statement="most efficient: 80 % among the fillings at 1200 rpm, "
                                   "1000 rpm among the speeds at 80 % (section 3.5)",
                         paper="80 %, 1000 rpm",
                         ours=f"{round(best_fill[1] * 100)} %, {best_rpm[0]:.0f} rpm",
                         verdict=(f"incomplete ({ran} of {need} cases run)" if ran < need else
                                  "matches" if (best_fill[1] == 0.8 and best_rpm[0] == 1000.0)
                                  else "missed")))
    # the statements the twelve above left out
    add("collision stress energy SE_cs lowest in SEV_3 in all cases (section 3.4, figure 14)",
        "min SEV_3", lambda st: _order(q_vals(st, "SE_cs_w_per_m3")), list(CASES),
        lambda got, vals: all(g.endswith("min SEV_3") for g in got))
    add("highest local SN_g 'more than 15 x 10^8' 1/(m3 s) at 1400 rpm, 80 % (section 3.4, "
        "figure 13b), against the chamber's SN_g, a mean that no peak is below [1/(m3 s)]",
        f"peak ~{PAPER_PEAK_SN_G:.2g}", lambda st: cq(st)["total"]["SN_g_per_m3_s"],
        list(CASES), lambda got, vals: all(g <= 10.0 * PAPER_PEAK_SN_G for g in got),
        "the chamber's mean at most a decade above the paper's peak")
    if any(runs.get(k) is not None and runs[k]["flow"].get("circumferential") for k in at80):
        add("circumferential filling at 80 %: a maximum near 60 degrees at every speed (section 3.2, "
            "figure 8b)", "max near 60 degrees", _circ_text, at80,
            lambda got, vals: all(_circ_max(runs[k]) for k, _ in vals),
            f"the highest 30-degree bin within a bin of {PAPER_MAX_AZIMUTH_DEG:g} degrees from the top "
            f"with the rotation, at least {CIRC_MAX_OVER_MEAN - 1:.0%} over the mean")
    else:
        rows.append(dict(statement="circumferential filling at 80 %: a maximum near 60 degrees at "
                                   "every speed (section 3.2, figure 8b)",
                         paper="max near 60 degrees", ours="a sector without gravity",
                         verdict="not evaluated (needs the full slice with gravity)"))
    variant = variant_of(out_dir)
    for r in rows:
        r["variant"] = variant
    return rows


def _circ_peak(st):
    """(azimuth [deg] of the highest bin's centre, from the top with the rotation; its beads
    over the bins' mean) of a full slice's ``flow.circumferential``."""
    c = st["flow"]["circumferential"]
    rel = np.asarray(c["per_bin_over_mean"], float)
    i = int(np.argmax(rel))
    return (i + 0.5) * c["azimuth_bin_deg"], float(rel[i])


def _circ_max(st) -> bool:
    az, top = _circ_peak(st)
    off = abs((az - PAPER_MAX_AZIMUTH_DEG + 180.0) % 360.0 - 180.0)
    return top >= CIRC_MAX_OVER_MEAN and off <= st["flow"]["circumferential"]["azimuth_bin_deg"]


def _circ_text(st) -> str:
    az, top = _circ_peak(st)
    rel = st["flow"]["circumferential"]["per_bin_over_mean"]
    return (f"highest bin at {az:g} degrees from the top with the rotation ({PAPER_MAX_AZIMUTH_DEG:g} "
            f"is the paper's 60), {top:.3f} of the mean; bins {min(rel):.3f}-{max(rel):.3f}")


def _across_cases(accept):
    """Mark a statement's test as one over several cases (not judged on one case)."""
    accept.across_cases = True
    return accept


def _per_case(accept) -> bool:
    return not getattr(accept, "across_cases", False)


def _spreads(q):
    """Standard deviation over the zones of log10 SN_g and of log10 SI of the counted
    quantities q (:func:`counted`)."""
    z = q["zones"]
    sn = [math.log10(z[k]["SN_g_per_m3_s"]) for k in ZONE_NAMES if z[k]["SN_g_per_m3_s"]]
    si = [math.log10(z[k]["SI_j"]) for k in ZONE_NAMES if z[k]["SI_j"]]
    return float(np.std(sn)), float(np.std(si))


def markdown(rows, label: str = "ours (coupled)") -> str:
    lines = [f"| seed 002 statement | paper | {label} | verdict |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['statement']} | {r['paper']} | {r['ours']} | {r['verdict']} |")
    if rows:
        n = sum(r["verdict"].startswith("matches") for r in rows)
        lines += ["", (f"Variant ({rows[0]['variant']}; seed 002's mill has none): {n} of "
                       f"{len(rows)} statements hold here, none counted as a match of the "
                       f"paper's." if rows[0].get("variant") else
                       f"On the paper's mill: {n} of {len(rows)} statements match.")]
    return "\n".join(lines)


def deviation_table(columns) -> list[dict]:
    """Seed 002's statements against several campaigns: ``columns`` a list of (label,
    folder[, counting]). One dict per statement: statement, paper, ``cells`` (label ->
    {ours, verdict}), ``verdict``: the labels under which it matches, or missed, and
    ``not_counted``: what holds under a variant or at a one-case campaign's case (the end of
    ``verdict``). A
    campaign of some of the cases (a full slice at one point) is judged on the cases it has,
    and what holds there is shown, not counted: a statement of seed 002's cases is matched
    by a campaign of all of them."""
    out, order, variants, partials = {}, [], {}, {}
    for col in columns:
        label, folder = col[0], col[1]
        counting = col[2] if len(col) > 2 else None
        variants[label] = variant_of(folder)
        partial = partials[label] = not all(_has(folder, *k) for k in CASES)
        for r in deviation_rows(folder, counting, partial=partial):
            key = r["statement"]
            if key not in out:
                out[key] = dict(statement=key, paper=r["paper"], cells={})
                order.append(key)
            out[key]["cells"][label] = dict(ours=r["ours"], verdict=r["verdict"],
                                            variant=variants[label], partial=partial)
    rows = []

    def named(cells):
        return [lab + (" (" + c["verdict"][len("matches at "):].split(" (")[0] + ")"
                       if c["verdict"].startswith("matches at ") else "")
                for lab, c in cells if c["verdict"].startswith("matches")]
    for key in order:
        r = out[key]
        for col in columns:
            r["cells"].setdefault(col[0], dict(ours="not run", verdict="not run",
                                               variant=variants[col[0]], partial=partials[col[0]]))
        own = [(lab, c) for lab, c in r["cells"].items() if not c["variant"] and not c["partial"]]
        ok = named(own)
        judged = any(c["verdict"].startswith(("matches", "missed")) for _, c in own)
        var = named((lab, c) for lab, c in r["cells"].items() if c["variant"])
        some = named((lab, c) for lab, c in r["cells"].items() if c["partial"] and not c["variant"])
        # what holds under a variant or at a one-case campaign's case, shown after any verdict
        r["not_counted"] = (("; not counted: holds under the variant " + ", ".join(var) if var else "") +
                            ("; not counted: holds at its case under " + ", ".join(some) if some else ""))
        r["verdict"] = ("matches under " + ", ".join(ok) if ok else
                        "missed under all" if judged else "not evaluated") + r["not_counted"]
        rows.append(r)
    return rows


def count(rows) -> dict:
    """The statements of :func:`deviation_table`'s rows matched on the paper's mill: per
    campaign (its label -> number; variants and campaigns of some cases left out) and under
    all of them together (``together``), of ``statements``."""
    per = {}
    for r in rows:
        for lab, c in r["cells"].items():
            if not c["variant"] and not c["partial"]:
                per[lab] = per.get(lab, 0) + c["verdict"].startswith("matches")
    return {"statements": len(rows), "per_campaign": per,
            "together": sum(r["verdict"].startswith("matches") for r in rows)}


#: the docs' short names of the campaigns on the paper's mill (the verdict column)
SHORT_NAMES = {"physical, model B": "model B", "physical, model A": "model A",
               "paper's method": "paper's method",
               "paper's method, Schiller-Naumann": "paper's method with Schiller-Naumann drag"}


def _short(labels) -> str:
    order = list(SHORT_NAMES)
    labels = sorted(labels, key=lambda lab: order.index(lab) if lab in order else len(order))
    names = [SHORT_NAMES.get(lab, lab) for lab in labels]
    both = ("paper's method", "paper's method with Schiller-Naumann drag")
    if all(b in names for b in both):
        names = [n for n in names if n != both[1]]
        names[names.index(both[0])] = "paper's method by both drag laws"
    return ", ".join(names)


def verdict_cell(r) -> str:
    """One row of :func:`deviation_table` as the docs' "verdict on the paper's mill": the
    campaigns of all of seed 002's cases on its mill under which the statement matches
    ("matches (...)"), else those under which it is missed ("missed (...)"), else "not
    evaluated"; a statement none of them judges names what a campaign of some of the
    cases (shown, never counted) found at its case."""
    own = [(lab, c) for lab, c in r["cells"].items() if not c["variant"] and not c["partial"]]
    for word in ("matches", "missed"):
        labs = [lab for lab, c in own if c["verdict"].startswith(word)]
        if labs:
            return f"{word} ({_short(labs)})"
    some = [f"{lab} at its case: {'holds' if c['verdict'].startswith('matches') else 'missed'}"
            for lab, c in r["cells"].items()
            if c["partial"] and not c["variant"] and c["verdict"].startswith(("matches", "missed"))]
    return "not evaluated" + (f" ({'; '.join(some)}; not counted)" if some else "")


def markdown_columns(rows) -> str:
    """The table of :func:`deviation_table`: one column per campaign (its verdict, then
    what it gave), and the verdict over all (:func:`verdict_cell`, then what holds under a
    variant or at a one-case campaign's case, not counted)."""
    labels = list(rows[0]["cells"]) if rows else []
    heads = [lab + (f" (variant: {rows[0]['cells'][lab]['variant']}, not counted)"
                    if rows[0]["cells"][lab]["variant"] else "") for lab in labels]
    lines = ["| seed 002 statement | paper | " + " | ".join(heads) + " | verdict |",
             "|---" * (3 + len(labels)) + "|"]
    for r in rows:
        cells = [f"{c['verdict']}: {c['ours']}" for c in r["cells"].values()]
        lines.append(f"| {r['statement']} | {r['paper']} | " + " | ".join(cells) +
                     f" | {verdict_cell(r)}{r['not_counted']} |")
    if rows:
        c = count(rows)
        lines += ["", f"On the paper's mill, of {c['statements']} statements: " +
                  ", ".join(f"{lab} {n}" for lab, n in c["per_campaign"].items()) +
                  f"; {c['together']} under these together." +
                  (" Variants and campaigns of some cases are shown, not counted."
                   if len(c["per_campaign"]) < len(labels) else "")]
    return "\n".join(lines)


# --- the command: python -m validation.seed002 -------------------------------------------

def parser() -> argparse.ArgumentParser:
    """The campaign's options."""
    s2 = argparse.ArgumentParser(prog="python -m validation.seed002",
                                 description="Seed 002 side by side (accelerator mill): run "
                                             "its cases, print the deviation table. Run from "
                                             "a checkout's root.")
    s2.add_argument("action", choices=("run", "table", "summarize"), help="run the cases "
                    "(skipping those done), print the table from their results (without --out: "
                    "from the shipped summary validation/runs/seed002_sector.json), or add the "
                    "campaign in --out to that summary")
    s2.add_argument("--out", help="folder of the case runs (needed by run and summarize)")
    s2.add_argument("--label", help="summarize: the campaign's name in the summary (default "
                    "its method); table without --out: print this shipped campaign alone, "
                    "case by case")
    s2.add_argument("--method", choices=tuple(METHODS),
                    default="physical",
                    help="run: physical (the slice's own coupling, every contact event "
                         "counted), paper (seed 002's numerics: discrete phase model with "
                         "Koch-Hill drag, CFD step 0.01 s, 2 s spin-up and 1 s recorded, "
                         "contacts counted at 20 frames per second), paper-SN (paper with "
                         "Schiller-Naumann drag, 1 s spin-up and 0.5 s recorded) or "
                         "physical-A (physical with model A's pressure-gradient force)")
    s2.add_argument("--primed", action="store_true", help="run: start the beads in the "
                    "bead-free liquid's circulation (primed start) instead of from rest")
    s2.add_argument("--baffles", action="store_true", help="run: with stationary baffles "
                    "on the chamber wall between the rotors (BAFFLES; the liquid in "
                    "12 theta cells per 60 degrees)")
    s2.add_argument("--full-slice", action="store_true", help="run: on the paper's whole "
                    "360-degree slice with gravity across the axis (validation/scenes/"
                    "accelerator_full_gravity.toml) instead of the 60-degree sector without")
    s2.add_argument("--case", action="append", metavar="RPM:FILLING", help="run only this "
                    "case (e.g. 1200:0.8; repeatable; default all seven)")
    s2.add_argument("--compare", action="append", metavar="LABEL=DIR", help="table: also "
                    "this campaign as a column (repeatable), beside --out's")
    s2.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    s2.add_argument("--export-table", metavar="PREFIX", help="also write the stress-energy "
                    "table of the 80 %% runs over the rotor speeds to PREFIX.npz/.json (e.g. "
                    "millfmu/data/accelerator_table)")
    return s2


def _case(text: str) -> tuple:
    """'1200:0.8' -> (1200.0, 0.8), one of the cases."""
    try:
        rpm, fill = (float(x) for x in text.split(":"))
    except ValueError:
        raise ValueError(f"--case {text!r}: write RPM:FILLING, e.g. 1200:0.8") from None
    for c in CASES:
        if abs(c[0] - rpm) < 1e-9 and abs(c[1] - fill) < 1e-9:
            return c
    raise ValueError(f"--case {text!r}: not one of seed 002's cases "
                     f"{[f'{n:g}:{f:g}' for n, f in CASES]}")


def _label(folder) -> str:
    c = campaign_of(folder)
    return c["method"] + (", primed" if c.get("primed") else "") + \
        (", baffles" if c.get("baffles") else "") + (", full slice" if c.get("full_slice") else "")


def _compare_col(text: str) -> tuple:
    label, sep, folder = text.partition("=")
    if not sep or not label or not folder:
        raise ValueError(f"--compare {text!r}: write LABEL=DIR")
    return label, folder


def main(argv=None) -> int:
    """``python -m validation.seed002 run|table --out DIR [...]``: print the deviation table
    (after running the cases with ``run``), export the table with ``--export-table``; 2
    with the reason on stderr."""
    from millfmu.dem.run import DemRunError

    args = parser().parse_args(argv)
    cases = CASES
    try:
        if args.out is None:
            if args.action != "table":
                raise ValueError(f"{args.action}: give --out DIR, the folder of the case runs")
            if args.compare or args.export_table:
                raise ValueError("--compare and --export-table read run folders: give --out DIR")
            if args.label:
                print(markdown(deviation_rows(Shipped(args.label)), f"ours ({args.label})"))
            else:
                print(markdown_columns(deviation_table([(lab, Shipped(lab)) for lab in
                                                        shipped_labels()])))
            return 0
        if args.action == "summarize":
            print(f"wrote {summarize(args.out, args.label)}")
            return 0
        if args.case:
            cases = tuple(_case(c) for c in args.case)
        cols = [(_label(args.out), args.out)] + [_compare_col(c) for c in args.compare or ()]
        if args.action == "run":
            run_campaign(args.out, cases=cases, threads=args.threads, method=args.method,
                         primed=args.primed, baffles=args.baffles, full_slice=args.full_slice)
        if len(cols) == 1:
            print(markdown(deviation_rows(args.out), f"ours ({cols[0][0]})"))
        else:
            print(markdown_columns(deviation_table(cols)))
    except (ValueError, DemRunError) as e:
        print(f"python -m validation.seed002: {e}", file=sys.stderr)
        return 2
    if args.export_table:
        from millfmu.stress_tables.spec import TableError

        try:
            t = export_table(args.out, args.export_table)
        except TableError as e:
            print(f"python -m validation.seed002: {e}", file=sys.stderr)
            return 2
        print(f"exported {args.export_table}.npz/.json ({t.axes['tip_speed_m_per_s'].size} "
              f"tip speeds)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
