"""Wet collisions (validation/wet_collisions.py): two beads through the engine against the
closed form of its lubrication law, and the shipped summary's verdicts and the page's figures
recomputed from its numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from validation import wet_collisions as W

ROOT = Path(__file__).resolve().parents[2]


def test_the_closed_form_of_the_lubrication_law():
    """No rebound below St_c = L (1 + e) / e, the dry restitution at large St, and the
    speed lost both ways, L = ln(h_cut / h_min) + 1 (St in units of it)."""
    big_l = math.log(100.0) + 1.0
    e = 0.99
    st_c = big_l * (1 + e) / e
    assert W.closed_form(0.999 * st_c, e) == 0.0 and W.closed_form(1.01 * st_c, e) > 0.0
    assert W.closed_form(1e7, e) == pytest.approx(e, abs=1e-5)
    assert W.closed_form(4 * big_l, e) == pytest.approx(e * 0.75 - 0.25)
    assert W.published(35.0, 1.0) == pytest.approx(math.exp(-1.0))
    # the Stokes number of a collision energy: 1/2 m* v^2 at v of St
    m, r = W.reduced()
    st = W.stokes_of_energy(0.5 * m * W.speed_at(50.0) ** 2)
    assert st == pytest.approx(50.0)


@pytest.mark.parametrize("st", [16.0, 200.0])
def test_two_beads_through_the_engine_follow_the_law(st):
    v = W.speed_at(st)
    dry = W.run_collision(v, False)
    assert dry == pytest.approx(W.MATERIAL["restitution"], abs=1e-3)
    assert abs(W.run_collision(v, True) - W.closed_form(st, dry)) <= W.TOLERANCE


def test_the_shipped_summary_verdicts_and_the_pages_figures():
    doc = json.loads(W.SUMMARY.read_text())
    assert [r["stokes"] for r in doc["rows"]] == list(W.STOKES)
    v = W.verdicts(doc)
    assert v["engine_matches_closed_form"] and v["legendre2006_matches_published"]
    assert v["walls_dry_under_lubrication"]
    assert v["critical_stokes_law"] == pytest.approx(11.3, abs=0.05)
    page = " ".join((ROOT / "docs" / "rates-and-calibration.md").read_text(encoding="utf-8").split())
    said = (f"St {v['stokes_at_limestone_threshold']:.0f}), e {v['e_law_at_threshold']:.2f} by the "
            f"table's law against {v['e_published_at_threshold']:.2f} by the published curve")
    assert said in page
    rows = {r["stokes"]: r for r in doc["rows"]}
    for st in (16.0, 50.0, 200.0):
        assert f"St {st:g}: {rows[st]['e_run']:.2f} against {rows[st]['e_published']:.2f}" in page
    # the DEM page's table: each law's engine runs at the Stokes numbers it shows
    dem = (ROOT / "docs" / "dem.md").read_text(encoding="utf-8")
    shown = (12.0, 16.0, 30.0, 50.0, 200.0, 1000.0)
    for key, name in (("e_published", "published, e_dry exp(-35 / St)"),
                      ("e_legendre2006_run", "`legendre2006`, two beads"),
                      ("e_wall_legendre2006_run", "`legendre2006`, bead on a wall"),
                      ("e_wall_lubrication_run", "`lubrication`, bead on a wall")):
        assert f"| {name} | " + " | ".join(f"{rows[st][key]:.3f}" for st in shown) + " |" in dem, name
    assert "| `lubrication`, two beads (its closed form) | " + " | ".join(
        f"{rows[st]['e_run']:.3f} ({rows[st]['e_closed_form']:.3f})" for st in shown) + " |" in dem

