"""Geometry, zones, scenes, statistics and CLI of the bead DEM (mostly without numba)."""

import argparse
import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from millfmu.dem.analysis.stats import DemStats, energy_distribution, se_bin_edges_j
from millfmu.dem.mills.geometry import (GeometryError, MillGeometry, bead_count_for_filling,
                                        place_beads, simple_cubic_annulus)
from millfmu.dem.mills.zones import Zones, ZoneSpec
from millfmu.dem.scene import DemSceneError, load_scene, scene_from_dict

PM1 = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.028,
                   disc_radius_m=0.036, disc_thickness_m=0.008)


def test_import_is_numba_free():
    code = ("import sys, millfmu.dem, millfmu.dem.cli, millfmu.dem.scene, millfmu.dem.analysis.stats,"
            " millfmu.dem.run, millfmu.dem.mills.zones, benchmarks.dem_peers;"
            " print('numba' in sys.modules)")
    # from the checkout's root, where the benchmarks package lives
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.strip() == "False"


def test_bench_lattice_has_the_issue_bead_count():
    x = simple_cubic_annulus(0.84e-3, 15.5e-3, 44.5e-3, 4e-3)
    # the count LAMMPS' lattice sc + create_atoms gives for the same region
    assert x.shape[0] == 38560
    r = np.hypot(x[:, 0], x[:, 1])
    assert r.min() >= 15.5e-3 and r.max() <= 44.5e-3


def test_bench_dilute_bed_is_a_granular_gas(tmp_path, monkeypatch):
    """The bench's second bed (python -m benchmarks.dem_peers --bed dilute): made once like the dense one, a
    gas of few contacts per bead (coordination below 0.5; the dense bed's is several),
    moving beads; the dense bed keeps its file name (its recipe's key without the gas
    speed); an unknown bed is refused by name."""
    pytest.importorskip("numba")
    from benchmarks import dem_peers as B

    monkeypatch.setenv("MILLFMU_BENCH_DIR", str(tmp_path))
    assert B.BED.key() != B.DILUTE_BED.key()
    # the dense bed's key leaves the new field out, so its cached file keeps its name
    rec = B.asdict(B.BED)
    rec.pop("gas_speed_m_per_s")
    want = dict(recipe=rec, geometry=B.asdict(B.BENCH_GEOMETRY), material=B.asdict(B.BENCH_MATERIAL),
                diameter_m=B.BENCH_DIAMETER_M, tip_speed_m_per_s=B.BENCH_TIP_SPEED_M_PER_S, dt_s=B.BENCH_DT_S)
    assert B.BED.key() == B.hashlib.sha256(json.dumps(want, sort_keys=True).encode()).hexdigest()[:12]
    path = B.bed_file(B.DILUTE_BED, threads=1, out=lambda s: None)
    info = B.bed_info(path)
    assert info["beads"] == B.read_data(path).x.shape[0] > 20000
    assert 0.05 < info["coordination"] < 0.5
    assert info["mean_speed_m_per_s"] > 0.05 and info["max_speed_m_per_s"] < 20.0
    with pytest.raises(ValueError, match="bed = 'sparse': allowed"):
        B.bench(bed="sparse")


def test_bench_ke_table_sets_the_references_beside_ours_and_flags_over_3_percent():
    """The bench's kinetic-energy lines (no LAMMPS needed): each run's energies and their
    differences from LAMMPS' and LIGGGHTS' in %, '!' above 3 %; the figures are the
    bench's 1000-step energies of issue 28 (1 core each)."""
    from benchmarks import dem_peers as B

    def run(code, et, er):
        return B.RunResult(code=code, cores=1, device="cpu", beads=52312, steps=1000,
                           loop_s=10.0, ke_trans_j=et, ke_rot_j=er, coordination=5.5)

    best = {"millfmu.dem 1 thr": run("millfmu.dem", 1.508e-4, 9.73e-5),
            "LAMMPS 1 MPI": run("LAMMPS", 1.294e-4, 8.51e-5),
            "LIGGGHTS 1 MPI": run("LIGGGHTS", 1.299e-4, 9.05e-5)}
    lines = B.ke_table(best, 1000)
    assert "after 1000 steps" in lines[0] and "3 %" in lines[0]
    assert "vs LAMMPS" in lines[1] and "vs LIGGGHTS" in lines[1]
    ours = next(x for x in lines if x.strip().startswith("millfmu.dem"))
    assert "+16.5 %!" in ours and "+16.1 %!" in ours  # KE_trans against both
    assert "+14.3 %!" in ours and "+7.5 %!" in ours  # KE_rot against both
    lmp = next(x for x in lines if x.strip().startswith("LAMMPS"))
    assert "-0.4 % " in lmp and "-6.0 %!" in lmp  # within 3 % and not, against LIGGGHTS
    assert B.ke_table({"millfmu.dem 1 thr": best["millfmu.dem 1 thr"]}, 1000) == []


def test_bench_ratio_lines_give_the_bests_and_each_rounds_ratio():
    """The bench's speed ratios (no LAMMPS needed): ours against the faster reference's
    best run, then round by round (runs of a round follow each other within seconds) with
    their median; a core count without a reference gives no line."""
    from benchmarks import dem_peers as B

    def run(code, nc, loop_s):
        return B.RunResult(code=code, cores=nc, device="cpu", beads=1000, steps=100,
                           loop_s=loop_s, ke_trans_j=1.0, ke_rot_j=1.0, coordination=1.0)

    runs = {"millfmu.dem 2 thr": [run("millfmu.dem", 2, t) for t in (1.0, 2.0, 1.2)],
            "LAMMPS 2 MPI": [run("LAMMPS", 2, t) for t in (1.5, 2.2, 1.5)],
            "LIGGGHTS 2 MPI": [run("LIGGGHTS", 2, t) for t in (3.0, 3.0, 3.0)],
            "millfmu.dem 1 thr": [run("millfmu.dem", 1, 2.0)]}
    lines = B.ratio_lines(runs, (1, 2))
    assert lines == [
        "on 2 core(s): millfmu.dem / LAMMPS (the faster reference) = 1.50; / LIGGGHTS = 3.00",
        "  per round, millfmu.dem / LAMMPS: 1.50, 1.10, 1.25 (median 1.25)"]
    # the same as --record's figures, from the runs in the order they ran
    flat = [rs[k] for k in range(3) for rs in runs.values() if k < len(rs)]
    f = B.peer_figures(flat, (1, 2))
    assert f == {"ratio_2_cores": 1.5, "round_median_2_cores": 1.25,
                 "ours_M_particle_steps_per_s_2_cores": 0.1, "lammps_M_particle_steps_per_s_2_cores": 0.07,
                 "liggghts_M_particle_steps_per_s_2_cores": 0.03}
    assert B.peer_figures([r for r in flat if r.code == "millfmu.dem"], (1, 2)) == {}


def test_bench_record_refusals(tmp_path, capsys):
    """--record takes one bed's CPU rows against the peers, into a file that can be written;
    refused before anything runs otherwise."""
    from benchmarks import dem_peers as B

    assert B.main(["--record", str(tmp_path / "r.json"), "--bed", "both"]) == 2
    assert "--record: the CPU rows of one bed" in capsys.readouterr().err
    assert B.main(["--record", str(tmp_path / "r.json"), "--bed", "dense", "--coupled"]) == 2
    assert "or the coupled row alone (--bed none --coupled)" in capsys.readouterr().err
    assert B.main(["--record", str(tmp_path / "no" / "r.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_zone_volumes_partition_the_pm1_cell_and_follow_seed_order():
    z = Zones(PM1)
    v = z.volumes_m3()
    assert v.sum() == pytest.approx(PM1.free_volume_m3(), rel=1e-12)
    v1, v2, v3, v4 = v
    # seed 001, section 3.4: absolute collision numbers V3 > V4 > V2 > V1 "corresponding
    # to the order of volume size"
    assert v3 > v4 > v2 > v1
    # Monte-Carlo check of classify() against the analytic volumes
    rng = np.random.default_rng(0)
    n = 400_000
    r = np.sqrt(rng.uniform(0.015 ** 2, 0.045 ** 2, n))
    th = rng.uniform(0, 2 * math.pi, n)
    zz = rng.uniform(-0.014, 0.014, n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th), zz])
    cls = z.classify(p)
    box = math.pi * (0.045 ** 2 - 0.015 ** 2) * 0.028
    for k in range(4):
        assert (cls == k).mean() * box == pytest.approx(v[k], rel=0.02)
    in_disc = (np.abs(zz) < 0.004) & (r < 0.036)
    assert np.all(cls[in_disc] == -1) and np.all(cls[~in_disc] >= 0)
    # the statistics classify recorded contacts' rows in blocks: the same zones
    from millfmu.dem.analysis import stats as S

    ev = np.zeros((n, 11))
    ev[:, 3:6] = p
    cols = dict(x=3, y=4, z=5)
    whole = S.zone_of_rows(z, ev, cols)
    assert whole.dtype == np.int8 and np.array_equal(whole, cls)
    old = S.BLOCK_ROWS
    try:
        S.BLOCK_ROWS = 7001  # not a divisor of n
        assert np.array_equal(S.zone_of_rows(z, ev, cols), cls)
    finally:
        S.BLOCK_ROWS = old


def test_zone_spec_errors_name_key_and_value():
    with pytest.raises(ValueError, match="r_v1_over_disc_radius = 0.9"):
        Zones(PM1, ZoneSpec(r_v1_over_disc_radius=0.9))
    with pytest.raises(ValueError, match="v1_width_m = 0.02"):
        Zones(PM1, ZoneSpec(v1_width_m=0.02))


def test_sector_rules_and_placement_without_overlap():
    with pytest.raises(GeometryError, match="sector_deg = 100"):
        MillGeometry(0.015, 0.045, 0.028, 0.036, 0.008, sector_deg=100.0)
    g = MillGeometry(0.015, 0.045, 0.028, 0.036, 0.008, sector_deg=30.0)
    n = bead_count_for_filling(g, 0.9, 0.8e-3)
    x = place_beads(g, n, 0.4e-3)
    assert x.shape[0] == n
    assert np.all(g.inside(x, 0.4e-3))
    from scipy.spatial import cKDTree

    # periodic in z and across the sector boundary: add images and check all distances
    sec = math.radians(30.0)
    c, s = math.cos(sec), math.sin(sec)
    rot = np.column_stack([c * x[:, 0] - s * x[:, 1], s * x[:, 0] + c * x[:, 1], x[:, 2]])
    allp = np.vstack([x, x + [0, 0, 0.028], rot])
    pairs = cKDTree(allp).query_pairs(0.8e-3 * 0.999)
    assert len(pairs) == 0
    with pytest.raises(GeometryError, match="n_beads"):
        place_beads(g, 10 * n, 0.4e-3)


def test_scene_files_load_and_validate():
    ds = load_scene("disc_slice")
    assert ds.tip_speed_m_per_s == 10.0 and ds.filling == 0.8
    assert ds.material.youngs_modulus_pa == 6.3e6 and ds.material.restitution == 0.99
    assert ds.geometry.height_m == pytest.approx(0.028)
    assert ds.omega_rad_per_s == pytest.approx(10.0 / 0.036)
    an = load_scene("annulus")
    assert an.placement == "lattice" and an.fluid is None
    with pytest.raises(DemSceneError, match=r"mill.tip_speed_m_per_s = 20.0: allowed 6 to 14"):
        ds.with_overrides(tip_speed_m_per_s=20.0)
    with pytest.raises(DemSceneError, match=r"beads.filling = 0.3"):
        ds.with_overrides(filling=0.3)
    with pytest.raises(DemSceneError, match="gravity"):
        ds.with_overrides(sector_deg=30.0)
    with pytest.raises(DemSceneError, match="scene.kind = 'cube'"):
        scene_from_dict({"kind": "cube"})
    with pytest.raises(DemSceneError, match="beads.restitution = 1.5"):
        scene_from_dict({"kind": "annulus", "mill": {"tip_speed_m_per_s": 8.0},
                         "beads": {"restitution": 1.5, "filling": 0.5}})
    with pytest.raises(DemSceneError, match="no such shipped scene"):
        load_scene("nonexistent")


def test_energy_distribution_density_and_quantiles():
    edges = se_bin_edges_j()
    rng = np.random.default_rng(1)
    se = 10 ** rng.normal(-9, 1, 20000)
    d = energy_distribution(se, edges)
    dens = np.asarray(d.density_per_decade)
    assert np.sum(dens * np.diff(np.log10(edges))) == pytest.approx(1.0)
    assert math.log10(d.quantiles_j["q50"]) == pytest.approx(-9, abs=0.03)
    assert math.log10(d.quantiles_j["q90"]) == pytest.approx(-9 + 1.2816, abs=0.05)
    empty = energy_distribution(np.zeros(0), edges)
    assert empty.quantiles_j["q50"] is None


def _parser():
    from millfmu.dem import cli

    p = argparse.ArgumentParser(prog="millfmu")
    sub = p.add_subparsers(dest="command")
    cli.register(sub)
    return p


def test_cli_registers_run_not_the_bench_and_rejects_bad_values(capsys, tmp_path):
    p = _parser()
    a = p.parse_args(["dem", "run", "disc_slice", "--out", str(tmp_path), "--tip-speed",
                      "30"])
    assert a.func(a) == 2
    assert "tip_speed_m_per_s = 30.0" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # the bench is python -m benchmarks.dem_peers now
        p.parse_args(["dem", "bench", "--steps", "10"])
    capsys.readouterr()
    a = p.parse_args(["dem", "run", "disc_slice"])  # --out is required (unless --resume)
    assert a.func(a) == 2
    assert "a scene and --out are required" in capsys.readouterr().err


def test_disc_slice_short_run_gives_zone_statistics(tmp_path):
    """A short, small disc_slice run through the CLI: structure and units of stats.json."""
    pytest.importorskip("numba")
    p = _parser()
    out = tmp_path / "ds"
    a = p.parse_args(["dem", "run", "disc_slice", "--out", str(out), "--sector-deg", "30",
                      "--no-gravity", "--spin-up", "1e-4", "--record", "2e-4",
                      "--sample-every", "5e-5", "--windows", "1e-4", "--no-progress",
                      "--fluid", "prescribed"])
    assert a.func(a) == 0
    stats = DemStats.from_json((out / "stats.json").read_text())
    assert [z.name for z in stats.zones] == ["V1", "V2", "V3", "V4"]
    assert stats.record_s == pytest.approx(2e-4) and stats.spin_up_s == pytest.approx(1e-4)
    assert "prescribed swirl" in stats.fluid_model
    geo = load_scene("disc_slice").with_overrides(sector_deg=30.0,
                                                  gravity_m_per_s2=(0, 0, 0)).geometry
    assert sum(z.volume_m3 for z in stats.zones) == pytest.approx(geo.free_volume_m3())
    # all bead volume sits in some zone: sum of filling x V x (1 - eps) = bead volume
    vb = stats.beads * math.pi / 6 * 0.8e-3 ** 3
    assert sum(z.filling * z.volume_m3 * 0.6 for z in stats.zones) == pytest.approx(vb,
                                                                                  rel=1e-6)
    for z in stats.zones:
        assert 0.3 < z.filling < 1.3
        assert z.collision_frequency_per_m3_s >= 0 and z.collision_power_w >= 0
        assert set(z.se) == {"tn", "ts", "total"}
        assert len(z.se["tn"].density_per_decade) == len(stats.se_bin_edges_j) - 1
    total = sum(z.collision_count for z in stats.zones)
    assert total > 0 and total == stats.counts["bead_bead"]
    # every bead-wall contact counts in the zone of the bead's centre (recorded at the
    # contact point, inside the wall by the overlap, none counted before)
    walls = sum(z.wall_collision_frequency_per_m3_s * z.volume_m3 * stats.record_s
                for z in stats.zones)
    assert stats.counts["bead_wall"] > 0
    assert walls == pytest.approx(stats.counts["bead_wall"], rel=1e-9)
    # and per wall: the impacts' count, rate and energy tail
    assert set(stats.walls) <= {"shaft", "chamber", "disc"} and stats.walls
    assert sum(w["contacts"] for w in stats.walls.values()) == stats.counts["bead_wall"]
    for w in stats.walls.values():
        assert w["rate_per_s_cell"] == pytest.approx(w["contacts"] / stats.record_s)
        for c in ("se_tn_j", "se_ts_j"):
            e = w[c]
            assert 0.0 <= e["q50"] <= e["q90"] <= e["q99"] <= e["max"]
    assert stats.stirrer_torque_nm > 0 and stats.stirrer_power_w == pytest.approx(
        stats.stirrer_torque_nm * 10.0 / 0.036)
    assert {"mean_j", "rel_std", "rel_trend_over_record"} <= set(stats.kinetic_energy)
    json.loads((out / "stats.json").read_text())  # plain JSON
    for f in ("se_histograms.csv", "kinetic_energy.csv", "map_stress_energy.png",
              "map_collision_frequency.png", "map_collision_power.png",
              "se_distributions.png", "windows.csv"):
        assert (out / f).stat().st_size > 0
    # Two windows of equal length: their mean collision frequency is the whole recording's,
    # and the drift between them is what a table's manifest reports.
    with open(out / "windows.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(float(r["t_start_s"]), float(r["t_end_s"]), r["zone"]) for r in rows[::4]] == [
        (pytest.approx(1e-4), pytest.approx(2e-4), "V1"),
        (pytest.approx(2e-4), pytest.approx(3e-4), "V1")]
    for k, z in enumerate(stats.zones):
        f = [float(r["collision_frequency_per_m3_s"]) for r in rows if r["zone"] == z.name]
        assert np.mean(f) == pytest.approx(z.collision_frequency_per_m3_s, rel=1e-10)
    from millfmu.dem.tables.dem_builder import recording_drift
    from millfmu.stress_tables.spec import DRIFT_FIELDS

    drift = recording_drift(out / "windows.csv", [z.name for z in stats.zones])
    f = [float(r["collision_frequency_per_m3_s"]) for r in rows if r["zone"] == "V2"]
    assert drift["collision_frequency_per_m3_s"][1] == pytest.approx(
        (f[1] - f[0]) / (0.5 * (f[0] + f[1])))
    assert set(drift) == set(DRIFT_FIELDS)


def test_cli_refuses_a_nonpositive_window(capsys, tmp_path):
    p = _parser()
    a = p.parse_args(["dem", "run", "disc_slice", "--out", str(tmp_path), "--windows", "0"])
    assert a.func(a) == 2
    assert "--windows = 0.0" in capsys.readouterr().err


def test_radial_collision_profile_counts_per_open_volume_and_matches_the_maps():
    """collision_maps.npz's radial profile (a quarter bead diameter per bin): every
    bead-bead collision counted once, per volume open to the beads (inside the disc's
    radius its thickness is not), and over the disc's radius the same frequency as the
    axial maps averaged over their axial bins; None where vanes or baffles take volume."""
    from millfmu.dem.analysis.plots import radial_collision_profile, section_maps

    sc = load_scene("disc_slice").with_overrides(sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0),
                                                 record_s=0.5)
    g = sc.geometry
    rng = np.random.default_rng(3)
    n = 20_000
    r = np.sqrt(rng.uniform(g.shaft_radius_m ** 2, g.chamber_radius_m ** 2, n))  # uniform in volume
    th = rng.uniform(0.0, math.radians(10.0), n)
    z = rng.uniform(-0.5 * g.height_m, 0.5 * g.height_m, n)
    inside = (r < g.disc_radius_m) & (np.abs(z) < 0.5 * g.disc_thickness_m)
    r, th, z = r[~inside], th[~inside], z[~inside]
    ev = np.zeros((r.size + 50, 7))
    ev[:r.size, 1], ev[:r.size, 2], ev[:r.size, 3] = r * np.cos(th), r * np.sin(th), z
    ev[:r.size, 4:7] = 1e-9, 2e-9, 0.0  # SE_total 3e-9 J per collision
    ev[r.size:, 0] = 1  # bead-wall contacts: not counted
    cols = dict(type=0, x=1, y=2, z=3, setn=4, sets=5, serot=6)
    edges, freq, power = radial_collision_profile(sc, ev, cols)
    assert np.allclose(np.diff(edges), sc.bead_diameter_m / 4)
    ring = math.pi * np.diff(edges ** 2) * g.sector_fraction
    h = np.where(edges[1:] <= g.disc_radius_m, g.height_m - g.disc_thickness_m, g.height_m)
    assert np.isclose((freq * ring * h).sum() * sc.record_s, r.size)
    assert np.allclose(power, 3e-9 * freq)
    # uniform in the open volume: the same frequency on both sides of the disc's radius
    near_disc = np.abs(0.5 * (edges[1:] + edges[:-1]) - g.disc_radius_m) < 3e-3
    assert abs(freq[near_disc].mean() / freq.mean() - 1.0) < 0.1
    ze, re_, _, fmap, _ = section_maps(sc, ev, cols)
    outer = re_[:-1] >= g.disc_radius_m  # bins clear of the disc at every axial position
    starts = np.searchsorted(edges, re_[:-1] - 1e-12)  # the profile's bins within each map bin
    vol = ring * h
    coarse = np.add.reduceat(freq * vol, starts) / np.add.reduceat(vol, starts)
    assert np.allclose(fmap[:, outer].mean(axis=0), coarse[outer])
    acc = load_scene("accelerator_slice")
    assert radial_collision_profile(acc, ev, cols) is None
