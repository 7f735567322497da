"""The wet-restitution study's shipped summary (validation/runs/wet_restitution.json): its
ratios recomputed from its readings and the stiffness study's, the direction of the trends,
and the page's figures taken from it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from validation import bead_stiffness as B
from validation import wet_restitution as W

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def summary():
    return json.loads(W.SUMMARY.read_text())


def test_the_ratios_are_the_readings_over_the_table_laws(summary):
    ref = json.loads(W.REFERENCE.read_text())
    base = {"anchor": ref["runs"]["1"], **{p: ref["point_runs"][p]["1"] for p in W.POINTS if p}}
    assert list(summary["runs"]) == list(base)
    for k, run in summary["runs"].items():
        for key in B.CHAMBER_KEYS:
            assert summary["ratio_to_lubrication"][k][key] == pytest.approx(run[key] / base[k][key], rel=1e-12)
    t = summary["trends"]
    assert t["lubrication"] == ref["trends"]["detailed"]["1"]["relative_rate"]
    assert t["simple"] == pytest.approx(ref["trends"]["simple"])


def test_the_trends_move_towards_the_simple_models(summary):
    t = summary["trends"]
    for p in t["simple"]:
        off_wet = abs(math.log(t["legendre2006"][p] / t["simple"][p]))
        off_lub = abs(math.log(t["lubrication"][p] / t["simple"][p]))
        assert off_wet < off_lub, p


def test_the_pages_figures_are_the_summarys(summary):
    page = " ".join((ROOT / "docs" / "rates-and-calibration.md").read_text(encoding="utf-8").split())
    r = summary["ratio_to_lubrication"]
    for key, name in (("frequency_per_m3_s", "collisions per volume"),
                      ("above_limestone_threshold_per_m3_s", "collisions with SE_tn above 2.7e-9 J"),
                      ("power_W_per_m3", "collision power")):
        assert f"| {name} | " + " | ".join(f"{r[k][key]:.2f}" for k in r) + " |" in page, name
    t = summary["trends"]
    f = t["f_mat_kg_per_J_m"]
    assert f"{f['lubrication']:.0f} and {f['legendre2006']:.0f} kg/(J m)" in page
    v, d = "v_t 14", "d 1.2 mm"
    assert (f"changes at 14 m/s by {t['legendre2006'][v]:.3g} instead of {t['lubrication'][v]:.3g} and with "
            f"1.2 mm beads by {t['legendre2006'][d]:.3g} instead of {t['lubrication'][d]:.3g}") in page
    assert (f"from {t['lubrication'][v] / t['simple'][v]:.2f} and {t['lubrication'][d] / t['simple'][d]:.2f} "
            f"times the simple model's change to {t['legendre2006'][v] / t['simple'][v]:.2f} and "
            f"{t['legendre2006'][d] / t['simple'][d]:.2f} times") in page
