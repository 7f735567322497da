"""The contact-law study (validation/contact_law.py): our engine against the closed forms of
a bead sliding into rolling and of a sliding oblique impact, and the shipped summary's
verdicts recomputed from its numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from validation import contact_law as C

SUMMARY = Path(__file__).resolve().parents[2] / "validation" / "runs" / "contact_law.json"


def test_sliding_to_rolling_on_a_wall_follows_the_closed_form():
    """Case a through the engine (a bead launched at 0.1 m/s on the disc's face): rolling
    from t1 = 2 v0 / (7 mu g) at 5/7 v0, slowed at mu g and spun up at 5/2 mu g / R."""
    case = C.case_slide_roll(moving_wall=False, mur=0.0, workdir=None)
    rows = case["quantities"]
    assert rows["roll onset t1 [s]"]["liggghts"] == "not installed"
    mu, v0 = C.SEED001["friction"], C.SLIP_SPEED_M_PER_S
    assert rows["roll onset t1 [s]"]["closed_form"] == pytest.approx(2 * v0 / (7 * mu * C.G_M_PER_S2))
    assert rows["speed at t1 [m/s]"]["closed_form"] == pytest.approx(5 / 7 * v0)
    for q, row in rows.items():
        assert abs(row["ours"] - row["closed_form"]) <= 1e-3 * abs(row["closed_form"]), q


def test_rolling_friction_slows_a_rolling_bead_at_five_sevenths_mu_r_g():
    """Case d on the fixed wall: rolling onset v0 / ((7/2 mu - 5/2 mu_r) g), then 5/7 mu_r g."""
    rows = C.case_slide_roll(moving_wall=False, mur=0.1, workdir=None)["quantities"]
    assert rows["rolling acceleration / (mu_r g)"]["ours"] == pytest.approx(5 / 7, rel=1e-3)
    assert rows["roll onset t1 [s]"]["ours"] == pytest.approx(0.1 / (0.8 * C.G_M_PER_S2), rel=1e-3)


def test_a_sliding_oblique_impact_gives_the_coulomb_rebound():
    """Case b at 60 degrees (Chung & Ooi's Test 4, sliding throughout): e_t = 1 - mu (1 + e_n)
    / tan(theta), omega R = 5/2 mu (1 + e_n) v_n."""
    rows = C.case_oblique(None, angles_deg=(60.0,))["quantities"]
    en = rows["e_n at 60 deg"]["ours"]
    assert en == pytest.approx(0.98, abs=2e-3)
    mu, th = C.CHUNG_OOI["friction"], math.radians(60.0)
    assert rows["e_t at 60 deg"]["ours"] == pytest.approx(1 - mu * (1 + en) / math.tan(th), abs=1e-3)
    spin = 2.5 * mu * (1 + en) * C.CHUNG_OOI_SPEED_M_PER_S * math.cos(th) / C.CHUNG_OOI_RADIUS_M
    assert rows["spin [rad/s] at 60 deg"]["ours"] == pytest.approx(spin, rel=1e-3)


def test_the_shipped_summary_agrees_with_its_own_numbers():
    """Every relative difference and verdict of validation/runs/contact_law.json recomputed
    from its values; the closed forms of case a are the docstring's."""
    s = json.loads(SUMMARY.read_text())
    assert s["command"].startswith("python -m validation.contact_law")
    assert s["verdicts"] == C.verdicts(s["cases"], s["tolerances"])
    for case in s["cases"].values():
        for q, row in case["quantities"].items():
            for comp, a, b in (("ours_vs_closed", "ours", "closed_form"),
                               ("ours_vs_liggghts", "ours", "liggghts"),
                               ("liggghts_vs_closed", "liggghts", "closed_form")):
                x, y = row[a], row[b]
                want = C.rel_diff(x, y, row["scale"]) if isinstance(x, float) and \
                    isinstance(y, float) else None
                assert row[comp] == pytest.approx(want), (q, comp)
    a = s["cases"]["a sliding to rolling (fixed wall)"]["quantities"]
    closed = C.slide_roll_closed_form(C.SLIP_SPEED_M_PER_S, C.SEED001["friction"], 0.0, False, 0.0)
    for q, v in closed.items():
        assert a[q]["closed_form"] == pytest.approx(v), q


def test_verdicts_flag_a_difference_beyond_the_tolerance():
    row = {"ours": 1.0, "liggghts": 1.05, "closed_form": 1.0, "scale": 0.0}
    v = C.verdicts({"x": {"quantities": {"q": row}}}, {"closed_form": 0.02, "liggghts": 0.01})
    assert v["x"] == {"ours_vs_closed": "agree", "ours_vs_liggghts": "differ: q",
                      "liggghts_vs_closed": "differ: q"}
    row["liggghts"] = "not installed"
    v = C.verdicts({"x": {"quantities": {"q": row}}}, {"closed_form": 0.02, "liggghts": 0.01})
    assert v["x"]["ours_vs_liggghts"] == "not compared"
