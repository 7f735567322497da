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
        if S.summary_stats(full_slice=True):  # the full slice's column, once its summary is kept
            assert cells[3] == r["full"].replace("|", "/"), r["statement"]
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


def _with_full_slice(tmp_path, stats):
    """The shipped summary with ``stats`` as its full slice's case, written to tmp_path."""
    doc = json.loads(S.SUMMARY.read_text())
    doc["full_slice"] = {"runs": {"10 m/s, 80 %": {"tip_speed_m_per_s": 10.0, "filling": 0.8,
                                                   "stats": stats}}}
    p = tmp_path / "summary.json"
    p.write_text(json.dumps(doc))
    return p


def test_the_full_slice_column_is_computed_from_the_summary_and_never_counted(tmp_path, rows):
    """A summary with a full slice (here, synthetically, the sector's 10 m/s, 80 % case in
    its place): its column shows the value at its one case and whether the statement holds
    there; the verdicts and the count stay the sector's."""
    sector = S.summary_stats()[(10.0, 0.8)]
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, sector))
    assert [r["verdict"] for r in got] == [r["verdict"] for r in rows]
    assert S.count(got) == S.count(rows)

    def full(start):
        return next(r["full"] for r in got if r["statement"].startswith(start))
    assert full("mean bead speed / tip speed in V1 at 80 ") == "0.136 (holds)"
    assert full("mean bead speed / tip speed in V3 at 80 ") == "0.0976 (holds)"  # the sector misses it
    assert full("angular velocity of the first bead layer") == "0.16 (missed)"
    assert full("at 90 % filling V3 has the lowest collis").startswith("not run (its one case")
    assert full("collision density of the chamber about l") == "not evaluated (one tip speed)"
    assert full("mean bead speed lowest in V3 in all case") == "slowest V2 (missed)"
    assert full("collision frequency peaks about two bead ") == "0.8 mm (1.0 d) (missed)"
    assert full("locally highest collision power at the s").endswith("0.88 d from the rim (holds)")
    assert full("a secondary vortex between disc tip and c") == "fluid: none / beads: none (missed)"
    # without the maps the map rows cannot be judged there
    bare = {k: v for k, v in sector.items() if k != "maps"}
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, bare))
    assert got[-1]["full"] == "not evaluated (its run kept no collision maps)"
    assert all(r["full"] == "not run" for r in rows)  # the shipped summary has none yet


def test_summarize_keeps_the_sector_cases_and_the_full_slice_apart(tmp_path):
    """summarize --full-slice adds the full slice's case beside the sector's cases, and a
    summary of the sector's cases keeps it; each from its own run folders."""
    shipped = S.summary_stats()
    out = tmp_path / "runs"
    for (vt, fl), st in shipped.items():
        d = S.case_dir(out, "coupled", vt, fl)
        d.mkdir(parents=True)
        (d / "stats.json").write_text(json.dumps(st))
    p = tmp_path / "summary.json"
    S.summarize(out, path=p)
    assert S.summary_stats(p) == shipped and S.summary_stats(p, full_slice=True) == {}
    with pytest.raises(FileNotFoundError, match="c360_v10_f80"):
        S.summarize(out, path=p, full_slice=True)
    d = S.case_dir(out, "coupled", 10.0, 0.8, S.FULL_SECTOR_DEG)
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(shipped[(6.0, 0.8)]))
    S.summarize(out, path=p, full_slice=True)
    assert S.summary_stats(p, full_slice=True) == {(10.0, 0.8): shipped[(6.0, 0.8)]}
    S.summarize(out, path=p)  # the sector's again: the full slice stays
    assert S.summary_stats(p) == shipped
    assert S.summary_stats(p, full_slice=True) == {(10.0, 0.8): shipped[(6.0, 0.8)]}
    assert S.deviation_rows(out)[0]["full"] == "0.147 (holds)"  # from the run folders too


def test_the_full_slice_is_seed_001s_configuration_as_the_page_runs_it():
    """The campaign's full slice is the scene the page's command runs (disc_slice, its
    gravity, 360 degrees, 32 theta cells, the sector campaign's protocol)."""
    from millfmu.dem.scene import load_scene

    sc = S.full_slice_scene()
    assert sc == load_scene("disc_slice").with_overrides(
        tip_speed_m_per_s=10.0, filling=0.8, n_theta=32, spin_up_s=1.0, record_s=0.3,
        sample_every_s=0.01, initial_rotation=0.1)
    assert sc.geometry.sector_deg == 360.0 and sc.gravity_m_per_s2 == (0.0, -9.81, 0.0)
    assert sc.coupling.n_theta == 32 and sc.fluid_mode == "coupled"
    text = PAGE.read_text(encoding="utf-8")
    assert "python -m validation.seed001 run --out DIR --full-slice" in text


def test_a_smoothing_variant_runs_and_is_summarized_as_such(tmp_path):
    """--smoothing-diameters D: the campaign's scene with the exchange smoothed over D bead
    diameters (refused below 0), its summary in a file of its own saying so, with the
    commands that rebuild it."""
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_smoothing(base, None) is base
    assert S.with_smoothing(base, 0.0).coupling.smoothing_diameters == 0.0
    assert S.with_smoothing(base, 0.0).coupling.cell_m == base.coupling.cell_m
    with pytest.raises(ValueError, match="smoothing_diameters = -1: must be a number >= 0"):
        S.with_smoothing(base, -1)
    out = tmp_path / "runs"
    d = S.case_dir(out, "coupled", 10.0, 0.8)
    d.mkdir(parents=True)
    (d / "stats.json").write_text(json.dumps(S.summary_stats()[(10.0, 0.8)]))
    p = S.summarize(out, path=tmp_path / "seed001_sector_smoothing0.json", smoothing_diameters=0.0)
    doc = json.loads(p.read_text())
    assert doc["protocol"]["smoothing_diameters"] == 0.0 and "a variant" in doc["note"]
    assert doc["command"].endswith("summarize --out DIR --smoothing-diameters 0 --summary "
                                   "validation/runs/seed001_sector_smoothing0.json")
    assert S.summary_stats(p) == {(10.0, 0.8): S.summary_stats()[(10.0, 0.8)]}


def test_the_no_smoothing_variants_count_on_the_page_is_its_summarys():
    """The page's count of the campaign with no smoothing (a variant, not counted) follows
    from its kept summary, validation/runs/seed001_sector_smoothing0.json."""
    p = S.SUMMARY.parent / "seed001_sector_smoothing0.json"
    doc = json.loads(p.read_text())
    assert doc["protocol"]["smoothing_diameters"] == 0.0
    assert sorted((r["tip_speed_m_per_s"], r["filling"]) for r in doc["runs"].values()) == sorted(S.CASES)
    rows = S.deviation_rows(summary=p)
    c = S.count(rows)
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    assert "with no smoothing (a variant, not counted:" in text
    assert f"the sector matches {c['matches']} of the {c['statements']} statements: it gains the first layer" in text
    layer = next(r for r in rows if r["statement"].startswith("angular velocity of the first bead layer"))
    assert layer["verdict"].startswith("matches")
