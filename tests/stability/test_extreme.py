"""Stiff and extreme cases: finite, non-negative, conserving."""

import numpy as np
import pytest

from millfmu.mill import MillModel
from millfmu.scene import SceneError
from tests.conftest import make_scene


def _check(m, m_expected):
    assert np.all(np.isfinite(m.y)) and m.y.min() >= 0.0
    assert abs(m.total_mass_kg() - m_expected) <= 1e-13 * max(m_expected, 1e-300)
    o = m.outputs()
    for k in ("x10_m", "x50_m", "x90_m", "holdup_kg", "power_W", "sf_per_s", "specific_energy_J_per_kg"):
        assert np.isfinite(o[k]), k


def _stiff(scene_dict, **extra):
    # S spans 1e-8 ... 1e8 1/s over the grid (0.1 ... 200 um): S = 1e8 (x / 200 um)^4.85
    return make_scene(scene_dict, material={"model": "austin", "selection": {"a_per_s": 1e8, "x0_m": 200e-6,
                                                                             "alpha": 4.85, "Lambda": 0.0}},
                      kinetics={"model": "none"}, feed={"kind": "lognormal", "x50_m": 30e-6, "sigma_ln": 0.8}, **extra)


@pytest.mark.parametrize("mode", ["batch", "continuous"])
def test_rates_spanning_16_decades_with_1000_s_steps(scene_dict, mode):
    ops = {"mode": mode, "n_tanks": 3, "feed_mass_flow_kg_per_s": 1e-3}
    m = MillModel(_stiff(scene_dict, operation=ops))
    r = m.class_rates_per_s()
    assert r.max() > 1e7 and r[r > 0].min() < 1e-7
    for _ in range(5):
        m.step(1000.0)
        _check(m, m.m0_kg + m.fed_kg)
    # k steps of h = one step of k h, even this stiff.
    a, b = MillModel(_stiff(scene_dict, operation=ops)), MillModel(_stiff(scene_dict, operation=ops))
    for _ in range(10):
        a.step(100.0)
    b.step(1000.0)
    assert np.max(np.abs(a.y - b.y)) / b.y.sum() < 1e-10


def test_stiff_with_tiny_steps(scene_dict):
    m = MillModel(_stiff(scene_dict))
    for h in (1e-9, 1e-6, 1e-3):
        m.step(h)
        _check(m, m.m0_kg)


def test_zero_rates_leave_psd_unchanged(scene_dict):
    s = make_scene(scene_dict, material={"model": "austin", "selection": {"a_per_s": 0.0}}, kinetics={"model": "none"})
    m = MillModel(s)
    y0 = m.y.copy()
    m.step(1000.0)
    assert np.array_equal(m.y, y0)


def test_tip_speed_zero(scene_dict):
    m = MillModel(make_scene(scene_dict, mill={"tip_speed_m_per_s": 0.0}))
    y0 = m.y.copy()
    o = m.step(1000.0)
    assert np.array_equal(m.y, y0)
    assert o["power_W"] == 0.0 and o["se_beads_J"] == 0.0 and o["specific_energy_J_per_kg"] == 0.0
    _check(m, m.m0_kg)


def test_zero_feed_continuous(scene_dict):
    m = MillModel(make_scene(scene_dict,
                             operation={"mode": "continuous", "n_tanks": 2, "feed_mass_flow_kg_per_s": 0.0}))
    h0 = m.outputs()["holdup_kg"]
    o = m.step(1000.0)
    assert o["product_mass_flow_kg_per_s"] == 0.0
    assert o["holdup_kg"] == pytest.approx(h0, rel=1e-13)
    _check(m, m.m0_kg)


def test_one_occupied_class(scene_dict):
    m = MillModel(make_scene(scene_dict, feed={"kind": "monodisperse", "x_m": 30e-6}))
    assert np.count_nonzero(m.y) == 1
    for h in (1e-6, 1.0, 1000.0):
        m.step(h)
        _check(m, m.m0_kg)
    assert np.count_nonzero(m.y) > 10


def test_only_finest_class_occupied(scene_dict):
    """What breaks in the finest class leaves the grid: it goes below the grid, nowhere else."""
    m = MillModel(make_scene(scene_dict, feed={"kind": "monodisperse", "x_m": 0.101e-6}, kinetics={"model": "simple"},
                             grid={"x_min_m": 0.1e-6}))
    y0 = m.y.copy()
    m.step(1000.0)
    changed = np.flatnonzero(m.y != y0)
    assert set(changed) <= {1, len(y0) - 1}  # the finest class and the below-grid state
    assert m.y[-1] > 0.0 and m.outputs()["below_grid_fraction"] == m.y[-1] / m.y[1:].sum()
    _check(m, m.m0_kg)


def test_extreme_operating_points(scene_dict):
    for mill in ({"tip_speed_m_per_s": 40.0}, {"bead_filling": 1e-6}, {"tip_speed_m_per_s": 1e-9}):
        m = MillModel(make_scene(scene_dict, mill=mill, kinetics={"model": "simple"}))
        m.step(1e4)
        _check(m, m.m0_kg)


def test_extreme_tip_speeds_on_the_default_table(detailed_scene_dict):
    """The detailed example reads the default scene's DEM table: tip speeds beyond its grid
    use the edge's dimensionless fields (similarity); a filling beyond it is refused, naming
    the bounds."""
    for v in (40.0, 1e-9):
        m = MillModel(make_scene(detailed_scene_dict, mill={"tip_speed_m_per_s": v}))
        m.step(1e4)
        _check(m, m.m0_kg)
    with pytest.raises(SceneError,
                       match="mill.bead_filling = 1e-06: outside the stress-energy table's grid; allowed 0.5 to 0.9"):
        MillModel(make_scene(detailed_scene_dict, mill={"bead_filling": 1e-6}))
