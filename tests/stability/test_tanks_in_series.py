"""Continuous mill as N tanks in series, stiff and extreme: the stability matrix of tank count
x rate span x step size. Every step finite, non-negative and mass-conserving, and k steps of
h equal one step of k h (rates frozen), up to 100 tanks and 1e8 s steps; the block-structured
propagator agrees with the dense matrix exponential where that one is affordable."""

import numpy as np
import pytest

from millfmu.kinetics import pbm
from millfmu.mill import MillModel
from tests.conftest import make_scene

#: Selection S = a (x / 200 um)^alpha on the 0.1-200 um grid: (a, alpha) for rates spanning
#: about 1e-3 ... 1 1/s (mild) and 1e-8 ... 1e8 1/s (16 decades).
SPANS = {"mild": (1.0, 1.0), "16 decades": (1e8, 4.85)}


def _scene(scene_dict, n_tanks, span):
    a, alpha = SPANS[span]
    return make_scene(scene_dict, material={"model": "austin",
                                            "selection": {"a_per_s": a, "x0_m": 200e-6, "alpha": alpha, "Lambda": 0.0}},
                      kinetics={"model": "none"}, feed={"kind": "lognormal", "x50_m": 30e-6, "sigma_ln": 0.8},
                      operation={"mode": "continuous", "n_tanks": n_tanks, "feed_mass_flow_kg_per_s": 1e-3})


@pytest.mark.parametrize("n_tanks", [1, 10, 50, 100])
@pytest.mark.parametrize("span", list(SPANS))
@pytest.mark.parametrize("h", [1e-6, 1.0, 1e4, 1e8])
def test_stability_matrix(scene_dict, n_tanks, span, h):
    s = _scene(scene_dict, n_tanks, span)
    a, b = MillModel(s), MillModel(s)
    if span == "16 decades":
        r = a.class_rates_per_s()
        assert r.max() > 1e7 and r[r > 0].min() < 1e-7
    k = 4
    for _ in range(k):
        a.step(h)
        assert np.all(np.isfinite(a.y)) and a.y.min() >= 0.0
        m_in = a.m0_kg + a.fed_kg
        assert abs(a.total_mass_kg() - m_in) <= 1e-13 * m_in
        o = a.outputs()
        assert all(np.isfinite(o[key])
                   for key in ("x10_m", "x50_m", "x90_m", "holdup_kg", "product_mass_flow_kg_per_s"))
    b.step(k * h)
    assert b.y.min() >= 0.0
    # Step invariance with frozen rates, relative to the mass in the system.
    assert np.max(np.abs(a.y - b.y)) / b.y.sum() < 1e-10


@pytest.mark.parametrize("inert", [False, True])
@pytest.mark.parametrize("n_tanks,d,h", [(1, 0.0, 5.0), (1, 0.05, 30.0), (3, 0.0, 5.0), (7, 1e-9, 2.0),
                                         (12, 0.05, 30.0), (25, 40.0, 1e3),
                                         (40, 2.0, 1e-5)])
def test_block_propagator_equals_the_dense_exponential(n_tanks, d, h, inert):
    from millfmu.kinetics.grid import SizeGrid

    grid = SizeGrid.with_classes(1e-7, 1e-4, 24)
    op = pbm.BreakageOperator(grid, lambda r: 0.3 * r**0.8 + 0.7 * r**4, inert_fragments=inert)
    series = pbm.TanksInSeries(op.matrix(0.05 * (op.nodes_m / 1e-5) ** 2), n_tanks, d, n_in=24)
    g, f = series.matrices()
    phi, gam = pbm.propagators(g, f, h)
    rng = np.random.default_rng(n_tanks)
    y, u = rng.random(series.size), rng.random(24)
    prop = series.propagator(h)
    want = phi @ y + gam @ u
    np.testing.assert_allclose(prop.apply(y, u), want, rtol=0, atol=1e-12 * want.sum())
    # Column sums: every state's mass stays or leaves (1), the feed adds h per unit flow.
    assert prop.gamma.min() >= 0.0 and prop.gamma_out.min() >= 0.0
    np.testing.assert_allclose(prop.gamma.sum(axis=(0, 1)) + prop.gamma_out, h, rtol=1e-14)
    np.testing.assert_allclose(prop.p.sum() + prop.tail[0], 1.0, rtol=1e-14)


def test_cost_grows_about_linearly_with_the_tank_count(scene_dict):
    """Not a timing assertion: the work of a step counts the propagator's stored numbers,
    which must grow linearly in N (the dense system matrix grows as N^2, its exponential as N^3)."""
    sizes = {}
    for n in (10, 100):
        m = MillModel(_scene(scene_dict, n, "mild"))
        series, u, _ = m._system(m.inputs)
        p = series.propagator(1.0)
        sizes[n] = p.e.size + p.gamma.size + p.toeplitz.size + p.tail.size
    assert sizes[100] / sizes[10] < 11.0
