"""The dilute discrete phase model (millfmu.dem.coupling.dpm) against the closed form of a
single settling bead, at seed 002's numerics (0.8 mm zirconia in 0.4 Pa s, CFD step
0.01 s, about 19 bead relaxation times)."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem.coupling.cfd_dem import CfdDem  # noqa: E402
from millfmu.dem.coupling.dpm import DiscretePhaseCoupling  # noqa: E402
from millfmu.dem.coupling.schiller_naumann import (drag_coefficient_py,  # noqa: E402
                                                   terminal_speed_m_per_s)
from millfmu.dem.coupling.settings import CouplingSettings  # noqa: E402
from millfmu.dem.engine.params import BeadMaterial  # noqa: E402
from millfmu.dem.engine.sim import DemSimulation, FluidSettings  # noqa: E402
from millfmu.dem.fluid.grid import mill_grid  # noqa: E402
from millfmu.dem.fluid.solver import FluidProperties  # noqa: E402
from millfmu.dem.mills.geometry import MillGeometry  # noqa: E402

D, RHO_P = 0.8e-3, 6040.0
RHO_F, MU_F = 1050.0, 0.4
DT = 1e-5


def _settle(scheme, t_s=0.2, steps=5, cfd_step_s=0.01, dpm_drag="schiller_naumann"):
    """One zirconia bead settling along the axis of an annulus in still liquid (the column
    held by a mean pressure gradient, as in a closed container): its speed [m/s] after
    t_s, and the coupling."""
    geo = MillGeometry(0.015, 0.025, 0.01, sector_deg=360.0)
    sim = DemSimulation(geo, BeadMaterial(density_kg_per_m3=RHO_P), np.array([[0.02, 0.0, 0.005]]),
                        0.5 * D, 0.0, DT, gravity_m_per_s2=(0.0, 0.0, -9.81),
                        fluid=FluidSettings(density_kg_per_m3=RHO_F, viscosity_Pa_s=MU_F,
                                            drag=False, lubrication=False), threads=1)
    grid = mill_grid(geo, 1e-3)
    st = CouplingSettings(model="B", turbulence="laminar", steps=steps, scheme=scheme,
                          cfd_step_s=cfd_step_s, dpm_drag=dpm_drag)
    cls = DiscretePhaseCoupling if scheme == "dpm" else CfdDem
    cpl = cls(sim, grid, FluidProperties(RHO_F, MU_F), st, 0.0)
    weight = sim.mass[0] * 9.81 * (1.0 - RHO_F / RHO_P)
    cpl.solver.body_z = weight / grid.fluid_volume_m3
    cpl.run(int(round(t_s / DT)))
    return -float(sim.v[0, 2]), cpl, sim


def test_schiller_naumann_closed_forms():
    # Stokes limit: 3 pi mu d; the terminal speed of a Stokes bead
    assert drag_coefficient_py(D, MU_F, RHO_F, 0.0) == pytest.approx(3 * math.pi * MU_F * D)
    stokes = (RHO_P - RHO_F) * 9.81 * D ** 2 / (18 * MU_F)
    u = terminal_speed_m_per_s(D, RHO_P, RHO_F, MU_F)
    re = RHO_F * D * u / MU_F
    assert u == pytest.approx(stokes / (1 + 0.15 * re ** 0.687), rel=1e-9)
    # water, a 3 mm glass bead: Re ~ 1000, continuous across Newton's regime
    c_lo = drag_coefficient_py(3e-3, 1e-3, 998.0, 999.0 / (998.0 * 3e-3 / 1e-3))
    c_hi = drag_coefficient_py(3e-3, 1e-3, 998.0, 1001.0 / (998.0 * 3e-3 / 1e-3))
    assert c_hi / c_lo == pytest.approx(1.0, abs=0.05)


def test_dpm_settling_bead_at_the_papers_cfd_step():
    """At a CFD step of 0.01 s (18.6 relaxation times) the bead settles at the closed-form
    speed (drag updated every 5e-5 s in the frozen liquid); what the liquid and the bead
    exchanged agree up to the one step the liquid lags behind."""
    u_t = terminal_speed_m_per_s(D, RHO_P, RHO_F, MU_F)
    tau = RHO_P * D ** 2 / (18 * MU_F)
    v, cpl, sim = _settle("dpm")
    uf = float(sim.per_bead["fluid_at_bead"][0, 2])
    print(f"dpm: settling {v:.6f} m/s, relative to the liquid {v + uf:.6f}, closed form "
          f"{u_t:.6f} m/s; CFD step / tau = {0.01 / tau:.1f}")
    assert 0.01 / tau > 15
    assert (v + uf) / u_t == pytest.approx(1.0, abs=0.01)
    assert cpl.intervals == 20 and cpl.unit_steps == 1000
    # the liquid has the drag of all CFD steps but the last (it receives each step's drag
    # at the start of the next): at steady state that is one step of the bead's weight
    weight = float(sim.mass[0]) * 9.81 * (1.0 - RHO_F / RHO_P)
    f, b = cpl.solver.exchange_axial_ns, cpl.axial_impulse_to_beads_ns
    print(f"liquid lost {-f:.6g} N s, bead gained {b:.6g} N s, one step of weight "
          f"{weight * 0.01:.6g} N s")
    assert abs(f + b - weight * 0.01) <= 1e-3 * abs(b)


def _koch_hill_terminal_speed(eps):
    """Settling speed [m/s] of the zirconia bead in still liquid under Koch-Hill's drag at
    void fraction eps, V beta(eps, u) / eps u = (rho_p - rho_f) V g (model B's form), by
    bisection on the plain-Python terms of the law."""
    from millfmu.dem.engine.koch_hill2001 import f0_f3_python

    f0, f3 = f0_f3_python(eps)
    vol = math.pi / 6 * D ** 3

    def drag(u):
        re = D * eps * u * RHO_F / MU_F
        return vol * 18 * MU_F * eps * eps * (f0 + 0.5 * f3 * re) / D ** 2 / eps * u

    weight = (RHO_P - RHO_F) * vol * 9.81
    lo, hi = 0.0, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if drag(mid) < weight else (lo, mid)
    return 0.5 * (lo + hi)


def test_koch_hill_closed_forms():
    """Koch-Hill's law without neighbours is Stokes' drag with its own inertial term: F0 =
    1, F3 = 0.0673 + 0.0232, so V beta = 3 pi mu d (1 + 0.04525 Re_p); at seed 002's packed
    layer (eps 0.4) F0 = 10 phi / eps^3 = 93.75, 93.75 eps^2 / eps = 37.5 times the
    isolated sphere's Stokes coefficient at Re_p -> 0."""
    from millfmu.dem.engine.koch_hill2001 import f0_f3_python

    assert f0_f3_python(1.0) == pytest.approx((1.0, 0.0905), rel=1e-12)
    assert _koch_hill_terminal_speed(1.0) * (1 + 0.04525 * RHO_F * D * _koch_hill_terminal_speed(
        1.0) / MU_F) == pytest.approx((RHO_P - RHO_F) * 9.81 * D ** 2 / (18 * MU_F), rel=1e-9)
    f0, _ = f0_f3_python(0.4)
    assert f0 == pytest.approx(93.75, rel=1e-12)
    assert f0 * 0.4 == pytest.approx(37.5, rel=1e-12)


def test_dpm_koch_hill_settling_bead_at_its_void_fraction():
    """With seed 002's drag law the discrete phase model settles the bead at Koch-Hill's
    closed-form speed at the void fraction the bead's own volume leaves in its smoothed
    cells (0.9998): a law of its own, not Schiller-Naumann's (which it differs from by the
    neighbours' term and the inertial term), and the liquid still sees no void fraction."""
    v, cpl, sim = _settle("dpm", dpm_drag="koch_hill2001")
    uf = float(sim.per_bead["fluid_at_bead"][0, 2])
    eps = float(cpl.drag_void_fraction_at_beads()[0])
    u_kh = _koch_hill_terminal_speed(eps)
    u_sn = terminal_speed_m_per_s(D, RHO_P, RHO_F, MU_F)
    print(f"dpm, Koch-Hill: settling {v + uf:.7f} m/s relative to the liquid, closed form "
          f"{u_kh:.7f} m/s at eps {eps:.6f} (ratio {(v + uf) / u_kh:.6f}); "
          f"Schiller-Naumann's {u_sn:.7f} m/s")
    assert 0.99 < eps < 1.0
    # within a tenth of the two laws' difference (2.3 %)
    assert (v + uf) / u_kh == pytest.approx(1.0, abs=0.002)
    assert abs(u_kh / u_sn - 1.0) > 0.02
    assert float(np.abs(cpl.solver.eps_c - 1.0).max()) == 0.0
    # Schiller-Naumann's coupling reads no void fraction
    _, cpl_sn, _ = _settle("dpm", t_s=0.01)
    assert np.all(cpl_sn.drag_void_fraction_at_beads() == 1.0)


def test_held_drag_at_the_same_interval_misses_where_dpm_does_not():
    """The volume-averaged scheme holds each bead's drag over its coupling interval: at
    0.01 s it cannot follow a bead that relaxes in 0.54 ms (its exact-relaxation
    coefficient keeps it stable, but the bead then falls under gravity for a whole
    interval before the drag answers): the settling speed is far off. This is why the
    discrete phase model updates the drag within the CFD step."""
    u_t = terminal_speed_m_per_s(D, RHO_P, RHO_F, MU_F)
    v, _, sim = _settle("vans", steps=1000)
    uf = float(sim.per_bead["fluid_at_bead"][0, 2])
    print(f"held drag over 0.01 s: {v + uf:.5f} m/s against {u_t:.5f}")
    assert abs((v + uf) / u_t - 1.0) > 0.5


def test_dpm_refuses_a_cfd_step_that_is_not_whole_drag_updates():
    geo = MillGeometry(0.015, 0.025, 0.01, sector_deg=360.0)
    sim = DemSimulation(geo, BeadMaterial(), np.array([[0.02, 0.0, 0.005]]), 0.5 * D, 0.0, DT,
                        threads=1)
    st = CouplingSettings(turbulence="laminar", steps=7, scheme="dpm", cfd_step_s=0.01)
    with pytest.raises(ValueError, match="cfd_step_s = 0.01.*7 x 1e-05"):
        DiscretePhaseCoupling(sim, mill_grid(geo, 1e-3), FluidProperties(RHO_F, MU_F), st,
                              0.0)


def test_primed_start_puts_the_beads_into_the_bead_free_circulation():
    """After a primed start every bead moves with the bead-free liquid at its centre (the
    rotor's pumped flow: outwards in the channel), and the liquid kept its velocities when
    the beads' void fractions came in; a scene refuses a primed start without the coupled
    fluid."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import DemSceneError
    from validation import seed002 as S

    for method in ("physical", "paper"):
        sc = S.scene_for(1200.0, 0.6, sector_deg=30.0, method=method, primed=True)
        sc = sc.with_overrides(primed_s=0.05)
        sim, cpl = make_simulation(sc, threads=1)
        assert cpl.primed_s == 0.05
        s = cpl.solver
        u = sim.per_bead["fluid_at_bead"][:, 0:3]
        r = np.hypot(sim.x[:, 0], sim.x[:, 1])
        vr = (sim.x[:, 0] * sim.v[:, 0] + sim.x[:, 1] * sim.v[:, 1]) / r
        vt = (sim.x[:, 0] * sim.v[:, 1] - sim.x[:, 1] * sim.v[:, 0]) / r
        assert np.allclose(vr, u[:, 0], atol=1e-12) and np.allclose(vt, u[:, 1], atol=1e-12)
        assert np.allclose(sim.v[:, 2], u[:, 2], atol=1e-12)
        # swirling with the rotor, and pumped outwards somewhere (the channel)
        assert 0.2 < np.median(vt / (sc.omega_rad_per_s * r)) < 1.0
        assert vr.max() > 0.05
        ur0 = s.ur.copy()
        cpl.run(cpl.unit_steps)
        if method == "physical":
            assert float(np.abs(cpl.solver.eps_c - 1.0).max()) > 0.3  # beads arrived
        assert np.isfinite(s.ur).all() and np.abs(s.ur - ur0).max() < 1.0
    bad = S.scene_for(1200.0, 0.6).with_overrides(fluid_mode="prescribed")
    with pytest.raises(DemSceneError, match="primed_s = 0.1: a primed start needs"):
        bad.with_overrides(primed_s=0.1)


def test_scene_chooses_the_scheme_by_name_and_refuses_what_does_not_fit():
    from millfmu.dem.scene import DemSceneError, load_scene_dict, scene_from_dict

    d = load_scene_dict("accelerator_slice")
    c = d["fluid"]["coupled"]
    c["scheme"] = "dpm"
    with pytest.raises(DemSceneError, match="vans_model = 'B' with scheme 'dpm'"):
        scene_from_dict(d)
    c.pop("vans_model")
    c["cfd_step_s"] = 0.01
    sc = scene_from_dict(d)
    assert sc.coupling.scheme == "dpm" and "discrete phase model" in sc.fluid_description
    c["scheme"] = "mppic"
    with pytest.raises(DemSceneError, match=r"scheme = 'mppic': allowed \['vans', 'dpm'\]"):
        scene_from_dict(d)
    c["scheme"] = "dpm"
    c["cfd_step_s"] = -1.0
    with pytest.raises(DemSceneError, match="cfd_step_s"):
        scene_from_dict(d)
    c["cfd_step_s"] = 0.01
    # the drag law by name
    assert sc.coupling.dpm_drag == "schiller_naumann" and "Schiller-Naumann" in sc.fluid_description
    c["dpm_drag"] = "koch_hill2001"
    sc = scene_from_dict(d)
    assert sc.coupling.dpm_drag == "koch_hill2001" and "Koch-Hill" in sc.fluid_description
    c["dpm_drag"] = "stokes"
    with pytest.raises(DemSceneError, match=r"dpm_drag = 'stokes': allowed \['schiller_naumann', "
                                            r"'koch_hill2001'\]"):
        scene_from_dict(d)
    c["dpm_drag"] = "koch_hill2001"
    c["scheme"] = "vans"
    with pytest.raises(DemSceneError, match="dpm_drag = 'koch_hill2001' with scheme 'vans'"):
        scene_from_dict(d)


def test_seed002_paper_method_takes_the_papers_drag_law_and_run_length():
    """`seed002 run --method paper` is seed 002's numerics with its Koch-Hill drag, 2 s of
    spin-up and 1 s recorded (section 2.3); `paper-SN` the earlier Schiller-Naumann form on
    the campaigns' shorter protocol."""
    from validation import seed002 as S

    sc = S.scene_for(1200.0, 0.8, method="paper")
    assert (sc.coupling.scheme, sc.coupling.dpm_drag) == ("dpm", "koch_hill2001")
    assert (sc.spin_up_s, sc.record_s) == (2.0, 1.0)
    sn = S.scene_for(1200.0, 0.8, method="paper-SN")
    assert (sn.coupling.scheme, sn.coupling.dpm_drag) == ("dpm", "schiller_naumann")
    assert (sn.spin_up_s, sn.record_s) == (S.SPIN_UP_S, S.RECORD_S)
    assert S.scene_for(1200.0, 0.8).coupling.scheme == "vans"


def test_dem_run_primed_from_the_command_line(tmp_path, capsys):
    """`dem run --primed S` runs the bead-free liquid first; with a prescribed fluid it is
    refused by name (exit 2), nothing run."""
    import argparse

    from millfmu.dem.cli import register

    p = argparse.ArgumentParser()
    register(p.add_subparsers())
    base = ["dem", "run", "accelerator_slice", "--sector-deg", "30", "--filling", "0.6", "--spin-up", "1e-3",
            "--record", "1e-3", "--sample-every", "1e-3", "--no-progress", "--threads", "1", "--primed", "0.01"]
    a = p.parse_args(base + ["--out", str(tmp_path / "ok")])
    assert a.func(a) == 0
    assert (tmp_path / "ok" / "stats.json").exists()
    a = p.parse_args(base + ["--out", str(tmp_path / "no"), "--fluid", "prescribed"])
    assert a.func(a) == 2
    assert "a primed start needs the coupled fluid" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()


def test_every_dpm_drag_law_has_its_name_in_the_scene_description():
    """The scene's description names each drag law the discrete phase model takes (the
    settings list the laws, the scene their names): the two lists name the same laws."""
    from millfmu.dem.coupling.settings import DPM_DRAG_LAWS
    from millfmu.dem.scene import DPM_DRAG_NAMES

    assert set(DPM_DRAG_NAMES) == set(DPM_DRAG_LAWS)
