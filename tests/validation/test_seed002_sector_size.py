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

PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation-seed002.md"


def test_the_wide_scene_is_the_campaigns_but_for_the_sector():
    wide, narrow = S2.scene_for(*Z.CASE, sector_deg=Z.SECTOR_DEG), S2.scene_for(*Z.CASE)
    differ = {f.name for f in dataclasses.fields(wide) if repr(getattr(wide, f.name)) != repr(getattr(narrow, f.name))}
    assert differ == {"geometry"}
    assert (narrow.geometry.sector_deg, wide.geometry.sector_deg) == (S2.SECTOR_DEG, 90.0)
    assert dataclasses.replace(wide.geometry, sector_deg=S2.SECTOR_DEG) == narrow.geometry


def test_keep_compares_a_run_with_the_kept_case(tmp_path):
    """A run folder holding the kept case itself: every difference is zero, and the table
    shows each quantity."""
    d = Z.case_dir(tmp_path)
    d.mkdir(parents=True)
    (d / "stats.json").write_text(json.dumps(Z.kept_case()))
    (d / "windows.csv").write_text("t_start_s,t_end_s,zone,filling,speed_over_tip_speed\n"
                                   "1.0,1.1,SEV_1,1.0,0.7\n1.1,1.2,SEV_1,1.01,0.69\n")
    doc = json.loads(Z.keep(tmp_path, path=tmp_path / "kept.json").read_text())
    assert [q["quantity"] for q in doc["comparison"]] == [q[0] for q in Z.QUANTITIES]
    assert all(q["relative_difference"] == 0.0 for q in doc["comparison"])
    assert [w["t_start_s"] for w in doc["windows"]] == [1.0, 1.1]
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
