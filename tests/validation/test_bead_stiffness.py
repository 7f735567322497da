"""The bead-stiffness study (validation/bead_stiffness.py): its scenes keep the contact
resolved and the liquid's step, and the shipped summary's readings and verdicts follow from
its numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from validation import bead_stiffness as B

SUMMARY = Path(__file__).resolve().parents[2] / "validation" / "runs" / "bead_stiffness.json"


@pytest.mark.parametrize("factor", [1.0, 10.0, 100.0])
def test_scene_scales_the_step_with_the_hertz_contact_time_and_keeps_the_liquid_step(factor):
    s = B.scene_for(factor, 0.8, 0.2)
    assert s.material.youngs_modulus_pa == pytest.approx(6.3e6 * factor)
    # Hertz contact time ~ Y^(-2/5): dt / t_c the same as the table's
    assert s.dt_s == pytest.approx(5e-6 * factor ** -0.4)
    assert s.dt_s * s.coupling.steps == pytest.approx(5e-5, rel=0.02)
    assert (s.tip_speed_m_per_s, s.filling, s.geometry.sector_deg) == (10.0, 0.8, 10.0)
    assert s.spin_up_s == 0.8 and s.record_s == 0.2 and s.initial_rotation == 0.1


def test_zone_readings_from_a_known_distribution():
    """One zone whose collisions all sit in one bin above the limestone threshold: its rate
    above the threshold is its frequency, its breaking rate the frequency times P(E)."""
    edges = np.logspace(-12, -6, 31)
    dens = np.zeros(30)
    k = 25  # bin centre about 1e-7 J: above 2.7e-9 J and 2.8e-10 J
    dens[k] = 1.0 / np.diff(np.log10(edges))[k]
    e = math.sqrt(edges[k] * edges[k + 1])
    st = {"se_bin_edges_j": list(edges), "zones": [
        {"name": "V1", "volume_m3": 2.0, "collision_frequency_per_m3_s": 3.0, "collision_power_w": 4.0,
         "filling": 0.5, "speed_over_tip_speed": 0.1,
         "se": {"tn": {"density_per_decade": list(dens), "quantiles_j": {"q10": e, "q50": e, "q90": e}}}},
        {"name": "V2", "volume_m3": 2.0, "collision_frequency_per_m3_s": 0.0, "collision_power_w": 0.0,
         "filling": 0.0, "speed_over_tip_speed": 0.0,
         "se": {"tn": {"density_per_decade": list(np.zeros(30)), "quantiles_j": {}}}}]}
    r = B._zone_rates(st)
    e = B.BEAD_MASS_FACTOR * e  # the detailed examples' SE_tn: the bead's mass, not the pair's
    assert r["frequency_per_m3_s"] == pytest.approx(1.5)
    assert r["above_limestone_threshold_per_m3_s"] == pytest.approx(1.5)
    assert r["above_yeast_burst_per_m3_s"] == pytest.approx(1.5)
    m_p = B.RHO_LIMESTONE_KG_PER_M3 * math.pi / 6 * B.X_PROBE_M ** 3
    p = -math.expm1(-B.F_MAT_KG_PER_J_M * B.X_PROBE_M * e * B.ELASTICITY_FACTOR / m_p)
    assert r["limestone_breaking_per_m3_s"] == pytest.approx(1.5 * p)
    assert r["power_W_per_m3"] == pytest.approx(1.0)
    assert B.LIMESTONE_THRESHOLD_10UM_J == pytest.approx(2.7e-9, rel=0.01)


def test_verdicts_flag_a_change_beyond_the_factor():
    base = dict.fromkeys(B.CHAMBER_KEYS, 1.0)
    runs = {"1": base, "10": {**base, "frequency_per_m3_s": 0.5, "power_W_per_m3": 1.4}}
    v = B.verdicts(runs)["10"]
    assert v["frequency_per_m3_s"] == "moves" and v["power_W_per_m3"] == "holds"


@pytest.mark.skipif(not SUMMARY.exists(), reason="no shipped summary")
def test_the_shipped_summary_agrees_with_its_own_numbers():
    s = json.loads(SUMMARY.read_text())
    assert s["command"].startswith("python -m validation.bead_stiffness table")
    assert s["verdicts"] == B.verdicts(s["runs"])
    for run in s["runs"].values():
        assert [z["zone"] for z in run["zones"]] == ["V1", "V2", "V3", "V4"]
        for key in ("above_limestone_threshold_per_m3_s", "above_yeast_burst_per_m3_s",
                    "limestone_breaking_per_m3_s"):
            assert 0.0 <= run[key] <= run["frequency_per_m3_s"] * (1 + 1e-12), key
    assert set(s["runs"]) >= {"1", "10"}
    # the trends at the points the runs cover: the simple model's own changes (Kwade, from
    # the trend study) and the detailed model's at each stiffness the points ran at
    tr = s["trends"]
    # the points it ran: of the trend points the studies share (the wet-restitution study
    # runs more of them)
    assert set(tr["simple"]) == set(s["point_runs"]) <= set(B.TREND_POINTS)
    assert tr["simple"]["v_t 14"] == pytest.approx(1.40, rel=0.01)
    assert tr["simple"]["d 1.2 mm"] == pytest.approx(0.296, rel=0.01)
    assert set(tr["detailed"]) == {f"{f:g}" for f in s["point_factors"]} >= {"1", "10"}
    for d in tr["detailed"].values():
        assert set(d["relative_rate"]) == set(s["point_runs"]) and d["f_mat_kg_per_J_m"] > 0
