"""Seed 002's sector width (validation/seed002_sector_size.py): the wider sector's scene is the
campaign's but for the sector; the comparison is computed from the kept summaries, so that the
page's table and the summaries cannot disagree."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from validation import seed002 as S2
from validation import seed002_sector_size as Z

PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation-seed002-sector.md"


def test_the_runs_are_the_campaigns_case_but_for_sector_and_placement():
    narrow = S2.scene_for(*Z.CASE)
    assert Z.COLUMNS[0] == (narrow.geometry.sector_deg, narrow.seed) == (S2.SECTOR_DEG, 1)
    for deg, seed in Z.RUNS:
        sc = Z.scene(deg, seed)
        differ = {f.name for f in dataclasses.fields(sc) if repr(getattr(sc, f.name)) != repr(getattr(narrow, f.name))}
        assert differ <= {"geometry", "seed"} and differ
        assert (sc.geometry.sector_deg, sc.seed) == (deg, seed)
        assert dataclasses.replace(sc.geometry, sector_deg=S2.SECTOR_DEG) == narrow.geometry
    # a realization at each width: the kept one and another placement at 60, two at 90
    assert sorted(Z.COLUMNS) == [(S2.SECTOR_DEG, 1), (S2.SECTOR_DEG, 2), (90.0, 1), (90.0, 2)]


def _fake_runs(tmp_path, scale_wide=1.0):
    """Run folders holding the kept case (its quantities scaled by ``scale_wide`` on the wide
    sector's runs, where SN_g, SI and SE_cs are scaled)."""
    for deg, seed in Z.RUNS:
        st = json.loads(json.dumps(Z.kept_case()))
        if deg == Z.SECTOR_DEG:
            for z in st["flow"]["seed002"]["zones"].values():
                for k in z:
                    z[k] *= scale_wide
        d = Z.case_dir(tmp_path, deg, seed)
        d.mkdir(parents=True)
        (d / "stats.json").write_text(json.dumps(st))
        (d / "windows.csv").write_text("t_start_s,t_end_s,zone,filling,speed_over_tip_speed\n"
                                       "1.0,1.1,SEV_1,1.0,0.7\n1.1,1.2,SEV_1,1.01,0.69\n")


def test_keep_compares_the_widths_beside_the_placements(tmp_path):
    """Runs holding the kept case, the wide ones with their zone quantities scaled by 1.25:
    the placements differ by nothing, the wide sector's mean by +25 % in exactly those."""
    _fake_runs(tmp_path, 1.25)
    doc = json.loads(Z.keep(tmp_path, path=tmp_path / "kept.json").read_text())
    assert [q["quantity"] for q in doc["comparison"]] == [q[0] for q in Z.QUANTITIES]
    for q in doc["comparison"]:
        assert q["placement_narrow"] == 0.0 and q["placement_wide"] == 0.0
        zonal = q["quantity"].split()[0] in ("SN_g", "SI", "SE_cs") and "SEV" in q["quantity"]
        assert q["wide_over_narrow"] == pytest.approx(0.25 if zonal else 0.0, abs=1e-12), q["quantity"]
    assert [w["t_start_s"] for w in doc["runs"]["90 deg, placement 2"]["windows"]] == [1.0, 1.1]
    assert len(Z.markdown(doc).splitlines()) == 2 + len(Z.QUANTITIES)
    with pytest.raises(FileNotFoundError, match="no stats.json"):
        Z.keep(tmp_path / "none")


def test_se_cs_sum_holds_its_shear_and_normal_parts():
    """SE_cs,sum (shear over its share) is at least the sum of its tangential shear and
    normal parts (the rolling part is the rest)."""
    st = Z.kept_case()
    fn = dict((q[0], q[2]) for q in Z.QUANTITIES)["SE_cs,sum"]
    t = st["flow"]["seed002"]["total"]
    assert fn(st) >= (t["SE_ts_sum_w"] + t["SE_tn_sum_w"]) * (1 - 1e-12)
    assert fn(st) * t["ts_share"] == pytest.approx(t["SE_ts_sum_w"], rel=1e-12)


def test_the_page_shows_the_kept_comparison():
    doc = json.loads(Z.SUMMARY.read_text())
    page = PAGE.read_text(encoding="utf-8")
    for line in Z.markdown(doc).splitlines():
        assert line in page, line
    assert sorted(tuple((r["sector_deg"], r["seed"])) for r in doc["runs"].values()) == sorted(Z.RUNS)
    # the kept campaign case is the shipped summary's own
    assert doc["comparison"][0]["values"][Z._label(*Z.COLUMNS[0])] == Z.QUANTITIES[0][2](Z.kept_case())
