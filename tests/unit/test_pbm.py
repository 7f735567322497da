"""Population balance: conservation, non-negativity, step invariance, continuous mass balance, integrator order."""

import numpy as np
import pytest

from millfmu.kinetics import pbm
from millfmu.kinetics.grid import (SizeGrid, characteristic_size_m, characteristic_sizes_m, fractions_from_q3,
                                   q3_lognormal)
from millfmu.mill import InputError, MillModel
from tests.conftest import make_scene


def _operator(n=60, inert=False, alpha=2.0):
    grid = SizeGrid.with_classes(1e-7, 1e-4, n)
    op = pbm.BreakageOperator(grid, lambda r: 0.3 * r**0.8 + 0.7 * r**4, inert_fragments=inert)
    s = 0.05 * (op.nodes_m / 1e-5) ** alpha
    return op, op.matrix(s)


@pytest.mark.parametrize("inert", [False, True])
def test_operator_columns_sum_to_zero_and_metzler(inert):
    op, a = _operator(inert=inert)
    scale = np.abs(np.diag(a)).max()
    assert np.max(np.abs(a.sum(axis=0))) <= 1e-15 * scale * a.shape[0]
    off = a - np.diag(np.diag(a))
    assert off.min() >= 0.0 and np.diag(a).max() <= 0.0
    # Fragments only go to finer classes (or below the grid): triangular in upper_order.
    o = op.upper_order
    assert np.all(np.tril(a[np.ix_(o, o)], -1) == 0.0)
    assert np.all(a[-1] >= 0.0) and a[-1, -1] == 0.0  # the below-grid state only receives


def test_system_matrix_block_bidiagonal_and_conservative():
    _, a = _operator(n=20)
    m = a.shape[0]  # 20 classes and the below-grid state
    g = pbm.system_matrix(a, 3, 0.7)
    f = pbm.feed_matrix(m, 3, 20)
    assert np.max(np.abs(g.sum(axis=0))) <= 1e-14 * np.abs(g).max()
    np.testing.assert_array_equal(g[pbm.tank_slice(1, m, 3), pbm.tank_slice(0, m, 3)], 0.7 * np.eye(m))
    np.testing.assert_array_equal(g[pbm.tank_slice(0, m, 3), pbm.tank_slice(1, m, 3)], 0.0)
    assert np.all(f.sum(axis=0) == 1.0) and np.all(f[pbm.tank_slice(0, m, 3)].sum(axis=0) == 1.0)


def test_propagator_nonnegative_unit_columns():
    _, a = _operator()
    g = pbm.system_matrix(a, 1, 0.0)
    for h in (1e-3, 1.0, 1e3, 1e6):
        phi, _ = pbm.propagators(g, None, h)
        assert phi.min() >= 0.0
        assert np.allclose(phi.sum(axis=0), 1.0, rtol=0, atol=phi.shape[0] * np.finfo(float).eps)


@pytest.mark.parametrize("mode", ["batch", "continuous"])
def test_step_invariance_frozen_rates(scene_dict, mode):
    """k steps of h equal one step of k h to 1e-10 relative when rates are frozen."""
    ops = {"mode": mode, "n_tanks": 3, "feed_mass_flow_kg_per_s": 1e-4} if mode == "continuous" else {"mode": "batch"}
    s = make_scene(scene_dict, operation=ops)
    for k, h in ((10, 1.0), (7, 13.0), (100, 0.25)):
        m1, m2 = MillModel(s), MillModel(s)
        for _ in range(k):
            m1.step(h)
        m2.step(k * h)
        rel = np.max(np.abs(m1.y - m2.y)) / m2.y.sum()
        assert rel <= 1e-10, (k, h, rel)


def test_batch_mass_conserved_and_nonnegative(scene_dict):
    m = MillModel(make_scene(scene_dict))
    m0 = m.total_mass_kg()
    for h in (0.1, 1.0, 10.0, 1000.0, 1e5):
        m.step(h)
        assert m.y.min() >= 0.0
        assert abs(m.total_mass_kg() - m0) <= 1e-14 * m0


def test_continuous_mass_balance_in_out_accumulation(scene_dict):
    s = make_scene(scene_dict, operation={"mode": "continuous", "n_tanks": 4, "feed_mass_flow_kg_per_s": 2e-4})
    m = MillModel(s)
    holdup0 = m.outputs()["holdup_kg"]
    fed = out = 0.0
    rng = np.random.default_rng(1)
    for _ in range(200):
        h = rng.uniform(0.1, 20.0)
        mdot = rng.uniform(0.0, 5e-4)
        o = m.step(h, feed_mass_flow_kg_per_s=mdot)
        fed += mdot * h
        out += o["product_mass_flow_kg_per_s"] * h
        assert m.y.min() >= 0.0
    acc = o["holdup_kg"] - holdup0
    assert abs(fed - out - acc) <= 1e-12 * (holdup0 + fed)


def test_feed_ramp_within_a_step_books_the_mass_fed(scene_dict):
    """A feed rate ramped within one step (adaptive path): the mass balance still closes."""
    m = MillModel(make_scene(scene_dict,
                             operation={"mode": "continuous", "n_tanks": 2, "feed_mass_flow_kg_per_s": 1e-3}))
    m.step(10.0, inputs_end={"feed_mass_flow_kg_per_s": 3e-3}, feed_mass_flow_kg_per_s=1e-3)
    assert m.fed_kg == pytest.approx(0.02, rel=1e-15)
    assert abs(m.total_mass_kg() - (m.m0_kg + m.fed_kg)) <= 1e-12 * m.total_mass_kg()


def test_continuous_steady_state_residence_time(scene_dict):
    """With zero rates the outlet follows the N-tanks-in-series washout: holdup -> V c for any initial content."""
    s = make_scene(scene_dict, operation={"mode": "continuous", "n_tanks": 2, "feed_mass_flow_kg_per_s": 1e-3},
                   mill={"tip_speed_m_per_s": 0.0})
    m = MillModel(s)
    op = m.operating_point(m.inputs)
    q = 1e-3 / op.solids_concentration_kg_per_m3
    v = m.suspension_volume_m3(op)
    tau = v / q
    m.y[1:] *= 0.5  # half-empty start (y[0] is the outflow accumulator)
    o = m.step(40 * tau)
    assert o["holdup_kg"] == pytest.approx(op.solids_concentration_kg_per_m3 * v, rel=1e-9)
    assert o["product_mass_flow_kg_per_s"] == pytest.approx(1e-3 * (40 * tau - 0.5 * tau) / (40 * tau), rel=1e-6)


def test_state_round_trip_bit_identical(scene_dict):
    m = MillModel(make_scene(scene_dict,
                             operation={"mode": "continuous", "n_tanks": 2, "feed_mass_flow_kg_per_s": 1e-4}))
    m.step(3.0)
    st = m.get_state()
    a = [m.step(h)["x50_m"] for h in (1.0, 2.5, 0.3)]
    y_a = m.y.copy()
    m.set_state(st)
    b = [m.step(h)["x50_m"] for h in (1.0, 2.5, 0.3)]
    assert a == b and np.array_equal(y_a, m.y)


def test_bad_input_leaves_state_unchanged(scene_dict):
    m = MillModel(make_scene(scene_dict, operation={"mode": "continuous", "feed_mass_flow_kg_per_s": 1e-4}))
    m.step(1.0)
    st = m.get_state()
    n = m.grid.n
    bad = [
        {"tip_speed_m_per_s": -1.0}, {"tip_speed_m_per_s": float("nan")}, {"feed_mass_flow_kg_per_s": -1e-3},
        {"feed_mass_flow_kg_per_s": float("inf")}, {"bead_filling": 1.0}, {"bead_filling": 0.0},
        {"psd_in": np.full(n, 0.5 / n)}, {"psd_in": np.r_[-0.1, np.full(n - 1, 1.1 / (n - 1))]}, {"psd_in": np.ones(3)},
        {"solids_mass_fraction": 0.0}, {"bogus": 1.0},
    ]
    for b in bad:
        with pytest.raises(InputError) as e:
            m.step(1.0, **b)
        assert list(b)[0] in str(e.value) or "psd_in" in str(e.value)
        assert np.array_equal(m.y, st["y"]) and m.t_s == st["t_s"]
    b = MillModel(make_scene(scene_dict))
    with pytest.raises(InputError, match="batch"):
        b.step(1.0, feed_mass_flow_kg_per_s=1e-3)
    for h in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="dt_s"):
            m.step(h)


def test_feed_distribution_changed_in_place_is_checked_again(scene_dict):
    """The check of psd_in is remembered by content (a host passes the same array at every
    step): an array the caller changes in place between steps is checked again, and the
    normalised fractions follow its new content."""
    m = MillModel(make_scene(scene_dict, operation={"mode": "continuous", "feed_mass_flow_kg_per_s": 1e-4}))
    n = m.grid.n
    feed = np.full(n, 1.0 / n)
    m.step(1.0, psd_in=feed)
    m.step(1.0, psd_in=feed)
    feed[0] = -0.1
    with pytest.raises(InputError, match=r"psd_in\[1\]"):
        m.step(1.0, psd_in=feed)
    feed[:] = 0.0
    feed[-1] = 1.0
    m.step(1.0, psd_in=feed)
    assert m.inputs["psd_in"][-1] == 1.0 and m.inputs["psd_in"][:-1].sum() == 0.0


def test_q3_sizes_step_after_step_equal_a_fresh_search():
    """The step's quantile search starts from the last call's classes: over distributions
    that drift, jump, and have empty classes and levels on class edges, it gives exactly
    the sizes of a search from scratch."""
    from millfmu.kinetics.grid import Q3Sizes, sizes_from_cumulative

    grid = SizeGrid.geometric(1e-7, 1e-3, 30)
    le = np.log(grid.edges_m)
    q = (0.1, 0.5, 0.9)
    walk = Q3Sizes(le, q)
    rng = np.random.default_rng(3)
    w = rng.random(30)
    for i in range(300):
        if i % 50 == 0:
            w = rng.random(30) ** 8  # a jump
        w = w * np.exp(0.05 * rng.normal(size=30))
        if i % 7 == 0:
            w[rng.integers(0, 30, 5)] = 0.0  # empty classes
        if i % 11 == 0:
            w = np.zeros(30)
            w[[3, 4, 20]] = [0.1, 0.4, 0.5]  # levels exactly on class edges
        cum = w.cumsum()
        below = float(rng.random() * cum[0]) if i % 3 else 0.0
        assert walk.sizes(cum, below) == sizes_from_cumulative(le, cum, q, below)
    assert all(np.isnan(walk.sizes(np.zeros(30))))


def test_characteristic_sizes_lognormal():
    grid = SizeGrid.geometric(1e-7, 1e-3, 16)
    w = fractions_from_q3(grid, q3_lognormal(grid.edges_m, 1e-5, 0.7))
    x10, x50, x90 = characteristic_sizes_m(grid, w, (0.1, 0.5, 0.9))
    assert x50 == pytest.approx(1e-5, rel=1e-3)
    assert x10 == pytest.approx(1e-5 * np.exp(-1.2815516 * 0.7), rel=2e-3)
    assert x90 == pytest.approx(1e-5 * np.exp(1.2815516 * 0.7), rel=2e-3)
    assert characteristic_size_m(grid, w, 0.5) == pytest.approx(x50, rel=1e-12)


def test_adaptive_exponential_midpoint_second_order():
    """Fixed-step convergence of the exponential midpoint with a time-varying rate: order ~2."""
    _, a = _operator(n=30)
    y0 = np.zeros(a.shape[0] + 1)
    y0[25] = 1.0

    def system(t, y):
        return pbm.TanksInSeries(a * (1.0 + 0.9 * np.sin(t)), 1, 0.0), None

    def run(n):
        y, t, h = y0.copy(), 0.0, 4.0 / n
        for _ in range(n):
            # rtol=1 accepts the first try: one midpoint step of h/2 twice, fixed step size.
            y, _ = pbm.adaptive_exponential_step(y, t, h, system, rtol=1.0, atol=1.0)
            t += h
        return y

    ref, _ = pbm.adaptive_exponential_step(y0, 0.0, 4.0, system, rtol=1e-12, atol=1e-16)
    errs = [np.abs(run(n) - ref).sum() for n in (8, 16, 32, 64)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.9), orders


def test_adaptive_ramp_matches_fine_steps(scene_dict):
    """A tip-speed ramp within one step (adaptive) against many small frozen steps."""
    s = make_scene(scene_dict)
    a, b = MillModel(s), MillModel(s)
    a.step(60.0, inputs_end={"tip_speed_m_per_s": 12.0}, tip_speed_m_per_s=6.0)
    n = 6000
    for i in range(n):
        b.step(60.0 / n, tip_speed_m_per_s=6.0 + 6.0 * (i + 0.5) / n)
    assert np.abs(a.y - b.y).sum() / b.y.sum() < 1e-5
    assert abs(a.total_mass_kg() - a.m0_kg) <= 1e-14 * a.m0_kg
    assert abs(b.total_mass_kg() - b.m0_kg) <= n * np.finfo(float).eps * b.m0_kg  # round-off of n steps


def test_no_subnormal_masses_after_a_long_batch():
    """A class that decays below the smallest normal double is set to zero (a subnormal
    makes every later product with it several times slower on x86); the mass stays."""
    from millfmu.kinetics.pbm import SUBNORMAL, flush_subnormal
    from millfmu.mill import MillModel
    from millfmu.scene import load_scene

    a = np.array([1.0, 1e-310, -1e-310, 2.2250738585072014e-308, 0.0])
    assert flush_subnormal(a).tolist() == [1.0, 0.0, 0.0, 2.2250738585072014e-308, 0.0]
    m = MillModel(load_scene())
    total = m.y.sum()
    for _ in range(3000):  # the default scene's coarse classes reach 1e-308 kg within the hour
        m.step(1.0)
    y = m.y
    assert not np.any((y != 0.0) & (np.abs(y) < SUBNORMAL)) and np.all(y >= 0.0)
    assert np.any(y == 0.0)  # the case reaches the flush
    assert abs(y.sum() - total) <= 1e-13 * total
