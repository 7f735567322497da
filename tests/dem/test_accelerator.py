"""Accelerator slice of seed 002: geometry, zones, the paper's stress quantities, a short
coupled run through the CLI."""

import argparse
import json
import math

import numpy as np
import pytest

from millfmu.dem.mills import accelerator as A
from millfmu.dem.mills import zones_for
from millfmu.dem.mills.geometry import GeometryError, MillGeometry, bead_count_for_filling
from millfmu.dem.scene import DemSceneError, load_scene, load_scene_dict, scene_from_dict

MM = 1e-3


def _scene(**mill):
    d = load_scene_dict("accelerator_slice")
    d["mill"].update(mill)
    return scene_from_dict(d)


def test_scene_reproduces_the_papers_bead_counts_and_speeds():
    """30 mL slice: 40,306-60,459 beads at 60-90 % filling (seed 002 section 2.3) within
    2 %; rim at Z'/R = 0.39; 800-1400 rpm as tip speeds 2 pi n R."""
    s = load_scene("accelerator_slice")
    g = s.geometry
    full = g.free_volume_m3() / g.sector_fraction
    assert full == pytest.approx(30e-6, rel=0.02)
    for phi, paper in ((0.6, 40306), (0.9, 60459)):
        n = bead_count_for_filling(g, phi, 0.8e-3) / g.sector_fraction
        assert n == pytest.approx(paper, rel=0.02)
    span = g.chamber_radius_m - g.shaft_radius_m
    assert (g.chamber_radius_m - g.disc_radius_m) / span == pytest.approx(0.39)
    assert s.rotor_speed_rpm == pytest.approx(1200.0)
    assert s.tip_speed_m_per_s == pytest.approx(2 * math.pi * 20.0 * g.disc_radius_m)
    m = s.material
    assert (m.density_kg_per_m3, m.restitution, m.friction, m.rolling_friction) == (
        6040.0, 0.5, 0.3, 0.01)
    # shear modulus of seed 002 Table 1, G = Y / (2 (1 + nu))
    assert m.youngs_modulus_pa / (2 * (1 + m.poisson_ratio)) == pytest.approx(3.36e6)
    assert (s.fluid.density_kg_per_m3, s.fluid.viscosity_Pa_s) == (1050.0, 0.4)


def test_rotor_volume_and_walls_agree_with_the_kernels():
    """Shroud and vane volumes by hand; the kernels' wall distances (walls 2 and 3) equal
    the numpy geometry's at random points."""
    pytest.importorskip("numba")
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation

    s = load_scene("accelerator_slice")
    g = s.geometry
    shrouds = math.pi * (22.2 ** 2 - 14.0 ** 2) * (6.0 - 3.0)
    vanes = 12 * 1.0 * (22.2 - 10.0) * 3.0
    assert g.rotor_volume_m3() == pytest.approx((shrouds + vanes) * MM ** 3)
    x0 = np.array([[0.028 * math.cos(0.2), 0.028 * math.sin(0.2), 0.006]])
    sim = DemSimulation(g, s.material, x0, 0.4e-3, s.omega_rad_per_s, 1e-5)
    rng = np.random.default_rng(3)
    n = 4000
    r = rng.uniform(g.shaft_radius_m, g.chamber_radius_m, n)
    th = rng.uniform(0.0, math.radians(30.0), n)
    z = rng.uniform(-0.5 * g.height_m, 0.5 * g.height_m, n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th), z])
    for ang in (0.0, 0.1):
        sim.prm[K.P_ROTANG] = ang
        dv = g.vane_distance(p, ang)
        for i in range(0, n, 7):
            d, nx, ny, nz, ok = K.wall_gap(p[i, 0], p[i, 1], p[i, 2], 0.4e-3, 3, sim.prm)
            if ok and d > 0:
                assert d == pytest.approx(dv[i], abs=1e-12)
                assert nx * nx + ny * ny + nz * nz == pytest.approx(1.0)
    # shroud: a point above the upper shroud's face, one in the eye (no shroud), one in
    # the channel below the shroud
    hb, hc = 0.5 * g.disc_thickness_m, 0.5 * g.channel_height_m
    for (rr, zz), want in (((0.018, hb + 1e-3), 1e-3), ((0.012, hb + 1e-3), None),
                           ((0.018, hc - 0.5e-3), 0.5e-3)):
        d, nx, ny, nz, ok = K.wall_gap(rr, 0.0, zz, 0.4e-3, 2, sim.prm)
        if want is None:
            assert d == pytest.approx(math.hypot(0.014 - rr, zz - hb))  # the eye's corner
        else:
            assert d == pytest.approx(want) and abs(nz) == pytest.approx(1.0)


def test_geometry_refuses_what_cannot_be_built():
    base = dict(shaft_radius_m=0.01, chamber_radius_m=0.03, height_m=0.0132,
                disc_radius_m=0.0222, disc_thickness_m=0.006, eye_radius_m=0.014,
                channel_height_m=0.003, vane_count=12, vane_thickness_m=0.001)
    MillGeometry(**base, sector_deg=30.0)
    with pytest.raises(GeometryError, match="vane pitches"):
        MillGeometry(**base, sector_deg=45.0)
    with pytest.raises(GeometryError, match="eye_radius_m"):
        MillGeometry(**dict(base, eye_radius_m=0.025))
    with pytest.raises(GeometryError, match="channel_height_m"):
        MillGeometry(**dict(base, channel_height_m=0.007))
    with pytest.raises(DemSceneError, match="rotor_speed_rpm"):
        _scene(rotor_speed_rpm=3000.0)
    with pytest.raises(DemSceneError, match="give one of them"):
        _scene(tip_speed_m_per_s=2.0)
    d = load_scene_dict("accelerator_slice")
    d["zones"]["v1_width_m"] = 0.002
    with pytest.raises(DemSceneError, match="zones.v1_width_m"):
        scene_from_dict(d)


def test_sev_zones_follow_the_papers_stages_and_tile_the_chamber():
    s = load_scene("accelerator_slice")
    g = s.geometry
    z = zones_for(s)
    assert z.names == ("SEV_1", "SEV_2", "SEV_3", "SEV_4")
    span = g.chamber_radius_m - g.shaft_radius_m
    half = 0.5 * g.height_m

    def at(zr, xl):  # point at Z'/R, X'/L (X' from the mid-plane between rotors)
        r = g.chamber_radius_m - zr * span
        return [r, 0.0, half * (1.0 - xl)]

    pts = np.array([at(0.1, 0.1), at(0.38, 0.9), at(0.5, 0.2), at(0.68, 0.95),
                    at(0.8, 0.3), at(0.95, 0.1), at(0.8, 0.5), at(0.95, 0.99)])
    assert list(z.classify(pts)) == [0, 0, 1, 1, 2, 2, 3, 3]
    v = z.volumes_m3()
    assert v.sum() == pytest.approx(g.free_volume_m3(), rel=1e-12)
    # SEV_1 by hand: the ring rim..wall over the whole period (no rotor there)
    v1 = math.pi * (g.chamber_radius_m ** 2 - (g.chamber_radius_m - 0.39 * span) ** 2) * \
        g.height_m * g.sector_fraction
    assert v[0] == pytest.approx(v1, rel=1e-12)
    # and all four against a midpoint count of random points classified and kept open
    rng = np.random.default_rng(5)
    n = 400_000
    r = np.sqrt(rng.uniform(g.shaft_radius_m ** 2, g.chamber_radius_m ** 2, n))
    th = rng.uniform(0.0, math.radians(g.sector_deg), n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th), rng.uniform(-half, half, n)])
    keep = g.inside(p, 1e-12) & (g.vane_distance(p, 0.0) > 0.0)
    box = math.pi * (g.chamber_radius_m ** 2 - g.shaft_radius_m ** 2) * g.height_m * \
        g.sector_fraction
    mc = np.array([(keep & (z.classify(p) == k)).sum() for k in range(4)]) / n * box
    assert mc == pytest.approx(v, rel=0.03)


def test_stress_quantities_match_hand_calculations():
    """Two bead-bead contacts and one wall contact, recorded with m* = m/2, I* = I/2: the
    paper's SE_tn = 1/2 m v_n^2, SE_ts = 1/2 I w^2, SI, SN_g, SE_cs, shares, SE_net."""
    s = load_scene("accelerator_slice")
    z = zones_for(s)
    g = s.geometry
    d, rho = 0.8e-3, 6040.0
    m = math.pi / 6 * d ** 3 * rho
    inertia = m * d * d / 10
    cols = dict(type=0, x=1, y=2, z=3, setn=4, sets=5, serot=6)
    vn, w = 0.3, 200.0
    near_wall = [0.029, 0.0, 0.0]  # SEV_1
    ev = np.array([
        [0, *near_wall, 0.5 * (m / 2) * vn ** 2, 0.0, 0.5 * (inertia / 2) * w ** 2],
        [0, *near_wall, 0.5 * (m / 2) * (2 * vn) ** 2, 0.0, 0.0],
        [1, *near_wall, 1.0, 1.0, 1.0],  # a wall contact: not a stress event here
    ])
    t = 0.5
    q = A.stress_quantities(ev, cols, z, t, d, rho, n_beads=100,
                            tip_speed_m_per_s=s.tip_speed_m_per_s, omega_rad_per_s=s.omega_rad_per_s)
    z1 = q["zones"]["SEV_1"]
    tn = 0.5 * m * vn ** 2 + 0.5 * m * (2 * vn) ** 2
    ts = 0.5 * inertia * w ** 2
    v1 = z.volumes_m3()[0]
    assert z1["contacts"] == 2
    assert z1["SE_tn_mean_j"] == pytest.approx(tn / 2)
    assert z1["SE_ts_mean_j"] == pytest.approx(ts / 2)
    assert z1["SI_j"] == pytest.approx((tn + ts) / 2)
    assert z1["SN_g_per_m3_s"] == pytest.approx(2 / (v1 * t))
    assert z1["SE_cs_w_per_m3"] == pytest.approx((tn + ts) / (v1 * t))
    frac = g.sector_fraction
    assert z1["SE_cs_sum_w"] == pytest.approx((tn + ts) / t / frac)
    assert z1["ts_share"] == pytest.approx(ts / (tn + ts))
    assert q["zones"]["SEV_3"]["contacts"] == 0 and q["zones"]["SEV_3"]["SI_j"] is None
    n_rev = s.omega_rad_per_s / (2 * math.pi)
    se_net = 6 / math.pi * (100 * m / frac) * s.tip_speed_m_per_s ** 2 * n_rev / 1.04
    assert q["total"]["SE_net_w"] == pytest.approx(se_net)
    assert q["total"]["efficiency"] == pytest.approx((tn + ts) / t / frac / se_net)


def test_fluid_grid_has_shrouds_eye_and_a_driven_channel():
    from millfmu.dem.fluid.grid import FLUID, ROTOR, mill_grid

    g = load_scene("accelerator_slice").geometry
    grid = mill_grid(g, 5e-4)
    rf = grid.r_faces_m
    for r in (g.shaft_radius_m, g.eye_radius_m, g.disc_radius_m, g.chamber_radius_m):
        assert np.min(np.abs(rf - r)) < 1e-12
    rc = grid.r_centres_m
    zc = grid.z_centres_m
    zr = zc - g.height_m * np.floor(zc / g.height_m + 0.5)
    i_in = np.where((rc > g.eye_radius_m) & (rc < g.disc_radius_m))[0][0]
    k_sh = np.where((np.abs(zr) > 0.5 * g.channel_height_m) &
                    (np.abs(zr) < 0.5 * g.disc_thickness_m))[0]
    k_ch = np.where(np.abs(zr) < 0.5 * g.channel_height_m)[0]
    assert (grid.solid[i_in, 0, k_sh] == ROTOR).all()
    assert (grid.solid[0, 0, k_sh] == FLUID).all()  # the eye
    assert grid.driven[i_in, 0, k_ch].all() and grid.driven[0, 0, k_ch].all()
    assert not grid.driven[rc > g.disc_radius_m].any()
    # the open volume of the fluid grid is the chamber minus the shrouds
    shrouds = math.pi * (g.disc_radius_m ** 2 - g.eye_radius_m ** 2) * \
        (g.disc_thickness_m - g.channel_height_m) * g.sector_fraction
    open_ = math.pi * (g.chamber_radius_m ** 2 - g.shaft_radius_m ** 2) * g.height_m * \
        g.sector_fraction - shrouds
    assert grid.fluid_volume_m3 == pytest.approx(open_)


def test_vanes_pump_the_liquid_out_at_the_rim():
    """The liquid alone: the vanes hold the channel's swirl at the rotor's speed, the liquid
    leaves the channel at the rim and returns between the rotors (seed 002 section 3.1);
    the rotor's torque (vanes included) balances the angular momentum budget."""
    pytest.importorskip("numba")
    from millfmu.dem.fluid.grid import mill_grid
    from millfmu.dem.fluid.solver import FluidProperties, FluidSolver

    s = load_scene("accelerator_slice")
    g = s.geometry
    grid = mill_grid(g, 1e-3)
    fs = FluidSolver(grid, FluidProperties(1050.0, 0.4), s.omega_rad_per_s, turbulence="laminar")
    l0 = fs.angular_momentum_kgm2_s()
    for _ in range(20):
        fs.advance(1e-3)
    drv = grid.driven
    om_r = s.omega_rad_per_s * grid.r_centres_m[:, None, None]
    assert np.allclose(fs.ut[drv], np.broadcast_to(om_r, fs.ut.shape)[drv], rtol=2e-3)
    i = int(np.argmin(np.abs(grid.r_faces_m - g.disc_radius_m)))
    zr = grid.z_centres_m - g.height_m * np.floor(grid.z_centres_m / g.height_m + 0.5)
    ch = np.abs(zr) < 0.5 * g.channel_height_m
    gap = np.abs(zr) > 0.5 * g.disc_thickness_m
    area = grid.r_faces_m[i] * grid.dtheta_rad * grid.dz_m
    q_out = (fs.ur[i, 0, ch] * area).sum()
    q_gap = (fs.ur[i, 0, gap] * area).sum()
    assert q_out > 0 and q_gap == pytest.approx(-q_out, rel=1e-6)  # continuity at r = R
    l1 = fs.angular_momentum_kgm2_s()
    torque_in = -(fs.angular_impulse_rotor_nms + fs.angular_impulse_shaft_nms)
    assert l1 - l0 == pytest.approx(torque_in - fs.angular_impulse_stator_nms, rel=1e-6)


def _parser():
    from millfmu.dem.cli import register

    p = argparse.ArgumentParser()
    register(p.add_subparsers())
    return p


def test_short_coupled_run_has_the_papers_quantities(tmp_path):
    """A short coupled run through the CLI: SEV zones, seed 002's quantities with their
    units, maps, and the budget closing."""
    pytest.importorskip("numba")
    from millfmu.dem.analysis.stats import DemStats

    out = tmp_path / "acc"
    a = _parser().parse_args(["dem", "run", "accelerator_slice", "--out", str(out),
                              "--rpm", "1000", "--filling", "0.7", "--spin-up", "2e-3",
                              "--record", "2e-3", "--sample-every", "1e-3", "--windows",
                              "1e-3", "--no-progress", "--threads", "1"])
    assert a.func(a) == 0
    stats = DemStats.from_json((out / "stats.json").read_text())
    assert [z.name for z in stats.zones] == list(A.ZONE_NAMES)
    assert stats.tip_speed_m_per_s == pytest.approx(2 * math.pi * 1000 / 60 * 0.0222)
    q = stats.flow["seed002"]
    assert q["rotor_speed_rpm"] == pytest.approx(1000.0)
    assert set(q["zones"]) == set(A.ZONE_NAMES)
    tot = q["total"]
    assert tot["SE_cs_sum_w"] == pytest.approx(sum(z["SE_cs_sum_w"]
                                                   for z in q["zones"].values()))
    assert 0 < tot["ts_share"] < 1 and 0 < tot["efficiency"] < 1
    assert sum(z["contacts"] for z in q["zones"].values()) == stats.counts["bead_bead"]
    assert "kg" in q["definitions"]["SE_net"] or "W" in q["definitions"]["SE_net"]
    # both countings, each named: every event, and the contacts present at the 2 samples
    assert q["counting"].startswith("every contact event")
    snap = q["snapshots"]
    assert snap["frames"] == 2 and snap["frame_interval_s"] == pytest.approx(1e-3)
    assert snap["total"]["SE_net_w"] == pytest.approx(tot["SE_net_w"])
    assert snap["total"]["SN_g_per_m3_s"] == pytest.approx(
        sum(z["contacts"] for z in snap["zones"].values()) /
        (sum(z["volume_m3"] for z in snap["zones"].values()) * 2e-3))
    assert "snapshots_20_per_s" not in q  # no sample falls on 0.05 s
    # (a 4 ms run from rest; the campaign's 1.5 s runs close to 1.4e-4 or better)
    assert abs(stats.flow["angular_momentum_budget"]["closure_rel"]) < 5e-3
    assert len(q["radial_speed_profile"]["speed_over_tip_speed"]) == 20
    for f in ("map_stress_intensity.png", "map_stress_number.png",
              "map_collision_stress_energy.png", "map_se_tn.png", "map_se_ts.png",
              "speed_profiles.png", "windows.csv", "fluid_fields.npz"):
        assert (out / f).stat().st_size > 0
    json.loads((out / "stats.json").read_text())


def _fake_stats(rpm, fill, eff):
    """stats.json content with every seed 002 statement holding."""
    from validation.seed002 import ZONE_NAMES

    speed = {"SEV_1": 0.3, "SEV_2": 0.4, "SEV_3": 0.6, "SEV_4": 0.55}
    filling = {"SEV_1": 0.9, "SEV_2": 0.7, "SEV_3": 0.5, "SEV_4": 0.8}
    sn = {"SEV_1": 4e11, "SEV_2": 2e11, "SEV_3": 0.5e11, "SEV_4": 1e11}
    si = {"SEV_1": 2e-8, "SEV_2": 1.5e-8, "SEV_3": 1.2e-8, "SEV_4": 1.4e-8}
    zq = {z: dict(SN_g_per_m3_s=sn[z] * fill, SI_j=si[z], SE_cs_w_per_m3=sn[z] * si[z])
          for z in ZONE_NAMES}
    prof = dict(z_over_r=[0.05, 0.5, 0.9],
                speed_over_tip_speed=[0.2, 0.4, 0.6], samples=[1, 1, 1])
    return dict(zones=[dict(name=z, filling=filling[z], speed_over_tip_speed=speed[z])
                       for z in ZONE_NAMES],
                flow=dict(seed002=dict(zones=zq, radial_speed_profile=prof, total=dict(
                    SN_g_per_m3_s=1e10 * fill, SE_ts_sum_w=10.0, SE_tn_sum_w=1.0,
                    ts_share=10.0 / 11.0, efficiency=eff))))


def _write_case(folder, case, st: dict):
    """A seed 002 case's stats.json with ``st`` in campaign ``folder``; returns its folder."""
    from validation.seed002 import case_dir

    d = case_dir(folder, *case)
    d.mkdir(parents=True, exist_ok=True)
    (d / "stats.json").write_text(json.dumps(st))
    return d


def test_a_run_without_liquid_writes_its_statistics_and_summary(tmp_path, capsys):
    """``dem run accelerator_slice --fluid none``: beads in vacuum have no rotor head to
    weigh the return leg against; the run writes its statistics and says so instead of
    failing after the run."""
    pytest.importorskip("numba")
    from millfmu.dem.analysis.stats import DemStats

    out = tmp_path / "dry"
    a = _parser().parse_args(["dem", "run", "accelerator_slice", "--out", str(out), "--fluid",
                              "none", "--no-gravity", "--spin-up", "2e-3", "--record", "2e-3",
                              "--sample-every", "1e-3", "--no-progress", "--threads", "1"])
    assert a.func(a) == 0
    leg = DemStats.from_json((out / "stats.json").read_text()).flow["seed002"]["return_leg"]
    assert leg["R"] is None and leg["k_for_R_1"] is None and leg["k_beads"] is not None
    assert "weight over rotor head R: none without a liquid" in capsys.readouterr().out


def test_seed002_table_gives_verdicts_from_the_runs(tmp_path):
    from validation import seed002 as S

    for case in S.CASES:
        eff = 0.004 if case in ((1000.0, 0.8), (1200.0, 0.8)) else 0.003
        if case == (1000.0, 0.8):
            eff = 0.0044
        _write_case(tmp_path, case, _fake_stats(*case, eff))
    rows = S.deviation_rows(tmp_path)
    assert len(rows) == 15  # the twelve and the three they left out
    judged = [r for r in rows if not r["verdict"].startswith("not evaluated")]
    assert len(judged) == 14  # the circumferential maximum needs gravity
    assert all(r["verdict"].startswith("matches") for r in judged), S.markdown(rows)
    assert S.markdown(rows).endswith("On the paper's mill: 14 of 15 statements match.")
    bad = _fake_stats(800.0, 0.8, 0.01)  # 1 % efficiency, and SEV_3 the slowest
    bad["zones"][2]["speed_over_tip_speed"] = 0.1
    _write_case(tmp_path, (800.0, 0.8), bad)
    v = {r["statement"][:40]: r["verdict"] for r in S.deviation_rows(tmp_path)}
    assert v["efficiency SE_cs,sum / SE_net at most 0."].startswith("missed")
    assert v["beads fastest in SEV_3 and SEV_4, slowes"].startswith("missed")
    assert "|" in S.markdown(rows).splitlines()[2]


def test_campaign_table_from_short_runs(tmp_path, monkeypatch):
    """The seed 002 campaign's runs at 80 % make a table over the rotor speeds that reads,
    verifies and is refused when a run's protocol differs."""
    pytest.importorskip("numba")
    from validation import seed002 as S
    from millfmu.stress_tables.table import read_table
    from millfmu.stress_tables.spec import TableError

    for name, v in (("SPIN_UP_S", 1e-3), ("RECORD_S", 2e-3), ("WINDOW_S", 1e-3),
                    ("SAMPLE_S", 1e-3), ("SPEEDS", (1000.0, 1400.0)), ("SECTOR_DEG", 30.0)):
        monkeypatch.setattr(S, name, v)
    S.run_campaign(tmp_path, cases=[(1000.0, 0.8), (1400.0, 0.8)], threads=1,
                   progress=False)
    t = S.export_table(tmp_path, tmp_path / "acc_table")
    back = read_table(npz=tmp_path / "acc_table.npz", manifest_path=tmp_path / "acc_table.json")
    assert back.zone_names == A.ZONE_NAMES
    r = 0.0222 * 2 * math.pi / 60
    assert back.axes["tip_speed_m_per_s"] == pytest.approx([1000 * r, 1400 * r])
    assert back.manifest["builder"] == S.CAMPAIGN_BUILDER_ID
    assert "seed002" in back.manifest["rebuild_command"]
    assert np.all(t.data["collision_frequency_norm"] > 0)
    monkeypatch.setattr(S, "SPIN_UP_S", 2e-3)
    with pytest.raises(TableError, match="not the protocol"):
        S.export_table(tmp_path, tmp_path / "again")
    # a campaign of another method is not the table's scene: refused by name
    (tmp_path / "campaign.json").write_text(json.dumps({"method": "paper", "primed": False}))
    with pytest.raises(TableError, match="'method': 'paper'.*from the physical campaign"):
        S.export_table(tmp_path, tmp_path / "again")


def test_seed002_columns_by_method_and_counting(tmp_path):
    """A campaign of the paper's method is read with its snapshot counts; two campaigns
    side by side give one row per statement with each one's verdict, and the verdict over
    all; a folder holds one campaign."""
    from validation import seed002 as S

    phys, paper = tmp_path / "phys", tmp_path / "paper"
    for folder, eff_events in ((phys, 0.03), (paper, 0.03)):
        for case in S.CASES:
            st = _fake_stats(*case, eff_events)
            q = st["flow"]["seed002"]
            snap = json.loads(json.dumps({k: q[k] for k in ("zones", "total")}))
            snap["total"]["efficiency"] = 0.004 if case == (1000.0, 0.8) else 0.003
            q["snapshots_20_per_s"] = snap
            _write_case(folder, case, st)
    (paper / "campaign.json").write_text(json.dumps({"method": "paper", "primed": False}))
    assert S.campaign_of(phys) == {"method": "physical", "primed": False, "baffles": False,
                                   "full_slice": False}
    eff = [r for r in S.deviation_rows(paper) if r["statement"].startswith("efficiency")][0]
    assert eff["verdict"].startswith("matches") and "0.003" in eff["ours"]
    eff = [r for r in S.deviation_rows(phys) if r["statement"].startswith("efficiency")][0]
    assert eff["verdict"].startswith("missed")
    rows = S.deviation_table([("physical", phys), ("paper", paper)])
    e = [r for r in rows if r["statement"].startswith("efficiency")][0]
    assert e["verdict"] == "matches under paper"
    assert e["cells"]["physical"]["verdict"].startswith("missed")
    md = S.markdown_columns(rows)
    assert md.splitlines()[0].count("|") == 6 and len(md.splitlines()) == 19
    assert S.count(rows) == {"statements": 15, "per_campaign": {"physical": 12, "paper": 13},
                             "together": 13}
    assert md.endswith("of 15 statements: physical 12, paper 13; 13 under these together.")
    # a variant run at one point (a primed start) is judged on it; statements across cases
    # are not
    one = tmp_path / "primed"
    d = S.case_dir(one, 1200.0, 0.8)
    d.mkdir(parents=True)
    (d / "stats.json").write_text((S.case_dir(paper, 1200.0, 0.8) / "stats.json").read_text())
    (one / "campaign.json").write_text(json.dumps({"method": "paper", "primed": True}))
    rows = {r["statement"][:30]: r for r in S.deviation_table([("paper", paper), ("primed", one)])}
    assert rows["efficiency SE_cs,sum / SE_net "]["cells"]["primed"]["verdict"] == "matches at 1200 rpm 80 %"
    assert rows["total SN_g rising with filling"]["cells"]["primed"]["verdict"].startswith("incomplete")
    with pytest.raises(ValueError, match="holds a campaign of"):
        S.run_campaign(paper, cases=(), method="physical")
    with pytest.raises(ValueError, match="counting = 'frames'"):
        S.counted(json.loads((S.case_dir(paper, 1200.0, 0.8) / "stats.json").read_text()),
                  "frames")


def test_seed002_summary_gives_the_tables_of_its_run_folders(tmp_path, capsys):
    """A campaign kept in the summary (zone statistics only) gives the same rows, verdicts
    and count as its run folders, a partial campaign included; the CLI computes the table
    from the summary without a run folder, and refuses what needs one by name."""
    from validation import seed002 as S

    phys, paper, one = tmp_path / "phys", tmp_path / "paper", tmp_path / "primed"
    for folder, cases in ((phys, S.CASES), (paper, S.CASES), (one, [(1200.0, 0.8)])):
        for case in cases:
            st = _fake_stats(*case, 0.03)
            q = st["flow"]["seed002"]
            snap = json.loads(json.dumps({k: q[k] for k in ("zones", "total")}))
            snap["total"]["efficiency"] = 0.004 if case == (1000.0, 0.8) else 0.003
            q["snapshots_20_per_s"] = snap
            st["zones"][0]["collision_frequency_per_m3_s"] = 1.0  # not read: not kept
            _write_case(folder, case, st)
    (paper / "campaign.json").write_text(json.dumps({"method": "paper", "primed": False}))
    (one / "campaign.json").write_text(json.dumps({"method": "paper", "primed": True}))
    path = tmp_path / "summary.json"
    for label, folder in (("model B", phys), ("paper's", paper), ("primed", one)):
        S.summarize(folder, label, path)
    S.summarize(phys, "model B", path)  # again: replaced, not added
    assert S.shipped_labels(path) == ["model B", "paper's", "primed"]
    kept = json.loads(path.read_text())["campaigns"]["model B"]
    assert "collision_frequency_per_m3_s" not in json.dumps(kept)
    assert "--out DIR --threads 1" in kept["command"]
    folders = [("model B", phys), ("paper's", paper), ("primed", one)]
    shipped = [(lab, S.Shipped(lab, path)) for lab, _ in folders]
    assert S.deviation_table(shipped) == S.deviation_table(folders)
    assert S.deviation_rows(shipped[1][1]) == S.deviation_rows(paper)
    assert S.campaign_of(shipped[2][1]) == {"method": "paper", "primed": True, "baffles": False,
                                            "full_slice": False}
    with pytest.raises(ValueError, match="campaign 'x': not in the shipped summary"):
        S.Shipped("x", path)
    with pytest.raises(ValueError, match="no case has a stats.json"):
        S.summarize(tmp_path / "empty", "e", path)
    S.SUMMARY, keep = path, S.SUMMARY
    try:
        assert S.main(["table"]) == 0
        # a primed start is a variant of seed 002's start from rest: shown, not counted
        out = capsys.readouterr().out
        assert "| primed (variant: primed start, not counted) |" in out
        assert "model B 12, paper's 13; 13 under these together. Variants and campaigns of some" in out
        assert S.main(["table", "--label", "paper's"]) == 0
        assert "On the paper's mill: 13 of 15" in capsys.readouterr().out
        assert S.main(["summarize"]) == 2
        assert "give --out DIR" in capsys.readouterr().err
        assert S.main(["table", "--compare", f"a={phys}"]) == 2
    finally:
        S.SUMMARY = keep


def test_seed002_baffled_variant_is_shown_never_counted(tmp_path):
    """Seed 002's mill has no baffles: a baffled campaign gets its own column, marked as a
    variant, and what holds only there is not counted as a match of the paper's statement,
    in the verdict and in the count."""
    from validation import seed002 as S

    plain, baffled = tmp_path / "plain", tmp_path / "baffled"
    for folder in (plain, baffled):
        for case in S.CASES:
            st = _fake_stats(*case, {(1000.0, 0.8): 0.0044, (1200.0, 0.8): 0.004}.get(case,
                                                                                     0.003))
            if folder == plain:  # SEV_2 the slowest zone: the speed order missed
                st["zones"][1]["speed_over_tip_speed"] = 0.2
            _write_case(folder, case, st)
    (baffled / "campaign.json").write_text(json.dumps({"method": "physical", "primed": False,
                                                       "baffles": True}))
    assert S.variant_of(plain) is None and S.variant_of(baffled) == "baffles"
    rows = S.deviation_table([("physical", plain), ("baffles", baffled)])
    r = next(r for r in rows if r["statement"].startswith("beads fastest in SEV_3"))
    assert r["cells"]["baffles"]["verdict"] == "matches"
    assert r["verdict"] == "missed under all; not counted: holds under the variant baffles"
    both = next(r for r in rows if r["statement"].startswith("SE_cs follows SN_g"))
    assert both["verdict"] == "matches under physical; not counted: holds under the " \
                              "variant baffles"
    assert S.count(rows) == {"statements": 15, "per_campaign": {"physical": 13},
                             "together": 13}
    md = S.markdown_columns(rows)
    assert "| baffles (variant: baffles, not counted) |" in md.splitlines()[0]
    assert md.endswith("physical 13; 13 under these together. Variants and campaigns of some "
                       "cases are shown, not counted.")
    alone = S.markdown(S.deviation_rows(baffled))
    assert alone.endswith("Variant (baffles; seed 002's mill has none): 14 of 15 statements "
                          "hold here, none counted as a match of the paper's.")


def test_model_a_runs_in_the_rotor():
    """Model A (the beads' -V grad p force) in the accelerator rotor at 0.4 Pa s: the beads
    stay below 1.2 times the rim speed over 200 steps. (It threw beads out at > 20 m/s while
    the first coupling interval counted the arrival of the beads in the bead-free liquid,
    eps 1 -> 0.4 in 5e-5 s, as a change of void fraction: pressure gradients of 2e10 Pa/m
    at the beads; measured with that guard off: 94 m/s after 200 steps, model B 10.6 m/s.)"""
    pytest.importorskip("numba")
    from millfmu.dem.run import make_simulation

    d = load_scene_dict("accelerator_slice")
    d["fluid"]["coupled"]["vans_model"] = "A"
    sc = scene_from_dict(d).with_overrides(sector_deg=30.0, filling=0.8,
                                           gravity_m_per_s2=(0.0, 0.0, 0.0))
    sim, cpl = make_simulation(sc, threads=1)
    cpl.run(200)
    vmax = float(np.linalg.norm(sim.v, axis=1).max())
    gp = float(np.abs(sim.per_bead["fluid_at_bead"][:, 3:6]).max())
    print(f"model A: vmax {vmax:.2f} m/s (rim {sc.tip_speed_m_per_s:.2f}), |grad p| {gp:.3g} Pa/m")
    assert vmax < 1.2 * sc.tip_speed_m_per_s


def test_model_a_pressure_gradient_timing_is_chosen_by_name():
    """[fluid.coupled] pressure_gradient names which interval's gradient model A's beads
    take; the default stays the previous interval's, seed 002's physical-A method takes the
    interval just solved; a wrong value, or the key with model B or the discrete phase
    model (no pressure-gradient force on the beads), is refused by name."""
    from validation import seed002 as S

    d = load_scene_dict("accelerator_slice")
    c = d["fluid"]["coupled"]
    c["vans_model"] = "A"
    assert scene_from_dict(d).coupling.pressure_gradient == "previous_interval"
    c["pressure_gradient"] = "this_interval"
    sc = scene_from_dict(d)
    assert sc.coupling.pressure_gradient == "this_interval"
    assert "pressure gradient of the interval just solved" in sc.fluid_description
    assert S.scene_for(1200.0, 0.8, method="physical-A").coupling.pressure_gradient == \
        "this_interval"
    c["pressure_gradient"] = "next_interval"
    with pytest.raises(DemSceneError, match=r"pressure_gradient = 'next_interval': allowed "
                                            r"\['previous_interval', 'this_interval'\]"):
        scene_from_dict(d)
    c["pressure_gradient"] = "this_interval"
    c["vans_model"] = "B"
    with pytest.raises(DemSceneError, match="only model A"):
        scene_from_dict(d)


@pytest.mark.parametrize("failure", ["memory", "speed"])
def test_an_unstable_run_stops_by_name_and_writes_nothing(tmp_path, monkeypatch, capsys, failure):
    """A run whose beads fly apart (model A's late blow-up in this rotor ran the neighbour
    lists out of memory inside the DEM) ends with exit 2 naming the time, the cause and the
    fluid, not a MemoryError traceback; no statistics are written."""
    pytest.importorskip("numba")
    from millfmu.dem.engine.sim import DemSimulation

    real = DemSimulation.run

    def broken(self, nsteps, record=False):
        st = real(self, nsteps, record=record)
        if self.step_count >= 4:
            if failure == "memory":
                raise MemoryError("Allocation failed (probably too large).")
            self.v[0] = [0.0, 0.0, 500.0]
        return st

    monkeypatch.setattr(DemSimulation, "run", broken)
    out = tmp_path / "acc"
    a = _parser().parse_args(["dem", "run", "accelerator_slice", "--out", str(out), "--sector-deg", "30",
                              "--filling", "0.6", "--spin-up", "2e-3", "--record", "2e-3",
                              "--sample-every", "1e-3", "--no-progress", "--threads", "1"])
    assert a.func(a) == 2
    err = capsys.readouterr().err
    assert "became unstable" in err and "nothing written" in err and "Traceback" not in err
    assert ("outgrew the memory" in err) if failure == "memory" else ("times the tip speed" in err)
    assert not (out / "stats.json").exists()


def test_seed002_cli_refuses_bad_cases_and_mixed_campaigns(tmp_path, capsys):
    """``python -m validation.seed002``: --case names one of the paper's cases; a folder
    keeps the campaign it holds; a comparison column needs LABEL=DIR: each refused with exit
    2 and the reason."""
    from validation import seed002 as S

    for args, want in ((["--case", "1200"], "write RPM:FILLING"),
                       (["--case", "1100:0.8"], "not one of seed 002's cases"),
                       (["--compare", "nolabel"], "write LABEL=DIR")):
        assert S.main(["table", "--out", str(tmp_path / "x")] + args) == 2
        assert want in capsys.readouterr().err
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "campaign.json").write_text(json.dumps({"method": "paper", "primed": False}))
    assert S.main(["run", "--out", str(tmp_path / "p"), "--method", "physical", "--case", "1200:0.8"]) == 2
    assert "holds a campaign of" in capsys.readouterr().err


def test_seed002_full_slice_judges_its_case_and_the_circumferential_maximum(tmp_path):
    """The paper's whole slice with gravity (``--full-slice``): the scene of
    validation/scenes/accelerator_full_gravity.toml; its one case judged (the circumferential
    maximum too, from ``flow.circumferential``), shown and not counted; kept in a summary
    with what row 15 reads."""
    from pathlib import Path

    from validation import seed002 as S

    sc = S.scene_for(1200.0, 0.8, full_slice=True)
    ref = load_scene(str(Path(S.__file__).parent / "scenes" / "accelerator_full_gravity.toml"))
    assert sc.geometry.sector_deg == 360.0 and sc.gravity_m_per_s2 == ref.gravity_m_per_s2
    assert sc.geometry == ref.geometry and sc.spin_up_s == 1.0 and sc.record_s == 0.5
    with pytest.raises(ValueError, match="full_slice"):
        S.scene_for(1200.0, 0.8, full_slice=True, baffles=True)
    plain, full = tmp_path / "plain", tmp_path / "full"
    for case in S.CASES:
        _write_case(plain, case, _fake_stats(*case, 0.003))
    st = _fake_stats(1200.0, 0.8, 0.003)
    rel = [1.0] * 12
    rel[6] = 1.05  # 195 degrees from the top with the rotation: 15 from the paper's 210
    st["flow"]["circumferential"] = dict(azimuth_bin_deg=30.0, samples=10, per_bin_over_mean=rel,
                                         rising_over_falling_half=1.01, centroid_up_m=[0.0])
    d = _write_case(full, (1200.0, 0.8), st)
    (full / "campaign.json").write_text(json.dumps({"method": "physical", "primed": False,
                                                    "baffles": False, "full_slice": True}))
    rows = S.deviation_table([("sector", plain), ("full", full)])
    circ = next(r for r in rows if r["statement"].startswith("circumferential filling"))
    assert circ["cells"]["full"]["verdict"].startswith("matches at 1200 rpm 80 %")
    assert "highest bin at 195 degrees" in circ["cells"]["full"]["ours"]
    assert circ["cells"]["sector"]["verdict"].startswith("not evaluated")
    assert circ["verdict"] == "not evaluated; not counted: holds at its case under full (1200 rpm 80 %)"
    assert S.count(rows)["per_campaign"] == {"sector": 13}  # the full slice not counted
    path = tmp_path / "summary.json"
    S.summarize(full, "full", path)
    kept = json.loads(path.read_text())["campaigns"]["full"]
    assert "--full-slice" in kept["command"]
    assert set(kept["runs"]["1200 rpm, 80 %"]["stats"]["flow"]["circumferential"]) == {
        "azimuth_bin_deg", "samples", "per_bin_over_mean", "rising_over_falling_half"}
    # flat within 1 %: no maximum, wherever the highest bin lies
    rel[6] = 1.01
    (d / "stats.json").write_text(json.dumps(st))
    assert S.deviation_rows(full, partial=True)[-1]["verdict"].startswith("missed at 1200 rpm 80 %")
    with pytest.raises(ValueError, match="holds a campaign of"):
        S.run_campaign(full, cases=(), method="physical")
