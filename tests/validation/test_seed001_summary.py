"""Seed 001's verdicts computed from the shipped summary of the coupled sector cases
(validation/runs/seed001_sector.json): the page's verdict column and count follow from it, so
a summary and a verdict that disagree fail here."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from validation import seed001 as S

PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation-seed001.md"


@pytest.fixture(scope="module")
def rows():
    return S.deviation_rows()


def _page_rows() -> dict:
    """statement -> cells of the page's verdict table."""
    out = {}
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        if line.startswith("| ") and not line.startswith("| seed 001 statement") and line.count("|") >= 7:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            out[cells[0]] = cells
    return out


def test_the_summary_holds_every_case_with_what_the_table_reads():
    doc = json.loads(S.SUMMARY.read_text())
    assert sorted((r["tip_speed_m_per_s"], r["filling"]) for r in doc["runs"].values()) == sorted(S.CASES)
    for r in doc["runs"].values():
        st = r["stats"]
        assert [z["name"] for z in st["zones"]] == ["V1", "V2", "V3", "V4"]
        assert all(set(S.ZONE_KEYS) <= set(z) for z in st["zones"])
        assert set(st["flow"]) == set(S.FLOW_KEYS)
        assert set(st["maps"]) == {"frequency_peak", "frequency_peak_near_wall", "power_peak"}
    assert S.SUMMARY.stat().st_size < 200_000  # zone statistics, not contacts or maps


def test_the_pages_figures_verdicts_and_count_are_the_summarys(rows):
    page = _page_rows()
    assert len(rows) == 14
    for r in rows:
        cells = page[r["statement"]]
        assert cells[2] == r["coupled"].replace("|", "/"), r["statement"]  # the sector's figures
        assert cells[-1] == r["verdict"], r["statement"]  # with its rule, word for word
    c = S.count(rows)
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    left = c["not evaluated"] or "none"
    assert (f"The sector campaign matches {c['matches']} of the {c['statements']} statements" in text
            and f"misses {c['missed']}" in text and f"leaves {left} unevaluated" in text)
    readme = " ".join((PAGE.parents[1] / "README.md").read_text(encoding="utf-8").split())
    assert f"seed 001 (disc mill): {c['matches']} of {c['statements']} statements match on a sector" in readme


def test_the_table_command_reads_the_summary_without_a_run_folder(capsys):
    assert S.main(["table"]) == 0
    out = capsys.readouterr().out
    assert "Coupled runs: " in out and "statements match" in out
    assert S.main(["summarize"]) == 2
