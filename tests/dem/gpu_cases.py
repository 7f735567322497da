"""The GPU path (DemSimulation(device="gpu"), numba.cuda) against the CPU path and closed
forms, on tiny scenes. Run by test_gpu_simulator.py in a process with
NUMBA_ENABLE_CUDASIM=1 (numba's CUDA simulator runs the kernels on the CPU, one Python
thread per CUDA thread: hence few beads and few steps); on a machine with a GPU the same
file runs on the GPU without the variable.

The GPU sums forces with atomic adds in no fixed order and records contacts in no fixed
order: it must agree with the CPU to round-off, and record the same contacts."""

import math

import numpy as np
import pytest

from millfmu.dem.engine import kernels as K
from millfmu.dem.engine.params import BeadMaterial, bead_mass_kg, hertz_contact_time_s
from millfmu.dem.engine.sim import DemSimulation, FluidSettings
from millfmu.dem.mills.geometry import MillGeometry, place_beads

R = 0.4e-3  # bead radius [m]
ANNULUS = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)


def both(*args, **kw):
    """The same simulation on each device."""
    return {dev: DemSimulation(*args, device=dev, **kw) for dev in ("cpu", "gpu")}


def sorted_events(ev):
    # bead-bead contacts first, then walls; within a type by beads and step
    return ev[np.lexsort((ev[:, K.EV_STEP], ev[:, K.EV_J], ev[:, K.EV_I], ev[:, K.EV_TYPE]))]


def assert_same_state(sims, atol_x=1e-15, rtol_v=1e-9):
    c, g = sims["cpu"], sims["gpu"]
    # the CPU may have reordered its beads (ids); the GPU never does
    order = np.argsort(c.ids)
    np.testing.assert_allclose(g.x, c.x[order], rtol=0, atol=atol_x)
    for name in ("v", "w", "f", "t"):
        a, b = getattr(g, name), getattr(c, name)[order]
        np.testing.assert_allclose(a, b, rtol=rtol_v, atol=rtol_v * np.abs(b).max() + 1e-300,
                                   err_msg=name)


def run_both(sims, steps, record=True):
    out = {dev: s.run(steps, record=record) for dev, s in sims.items()}
    assert out["gpu"].neighbour_builds == out["cpu"].neighbour_builds
    assert out["gpu"].dropped_events == out["cpu"].dropped_events == 0
    ec, eg = sorted_events(out["cpu"].events), sorted_events(out["gpu"].events)
    assert eg.shape == ec.shape
    # each column to round-off of its own scale: a GPU fuses multiply-adds (the CPU's
    # kernels do not), which moves a quantity that is a difference of larger terms (a
    # contact point's coordinate that should be 0, a shear energy of a nearly head-on
    # contact) by round-off of those terms, not of itself
    # (the position's three columns share one scale, as do the three stress energies)
    scale = np.abs(ec).max(axis=0) if ec.size else np.zeros(K.EV_NF)
    for group in ((K.EV_X, K.EV_Y, K.EV_Z), (K.EV_SETN, K.EV_SETS, K.EV_SEROT)):
        scale[list(group)] = scale[list(group)].max()
    for col in range(K.EV_NF):
        np.testing.assert_allclose(eg[:, col], ec[:, col], rtol=1e-9,
                                   atol=1e-12 * scale[col] + 1e-300, err_msg=f"column {col}")
    for key in ("torque_sum_nm_steps", "chamber_torque_sum_nm_steps"):
        a, b = getattr(out["gpu"], key), getattr(out["cpu"], key)
        assert a == pytest.approx(b, rel=1e-9, abs=1e-18), key
    return out


def test_head_on_restitution_hertz_time_and_cpu_agreement():
    e, v0, dt = 0.9, 2.0, 5e-7  # the contact lasts about 170 steps
    mat = BeadMaterial(restitution=e, friction=0.3, rolling_friction=0.0)
    c = np.array([0.017, 0.0, 0.002])
    x = np.array([c - [R + 1e-9, 0, 0], c + [R + 1e-9, 0, 0]])
    v = np.array([[0.5 * v0, 0, 0], [-0.5 * v0, 0, 0]])
    sims = both(ANNULUS, mat, x, R, 0.0, dt, velocities_m_per_s=v)
    g = sims["gpu"]
    steps = 0
    touching = 0
    for _ in range(40):
        run_both(sims, 5)
        steps += 5
        d = g.x[1] - g.x[0]
        if 2 * R - math.sqrt(d @ d) > 0:
            touching += 5
        elif touching:
            break
    assert_same_state(sims)
    assert g.v[1, 0] - g.v[0, 0] == pytest.approx(e * v0, rel=0.01)
    m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
    t_hertz = hertz_contact_time_s(m / 2, R / 2, mat.effective_youngs_pa, v0)
    # within the 5-step resolution of the check and the damping's lengthening
    assert touching * dt == pytest.approx(t_hertz, rel=0.05)


@pytest.mark.parametrize("ratio, mu", [(4.0, 0.3), (0.5, 100.0)])
def test_oblique_impacts_sliding_and_sticking_match_cpu(ratio, mu):
    """Tangential history, Coulomb cap and spin: gross sliding (ratio 4 of Maw's limit)
    and a stick impact (friction too high to slide)."""
    mat = BeadMaterial(restitution=0.99, friction=mu, rolling_friction=0.1)
    vn0 = 0.02
    vt0 = ratio * 3.5 * 0.3 * 1.99 * vn0
    c = np.array([0.017, 0.0, 0.002])
    x = np.array([c - [R + 1e-10, 0, 0], c + [R + 1e-10, 0, 0]])
    v = np.array([[0.5 * vn0, 0.5 * vt0, 0], [-0.5 * vn0, -0.5 * vt0, 0]])
    sims = both(ANNULUS, mat, x, R, 0.0, 2e-6, velocities_m_per_s=v)
    for _ in range(3):
        run_both(sims, 20)
    assert_same_state(sims)
    assert abs(sims["gpu"].w[0, 2]) > 0  # the contact did turn the beads


def test_shaft_chamber_and_fluid_forces_match_cpu():
    """Beads on the rotating shaft and the chamber wall, with gravity, Koch-Hill drag,
    lubrication and a held (coupled-fluid) force: forces, torques on both walls."""
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.0175, height_m=0.004)
    x = place_beads(geom, 12, R, seed=3)
    r = np.hypot(x[:, 0], x[:, 1])
    # push half of them onto the shaft, the others onto the chamber wall
    scale = np.where(np.arange(12) % 2 == 0, (0.015 + R - 2e-6) / r, (0.0175 - R + 2e-6) / r)
    x[:, :2] *= scale[:, None]
    sims = both(geom, BeadMaterial(), x, R, 500.0, 2e-6, gravity_m_per_s2=(0.0, -9.81, 0.0),
                fluid=FluidSettings(), max_neighbours=1)
    for s in sims.values():
        s.fext[:] = np.array([1e-6, 2e-9, -3e-7])  # F_r [N], T_z [N m], F_z [N]
    out = run_both(sims, 40)
    assert abs(out["gpu"].torque_sum_nm_steps) > 0
    assert abs(out["gpu"].chamber_torque_sum_nm_steps) > 0
    assert_same_state(sims)


def test_sector_disc_slice_gas_with_rebuilds_matches_cpu():
    """A bead gas in a 45 degree sector of a disc cell: image pairs across both boundary
    rays, wraps into the sector (history rotated), disc contacts, neighbour rebuilds with
    the history carried over, lists that overflow."""
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.024, height_m=0.006,
                        disc_radius_m=0.02, disc_thickness_m=0.002, sector_deg=45.0)
    x = place_beads(geom, 40, R, seed=11)
    v = np.random.default_rng(4).normal(0.0, 0.8, size=x.shape)
    sims = both(geom, BeadMaterial(), x, R, 400.0, 5e-6, velocities_m_per_s=v, max_neighbours=1,
                fluid=FluidSettings())
    builds = 0
    for _ in range(4):
        builds += run_both(sims, 25)["gpu"].neighbour_builds
    assert builds >= 2
    assert_same_state(sims, atol_x=1e-14, rtol_v=1e-8)
    th = np.arctan2(sims["gpu"].x[:, 1], sims["gpu"].x[:, 0])
    assert np.all(th > -0.01) and np.all(th < math.radians(45.0) + 0.01)


def test_zero_steps_change_nothing_then_agree_with_cpu():
    """run(0) moves nothing and keeps the forces on both devices (the GPU's kick zeroes
    the forces it reads, so a run that kicked without stepping would lose them)."""
    x = place_beads(ANNULUS, 16, R, seed=5)
    v = np.random.default_rng(2).normal(0.0, 0.5, size=x.shape)
    sims = both(ANNULUS, BeadMaterial(), x, R, 500.0, 2e-6, velocities_m_per_s=v,
                fluid=FluidSettings(), max_neighbours=1)
    before = {d: (s.x.copy(), s.v.copy(), s.f.copy()) for d, s in sims.items()}
    for d, s in sims.items():
        st = s.run(0, record=True)
        assert st.steps == 0 and st.events.shape[0] == 0
        for a, b in zip((s.x, s.v, s.f), before[d]):
            np.testing.assert_array_equal(a, b)
    run_both(sims, 30)
    assert_same_state(sims)


def test_hertz_energy_reads_the_gpu_lists():
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 30, R, seed=2, gap_m=-2e-6)  # every neighbour pair overlaps
    sims = both(geom, BeadMaterial(), x, R, 0.0, 1e-6)
    ec, eg = sims["cpu"].hertz_energy_j(), sims["gpu"].hertz_energy_j()
    assert ec > 0
    assert eg == pytest.approx(ec, rel=1e-12)


def test_contact_carried_across_a_sector_wrap_matches_cpu():
    """The wrap kernel and the history carried to the image pair (see the CPU test of
    the same name in test_contact_physics)."""
    from test_contact_physics import wrapping_contact_pair

    geom, pos, vel = wrapping_contact_pair(0.0)
    mat = BeadMaterial(restitution=0.9, friction=0.5, rolling_friction=0.0)
    sims = both(geom, mat, pos, R, 0.0, 2e-6, velocities_m_per_s=vel)
    for _ in range(12):
        run_both(sims, 5)
    assert np.arctan2(sims["gpu"].x[0, 1], sims["gpu"].x[0, 0]) > math.radians(30.0)
    assert_same_state(sims)


def test_coupled_primed_disc_sector_matches_cpu():
    """``dem run --device gpu`` with the coupled liquid: the liquid on the CPU; the DEM,
    the beads' side of the exchange and the smoothing on the GPU. The primed start gives
    the beads the liquid's velocity on the host (uploaded through host_state_changed); two
    coupling intervals then agree with the CPU's in the beads and the liquid."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    # smoothing over a quarter bead diameter: a few sweeps instead of about eighty (the
    # simulator runs one Python call per cell and sweep), the GPU's smoothing among them
    sc = load_scene("disc_slice").with_overrides(
        bead_diameter_m=2.4e-3, filling=0.5, sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0),
        primed_s=1e-3, smoothing_diameters=0.25)
    made = {dev: make_simulation(sc, 1, dev) for dev in ("cpu", "gpu")}
    assert made["gpu"][1]._gpu_side.smoother is not None
    sims = {dev: m[0] for dev, m in made.items()}
    assert 100 < sims["gpu"].n < 1000
    # the primed start moved the beads with the liquid (and the GPU holds that velocity)
    assert np.abs(sims["gpu"].v).max() > 1e-3
    np.testing.assert_array_equal(sims["gpu"]._gpu.v.copy_to_host(), sims["gpu"].v)
    for sim, cpl in made.values():
        cpl.run(2 * cpl.settings.steps)
    assert_same_state(sims, atol_x=1e-14, rtol_v=1e-8)
    sc_, sg = made["cpu"][1].solver, made["gpu"][1].solver
    for name in ("ur", "ut", "uz"):
        a, b = getattr(sg, name), getattr(sc_, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max(), err_msg=name)


@pytest.mark.parametrize("n_theta", [1, 4])
def test_coupled_beads_side_on_the_gpu_matches_the_cpu_kernels(n_theta):
    """The beads' side of the exchange on the GPU (coupling.gpu_exchange): stencils, drag
    coefficients and deposit columns, their deposit on the cells, and the held forces with
    the fluid at the beads, against the CPU's kernels on the same beads and cell fields: on
    the axisymmetric grid (4-wide stencils) and with theta cells (8-wide, the angle by
    atan2), in model A (the pressure gradient's part)."""
    from millfmu.dem.coupling import exchange_kernels as EK
    from millfmu.dem.coupling import projection as PJ
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        bead_diameter_m=2.4e-3, filling=0.5, sector_deg=40.0,
        gravity_m_per_s2=(0.0, 0.0, 0.0), initial_rotation=0.3, n_theta=n_theta)
    sim, cpl = make_simulation(sc, 1, "gpu")
    side = cpl._gpu_side
    assert side is not None and sim._gpu.fext_on_device
    assert 100 < sim.n < 1000
    cpl.model_b = False  # model A: the pressure gradient's share of q and the force
    rng = np.random.default_rng(7)
    g, s, pj = cpl.grid, cpl.solver, cpl.projector
    nr, nt, nz = g.shape
    ncell = nr * nt * nz
    fab = rng.normal(0.0, 1.0, (sim.n, 6)) * np.array([0.3, 2.0, 0.3, 50.0, 50.0, 50.0])
    sim.per_bead["fluid_at_bead"][:] = fab
    side.upload_fluid_at_beads()
    eps_cells = rng.uniform(0.45, 1.0, ncell)
    # the CPU's kernels on the same beads
    ns = cpl._idx.shape[1]
    assert ns == (8 if n_theta > 1 else 4)
    idx, w = np.zeros((sim.n, ns), np.int64), np.zeros((sim.n, ns))
    cyl, c, q, xm = np.zeros((sim.n, 4)), np.zeros(sim.n), np.zeros((sim.n, 6)), np.zeros(sim.n)
    fab_c = fab.copy()
    EK.beads_in(sim.x, sim.v, sim.rad, sim.mass, fab_c, eps_cells, s.body_z, 1.0, False,
                s.fluid.viscosity_Pa_s, s.rho, cpl.interval_s, pj.rc, pj.rtab, pj.rh,
                g.dtheta_rad, nt, g.dz_m, nz, g.height_m, g.solid, idx, w, cyl, c, q, xm)
    tot = np.zeros((6, ncell))
    PJ.deposit(idx, w, q, tot)
    tot_g = np.zeros((6, ncell))
    stiff = side.beads_in_and_deposit(eps_cells, tot_g)
    np.testing.assert_array_equal(side.idx.copy_to_host(), idx)
    np.testing.assert_allclose(side.w.copy_to_host(), w, rtol=0, atol=1e-14)
    for name, a in (("cyl", cyl), ("c", c), ("q", q)):
        np.testing.assert_allclose(getattr(side, name).copy_to_host(), a, rtol=1e-12,
                                   atol=1e-12 * np.abs(a).max(), err_msg=name)
    assert stiff == pytest.approx(xm.max(), rel=1e-12)
    assert np.abs(tot[1]).max() > 0.0  # drag coefficients deposited
    for m in range(6):
        np.testing.assert_allclose(tot_g[m], tot[m], rtol=0,
                                   atol=1e-12 * np.abs(tot[m]).max(), err_msg=f"column {m}")
    # every bead's volume, and nothing else, went onto the cells
    assert tot_g[0].sum() == pytest.approx(np.sum(np.pi / 6.0 * (2.0 * sim.rad) ** 3),
                                           rel=1e-12)
    cellv = rng.normal(0.0, 1.0, (6, ncell)) * np.array([[0.5], [3.0], [0.5], [80.0],
                                                          [80.0], [80.0]])
    for now in (False, True):
        fext = np.zeros((sim.n, 3))
        fab_n = fab_c.copy()
        ts, fs = EK.bead_forces(idx, w, cellv, c, cyl, sim.rad, fab_n, 1.0, now, s.body_z,
                                fext)
        side.fab.copy_to_device(fab_c)
        tg, fg = side.bead_forces(cellv, 1.0, now, s.body_z)
        fe_g = sim._gpu.fext.copy_to_host()
        np.testing.assert_allclose(fe_g, fext, rtol=0, atol=1e-12 * np.abs(fext).max())
        np.testing.assert_allclose(side.fab.copy_to_host(), fab_n, rtol=0,
                                   atol=1e-12 * np.abs(fab_n).max())
        assert tg == pytest.approx(ts, rel=1e-9, abs=1e-12 * np.abs(fext[:, 1]).sum())
        assert fg == pytest.approx(fs, rel=1e-9, abs=1e-12 * np.abs(fext[:, 2]).sum())
    # the host copies follow on demand; the DEM's run no longer uploads the held force
    side.to_host()
    np.testing.assert_array_equal(sim.fext, fe_g)
    sim.fext[:] = 0.0
    sim.run(1)
    np.testing.assert_array_equal(sim._gpu.fext.copy_to_host(), fe_g)


def test_coupled_gpu_beads_side_switched_off_and_on_gives_the_cpu_intervals():
    """A coupled disc sector whose beads' side runs on the GPU for an interval, then on the
    CPU (set_gpu_beads(False): the host arrays brought back), then on the GPU again, ends
    where the CPU's coupled run does, to round-off; the CPU's DEM refuses the GPU's side."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        bead_diameter_m=2.4e-3, filling=0.5, sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0),
        initial_rotation=0.3, smoothing_diameters=0.25)  # few sweeps: see above
    made = {dev: make_simulation(sc, 1, dev) for dev in ("cpu", "gpu")}
    with pytest.raises(ValueError, match="CPU"):
        made["cpu"][1].set_gpu_beads(True)
    sg, cg = made["gpu"]
    k = cg.settings.steps
    for on in (True, False, True):
        side = cg._gpu_side
        cg.set_gpu_beads(on)
        assert (cg._gpu_side is not None) == on == sg._gpu.fext_on_device
        if not on:  # the host's stencils are the last exchange's, not those before the GPU's
            np.testing.assert_array_equal(cg._idx, side.idx.copy_to_host())
            np.testing.assert_array_equal(cg._w, side.w.copy_to_host())
        cg.run(k)
    made["cpu"][1].run(3 * k)
    sims = {dev: m[0] for dev, m in made.items()}
    assert_same_state(sims, atol_x=1e-14, rtol_v=1e-8)
    np.testing.assert_allclose(cg.solver.ut, made["cpu"][1].solver.ut, rtol=0,
                               atol=1e-9 * np.abs(made["cpu"][1].solver.ut).max())


@pytest.mark.parametrize("n_theta", [1, 4])
def test_gpu_smoothing_matches_the_cpu_sweeps(n_theta):
    """The Projector's explicit-diffusion smoothing on the GPU
    (coupling.gpu_exchange.GpuSmoother, each cell gathering its faces' fluxes) against the
    CPU's sweeps (projection.diffuse, each face adding to its two cells): cell totals
    (conserved) and the first three columns of cell values (the rest untouched), on the disc
    sector's grid with its solid disc, axisymmetric and with theta cells."""
    from numba import cuda

    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        bead_diameter_m=2.4e-3, filling=0.5, sector_deg=40.0,
        gravity_m_per_s2=(0.0, 0.0, 0.0), n_theta=n_theta)
    sim, cpl = make_simulation(sc, 1, "gpu")
    side = cpl._gpu_side
    assert side.smoother is not None and side.smoother.sweeps == cpl.projector.sweeps
    g = cpl.grid
    assert np.any(g.solid != 0)
    ncell = int(np.prod(g.shape))
    pj, sm = cpl.projector, side.smoother
    rng = np.random.default_rng(3)
    a = rng.uniform(0.0, 1.0, (6, ncell)) * np.array([[1e-9], [5.0], [1e-3], [2e-4], [1e-6],
                                                       [3e-6]])
    a[:, (g.solid != 0).ravel()] = 0.0
    # one and two of the projector's sweeps (the simulator runs one Python call per cell
    # and sweep): the result in the second array (1) and in the first (2)
    for sweeps, totals, ncols in ((1, True, 6), (2, True, 6), (1, False, 3)):
        pj.sweeps = sm.sweeps = sweeps
        cpu = a.copy()
        pj._smooth(cpu, totals, ncols)
        d = cuda.to_device(a)
        out = sm.smooth(d, totals, ncols)
        assert (out is d) == (sweeps % 2 == 0) and sm.buf is not out
        res = out.copy_to_host()
        for m in range(6):
            ref = cpu[m]
            np.testing.assert_allclose(res[m], ref, rtol=0, atol=1e-13 * np.abs(ref).max(),
                                       err_msg=f"{sweeps} sweeps, totals {totals}, column {m}")
            if m >= ncols:
                np.testing.assert_array_equal(res[m], a[m])
            else:
                assert np.abs(ref - a[m]).max() > 1e-3 * np.abs(a[m]).max()  # it did smooth
            if totals:
                assert res[m].sum() == pytest.approx(a[m].sum(), rel=1e-13)
