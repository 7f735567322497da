"""Seed 001's full slice by seed 001's own protocol (validation/full_slice_paper.py): the
scene is the full-slice column's but for the protocol; a snapshot's zone state against a
closed form; the run keeps a snapshot at its checkpoints, and the trace reads them."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from millfmu.dem.analysis import flow_structure as FS
from millfmu.dem.mills import zones_for
from millfmu.dem.scene import load_scene
from validation import full_slice_paper as P
from validation import seed001 as S

PAGE = Path(__file__).resolve().parents[2] / "docs" / "dem-full-slices.md"


def test_the_scene_is_the_full_slice_columns_with_seed_001s_protocol():
    paper, column = P.scene(), S.full_slice_scene(*P.CASE)
    differ = {f.name for f in dataclasses.fields(paper)
              if repr(getattr(paper, f.name)) != repr(getattr(column, f.name))}
    assert differ == {"spin_up_s", "record_s", "sample_every_s", "initial_rotation"}
    assert (paper.spin_up_s, paper.record_s, paper.initial_rotation) == (2.0, 1.0, 0.0)
    assert round(paper.record_s / paper.sample_every_s) == 50  # seed 001's 50 samples
    assert paper.geometry.sector_deg == 360.0 and paper.gravity_m_per_s2[1] == -9.81


def test_a_snapshots_zone_state_against_a_closed_form():
    """Beads scattered over the slice with one speed per zone: each zone's filling is its
    beads' volume over the zone's volume times (1 - the bulk porosity), its speed that
    zone's speed over the tip speed."""
    sc = P.scene()
    zones = zones_for(sc)
    rng = np.random.default_rng(5)
    g = sc.geometry
    n = 4000
    r = rng.uniform(g.shaft_radius_m, g.chamber_radius_m, n)
    t = rng.uniform(0.0, 2 * math.pi, n)
    z = rng.uniform(0.0, g.height_m, n)
    x = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    zid = zones.classify(x)
    speeds = np.array([0.3, 0.7, 1.1, 1.9])  # [m/s] per zone
    v = np.zeros((n, 3))
    inside = zid >= 0
    v[inside, 2] = speeds[zid[inside]]
    rad = np.full(n, 0.5 * sc.bead_diameter_m)
    got = P.zone_state(sc, x, v, rad)
    vols = zones.volumes_m3()
    vb = 4.0 / 3.0 * math.pi * rad[0] ** 3
    for k, name in enumerate(zones.names):
        m = int((zid == k).sum())
        assert m > 0
        fill, speed = got[name]
        assert fill == pytest.approx(m * vb / (vols[k] * (1.0 - sc.bulk_porosity)), rel=1e-12)
        assert speed == pytest.approx(speeds[k] / sc.tip_speed_m_per_s, rel=1e-12)


def test_the_first_layer_against_a_closed_form():
    """Beads turning rigidly at 0.23 of the stirrer's angular velocity within 0.75 d of a
    disc face, and at 0.9 of it beyond: the first layer turns at 0.23 and counts the beads
    inside; two samples count twice."""
    sc = P.scene()
    g = sc.geometry
    d = sc.bead_diameter_m
    rng = np.random.default_rng(7)
    n = 3000
    r = rng.uniform(g.shaft_radius_m + d, g.disc_radius_m - d, n)
    t = rng.uniform(0.0, 2 * math.pi, n)
    gap = rng.uniform(0.0, 3.0 * d, n)  # from the disc face
    side = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    z = g.disc_z_m + side * (0.5 * g.disc_thickness_m + gap)
    x = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    inside = gap < FS.FIRST_LAYER_DIAMETERS * d
    om = np.where(inside, 0.23, 0.9) * sc.omega_rad_per_s
    v = np.column_stack([-om * x[:, 1], om * x[:, 0], np.zeros(n)])
    got = P.first_layer(sc, [x], [v])
    assert got["angular_velocity_ratio"] == pytest.approx(0.23, rel=1e-12)
    assert got["bead_samples"] == int(inside.sum()) > 0
    assert P.first_layer(sc, [x, x], [v, v])["bead_samples"] == 2 * int(inside.sum())


def test_the_run_keeps_snapshots_at_its_checkpoints_and_the_trace_reads_them(tmp_path, monkeypatch):
    """A short DEM-only sector in the study's child process, a checkpoint at every sample:
    the snapshots are the run's states in time order, and what ``trace`` keeps holds them,
    the windows and the run's compact statistics."""
    sc = load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="none", spin_up_s=0.006,
        record_s=0.004, sample_every_s=0.002)
    d = P.run(tmp_path, threads=1, sc=sc, checkpoint_every_s=1e-3, poll_s=0.05)
    assert (d / "stats.json").exists() and not (d / "checkpoint.pkl").exists()
    snaps = sorted((d / "snapshots").glob("snap_*.npz"))
    assert snaps, "no snapshot kept"
    for p in snaps:
        a = np.load(p)
        assert int(a["step"]) == int(p.stem.split("_")[1])
        assert float(a["t_s"]) == pytest.approx(int(a["step"]) * sc.dt_s, rel=1e-12)
        assert a["x"].shape == (len(a["rad"]), 3)
    kept = P.keep(tmp_path, path=tmp_path / "kept.json")
    doc = json.loads(kept.read_text())
    assert doc["finished"] and doc["stats"]["zones"] and doc["windows"]
    times = [row["t_s"] for row in doc["trace"]]
    assert times == sorted(times) and len(times) == len(snaps)
    for row in doc["trace"]:
        assert set(row["zones"]) == {"V1", "V2", "V3", "V4"}
        assert all(0.0 <= z["filling"] < 2.0 for z in row["zones"].values())
        fl = row["first_layer"]
        assert fl["bead_samples"] >= 0 and (fl["bead_samples"] > 0) == math.isfinite(fl["angular_velocity_ratio"])
    # the windows' first layers together are the recording's, as the run's statistics count it
    st = json.loads((d / "stats.json").read_text())
    samples = [w["first_layer"]["bead_samples"] for w in doc["windows"]]
    assert sum(samples) == st["flow"]["first_bead_layer_samples"]
    # so soon after the placement no bead lies within 0.75 d of a disc face: a thicker
    # layer holds beads, and the windows cut the kept samples in order
    monkeypatch.setattr(FS, "FIRST_LAYER_DIAMETERS", 2.0)
    a = np.load(d / "bead_samples.npz")
    x, v = a["x_m"].astype(float), a["v_m_per_s"].astype(float)
    per = round(S.WINDOW_S / sc.sample_every_s)
    wins = P.window_first_layers(d, st["record_s"])
    assert len(wins) == len(doc["windows"]) == -(-len(x) // per)
    for k, w in enumerate(wins):
        assert w == P.first_layer(P.scene(), x[k * per:(k + 1) * per], v[k * per:(k + 1) * per])
    assert sum(w["bead_samples"] for w in wins) == P.first_layer(P.scene(), x, v)["bead_samples"] > 0
    table = P.markdown(doc)
    assert table.count("(window)") == len(doc["windows"])
    # a finished run is not run again
    assert P.run(tmp_path, threads=1, sc=sc) == d


def test_a_folder_another_process_runs_is_left_alone(tmp_path):
    """Where another process holds the case folder's lock (a run whose parent stopped goes
    on in its child), ``run`` refuses by name instead of starting a second run on it."""
    from millfmu.dem.tables.point_folders import hold

    d = P.case_dir(tmp_path)
    d.mkdir(parents=True)
    with open(d / S.FULL_LOCK, "a+") as lock:
        assert hold(lock)
        with pytest.raises(RuntimeError, match="run by another process"):
            P.run(tmp_path, threads=1)
    assert not (d / "checkpoint.pkl").exists() and not (d / "snapshots").exists()

def test_the_table_shows_the_course_every_tenth_of_a_second_and_its_end():
    rows = [{"t_s": t} for t in (0.04, 0.08, 0.12, 0.16, 0.2, 0.24, 0.28, 0.32)]
    assert [r["t_s"] for r in P.shown(rows)] == [0.04, 0.12, 0.2, 0.32]
    rows = [{"t_s": t} for t in (0.1, 0.13, 0.2, 0.21)]
    assert [r["t_s"] for r in P.shown(rows)] == [0.1, 0.2, 0.21]
    assert P.shown([]) == []

def test_the_page_shows_the_kept_course():
    """The kept summary is this protocol's, and the page shows its course as `trace` prints
    it, with the time the run has reached."""
    doc = json.loads(P.SUMMARY.read_text())
    assert doc["protocol"] == {"spin_up_s": P.SPIN_UP_S, "record_s": P.RECORD_S,
                               "sample_every_s": P.SAMPLE_EVERY_S, "initial_rotation": P.INITIAL_ROTATION,
                               "window_s": S.WINDOW_S}
    times = [row["t_s"] for row in doc["trace"]]
    assert times == sorted(times) and times[-1] <= P.SPIN_UP_S + P.RECORD_S
    page = PAGE.read_text(encoding="utf-8")
    for line in P.markdown(doc).splitlines():
        assert line in page, line
    if not doc["finished"]:
        assert f"has reached t = {times[-1]:.2f} s of its {P.SPIN_UP_S + P.RECORD_S:g} s" in page


def test_the_windows_first_layers_take_their_own_samples(tmp_path):
    """Ten samples over 0.2 s make two 0.1 s windows of five: each window's first layer is
    that of its own samples (beads in the layer turning at 0.1 in the first window's
    samples, 0.3 in the second's)."""
    sc = P.scene()
    g = sc.geometry
    d = sc.bead_diameter_m
    r = np.linspace(g.shaft_radius_m + d, g.disc_radius_m - d, 50)
    x = np.column_stack([r, np.zeros_like(r), np.full_like(r, g.disc_z_m + 0.5 * g.disc_thickness_m + 0.3 * d)])
    xs, vs = [], []
    for k in range(10):
        om = (0.1 if k < 5 else 0.3) * sc.omega_rad_per_s
        xs.append(x)
        vs.append(np.column_stack([np.zeros_like(r), om * r, np.zeros_like(r)]))
    np.savez_compressed(tmp_path / "bead_samples.npz", x_m=np.array(xs, np.float32),
                        v_m_per_s=np.array(vs, np.float32), radii_m=np.full(r.size, 0.5 * d))
    wins = P.window_first_layers(tmp_path, 0.2)
    assert [w["bead_samples"] for w in wins] == [250, 250]
    assert [round(w["angular_velocity_ratio"], 6) for w in wins] == [0.1, 0.3]
