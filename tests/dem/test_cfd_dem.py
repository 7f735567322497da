"""Checks of the coupled fluid (millfmu.dem.coupling): the projection's exact transposes,
one settling bead, a fixed bed with flow through it, and the angular-momentum budget of a
coupled disc slice."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem.coupling import exchange_kernels as EK  # noqa: E402
from millfmu.dem.coupling import projection as PJ  # noqa: E402
from millfmu.dem.coupling.cfd_dem import CfdDem  # noqa: E402
from millfmu.dem.coupling.settings import CouplingSettings  # noqa: E402
from millfmu.dem.engine.koch_hill2001 import f0_f3_python  # noqa: E402
from millfmu.dem.engine.params import BeadMaterial  # noqa: E402
from millfmu.dem.engine.sim import DemSimulation, FluidSettings  # noqa: E402
from millfmu.dem.fluid.grid import mill_grid  # noqa: E402
from millfmu.dem.fluid.solver import FluidProperties, FluidSolver  # noqa: E402
from millfmu.dem.mills.geometry import MillGeometry, fcc_sites  # noqa: E402

D = 0.8e-3
RHO_F, MU_F = 998.2, 1.002e-3


def test_axisymmetric_stencils_are_4_wide_and_sum_as_the_8_wide():
    """On an axisymmetric grid a bead's stencil holds 4 corners (the two theta corners are
    one cell, the second of weight 0): the same cells and weights, in the same order, as
    the 8 corners' non-zero ones, so that deposits and read-backs are the same to the bit
    (an 8-wide stencil, as a checkpoint of earlier sources holds, still works); a grid
    with theta cells keeps 8."""
    geo = MillGeometry(0.015, 0.045, 0.028, disc_radius_m=0.036, disc_thickness_m=0.008,
                       sector_deg=10.0)
    grid = mill_grid(geo, 0.75e-3)
    assert grid.shape[1] == 1 and PJ.stencil_width(1) == 4 and PJ.stencil_width(3) == 8
    proj = PJ.Projector(grid, 0.8e-3)
    rng = np.random.default_rng(7)
    x = fcc_sites(geo, 0.4e-3, 0.3e-3)
    x = x[rng.permutation(len(x))][:600]
    n = x.shape[0]
    nr, nt, nz = grid.shape
    st = {}
    for ns in (4, 8):
        idx = np.zeros((n, ns), np.int64)
        w = np.full((n, ns), np.nan)
        PJ.bead_stencils(x, proj.rc, proj.rtab, proj.rh, grid.dtheta_rad, nt, grid.dz_m, nz,
                         grid.height_m, grid.solid, idx, w, np.zeros(n))
        st[ns] = idx, w
    (i4, w4), (i8, w8) = st[4], st[8]
    assert np.all(np.isfinite(w4)) and np.all(w8[:, [2, 3, 6, 7]] == 0.0)
    assert np.array_equal(w4, w8[:, [0, 1, 4, 5]])
    assert np.array_equal(i4, i8[:, [0, 1, 4, 5]])
    q = rng.normal(size=(n, 6))
    t4, t8 = np.zeros((6, grid.solid.size)), np.zeros((6, grid.solid.size))
    PJ.deposit(i4, w4, q, t4)
    PJ.deposit(i8, w8, q, t8)
    assert np.array_equal(t4, t8) and np.any(t4 != 0.0)
    b4, b8 = np.zeros((n, 6)), np.zeros((n, 6))
    PJ.gather(i4, w4, t4, b4)
    PJ.gather(i8, w8, t8, b8)
    assert np.array_equal(b4, b8)


def test_deposit_and_gather_are_transposes_and_conserve():
    """Deposit (with smoothing and node splits) conserves every bead total, and reading a
    field back is its exact transpose: <gather(field), q> = <field, deposit(q)>."""
    geo = MillGeometry(0.015, 0.045, 0.028, disc_radius_m=0.036, disc_thickness_m=0.008,
                       sector_deg=30.0)
    grid = mill_grid(geo, 1e-3, n_theta=3)
    proj = PJ.Projector(grid, 0.8e-3)
    rng = np.random.default_rng(5)
    x = fcc_sites(geo, 0.4e-3, 0.3e-3)[:400]
    x = x[rng.permutation(len(x))]
    n = x.shape[0]
    idx = np.zeros((n, 8), np.int64)
    w = np.zeros((n, 8))
    nr, nt, nz = grid.shape
    PJ.bead_stencils(x, proj.rc, proj.rtab, proj.rh, grid.dtheta_rad, nt, grid.dz_m, nz,
                     grid.height_m,
                     grid.solid, idx, w, np.zeros(n))
    q = rng.normal(size=(n, 6))
    tot = np.zeros((6, grid.solid.size))
    PJ.deposit(idx, w, q, tot)
    proj.smooth_totals(tot)
    assert proj.sweeps > 1
    assert np.allclose(tot.sum(axis=1), q.sum(axis=0), rtol=1e-12, atol=1e-12)
    assert np.all(tot.reshape((6,) + grid.shape)[:, grid.solid != 0] == 0.0)
    field = rng.normal(size=(6, grid.solid.size))
    field[:, grid.solid.ravel() != 0] = 0.0
    sm = field.copy()
    proj.smooth_values(sm)
    back = np.zeros((n, 6))
    PJ.gather(idx, w, sm, back)
    lhs = float((back * q).sum())
    rhs = float((field * tot).sum())
    assert abs(lhs - rhs) <= 1e-11 * (abs(lhs) + abs(rhs))
    # cells -> velocity nodes and back (the solver's node kinds: walls and the disc)
    s = FluidSolver(grid, FluidProperties(RHO_F, MU_F), 100.0, turbulence="laminar")
    t6 = np.abs(tot).reshape((6,) + grid.shape) * 1e-12  # small volumes: no clipping
    eps = [np.ones(grid.shape), np.ones(s.ur.shape), np.ones(grid.shape), np.ones(grid.shape)]
    kd = [np.zeros(s.ur.shape), np.zeros(grid.shape), np.zeros(grid.shape)]
    sd = [np.zeros(s.ur.shape), np.zeros(grid.shape), np.zeros(grid.shape)]
    EK.cells_to_exchange(t6, grid.cell_volume_m3, 0.35, grid.solid, s.kr, s.kt, s.kz,
                         np.ascontiguousarray(s.vol_r[:, 0, 0]), grid.r_centres_m, *eps, *kd,
                         *sd)
    node_tot = [kd[0] * s.vol_r, kd[1] * s.vol_c * grid.r_centres_m[:, None, None],
                kd[2] * s.vol_c, sd[0] * s.vol_r,
                sd[1] * s.vol_c * grid.r_centres_m[:, None, None], sd[2] * s.vol_c]
    for m, col in enumerate((1, 2, 1, 3, 4, 5)):
        assert abs(node_tot[m].sum() - t6[col].sum()) < 1e-12 * np.abs(t6).sum()
    vals = [rng.normal(size=a.shape) for a in (s.ur, s.ut, s.uz, s.ur, s.ut, s.uz)]
    cells = np.zeros((6, grid.solid.size))
    EK.nodes_to_cell_values(*vals, s.kr, s.kt, s.kz, grid.solid, cells)
    for m, col in enumerate((1, 2, 1, 3, 4, 5)):
        lhs = float((vals[m] * node_tot[m]).sum())
        rhs = float((cells[m] * t6[col].ravel()).sum())
        assert abs(lhs - rhs) <= 1e-11 * (abs(lhs) + abs(rhs))


def settling(model, n_theta=1, pressure_gradient="previous_interval"):
    """One glass bead settling along the axis in still water (the liquid column held by a
    mean pressure gradient, as in a closed container); returns the bead's speed after
    0.12 s, the coupling, the simulation. With theta cells: a 45 degree sector, the bead in
    its middle."""
    sector = 360.0 if n_theta == 1 else 45.0
    geo = MillGeometry(0.015, 0.025, 0.01, sector_deg=sector)
    a = math.radians(0.5 * sector if n_theta > 1 else 0.0)
    x0 = np.array([[0.02 * math.cos(a), 0.02 * math.sin(a), 0.005]])
    sim = DemSimulation(geo, BeadMaterial(), x0, 0.5 * D, 0.0, 2e-5,
                        gravity_m_per_s2=(0.0, 0.0, -9.81),
                        fluid=FluidSettings(drag=False, lubrication=False), threads=1)
    grid = mill_grid(geo, 1e-3, n_theta=n_theta)
    cpl = CfdDem(sim, grid, FluidProperties(RHO_F, MU_F),
                 CouplingSettings(model=model, turbulence="laminar", steps=5,
                                  n_theta=n_theta, pressure_gradient=pressure_gradient), 0.0)
    weight = sim.mass[0] * 9.81 * (1.0 - RHO_F / 2510.0)
    cpl.solver.body_z = weight / grid.fluid_volume_m3
    cpl.run(6000)
    return -float(sim.v[0, 2]), cpl, sim, weight


@pytest.mark.parametrize("model,n_theta,timing", [("A", 1, "previous_interval"),
                                                   ("B", 1, "previous_interval"),
                                                   ("A", 8, "previous_interval"),
                                                   ("A", 1, "this_interval")])
def test_settling_bead_terminal_velocity_and_exchange(model, n_theta, timing):
    """With eight theta cells over 45 degrees the bead's drag goes into a few cells only and
    drags the liquid around it along (u at the bead in the print): the settling speed is
    then the drag law's up to that self-induced velocity. Model A with the pressure
    gradient of the interval just solved: the same speed, the exchange exact but for the
    last interval's pressure impulse, which the liquid receives in the next."""
    v, cpl, sim, weight = settling(model, n_theta, timing)
    # the drag law at the bead's local void fraction: (rho_p - rho_f) V g = V beta u
    eps = float(cpl.void_fraction_at_beads()[0])
    f0, f3 = f0_f3_python(eps)
    uf = float(sim.per_bead["fluid_at_bead"][0, 2])

    def drag(u):
        re = D * eps * u * RHO_F / MU_F
        beta = 18 * MU_F * eps ** 2 * (f0 + 0.5 * f3 * re) / D ** 2
        return math.pi / 6 * D ** 3 * beta * u / (eps if model == "B" else 1.0)

    lo, hi = 1e-6, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if drag(mid) < weight else (lo, mid)
    u_law = 0.5 * (lo + hi)
    print(f"model {model}, {n_theta} theta cells: settling speed {v:.5f} m/s, drag law "
          f"{u_law:.5f} m/s "
          f"(relative to the liquid at the bead: {v + uf:.5f}), local eps {eps:.5f}")
    assert abs(v / u_law - 1.0) < 0.02
    # what the liquid lost through the exchange the bead gained, to round-off
    f, b = cpl.solver.exchange_axial_ns, cpl.axial_impulse_to_beads_ns
    due = 0.0
    if timing == "this_interval":
        # sum over intervals of V dt (g_n - g_(n-1)), g_0 = 0: the last gradient's impulse
        due = math.pi / 6 * D ** 3 * cpl.interval_s * sim.per_bead["fluid_at_bead"][0, 5]
        assert abs(due) > 1e-10 * abs(b)  # above round-off: the check below sees it
    assert abs(f + b + due) <= 1e-12 * abs(b)


def test_fixed_bed_pressure_drop_koch_hill():
    """A fixed fcc bed (void fraction 0.53) in an annular sector, liquid driven through it
    by a mean pressure gradient G over a ramp: G equals the Koch-Hill prediction
    (1 - eps) beta(eps, Re) U_s / eps^2 at the superficial velocity U_s the solver gives
    (with a smoothing length of 5 d, so that the void fraction is uniform up to the walls:
    the solver's consistency); Ergun printed beside."""
    geo = MillGeometry(0.02, 0.03, 0.006, sector_deg=10.0)
    x = fcc_sites(geo, 0.5 * D, 0.05 * D)
    sim = DemSimulation(geo, BeadMaterial(), x, 0.5 * D, 0.0, 5e-6,
                        fluid=FluidSettings(drag=False, lubrication=False), threads=1)
    grid = mill_grid(geo, 0.75e-3)
    cpl = CfdDem(sim, grid, FluidProperties(RHO_F, MU_F),
                 CouplingSettings(turbulence="laminar", steps=100, smoothing_diameters=5.0),
                 0.0)
    s = cpl.solver
    eps = 1.0 - x.shape[0] * math.pi / 6 * D ** 3 / geo.free_volume_m3()
    f0, f3 = f0_f3_python(eps)
    for g_pa_m in (2e3, 2e4, 2e5):
        s.body_z = g_pa_m
        for _ in range(300):
            cpl.exchange()  # the beads are never moved
        vol = s.vol_c[s.kz == 0]
        us = float((s.eps_z * s.uz)[s.kz == 0] @ vol / vol.sum())
        re = D * us * RHO_F / MU_F
        beta = 18 * MU_F * eps ** 2 * (f0 + 0.5 * f3 * re) / D ** 2
        pred = (1 - eps) * beta * us / eps ** 2
        ergun = 150 * MU_F * (1 - eps) ** 2 * us / (eps ** 3 * D ** 2) + \
            1.75 * RHO_F * (1 - eps) * us ** 2 / (eps ** 3 * D)
        print(f"bed eps {eps:.3f}: G {g_pa_m:.3g} Pa/m, U_s {us:.4g} m/s, Re {re:.3g}, "
              f"Koch-Hill {pred:.4g} Pa/m ({pred / g_pa_m - 1:+.2%}), Ergun {ergun:.4g} Pa/m")
        assert abs(pred / g_pa_m - 1.0) < 0.05


def test_coupled_disc_slice_angular_momentum_budget(tmp_path):
    """Stirrer drive = change of fluid + bead angular momentum + chamber wall impulse,
    over a short coupled run of the disc slice from rest (10 degree sector)."""
    from millfmu.dem.run import run_scene
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), spin_up_s=0.0005, record_s=0.002,
        sample_every_s=0.0005)
    assert sc.fluid_mode == "coupled"
    st = run_scene(sc, tmp_path, progress=False)
    b = st.flow["angular_momentum_budget"]
    print("budget", b)
    assert abs(b["closure_rel"]) < 0.01
    assert b["stirrer_drive_nms"] > 0 and b["change_fluid"] > 0 and b["change_beads"] > 0
    assert "coupled CFD-DEM" in st.fluid_model and "k_epsilon" in st.fluid_model
    for f in ("fluid_fields.npz", "map_fluid_radial.png", "swirl_profile.png"):
        assert (tmp_path / f).exists()
    fl = st.flow["fluid"]
    assert fl["grid"]["n_theta"] == 1 and fl["coupling_interval_s"] == pytest.approx(5e-5)
    t = st.flow["torque"]
    assert t["stirrer_total_nm"] == pytest.approx(t["stirrer_fluid_shear_nm"] +
                                                  t["stirrer_bead_contacts_nm"])


def test_dem_advanced_alone_does_not_enter_continuity():
    """Beads advanced without the liquid (sim.run between coupled intervals, as the bench
    does) must not give the liquid one interval's d(eps)/dt for the whole gap: the first
    interval after the gap starts from the beads' present void fraction. Coupled intervals
    in a row do carry the change of the void fraction."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="coupled",
        initial_rotation=0.1)
    sim, cpl = make_simulation(sc, 1)
    s, k = cpl.solver, cpl.settings.steps
    cpl.run(5 * k)
    assert np.abs(s.eps_c - s.eps_c_old).max() > 0.0  # in a row: the beads' motion counts
    sim.run(40 * k)  # the DEM alone
    cpl.run(k)
    np.testing.assert_array_equal(s.eps_c_old, s.eps_c)
    cpl.run(k)
    assert np.abs(s.eps_c - s.eps_c_old).max() > 0.0
    r = np.hypot(sim.x[:, 0], sim.x[:, 1])
    assert r.max() < sc.geometry.chamber_radius_m and r.min() > sc.geometry.shaft_radius_m


def test_full_slice_budget_counts_the_weights_angular_impulse(tmp_path):
    """A full slice with gravity across the axis: the beads' weight has a torque about the
    axis wherever their centre of mass is off the vertical through it, and the budget
    closes only with its impulse. Disc slice with 2.4 mm beads (about 8,700), 16 theta
    cells, from a turning start; gravity ten times the earth's, so that the bed's centroid
    moves off the axis within the test's 6 ms (at 1 g the weight's impulse would be smaller
    than what a start's transients leave in the budget over so short a run)."""
    from millfmu.dem.run import run_scene
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        bead_diameter_m=2.4e-3, n_theta=16, pressure_solver="theta_fft", spin_up_s=0.002,
        record_s=0.004, sample_every_s=0.002, initial_rotation=0.1,
        gravity_m_per_s2=(0.0, -98.1, 0.0))
    assert sc.geometry.sector_deg == 360.0
    st = run_scene(sc, tmp_path, progress=False)
    b = st.flow["angular_momentum_budget"]
    print("budget", b)
    weight = b["gravity_nms"]
    assert weight is not None and weight != 0.0
    without = (b["stirrer_drive_nms"] - b["change_fluid"] - b["change_beads"]
               - b["chamber_nms"]) / b["stirrer_drive_nms"]
    print("closure without the weight", without)
    assert abs(b["closure_rel"]) < 0.01
    assert abs(without) > 10.0 * abs(b["closure_rel"])
    c = st.flow["circumferential"]
    assert len(c["centroid_rising_m"]) == len(c["centroid_up_m"]) == c["samples"] == 2


def test_coupled_sector_with_the_ldl_pressure_solver():
    """``pressure_solver = "direct_ldl"``, the default, in a coupled disc sector: the same
    run as with direct_lu chosen by name to round-off (the pressure solves agree to about
    1e-13); a scene's description names the solver when it is not the default."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="coupled",
        initial_rotation=0.1)
    runs = {}
    for solver in ("direct_lu", "direct_ldl"):
        sc = base.with_overrides(pressure_solver=solver)
        if solver == "direct_ldl":
            assert base.coupling.pressure_solver == "direct_ldl"
            assert "pressure by" not in sc.fluid_description
        else:
            assert "pressure by direct_lu" in sc.fluid_description
        sim, cpl = make_simulation(sc, 1)
        cpl.run(100)
        runs[solver] = (sim, cpl)
    (a, ca), (b, cb) = runs["direct_lu"], runs["direct_ldl"]
    assert np.abs(a.x - b.x).max() < 1e-12
    assert np.abs(ca.solver.ut - cb.solver.ut).max() < 1e-9 * np.abs(ca.solver.ut).max()
    assert np.abs(ca.solver.p - cb.solver.p).max() < 1e-6 * np.abs(ca.solver.p).max()
    assert type(cb.solver.pressure._lu).__name__ == "LdlFactor"


def _coupled_sector():
    """The 10-degree disc sector without gravity, coupled, its beads turning at 0.1 of the
    stirrer at the start (6,536 beads)."""
    from millfmu.dem.scene import load_scene

    return load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="coupled",
        initial_rotation=0.1)


@pytest.mark.parametrize("cfl, two_tasks", [(None, None), (1e-4, None), (None, False),
                                            (1e-4, False)])
def test_fused_exchange_is_the_calls_to_the_bit(cfl, two_tasks):
    """The exchange in one compiled call (coupling.fused_exchange, taken where the form
    allows: explicit smoothing, ``direct_ldl``) gives what its thirteen calls from Python
    give, to the bit: beads, held forces, the liquid's fields, clock, counters and
    impulses, over intervals in a row, the first exchange, and an interval after the DEM
    advanced alone (a gap: the beads' present void fraction first). The fused run is
    checked to take the fused path throughout; other forms of the exchange keep the calls,
    and a velocity that is not finite raises FluidError on either path. With a CFL number
    of 1e-4 the liquid takes several substeps in some intervals (the fused exchange leaves
    only the last one's turbulence to run beside the values' smoothing). Both forms of the
    fused exchange: its two tasks (taken on one or two threads, as here) and the kernels' own
    loops (more threads)."""
    from dataclasses import replace

    from millfmu.dem.fluid.solver import FluidError
    from millfmu.dem.run import make_simulation

    base = _coupled_sector()
    if cfl is not None:
        base = replace(base, coupling=replace(base.coupling, cfl=cfl))
    runs = {}
    for fused in (False, True):
        sim, cpl = make_simulation(base, 1)
        k = cpl.settings.steps
        assert cpl.fused and cpl.fused_possible()
        cpl.fused = fused
        cpl.two_tasks = two_tasks
        if fused:
            assert cpl._tasks() is (two_tasks is None)
            def calls(*a, **kw):
                raise AssertionError("the fused exchange called the smoothing from Python")
            smooth = cpl.projector.smooth_totals
            cpl.projector.smooth_totals = calls
        cpl.run(6 * k)
        sim.run(2 * k)  # the DEM alone: a gap before the next exchange
        cpl.run(3 * k)
        if fused:
            cpl.projector.smooth_totals = smooth
        runs[fused] = sim, cpl
    (a, ca), (b, cb) = runs[False], runs[True]
    for name in ("x", "v", "w", "fext"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.per_bead["fluid_at_bead"], b.per_bead["fluid_at_bead"])
    sa, sb = ca.solver, cb.solver
    for name in ("ur", "ut", "uz", "p", "k", "e", "nu_t", "eps_c", "eps_c_old", "eps_r"):
        np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
    for i in range(3):
        np.testing.assert_array_equal(sa.mean_u[i], sb.mean_u[i])
        np.testing.assert_array_equal(sa.mean_gp[i], sb.mean_gp[i])
    for name in ("time_s", "_dt_stable", "substeps", "last_substeps",
                 "angular_impulse_rotor_nms", "angular_impulse_stator_nms",
                 "angular_impulse_shaft_nms", "exchange_angular_nms", "exchange_axial_ns"):
        assert getattr(sa, name) == getattr(sb, name), name
    assert sa.pressure.solves == sb.pressure.solves == sa.substeps
    if cfl is not None:
        assert sa.substeps > ca.intervals + 2  # several substeps in some intervals
    for name in ("intervals", "clipped_cells", "stiffness", "angular_impulse_to_beads_nms",
                 "axial_impulse_to_beads_ns"):
        assert getattr(ca, name) == getattr(cb, name), name
    np.testing.assert_array_equal(ca._eps_cells, cb._eps_cells)
    # other forms keep the calls
    for over in (dict(smoothing="split_implicit"), dict(pressure_solver="direct_lu")):
        sim, cpl = make_simulation(base.with_overrides(**over), 1)
        assert not cpl.fused_possible() and not cpl.fused, over
    # a liquid that is no longer finite stops either path with a clear error
    for fused, (sim, cpl) in runs.items():
        cpl.fused = fused
        cpl.solver.ut[cpl.solver.kt == 0] = np.nan
        with pytest.raises(FluidError, match="not finite"):
            cpl.run(cpl.settings.steps)


def test_compiled_intervals_are_the_calls_to_the_bit():
    """Runs of coupling intervals in one compiled call (CfdDem._run_compiled: each fused
    exchange and the DEM's steps after it, without Python between them) give what the
    exchange and sim.run called in turn give, to the bit: beads, held forces, the liquid,
    impulses, counters and the DEM's per-interval stats, across the beads' reorderings
    (which stop a compiled run) and a neighbour-list overflow in the middle of an interval
    (whose steps run() then finishes). Recording runs keep the calls."""
    from millfmu.dem.run import make_simulation

    base = _coupled_sector()
    runs = {}
    for compiled in (False, True):
        sim, cpl = make_simulation(base, 1)
        k = cpl.settings.steps
        assert cpl.fused and cpl.compiled
        cpl.compiled = compiled
        sim.sort_every_steps = 65  # reorderings inside the runs below, between intervals
        seen = {"calls": 0, "intervals": 0, "resumed": 0}
        if compiled:
            run_compiled, resume = cpl._run_compiled, sim.resume_run

            def counted(m, run_compiled=run_compiled, seen=seen):
                seen["calls"] += 1
                seen["intervals"] += m
                return run_compiled(m)

            def resumed(*a, resume=resume, seen=seen):
                seen["resumed"] += 1
                return resume(*a)

            cpl._run_compiled, sim.resume_run = counted, resumed
        stats = cpl.run(14 * k)
        # spare lists too short for the next build: advance stops in that step
        sim._alloc_spare(sim.pair_capacity // 3)
        stats += cpl.run(16 * k)
        before = seen["calls"]
        stats += cpl.run(3 * k, record=True)
        assert seen["calls"] == before  # recording keeps the calls
        runs[compiled] = sim, cpl, stats, seen
    (a, ca, sta, _), (b, cb, stb, seen) = runs[False], runs[True]
    assert seen["calls"] >= 4 and seen["intervals"] >= 20 and seen["resumed"] == 1
    assert a.step_count == b.step_count and a._last_sort == b._last_sort > 0
    for name in ("x", "v", "w", "f", "t", "fext", "psh", "pj", "nnb"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.per_bead["fluid_at_bead"], b.per_bead["fluid_at_bead"])
    assert len(sta) == len(stb) == 33
    for x, y in zip(sta, stb):
        assert (x.steps, x.torque_sum_nm_steps, x.chamber_torque_sum_nm_steps,
                x.dropped_events, x.neighbour_builds) == \
            (y.steps, y.torque_sum_nm_steps, y.chamber_torque_sum_nm_steps,
             y.dropped_events, y.neighbour_builds)
        np.testing.assert_array_equal(x.events, y.events)
    assert sum(x.neighbour_builds for x in sta) > 0
    sa, sb = ca.solver, cb.solver
    for name in ("ur", "ut", "uz", "p", "k", "e", "nu_t", "eps_c", "eps_c_old"):
        np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
    for name in ("time_s", "_dt_stable", "substeps", "last_substeps",
                 "angular_impulse_rotor_nms", "angular_impulse_stator_nms",
                 "angular_impulse_shaft_nms", "exchange_angular_nms", "exchange_axial_ns"):
        assert getattr(sa, name) == getattr(sb, name), name
    np.testing.assert_array_equal(sa._acc, sb._acc)
    assert sa.pressure.solves == sb.pressure.solves
    for name in ("intervals", "clipped_cells", "stiffness", "angular_impulse_to_beads_nms",
                 "axial_impulse_to_beads_ns", "_synced_step"):
        assert getattr(ca, name) == getattr(cb, name), name
