"""The rates page's table of both pairs' rates along each parameter is what the trend study
computes now from the shipped tables and scenes (``python -m validation.trends_causes
--markdown``): a table or scene change that moves a rate or a band fails here until the page
is regenerated."""

from __future__ import annotations

from pathlib import Path

from validation import trends_causes as tc

ROOT = Path(__file__).resolve().parents[2]


def test_the_rates_pages_trend_table_is_the_studys():
    page = (ROOT / "docs" / "rates-and-calibration.md").read_text(encoding="utf-8")
    rows = [line for line in tc.markdown_trend_table().splitlines() if line.startswith("|")]
    assert len(rows) > 20
    assert [r for r in rows if r not in page] == []
