"""Stationary baffles between the rotors of a slice (pin-mill style counter-elements):
geometry, wall distances against the kernels, volumes, the liquid's stationary cells, a
bead's rebound from a standing plate, the scene's refusals."""

import math

import numpy as np
import pytest

from millfmu.dem.mills import zones_for
from millfmu.dem.mills.geometry import (GeometryError, MillGeometry, bead_count_for_filling,
                                      place_beads)
from millfmu.dem.scene import DemSceneError, load_scene

MM = 1e-3
#: seed 002's study baffles (validation.seed002.BAFFLES), written out so that a
#: change there does not pass unnoticed
BAF = dict(baffle_count=6, baffle_thickness_m=0.002, baffle_inner_radius_m=0.016,
           baffle_height_m=0.004, baffle_angle_deg=32.5)


def _scene(**over):
    return load_scene("accelerator_slice").with_overrides(baffles=dict(BAF, **over))


def _at(g, s_m, t_m, zb_m, angle_deg=32.5):
    """Point at s along the baffle's mid-line, t across it, zb from its axial mid-plane."""
    a = math.radians(angle_deg)
    return np.array([[s_m * math.cos(a) - t_m * math.sin(a),
                      s_m * math.sin(a) + t_m * math.cos(a),
                      g.disc_z_m + 0.5 * g.height_m + zb_m]])


def test_study_baffles_are_the_ones_tested():
    from validation import seed002

    assert seed002.BAFFLES == BAF


def test_baffle_distances_by_hand_and_in_the_kernels():
    """Distances to the nearest plate at hand-made points (beside its face, above its top,
    inside of its inner edge, on the next baffle's side of the sector's image), and the
    kernels' wall 4 equal to the numpy geometry's at random points, with unit normals."""
    pytest.importorskip("numba")
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation

    s = _scene()
    g = s.geometry
    assert g.has_baffles
    cases = [((0.022, 3 * MM, 0.0), 2 * MM),            # beside the face: 3 - 1 mm
             ((0.022, 0.0, 3 * MM), 1 * MM),            # above its top edge (2 mm high half)
             ((0.013, 0.0, 0.0), 3 * MM),               # inside its inner edge at 16 mm
             ((0.013, 1.5 * MM, 2.5 * MM), math.sqrt(3 ** 2 + 0.5 ** 2 + 0.5 ** 2) * MM)]
    sim = DemSimulation(g, s.material, _at(g, 0.022, 5 * MM, 0.0), 0.4e-3, s.omega_rad_per_s,
                        1e-5)
    for (sm, tm, zm), want in cases:
        p = _at(g, sm, tm, zm)
        assert g.baffle_distance(p)[0] == pytest.approx(want, rel=1e-12)
        d, nx, ny, nz, ok = K.wall_gap(p[0, 0], p[0, 1], p[0, 2], 0.4e-3, 4, sim.prm)
        if want <= 0.4e-3 + 1e-12 or ok:
            assert d == pytest.approx(want, rel=1e-12)
    # the baffle 60 degrees on (the next pitch) is as near as this one
    p = _at(g, 0.022, 3 * MM, 0.0, 32.5 + 60.0)
    assert g.baffle_distance(p)[0] == pytest.approx(2 * MM, rel=1e-12)
    rng = np.random.default_rng(11)
    n = 3000
    r = rng.uniform(0.0145, g.chamber_radius_m, n)
    th = rng.uniform(0.0, math.radians(60.0), n)
    z = g.disc_z_m + 0.5 * g.height_m + rng.uniform(-3 * MM, 3 * MM, n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th), z])
    want = g.baffle_distance(p)
    hits = 0
    for i in range(n):
        d, nx, ny, nz, ok = K.wall_gap(p[i, 0], p[i, 1], p[i, 2], 0.4e-3, 4, sim.prm)
        if ok and d > 0:
            hits += 1
            assert d == pytest.approx(want[i], abs=1e-12)
            assert nx * nx + ny * ny + nz * nz == pytest.approx(1.0)
        elif not ok:  # the kernel's quick rejection: only beads out of reach
            assert want[i] > 0.4e-3
    assert hits > 500


def test_baffle_volumes_zones_and_placement():
    """Six 2 x 4 x 14 mm plates: 672 mm3 over the circle, off the free volume and off the
    zones they lie in (the smooth and slow-acceleration zones' axial band); the zones still
    tile the open chamber (a midpoint count with the plates cut out agrees); beads are
    placed clear of the plates and fewer of them at the same filling."""
    g0 = load_scene("accelerator_slice").geometry
    s = _scene()
    g = s.geometry
    assert g.baffle_volume_m3() == pytest.approx(6 * 2 * 4 * 14 * MM ** 3)
    assert g0.free_volume_m3() - g.free_volume_m3() == pytest.approx(
        672 * MM ** 3 * g.sector_fraction, rel=1e-12)
    z = zones_for(s)
    v = z.volumes_m3()
    assert v.sum() == pytest.approx(g.free_volume_m3(), rel=1e-12)
    rng = np.random.default_rng(5)
    n = 400_000
    half = 0.5 * g.height_m
    r = np.sqrt(rng.uniform(g.shaft_radius_m ** 2, g.chamber_radius_m ** 2, n))
    th = rng.uniform(0.0, math.radians(g.sector_deg), n)
    p = np.column_stack([r * np.cos(th), r * np.sin(th), rng.uniform(-half, half, n)])
    keep = g.inside(p, 1e-12) & (g.vane_distance(p, 0.0) > 0.0) & (g.baffle_distance(p) > 0)
    box = math.pi * (g.chamber_radius_m ** 2 - g.shaft_radius_m ** 2) * g.height_m * \
        g.sector_fraction
    mc = np.array([(keep & (z.classify(p) == k)).sum() for k in range(4)]) / n * box
    assert mc == pytest.approx(v, rel=0.03)
    # the plates lie in SEV_1 (r > 22.2 mm), SEV_2 and SEV_3 (X'/L < 0.4): those lose volume
    v0 = zones_for(load_scene("accelerator_slice")).volumes_m3()
    assert np.all(v[:3] < v0[:3]) and v[3] == pytest.approx(v0[3], rel=1e-12)
    x = place_beads(g, 6000, 0.4e-3)
    assert g.baffle_distance(x).min() >= 0.4e-3
    assert bead_count_for_filling(g, 0.8, 0.8e-3) < bead_count_for_filling(g0, 0.8, 0.8e-3)


def test_bad_baffles_are_refused_by_name():
    with pytest.raises(DemSceneError, match="baffle pitches"):
        _scene(baffle_count=4)  # 60 degrees hold 2/3 of a 90-degree pitch
    with pytest.raises(DemSceneError, match="baffle_height_m.*gap between two rotors"):
        _scene(baffle_height_m=0.007)
    with pytest.raises(DemSceneError, match="baffle_inner_radius_m"):
        _scene(baffle_inner_radius_m=0.031)
    with pytest.raises(DemSceneError, match="baffle_thickness_m"):
        _scene(baffle_thickness_m=0.01)
    with pytest.raises(DemSceneError, match="baffles.baffle_height_m: missing"):
        load_scene("accelerator_slice").with_overrides(
            baffles={k: v for k, v in BAF.items() if k != "baffle_height_m"})
    with pytest.raises(DemSceneError, match="baffles.pins: unknown baffle key"):
        _scene(pins=3)
    with pytest.raises(GeometryError, match="need a rotor"):
        MillGeometry(0.01, 0.03, 0.013, **BAF)


def test_liquid_holds_one_stationary_column_per_baffle():
    """With 12 theta cells over 60 degrees the baffle is the column from 30 to 35 degrees,
    every cell beyond r = 16 mm and within 2 mm of the mid-plane between the rotors
    stationary (the plate's faces on cell faces); one theta cell cannot hold a baffle and
    is refused by name."""
    from millfmu.dem.fluid.grid import STATOR, GridError, mill_grid

    g = _scene().geometry
    gr = mill_grid(g, 5e-4, n_theta=12)
    st = np.argwhere(gr.solid == STATOR)
    assert set(st[:, 1]) == {6}
    rc = gr.r_centres_m
    assert np.any(np.isclose(gr.r_faces_m, 0.016))
    zb = (np.arange(gr.n_z) + 0.5) * gr.dz_m - g.disc_z_m - 0.5 * g.height_m
    zb -= g.height_m * np.floor(zb / g.height_m + 0.5)
    want = int((rc > 0.016).sum()) * int((np.abs(zb) < 2 * MM).sum())
    assert st.shape[0] == want
    assert (np.abs(zb) < 2 * MM).sum() * gr.dz_m == pytest.approx(4 * MM)
    for nt in (1, 3):
        with pytest.raises(GridError, match=f"n_theta = {nt}: .*baffle"):
            mill_grid(g, 5e-4, n_theta=nt)


def test_the_liquid_pushing_on_a_baffle_turns_the_stator():
    """The torque the liquid gives the baffles' theta faces (pressure and normal stress of
    the fluid cell beside each face): none from a uniform pressure; a pressure p in the
    column ahead of the plate pushes it forward with p times its face's first moment,
    h (R^2 - r_in^2) / 2; behind it, backwards; the normal viscous stress with the
    opposite sign. Without baffles: 0."""
    from millfmu.dem.fluid.grid import mill_grid
    from millfmu.dem.fluid.solver import FluidSolver

    g = _scene().geometry
    s = FluidSolver(mill_grid(g, 5e-4, n_theta=12))
    moment = 4 * MM * (g.chamber_radius_m ** 2 - 0.016 ** 2) / 2.0  # [m3]
    s.p[:] = 1000.0
    assert s.plate_torque_nm() == pytest.approx(0.0, abs=1e-12)
    s.p[:] = 0.0
    s.p[:, 5, :] = 1000.0  # the column before the baffle's (6)
    assert s.plate_torque_nm() == pytest.approx(1000.0 * moment, rel=1e-12)
    s.p[:] = 0.0
    s.p[:, 7, :] = 1000.0
    assert s.plate_torque_nm() == pytest.approx(-1000.0 * moment, rel=1e-12)
    s.p[:] = 0.0
    s._ttt[:, 5, :] = 1000.0
    assert s.plate_torque_nm() == pytest.approx(-1000.0 * moment, rel=1e-12)
    plain = FluidSolver(mill_grid(load_scene("accelerator_slice").geometry, 5e-4, n_theta=12))
    plain.p[:, 5, :] = 1000.0
    assert plain.plate_torque_nm() == 0.0


def test_baffled_coupled_run_closes_its_angular_momentum_budget(tmp_path, monkeypatch):
    """A baffled accelerator sector, coupled, 10 ms from 0.1 of the rotor's rotation: the
    budget closes with the liquid's push on the baffles' faces counted for the stator
    (5e-4 measured); without it, it is off by more than a third (0.38)."""
    import millfmu.dem.run as R
    from validation.seed002 import scene_for

    sc = scene_for(1200, 0.8, baffles=True).with_overrides(
        spin_up_s=0.0, record_s=0.01, sample_every_s=0.005, primed_s=0.0,
        initial_rotation=0.1)
    made = {}
    make = R.make_simulation

    def keep(*a, **k):
        sim, cpl = make(*a, **k)
        made["solver"] = cpl.solver
        return sim, cpl

    monkeypatch.setattr(R, "make_simulation", keep)
    b = R.run_scene(sc, tmp_path, progress=False).flow["angular_momentum_budget"]
    plates = made["solver"].angular_impulse_plates_nms
    drive = b["stirrer_drive_nms"]
    without = (drive - b["change_fluid"] - b["change_beads"] - (b["chamber_nms"] - plates)) \
        / drive
    print("closure", b["closure_rel"], "without the plates", without)
    assert abs(b["closure_rel"]) < 2e-3
    assert abs(without) > 0.1


def test_a_bead_rebounds_from_the_standing_baffle():
    """A bead flying at 1 m/s square onto a baffle while the rotor turns: it comes back at
    about the restitution coefficient's 0.5 of its speed (Hertz with the restitution's
    damping), along the plate's normal, the plate standing (no drag on it from the
    rotor's speed: no tangential velocity appears); the impulse goes to the standing walls'
    torque, none to the stirrer's."""
    pytest.importorskip("numba")
    from millfmu.dem.engine.sim import DemSimulation

    s = _scene()
    g = s.geometry
    a = math.radians(32.5)
    nrm = np.array([-math.sin(a), math.cos(a), 0.0])  # the plate's +t face normal
    x0 = _at(g, 0.022, 1 * MM + 0.4e-3 + 0.02e-3, 0.0)
    sim = DemSimulation(g, s.material, x0, 0.4e-3, s.omega_rad_per_s, 1e-6,
                        velocities_m_per_s=-1.0 * nrm[None, :])
    st = sim.run(600)
    v = sim.v[0]
    vn = v @ nrm
    assert 0.45 < vn < 0.55
    assert np.linalg.norm(v - vn * nrm) < 1e-9
    m = math.pi / 6 * (0.8e-3) ** 3 * s.material.density_kg_per_m3
    # angular impulse about z taken by the baffle: r x (m dv) at s = 22 mm
    want = 0.022 * m * (vn + 1.0)
    assert abs(st.chamber_torque_sum_nm_steps * 1e-6) == pytest.approx(want, rel=0.02)
    assert st.torque_sum_nm_steps == 0.0


def test_return_leg_swirl_and_weight_ratio_by_hand():
    """Beads between the rotors turning at half the rotor's angular velocity, beads in the
    rotor's band ignored: k = 0.5, its radial profile flat; the solids fraction their
    volume over the region's open volume; R by the formula; the liquid's k from the
    section fields."""
    from millfmu.dem.mills.accelerator import return_leg

    g = _scene().geometry
    om = 125.0
    rng = np.random.default_rng(2)
    n = 500
    r = rng.uniform(0.0141, 0.0299, n)
    th = rng.uniform(0.0, math.radians(60.0), n)
    zb = rng.uniform(-3.4 * MM, 3.4 * MM, n)  # between the rotors (the gap is 7 mm)
    x = np.column_stack([r * np.cos(th), r * np.sin(th), g.disc_z_m + 0.5 * g.height_m + zb])
    v = 0.5 * om * np.column_stack([-x[:, 1], x[:, 0], np.zeros(n)])
    # beads in the rotor's own band, spinning with it, do not count
    xr = x.copy()
    xr[:, 2] = g.disc_z_m
    fields = dict(r_m=np.array([0.012, 0.02, 0.025]), zeta_m=np.array([0.0, 5 * MM]),
                  u_theta=np.array([[9.0, 9.0], [9.0, 0.3 * om * 0.02],
                                    [9.0, 0.3 * om * 0.025]]))
    out = return_leg([np.vstack([x, xr])], [np.vstack([v, 2.0 * v])], g, om, 0.8e-3, 6040.0,
                     1050.0, fields)
    assert out["k_beads"] == pytest.approx(0.5, rel=1e-12)
    assert all(k == pytest.approx(0.5) for k in out["k_beads_profile"]["k"])
    assert out["k_liquid"] == pytest.approx(0.3, rel=1e-12)
    vol = (math.pi * (0.03 ** 2 - 0.014 ** 2) * 7 * MM - 672 * MM ** 3) / 6.0
    phi = n * math.pi / 6 * (0.8e-3) ** 3 / vol
    assert out["solids_fraction"] == pytest.approx(phi, rel=1e-12)
    big_r = phi * (6040 - 1050) * 0.25 * (0.03 ** 2 - 0.014 ** 2) / \
        (1050 * (0.0222 ** 2 - 0.014 ** 2))
    assert out["R"] == pytest.approx(big_r, rel=1e-12)
    assert out["k_for_R_1"] == pytest.approx(0.5 / math.sqrt(big_r), rel=1e-12)
    # beads without a liquid (dem run --fluid none): no head to weigh the leg against
    dry = return_leg([np.vstack([x, xr])], [np.vstack([v, 2.0 * v])], g, om, 0.8e-3, 6040.0,
                     0.0, None)
    assert dry["R"] is None and dry["k_for_R_1"] is None and dry["k_liquid"] is None
    assert dry["k_beads"] == pytest.approx(0.5, rel=1e-12)
    assert dry["solids_fraction"] == pytest.approx(phi, rel=1e-12)


def test_seed002_baffled_campaign_is_its_own(tmp_path):
    """``seed002 run --baffles``: the study's baffles with 12 theta cells per 60 degrees of
    liquid, a campaign of its own (a folder of runs without baffles refuses it)."""
    from validation import seed002 as S

    sc = S.scene_for(1200.0, 0.8, baffles=True)
    assert sc.geometry.has_baffles and sc.coupling.n_theta == 12
    assert not S.scene_for(1200.0, 0.8).geometry.has_baffles
    (tmp_path / "campaign.json").write_text('{"method": "physical", "primed": false}')
    with pytest.raises(ValueError, match="holds a campaign of .*'baffles': False"):
        S.run_campaign(tmp_path, cases=((1200.0, 0.8),), baffles=True)


def test_section_maps_outline_the_baffles():
    """The maps average over the angle, so the baffles (one angle only) are drawn as two
    hatched outlines at the ends of the axial period, from their inner radius to the wall."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from millfmu.dem.analysis import plots

    fig, ax = plt.subplots()
    plots._zone_outline(ax, _scene())
    hatched = [c for c in ax.collections if c.get_hatch() == "//"]
    assert len(hatched) == 2
    ys = np.concatenate([c.get_paths()[0].vertices[:, 1] for c in hatched])
    assert ys.min() == pytest.approx(16.0) and ys.max() == pytest.approx(30.0)
    plt.close(fig)


def test_too_few_theta_cells_name_the_least_allowed():
    """Theta cells wider than 0.5 rad are refused with the count a sector needs."""
    from millfmu.dem.fluid.grid import GridError, mill_grid

    g = load_scene("accelerator_slice").with_overrides(sector_deg=360.0,
                                                       gravity_m_per_s2=(0.0, -9.81, 0.0))
    with pytest.raises(GridError, match=r"n_theta = 12: theta cells of 0.524 rad, wider than "
                                        r"the 0.5 rad allowed; use 1 \(axisymmetric\) or at "
                                        r"least 13 for 360 degrees"):
        mill_grid(g.geometry, 5e-4, n_theta=12)
    assert mill_grid(g.geometry, 5e-4, n_theta=13).shape[1] == 13


def test_scene_refuses_too_few_theta_cells_before_a_run(capsys, tmp_path):
    """The scene refuses theta cells wider than the grid allows, by name, from a file's value,
    an override and the CLI (no traceback, nothing written)."""
    from millfmu.cli import main

    sc = load_scene("accelerator_slice").with_overrides(sector_deg=360.0,
                                                        gravity_m_per_s2=(0.0, -9.81, 0.0))
    with pytest.raises(DemSceneError, match=r"fluid.coupled.n_theta = 12: theta cells of "
                                            r"0.524 rad over the 360 degree sector, .* at "
                                            r"least 13"):
        sc.with_overrides(n_theta=12)
    assert sc.with_overrides(n_theta=13).coupling.n_theta == 13
    # a narrower sector with the same count is fine; widening it afterwards is refused
    s60 = load_scene("accelerator_slice").with_overrides(n_theta=12)
    with pytest.raises(DemSceneError, match="n_theta = 12"):
        s60.with_overrides(sector_deg=360.0, gravity_m_per_s2=(0.0, -9.81, 0.0))
    out = tmp_path / "never"
    assert main(["dem", "run", "disc_slice", "--out", str(out), "--theta-cells", "8",
                 "--no-progress"]) == 2
    assert "n_theta = 8" in capsys.readouterr().err and not out.exists()


def test_a_grid_the_scene_cannot_make_is_a_run_error_and_writes_nothing(tmp_path):
    """A coupled liquid's grid that cannot be made (baffles with the axisymmetric liquid,
    which has no column to stand for them) ends the run with DemRunError naming the scene
    and the grid's reason, before the output folder exists."""
    from millfmu.dem.run import DemRunError, run_scene

    sc = _scene().with_overrides(n_theta=1)
    out = tmp_path / "never"
    with pytest.raises(DemRunError, match=r"accelerator_slice: the coupled liquid's grid: "
                                          r"n_theta = 1: .*baffle"):
        run_scene(sc, out, progress=False, threads=1)
    assert not out.exists()
