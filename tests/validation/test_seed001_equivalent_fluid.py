"""Seed 001's secondary vortex against its equivalent fluid (validation.seed001_equivalent_fluid):
the kept summary's verdict is the one its cases give, the page quotes it, and a short case
runs the liquid alone with seed 001's fluid and gives a census of its mean flow."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from validation import seed001_equivalent_fluid as E

ROOT = Path(__file__).resolve().parents[2]


def test_the_kept_summary_verdict_is_computed_and_quoted():
    s = json.loads(E.SUMMARY.read_text())
    assert s["verdict"] == E.verdict(s)
    p = s["protocol"]
    assert (p["rho_eff_kg_per_m3"], p["eta_eff_Pa_s"], p["t_start_s"], p["t_end_s"]) == \
        (E.RHO_EFF, E.ETA_EFF, E.T_START_S, E.T_END_S)
    assert {(c["tip_speed_m_per_s"], c["cell_m"]) for c in s["cases"]} == \
        {(v, c) for v in E.TIP_SPEEDS for c in E.CELLS_M}
    page = " ".join((ROOT / "docs" / "validation-seed001.md").read_text().split())
    assert s["verdict"] in page


def test_the_verdict_matches_only_where_every_grid_gives_seed_001s_speeds():
    def c(v, cell, sec):
        vort = [{"r_mm": 30.0, "zeta_mm": 9.0, "sign": -1, "strength": 1.0, "region": "between discs"}]
        if sec:
            vort.append({"r_mm": 43.0, "zeta_mm": 4.3, "sign": 1, "strength": 0.05, "region": "disc tip to wall"})
        m = {"large": 1, "secondary": int(sec), "vortices": vort}
        return {"tip_speed_m_per_s": v, "cell_m": cell, "mean": m, "halves": [m, m]}

    paper = {"cases": [c(v, cell, v in E.PAPER_WITH) for v in E.TIP_SPEEDS for cell in E.CELLS_M]}
    assert E.verdict(paper).endswith("matches")
    assert "0.75 mm cells: 8 m/s (5.0%), 10 m/s (5.0%)" in E.verdict(paper)
    one_grid = {"cases": [c(v, cell, v in E.PAPER_WITH and cell == 7.5e-4) for v in E.TIP_SPEEDS
                          for cell in E.CELLS_M]}
    assert E.verdict(one_grid).endswith("not reproduced in this geometry")
    assert "0.5 mm cells: none" in E.verdict(one_grid)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_a_short_case_runs_the_equivalent_fluid_alone():
    pytest.importorskip("numba")
    s = E.scene(10.0, 1.5e-3)
    assert (s.fluid.density_kg_per_m3, s.fluid.viscosity_Pa_s) == (E.RHO_EFF, E.ETA_EFF)
    assert s.coupling.turbulence == "laminar" and s.gravity_m_per_s2 == (0.0, 0.0, 0.0)
    c = E.case(10.0, 1.5e-3, t_start_s=0.02, t_end_s=0.06, sample_s=0.01)
    assert c["paper_reynolds"] == 438 and len(c["halves"]) == 2
    assert c["mean"]["vortices"] and c["mean"]["vortices"][0]["strength"] == 1.0
