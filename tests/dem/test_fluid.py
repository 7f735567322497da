"""Closed-form and published checks of the fluid solver (millfmu.dem.fluid), single phase.

- circular Couette flow (rotating shaft, fixed wall): exact profile and torque, measured
  spatial order, in the axisymmetric mode and with theta cells;
- a disc rotating in a closed housing against Daily & Nece (1960): laminar regime II and,
  with k-epsilon and wall functions, turbulent regime IV.
"""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem.fluid.grid import annulus_grid, housing_grid  # noqa: E402
from millfmu.dem.fluid.solver import FluidProperties, FluidSolver  # noqa: E402

R1, R2, OMEGA, MU, RHO = 0.015, 0.025, 20.0, 1.0, 1000.0


def couette(n_r, n_theta=1, sector=2 * math.pi):
    """Laminar Couette flow run to steady state (6 viscous times (r2 - r1)^2 / nu);
    returns (max profile error / shaft speed, torque error / exact torque)."""
    g = annulus_grid(R1, R2, 0.004, n_r, 4, n_theta=n_theta, sector_rad=sector)
    s = FluidSolver(g, FluidProperties(RHO, MU), OMEGA, turbulence="laminar")
    while s.time_s < 0.6:
        s.advance(2e-3)
    a = -OMEGA * R1 ** 2 / (R2 ** 2 - R1 ** 2)
    b = OMEGA * R1 ** 2 * R2 ** 2 / (R2 ** 2 - R1 ** 2)
    rc = g.r_centres_m
    exact = a * rc + b / rc
    err = np.abs(s.ut - exact[:, None, None]).max() / (OMEGA * R1)
    # torque per length 4 pi mu omega r1^2 r2^2 / (r2^2 - r1^2), on the simulated sector
    t_exact = 4 * math.pi * MU * OMEGA * R1 ** 2 * R2 ** 2 / (R2 ** 2 - R1 ** 2) * \
        g.height_m * sector / (2 * math.pi)
    t = -s.wall_torques_nm()["shaft"]
    assert np.abs(s.ur).max() < 1e-12 and np.abs(s.uz).max() < 1e-12
    return err, abs(t / t_exact - 1.0)


def test_couette_axisymmetric_profile_torque_and_order():
    res = [couette(n) for n in (8, 16, 32)]
    for (e0, t0), (e1, t1) in zip(res[:-1], res[1:]):
        p_prof = math.log2(e0 / e1)
        p_torque = math.log2(t0 / t1)
        print(f"Couette orders: profile {p_prof:.3f}, torque {p_torque:.3f}")
        assert p_prof >= 1.8 and p_torque >= 1.8
    print(f"Couette finest (32 cells): profile error {res[-1][0]:.2e}, torque error {res[-1][1]:.2e}")
    assert res[-1][1] < 5e-3


def test_couette_with_theta_cells_matches_axisymmetric():
    """Four theta cells over a 90 degree sector give the axisymmetric solution."""
    for n in (8, 16):
        e3, t3 = couette(n, n_theta=4, sector=math.pi / 2)
        e1, t1 = couette(n)
        assert abs(e3 - e1) < 1e-9 and abs(t3 - t1) < 1e-9


def enclosed_disc(re, gap_ratio, turbulence, cell_r, cell_z, nu, t_omega, n_theta=1):
    """Moment coefficient C_M = 2 M / (rho Omega^2 a^5) of the disc (both faces and rim)
    in a closed housing, shaft radius 0.1 a, radial clearance 2 mm, after t_omega / Omega;
    with theta cells on a 45 degree sector."""
    a = 0.05
    omega = re * nu / a ** 2
    gap = round(gap_ratio * a / cell_z) * cell_z
    sector = 2 * math.pi if n_theta == 1 else math.pi / 4
    g = housing_grid(a, gap, 2 * cell_z if turbulence != "laminar" else 1e-3, 0.1 * a,
                     2e-3, cell_r, cell_z, n_theta=n_theta, sector_rad=sector)
    s = FluidSolver(g, FluidProperties(1000.0, 1000.0 * nu), omega, turbulence=turbulence)
    if turbulence != "laminar":
        s.init_turbulence((0.02 * omega * a) ** 2, 0.1 * gap)
        s.init_solid_body(0.4)
    while s.time_s < t_omega / omega:
        s.advance(5.0 / omega)
    m = -s.wall_torques_nm()["rotor_cells"] * 2 * math.pi / sector
    return 2.0 * m / (1000.0 * omega ** 2 * a ** 5), gap / a


@pytest.mark.parametrize("n_theta", [1, pytest.param(4, marks=pytest.mark.slow)])
def test_enclosed_disc_laminar_regime_ii_daily_nece(n_theta):
    cm, gr = enclosed_disc(2e4, 0.128, "laminar", 1e-3, 0.2e-3, 1e-5, 100.0, n_theta)
    ref = 3.70 * gr ** 0.1 * 2e4 ** -0.5
    print(f"regime II (Re 2e4, s/a {gr:.3f}): C_M {cm:.5f}, Daily & Nece {ref:.5f}, "
          f"ratio {cm / ref:.3f}")
    assert abs(cm / ref - 1.0) < 0.10


@pytest.mark.parametrize("n_theta", [1, pytest.param(4, marks=pytest.mark.slow)])
def test_enclosed_disc_turbulent_regime_iv_daily_nece_k_epsilon(n_theta):
    """Daily & Nece (1960) regime IV: C_M = 0.102 (s/a)^(1/10) Re^(-1/5). (Quoted as 0.0102
    in the project notes: that would put the turbulent moment 18 times below the free
    disc's 0.146 Re^(-1/5) and below the laminar regime II value at the same Re, which an
    enclosed disc cannot do; 0.102 joins regime II near its transition, Re ~ 2e5.)"""
    cm, gr = enclosed_disc(1e6, 0.1, "k_epsilon", 1e-3, 0.25e-3, 1e-6, 150.0, n_theta)
    ref = 0.102 * gr ** 0.1 * 1e6 ** -0.2
    print(f"regime IV (Re 1e6, s/a {gr:.3f}): C_M {cm:.5f}, Daily & Nece {ref:.5f}, "
          f"ratio {cm / ref:.3f}")
    assert abs(cm / ref - 1.0) < 0.20


def test_projection_is_solved_to_round_off():
    g = housing_grid(0.05, 6e-3, 1e-3, 5e-3, 2e-3, 1e-3, 0.5e-3)
    s = FluidSolver(g, FluidProperties(1000.0, 0.01), 50.0, turbulence="laminar")
    rng = np.random.default_rng(3)
    b = rng.normal(size=g.shape)
    s.pressure.solve(b, check=True)
    assert s.pressure.last_residual < 1e-10
    for _ in range(20):
        s.advance(1e-3)
    assert s.max_divergence_s() < 1e-9 * 50.0


def test_interval_means_and_a_velocity_that_is_not_finite():
    """The interval's mean velocity is the substeps' time average (several substeps in one
    interval: their dt-weighted sum over the interval), and a velocity that is not finite
    stops the liquid by name instead of passing NaN to the beads."""
    from millfmu.dem.fluid.solver import FluidError

    g = annulus_grid(R1, R2, 0.004, 12, 4)
    s = FluidSolver(g, FluidProperties(RHO, MU), OMEGA, turbulence="laminar")
    s.advance(2e-3)
    ut0 = s.ut.copy()
    s.advance(3.0 * s._dt_stable)  # at least three substeps
    assert s.last_substeps >= 3
    lo, hi = np.minimum(ut0, s.ut), np.maximum(ut0, s.ut)
    m = s.mean_u[1]
    # the flow spins up monotonically, so its mean lies between the interval's ends
    assert np.all(m >= lo - 1e-12) and np.all(m <= hi + 1e-12)
    assert np.abs(m - s.ut).max() > 0.0 and np.abs(m - ut0).max() > 0.0
    s.ut[3, 0, 1] = np.nan
    with pytest.raises(FluidError, match="not finite at t = "):
        s.advance(2e-3)


@pytest.mark.parametrize("n_theta", [1, 4])
def test_ldl_pressure_is_the_direct_solution(n_theta):
    """pressure_solver 'direct_ldl' (L D L^T on a minimum-degree ordering, numba solve):
    the residual at round-off and direct_lu's solution to round-off, with a third or less
    of its factor's entries, on the housing grid (axisymmetric) and an annulus with theta
    cells."""
    from millfmu.dem.fluid.pressure import PressureSolver

    if n_theta == 1:
        g = housing_grid(0.05, 6e-3, 1e-3, 5e-3, 2e-3, 1e-3, 0.5e-3)
    else:
        g = annulus_grid(R1, R2, 0.004, 10, 6, n_theta=n_theta, sector_rad=0.5)
    lu = PressureSolver(g, "direct_lu")
    ldl = PressureSolver(g, "direct_ldl")
    assert ldl._lu.entries < lu._lu.L.nnz + lu._lu.U.nnz
    rng = np.random.default_rng(7)
    for _ in range(3):
        b = rng.normal(size=g.shape)
        x_lu = lu.solve(b)
        x = ldl.solve(b, check=True)
        assert ldl.last_residual < 1e-11
        assert np.abs(x - x_lu).max() <= 1e-11 * np.abs(x_lu).max()
    assert np.all(x[g.solid != 0] == 0.0)
    # the one-call path of a coupled run (no residual asked) gives the same to round-off
    fast = ldl.solve(b)
    assert np.abs(fast - x).max() <= 1e-12 * np.abs(x).max()
    assert np.all(fast[g.solid != 0] == 0.0)
    # a checkpoint factorises again: the same solves to the bit
    import pickle

    again = pickle.loads(pickle.dumps(ldl))
    np.testing.assert_array_equal(again.solve(b), fast)
    if n_theta == 1:
        # a fluid's description names the solver it has
        from millfmu.dem.fluid.solver import PRESSURE_DESCRIPTIONS, FluidSolver
        from millfmu.dem.fluid.settings import PRESSURE_SOLVERS

        assert set(PRESSURE_DESCRIPTIONS) == set(PRESSURE_SOLVERS)
        d = FluidSolver(g, pressure_solver="direct_ldl").describe()["pressure"]
        assert "direct_ldl" in d and "FFT" not in d


def test_periodic_neighbour_index_is_the_modulo():
    """The liquid's kernels find periodic neighbours by adding or taking away one period
    (vans_kernels.wrap) instead of Python's integer modulo: the same index for every offset
    they use (within two periods), on periods down to one cell."""
    from millfmu.dem.fluid.vans_kernels import wrap

    for n in range(1, 8):
        for a in range(-2 * n, 2 * n):
            assert wrap(a, n) == a % n, (a, n)


def test_liquid_rows_on_threads_give_the_same_bits_on_any_thread_count():
    """The kernels that run their rows of nodes in parallel (edge stresses, the momentum
    rates, the k-epsilon production and transport) give the same liquid to the bit on one
    thread and on two: an enclosed disc with k-epsilon and theta cells (every branch of the
    stencils: theta neighbours, walls, wall functions), a velocity field perturbed so that
    no two rows are alike, advanced alike on each thread count."""
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one CPU: numba has a single thread")
    runs = []
    for threads in (1, 2):
        s, omega = _turbulent_housing(advance=False)
        g = s.grid
        prev = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            for _ in range(3):
                s.advance(2.0 / omega)
        finally:
            numba.set_num_threads(prev)
        runs.append(s)
    one, two = runs
    assert one.substeps == two.substeps and one.substeps >= 3
    for name in ("ur", "ut", "uz", "p", "k", "e", "nu_t"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)
    assert one.wall_torques_nm() == two.wall_torques_nm()
    assert np.all(np.isfinite(one.k)) and np.ptp(one.k[g.solid == 0]) > 0.0


def _turbulent_housing(advance=True):
    """A k-epsilon liquid in a housing grid with 4 theta cells, disturbed so that no two
    rows are alike (advanced by one interval of 2 / omega where ``advance``); returns it
    and omega [rad/s]."""
    a, gap, nu = 0.05, 0.005, 1e-6
    omega = 1e6 * nu / a ** 2
    g = housing_grid(a, gap, 5e-4, 0.1 * a, 2e-3, 1e-3, 2.5e-4, n_theta=4,
                     sector_rad=math.pi / 4)
    s = FluidSolver(g, FluidProperties(1000.0, 1000.0 * nu), omega, turbulence="k_epsilon")
    s.init_turbulence((0.02 * omega * a) ** 2, 0.1 * gap)
    s.init_solid_body(0.4)
    rng = np.random.default_rng(7)
    for u in (s.ur, s.ut, s.uz):
        u += 0.05 * omega * a * rng.standard_normal(u.shape)
    if advance:
        s.advance(2.0 / omega)
    return s, omega


def test_turbulence_on_the_calling_thread_is_the_threaded_one_to_the_bit():
    """The k-epsilon step's serial twins (which the coupled exchange runs as one task
    beside the smoothing) give what its row-parallel kernels give, to the bit."""
    from millfmu.dem.fluid import step_kernels as SK

    s, omega = _turbulent_housing()
    out = []
    for on_threads in (True, False):
        F = tuple(a.copy() for a in s._F)
        W = tuple(a.copy() for a in s._W)
        dt = SK.turbulence(F, W, s._K, s.wall, s.wall_om, s.rf, s.rc, s.dr, s.vc,
                           s.dth, s.dz, s.nu, True, 0.2 / omega, s.cfl,
                           on_threads)
        out.append((dt, F))
    (dt1, f1), (dt2, f2) = out
    assert dt1 == dt2 > 0.0
    for i in (SK.KT, SK.ET, SK.NUT):
        np.testing.assert_array_equal(f1[i], f2[i])
    assert not np.array_equal(f1[SK.KT], s.k)  # the step changed k


def test_a_solver_pickled_before_the_turbulence_faces_goes_on_alike():
    """A solver pickled by sources whose work arrays lacked the k-epsilon transport's face
    arrays (a run's checkpoint) gets them when unpickled and advances as a new one does."""
    import io
    import pickle

    from millfmu.dem.run import _Pickler

    def again(obj):  # as a checkpoint pickles it (the kernel modules by name)
        fh = io.BytesIO()
        _Pickler(fh, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
        return pickle.loads(fh.getvalue())

    s, omega = _turbulent_housing()
    state = dict(s.__dict__)
    del state["_kf"]
    state["_W"] = state["_W"][:30]
    old = FluidSolver.__new__(FluidSolver)
    old.__setstate__(again(state))
    new = again(s)
    assert len(old._W) == len(new._W) == 36
    for t in (old, new):
        t.advance(2.0 / omega)
    for name in ("ur", "ut", "uz", "p", "k", "e", "nu_t"):
        np.testing.assert_array_equal(getattr(old, name), getattr(new, name), err_msg=name)
