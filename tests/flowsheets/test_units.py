"""The unit cores (no FMI): exact tank solution against an ODE solver, mass conservation of
every unit, the feed's integral of steps and ramps, the Tromp curve, the PI controller's
anti-windup, and flowsheet files that are refused with a clear message."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flowsheets.spec import FlowsheetError, flowsheet_from_dict
from flowsheets.units import Classifier, Feed, PIController, StepDiscarded, Tank, UnitInputError, tromp
from millfmu.kinetics.grid import SizeGrid

GRID = SizeGrid.geometric(0.1e-6, 200e-6, 4)
N = GRID.n
RNG = np.random.default_rng(5)


def _psd():
    w = RNG.random(N)
    return w / w.sum()


def _tank_ode(M0, S0, u, a, p, h):
    """Perfectly mixed tank integrated numerically: y = (M_1..M_n, S)."""
    def f(t, y):
        S = y[-1]
        return np.concatenate([u - p * y[:-1] / S, [a - p]])

    sol = solve_ivp(f, (0, h), np.concatenate([M0, [S0]]), method="LSODA", rtol=1e-11, atol=1e-14)
    return sol.y[:-1, -1], sol.y[-1, -1]


@pytest.mark.parametrize("inflow_solids, pump",
                         [(0.01, 0.02), (0.01, 0.08), (0.01, 0.05), (0.0, 0.03), (0.01, 0.05 * (1 + 1e-9))])
def test_tank_exact_step_matches_the_ode_and_conserves_mass(inflow_solids, pump):
    w0, w_in = _psd(), _psd()
    tank = Tank(GRID.edges_m, 2.0, 0.2, w0, pump)
    M0, S0 = tank.M.copy(), tank.S
    h = 37.0
    tank.step(h, [(inflow_solids, 0.2, w_in), (0.0, 0.5, None)])
    a = inflow_solids / 0.2
    M_ode, S_ode = _tank_ode(M0, S0, inflow_solids * w_in, a, pump, h)
    np.testing.assert_allclose(tank.S, S_ode, rtol=1e-10)
    np.testing.assert_allclose(tank.M, M_ode, rtol=1e-8, atol=1e-13)
    out = tank.outputs()["outflow_mass_flow"] * h
    assert abs(M0.sum() + inflow_solids * h - tank.M.sum() - out) <= 1e-15 * M0.sum() * 10


def test_tank_nearly_balanced_flows_keep_their_digits():
    # Inflow and pump balance to 1e-10: the step must agree with the balanced (k = 0)
    # solution to about 1e-10, not lose digits in (S0/S1)^(p/k) with p/k = 1e10.
    w0, w_in = _psd(), _psd()
    ms = []
    for pump in (0.05, 0.05 * (1 + 1e-10)):
        tank = Tank(GRID.edges_m, 2.0, 0.2, w0, pump)
        tank.step(0.1, [(0.01, 0.2, w_in), (0.0, 0.5, None)])
        ms.append(tank.M)
    np.testing.assert_allclose(ms[1], ms[0], rtol=1e-9)


def test_tank_runs_dry_and_then_passes_through():
    tank = Tank(GRID.edges_m, 0.1, 0.2, _psd(), 0.05)  # 0.5 kg of suspension, 0.05 kg/s: dry after 10 s
    w_in = _psd()
    tank.step(20.0, [(0.001, 0.2, w_in), (0.0, 0.5, None)])
    assert tank.S == 0.0 and tank.M.sum() == 0.0
    assert tank.outputs()["outflow_mass_flow"] * 20.0 == pytest.approx(0.1 + 0.02, rel=1e-14)
    tank.step(5.0, [(0.001, 0.2, w_in), (0.0, 0.5, None)])  # empty, inflow below the pump: passes through
    assert tank.outputs()["outflow_mass_flow"] == pytest.approx(0.001, rel=1e-14)
    np.testing.assert_allclose(tank.outputs()["psd"], w_in, rtol=1e-12)


def test_tank_refuses_bad_input_and_keeps_its_state():
    tank = Tank(GRID.edges_m, 1.0, 0.2, _psd(), 0.01)
    before = tank.get_state()
    bad = _psd() * 1.1
    with pytest.raises(UnitInputError, match="inlet1_psd = 'sum"):
        tank.step(1.0, [(0.01, 0.2, bad), (0.0, 0.5, None)])
    with pytest.raises(UnitInputError, match="inlet2_solids_mass_fraction = 1.5"):
        tank.step(1.0, [(0.0, 0.2, None), (0.01, 1.5, _psd())])
    assert tank.get_state() == before


def test_level_control_holds_the_sump_level():
    tank = Tank(GRID.edges_m, 0.1, 0.2, _psd(), 0.0, level_setpoint_kg=2.5, level_time_constant_s=30.0)
    for _ in range(200):
        tank.step(5.0, [(0.002, 0.2, _psd()), (0.0, 0.5, None)])
    assert tank.S == pytest.approx(2.5, rel=1e-3)


def test_classifier_split_conserves_each_class_and_follows_tromp():
    c = Classifier(GRID.edges_m, 8e-6, 3.0, 0.05, 0.3)
    w = _psd()
    c.step(2.0, 0.01, 0.2, w)
    o = c.outputs()
    coarse = o["coarse_mass_flow"] * o["coarse_psd"]
    fine = o["fine_mass_flow"] * o["fine_psd"]
    np.testing.assert_allclose(coarse + fine, 0.01 * w, rtol=1e-13, atol=1e-20)
    assert tromp(8e-6, 8e-6, 3.0, 0.05) == pytest.approx(0.05 + 0.95 / 2)
    assert tromp(1e-9, 8e-6, 3.0, 0.05) == pytest.approx(0.05, rel=1e-6)  # fines: only the bypass
    assert tromp(1e-3, 8e-6, 3.0, 0.05) == pytest.approx(1.0, rel=1e-6)
    # Liquid: 0.04 kg/s in the feed, 30 % to the coarse stream.
    m_c = o["coarse_mass_flow"]
    assert o["coarse_solids_mass_fraction"] == pytest.approx(m_c / (m_c + 0.3 * 0.04), rel=1e-12)


def test_classifier_before_any_flow_shows_the_split_of_the_feed_it_awaits():
    c = Classifier(GRID.edges_m, 8e-6, 3.0, 0.05, 0.3)
    w = _psd()
    c.await_feed(w)
    o = c.outputs()
    assert o["coarse_mass_flow"] == o["fine_mass_flow"] == 0.0
    c.step(2.0, 0.01, 0.2, w)  # the same feed flowing: the same distributions
    for s in ("coarse", "fine"):
        np.testing.assert_allclose(o[f"{s}_psd"], c.outputs()[f"{s}_psd"], rtol=1e-12, atol=1e-16)
        assert o[f"{s}_x50"] == pytest.approx(c.outputs()[f"{s}_x50"], rel=1e-12)


def test_feed_integrates_steps_and_ramps_exactly():
    w1, w2 = _psd(), _psd()
    prof = [[0.0, 1e-3], [10.0, 1e-3], [10.0, 2e-3], [30.0, 4e-3]]  # step at 10 s, ramp to 30 s, then constant
    f = Feed(GRID.edges_m, prof, [[0.0, w1], [25.0, w2]], 0.2)
    masses = np.zeros(N)
    for _ in range(8):
        f.step(7.0)  # steps straddle the jump (10 s) and the size change (25 s)
        o = f.outputs()
        masses += o["mass_flow"] * 7.0 * o["psd"]
    exact_total = 10 * 1e-3 + 20 * 3e-3 + 26 * 4e-3
    assert f.fed_kg == pytest.approx(exact_total, rel=1e-14)
    # Mass fed before 25 s has w1, after it w2: 10e-3 + 15 * (2e-3 + 3.5e-3)/2 before.
    before = 10e-3 + 15 * (2e-3 + 3.5e-3) / 2
    np.testing.assert_allclose(masses, before * w1 + (exact_total - before) * w2, rtol=1e-12)


def test_feed_discards_a_step_that_holds_a_jump():
    f = Feed(GRID.edges_m, [[0.0, 1e-3], [12.5, 1e-3], [12.5, 3e-3]], [[0.0, _psd()]], 0.2, event_tolerance_s=0.5)
    f.step(10.0)
    before = f.get_state()
    with pytest.raises(StepDiscarded, match="jump of the feed at t = 12.5 s"):
        f.step(10.0)
    assert f.get_state() == before
    f.step(2.5)  # ends at the jump: accepted
    f.step(10.0)
    assert f.fed_kg == pytest.approx(12.5e-3 + 10 * 3e-3, rel=1e-14)


def _plant_run(pi, steps=400, h=1.0, gain=-1.0, tau=20.0, y0=5.0):
    """First-order plant y' = (gain u + 15 - y)/tau driven by the controller, Jacobi-like."""
    y, ys, us = y0, [], []
    for _ in range(steps):
        pi.step(h, y)
        u = pi.outputs()["output"]
        y += (gain * u + 15.0 - y) * (1 - np.exp(-h / tau))
        ys.append(y)
        us.append(u)
    return np.array(ys), np.array(us)


def test_pi_reaches_its_setpoint():
    pi = PIController(setpoint=6.0, kp=0.5, ki=0.05, u_min=0.0, u_max=20.0, bias=8.0, direction=-1)
    ys, _ = _plant_run(pi)
    assert ys[-1] == pytest.approx(6.0, abs=1e-6)


def test_pi_anti_windup_keeps_the_integral_from_winding_up():
    # Setpoint 0 needs u = 15 > u_max = 12: the output saturates, and the integral must stay put.
    pi = PIController(setpoint=0.0, kp=0.5, ki=0.05, u_min=0.0, u_max=12.0, bias=8.0, direction=-1)
    _plant_run(pi, steps=300)
    assert pi.outputs()["saturated"] == 1.0
    i_sat = pi.integral
    _plant_run(pi, steps=300)
    assert pi.integral == i_sat  # not integrated while saturated
    assert abs(pi.integral) < 12.0 + 0.5 * 20  # bounded by what saturation needs, not growing with time
    # A reachable setpoint: leaves saturation and settles as fast as from a fresh start.
    pi.setpoint = 6.0
    ys, us = _plant_run(pi, steps=400, y0=15.0 - 12.0)
    assert ys[-1] == pytest.approx(6.0, abs=1e-5)
    assert us[5] < 12.0  # out of saturation within a few steps


# ---- flowsheet files --------------------------------------------------------------------
def _fs(**over):
    d = {"connections": ["tank.outflow_mass_flow -> mill.feed_mass_flow", "tank.psd[*] -> mill.psd_in[*]"],
         "flowsheet": {"t_end_s": 60.0, "step_s": 5.0},
         "units": {"tank": {"type": "tank", "pump_mass_flow_kg_per_s": 0.05, "initial_holdup_kg": 1.0},
                   "mill": {"type": "mill", "scene": {"operation": {"mode": "continuous", "n_tanks": 3}}}}}
    for k, v in over.items():
        d[k] = v
    return d


@pytest.mark.parametrize("change, key, value", [
    (dict(flowsheet={"t_end_s": 60.0, "step_s": 7.0}), "flowsheet.step_s", "7.0"),
    (dict(flowsheet={"t_end_s": 60.0, "step_s": 5.0, "algorithm": "newton"}), "flowsheet.algorithm", "'newton'"),
    (dict(flowsheet={"t_end_s": 60.0, "step_s": 5.0, "speed": 1}), "flowsheet.speed", "1"),
    (dict(connections=["tank.psd[*] -> mill.psd_in"]), "connections[0]", "[*]"),
    (dict(connections=["tank.outflow_mass_flow -> mil.feed_mass_flow"]), "connections[0]", "'mil'"),
    (dict(connections=["tank outflow -> mill"]), "connections[0]", "unit.variable -> unit.variable"),
    (dict(units={"tank": {"type": "vat"}}), "units.tank.type", "'vat'"),
    (dict(units={"tank": {"type": "tank", "pump_mass_flow_kg_per_s": -1.0}}), "units.tank.pump_mass_flow_kg_per_s",
     "-1.0"),
    (dict(units={"tank": {"type": "tank", "initial_psd": {"kind": "lognormal", "x50_m": -2e-6, "sigma_ln": 0.5}}}),
     "units.tank.initial_psd.x50_m", "-2e-06"),
    (dict(units={"m": {"type": "mill", "scene": {"operation": {"mode": "batch"}}}}), "units.m.scene.operation.mode",
     "'batch'"),
    (dict(units={"m": {"type": "mill", "scene": {"mill": {"tip_speed_m_per_s": 99.0}}}}),
     "units.m.scene.mill.tip_speed_m_per_s", "99.0"),
    (dict(units={"f": {"type": "feed", "mass_flow_kg_per_s": [[10.0, 1e-3], [5.0, 1e-3]]}}),
     "units.f.mass_flow_kg_per_s", "non-decreasing"),
    (dict(units={"c": {"type": "pi", "setpoint": 1, "kp": 1, "ki": 1, "u_min": 5, "u_max": 4, "bias": 4}}),
     "units.c.u_min", "5"),
])
def test_bad_flowsheets_are_refused_naming_key_and_value(change, key, value):
    with pytest.raises(FlowsheetError) as e:
        flowsheet_from_dict(_fs(**change), "fs.toml")
    assert e.value.key == key, str(e.value)
    assert value in str(e.value) and "fs.toml" in str(e.value)


def test_a_good_flowsheet_loads():
    fs = flowsheet_from_dict(_fs(), "fs.toml")
    assert fs.order == ["tank", "mill"] and fs.units["mill"].params["scene_dict"]["operation"]["n_tanks"] == 3
