"""Seed 002's verdicts computed from the shipped summary of the campaigns on the paper's mill
(validation/runs/seed002_sector.json): the page's case-by-case table, its columns' verdicts
and its count, and the README's line follow from it, so that a summary and a verdict that
disagree fail here."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from validation import seed002 as S

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "validation-seed002.md"
#: the summary's campaigns and the page's columns they fill
COLUMNS = {"physical, model B": "physical, model B", "paper's method": "paper's method",
           "paper's method, Schiller-Naumann": "paper's method, Schiller-Naumann",
           "physical, model A": "physical, model A"}
#: the primed start's campaigns (one case each, a variant of the start), in the order of the
#: parts of the page's one primed column
PRIMED = ("primed start, model B", "primed start, paper's method, Schiller-Naumann")
PRIMED_COLUMN = ("primed start, 1200 rpm 80 % (model B; paper's method, Schiller-Naumann; variant, "
                 "not counted)")
#: the paper's whole slice with gravity, one case, and its page column
FULL = "full slice, gravity"
FULL_COLUMN = "full slice, gravity, 1200 rpm 80 %"
ONE_CASE = PRIMED + (FULL,)


@pytest.fixture(scope="module")
def table():
    return S.deviation_table([(lab, S.Shipped(lab)) for lab in COLUMNS])


def _word(text: str) -> str:
    m = re.match(r"(matches|missed|holds|not evaluated|not run)", text.strip())
    assert m, text
    return {"holds": "matches"}.get(m.group(1), m.group(1))


def _page_columns() -> tuple[list[str], list[list[str]]]:
    """The header and the rows (by number) of the page's table of statements."""
    head, rows = None, []
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| # | seed 002 statement"):
            head = cells
        elif head is not None and re.match(r"\| \d+ \|", line):
            rows.append(cells)
        elif head is not None and rows and not line.startswith("|"):
            break
    return head, rows


def test_the_summary_holds_every_case_of_its_campaigns_with_what_the_table_reads():
    doc = json.loads(S.SUMMARY.read_text())
    assert list(doc["campaigns"]) == list(COLUMNS) + list(ONE_CASE)
    for label, camp in doc["campaigns"].items():
        cases = [(1200.0, 0.8)] if label in ONE_CASE else S.CASES
        assert sorted((r["rpm"], r["filling"]) for r in camp["runs"].values()) == sorted(cases), label
        assert camp["campaign"]["primed"] == (label in PRIMED)
        assert camp["campaign"].get("full_slice", False) == (label == FULL)
        for r in camp["runs"].values():
            st = r["stats"]
            assert [z["name"] for z in st["zones"]] == list(S.ZONE_NAMES)
            assert all(set(z) == set(S.ZONE_KEYS) for z in st["zones"])
            q = st["flow"]["seed002"]
            assert set(q["total"]) == set(S.Q_TOTAL_KEYS)
            assert "snapshots_20_per_s" in q  # both countings
    circ = doc["campaigns"][FULL]["runs"]["1200 rpm, 80 %"]["stats"]["flow"]["circumferential"]
    assert len(circ["per_bin_over_mean"]) == 12
    assert S.SUMMARY.stat().st_size < 200_000  # zone statistics, not contacts or maps


def test_the_case_by_case_table_is_the_summarys():
    text = PAGE.read_text(encoding="utf-8")
    want = S.markdown(S.deviation_rows(S.Shipped("physical, model B")), "ours (physical)")
    assert want in text


def test_the_columns_verdicts_and_the_count_follow_from_the_summary(table):
    head, rows = _page_columns()
    assert len(rows) == len(table) == 15
    col = {h: i for i, h in enumerate(head)}
    for n, (page, r) in enumerate(zip(rows, table), 1):
        for label, page_col in COLUMNS.items():
            assert _word(page[col[page_col]]) == _word(r["cells"][label]["verdict"]), (n, label)
    c = S.count(table)
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    n_b, n_p = c["per_campaign"]["physical, model B"], c["per_campaign"]["paper's method"]
    n_sn = c["per_campaign"]["paper's method, Schiller-Naumann"]
    n_a = c["per_campaign"]["physical, model A"]
    assert f"Model B matches {n_b} " in text and f"model A matches {n_a} " in text
    assert f"the paper's method matches {n_p} " in text
    assert f"with Schiller-Naumann drag {n_sn} " in text
    assert f"Under these four together {c['together']} match" in text
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    assert (f"seed 002 (accelerator mill): {max(n_b, n_p, n_sn, n_a)} of {c['statements']} match on its "
            f"mill by one method, {c['together']} by four") in readme


def test_the_one_case_columns_follow_from_the_summary():
    """The primed start's column (its two campaigns, model B; the paper's method with
    Schiller-Naumann drag) and the full slice's: per statement the verdict at their one case
    ("holds" / "missed"; "(one ...)" where a statement needs several cases), none counted in
    the verdict on the paper's mill (a primed start is a variant of the start from rest; a
    full slice has one of the cases)."""
    table = S.deviation_table([(lab, S.Shipped(lab)) for lab in list(COLUMNS) + list(ONE_CASE)])
    head, rows = _page_columns()

    def word(v):
        return ("holds" if v.startswith("matches") else "(one" if v.startswith(("incomplete", "not run"))
                else "missed" if v.startswith("missed") else "not evaluated")
    for n, (page, r) in enumerate(zip(rows, table), 1):
        parts = page[head.index(PRIMED_COLUMN)].split("; ")
        assert len(parts) == 2, (n, parts)
        for part, lab in zip(parts + [page[head.index(FULL_COLUMN)]], ONE_CASE):
            assert part.startswith(word(r["cells"][lab]["verdict"])), (n, lab, part)
        assert all(r["cells"][lab]["variant"] == "primed start" for lab in PRIMED)
    assert S.count(table) == S.count(S.deviation_table([(lab, S.Shipped(lab)) for lab in COLUMNS]))


def test_the_verdict_column_is_the_summarys():
    """Each row's "verdict on the paper's mill" is :func:`seed002.verdict_cell` of the
    summary's campaigns, word for word: the campaigns named under a match or a miss, and
    what a one-case campaign found where no campaign of all the cases judges."""
    table = S.deviation_table([(lab, S.Shipped(lab)) for lab in list(COLUMNS) + list(ONE_CASE)])
    head, rows = _page_columns()
    verdict = head.index("verdict on the paper's mill")
    for n, (page, r) in enumerate(zip(rows, table), 1):
        assert page[verdict] == S.verdict_cell(r), n
    assert S.verdict_cell(table[14]).startswith("not evaluated (full slice, gravity at its case: missed")


def test_the_table_command_reads_the_summary_without_a_run_folder(capsys):
    assert S.main(["table"]) == 0
    out = capsys.readouterr().out
    assert "On the paper's mill, of 15 statements: physical, model B " in out
