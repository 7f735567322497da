"""The wet-restitution study's shipped summary (validation/runs/wet_restitution.json): its
ratios recomputed from its readings, the direction of the trends by each law against the
simple model's, and the page's tables taken from it."""

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


def test_the_ratios_are_the_laws_readings_over_each_other(summary):
    runs = summary["runs"]
    assert set(runs) == set(W.LAWS)
    names = ["anchor", *W.POINTS[1:]]
    for law in W.LAWS:
        assert list(runs[law]) == names
    for k in names:
        for key in B.CHAMBER_KEYS:
            want = runs["legendre2006"][k][key] / runs["lubrication"][k][key]
            assert summary["ratio_to_lubrication"][k][key] == pytest.approx(want, rel=1e-12)
    assert set(summary["trends"]["simple"]) == set(W.POINTS[1:])


def test_the_published_curve_brings_the_trends_nearer_the_simple_models_on_the_whole(summary):
    """Summed over the points, the detailed model's distance from the simple model's change
    (|ln(detailed / simple)|) is smaller with the published curve than with the table's law;
    the page says point by point where it is not."""
    t = summary["trends"]

    def off(law):
        return sum(abs(math.log(t[law][p] / t["simple"][p])) for p in t["simple"])

    assert off("legendre2006") < off("lubrication")


def test_the_yeast_pairs_fit_says_where_no_burst_energy_reaches_its_rate(summary):
    """Each law's reference run reaches at most ``reach_at_p1`` of the stand-in's rate with
    every stress breaking a cell: where that is below 1 no burst energy is given (the
    published curve, whose collisions are about half the table's law's), else one that the
    table's trends share the direction of."""
    y = summary["yeast_trends"]
    assert set(y["simple"]) == set(W.POINTS[1:])
    for law in W.LAWS:
        assert (y["reach_at_p1"][law] < 1.0) == (y["burst_median_J"][law] is None)
    assert y["reach_at_p1"]["legendre2006"] < 1.0 < y["reach_at_p1"]["lubrication"]
    # the table's law: every change in the simple model's direction, within a factor 1.5
    for p in y["simple"]:
        assert 1 / 1.5 < y["lubrication"][p] / y["simple"][p] < 1.5, p


def test_the_pages_tables_are_the_summarys(summary):
    page = (ROOT / "docs" / "rates-and-calibration.md").read_text(encoding="utf-8")
    assert W.page_tables(summary) in page
    assert W.yeast_page_table(summary) in page
    y = summary["yeast_trends"]
    worst = max(max(y["lubrication"][p] / y["simple"][p], y["simple"][p] / y["lubrication"][p]) for p in y["simple"])
    text = " ".join(page.split())
    assert f"within a factor {worst:.2f} of the simple model's" in text
    assert f"give {y['reach_at_p1']['legendre2006']:.2f} of it" in text
    f = summary["trends"]["f_mat_kg_per_J_m"]
    text = " ".join(page.split())
    assert f"{f['lubrication']:.0f} and {f['legendre2006']:.0f} kg/(J m)" in text
