"""``millfmu report --quick``: one self-contained HTML page with every study's section, its
images beside it, the measured orders, the machine and the date."""

from __future__ import annotations

import json
import math
import re

import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")
pytest.importorskip("numba")


def test_quick_report_writes_every_section_and_no_missing_image(tmp_path):
    from millfmu.cli import main
    from millfmu.report import SECTIONS

    out = tmp_path / "report"
    assert main(["report", "--quick", "--out", str(out)]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    for sid, title in SECTIONS.items():
        assert f'id="{sid}"' in page and title in page, sid
    imgs = re.findall(r'<img src="([^"]+)"', page)
    assert {"pbm_integrators.png", "cosim_wp.png", "dem_recording.png"} <= set(imgs), imgs
    for name in imgs:
        assert "/" not in name and ":" not in name, name  # beside the page, relative
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    assert cell_problems(page) == []
    assert {"process_psd.png", "process_sizes.png"} <= set(imgs) and 'id="process"' in page
    # self-contained: no external style sheets, scripts or remote sources
    assert not re.search(r"<(link|script)\b", page, re.I)
    assert not re.search(r'(src|href)="(https?:)?//', page, re.I)
    for key in ("date_utc", "platform", "cpus", "python", "numpy"):
        assert page.count(key + ":") >= 3, key  # in the header and in every section run now

    pbm = json.loads((out / "pbm_integrators.json").read_text())
    smooth, stiff = pbm["smooth"]["orders"], pbm["stiff"]["orders"]
    assert 1.8 < smooth["exact step"] < 2.3 and 1.8 < stiff["exact step"] < 2.4
    assert 0.9 < smooth["Taylor 1"] < 1.2 and 1.8 < smooth["Taylor 2"] < 2.3
    assert math.isnan(stiff["Taylor 1"]) and math.isnan(stiff["Taylor 2"])  # unstable
    assert 1.6 < smooth["adaptive exponential"] < 3.0
    cosim = json.loads((out / "cosim_wp.json").read_text())
    assert cosim["order"] > 0.9
    dem = json.loads((out / "dem_recording.json").read_text())
    assert dem["recording"] and dem["law"]["collision_frequency"]["V2"] is not None


#: A number in a cell: a word may stand beside numbers, but no number may be inf, nan or huge.
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def cell_problems(page: str) -> list:
    """Table cells (and headers) that are not a finite number of sensible size or a word:
    raw inf, nan, huge numbers; headers without a unit where their column holds numbers."""
    import html as H

    bad = []
    for table in re.findall(r"<table>(.*?)</table>", page, re.S):
        rows = re.findall(r"<tr>(.*?)</tr>", table, re.S)
        head = [H.unescape(c) for c in re.findall(r"<th>(.*?)</th>", rows[0], re.S)]
        body = [[H.unescape(c) for c in re.findall(r"<td>(.*?)</td>", r, re.S)] for r in rows[1:]]
        for row in body:
            for j, cell in enumerate(row):
                words = re.findall(r"[A-Za-z]+", cell)
                if any(w.lower() in ("inf", "nan", "infinity") for w in words):
                    bad.append(f"{head[j]!r}: {cell!r}")
                    continue
                for num in _NUMBER.findall(cell):
                    x = float(num)
                    if not math.isfinite(x) or abs(x) >= 1e12:
                        bad.append(f"{head[j]!r}: {cell!r}")
        for j, h in enumerate(head):
            numeric = any(j < len(r) and re.fullmatch(r"\s*" + _NUMBER.pattern + r"\s*", r[j]) for r in body)
            if j > 0 and numeric and "[" not in h:
                bad.append(f"header {h!r} has no unit")
    return bad


def test_report_tables_say_diverged_and_give_units():
    from millfmu.report import _fmt, _table

    page = _table(["method", "error [-]", "run time [s]"],
                  [["Taylor 1", _fmt(float("inf")), _fmt(0.5, ".3g", None)],
                   ["Taylor 2", _fmt(float("nan")), _fmt(1.0, ".3g", None)],
                   ["Taylor 2", _fmt(-2.4e22), _fmt(2.0, ".3g", None)], ["exact", _fmt(1e-9), _fmt(3.0, ".3g", None)]])
    assert page.count("diverged") == 3 and cell_problems(page) == []
    raw = _table(["method", "error"], [["x", "inf"], ["y", "-2.4e+22"], ["z", "1.0"]])  # as before
    assert len(cell_problems(raw)) == 3  # the checker sees raw inf, a huge number, a header without unit


@pytest.mark.slow
def test_full_report_repeats_the_readme_studies(tmp_path):
    """The full report (tens of minutes; the DEM runs only with --dem-runs): the integrator
    study at 2^2 ... 2^10 steps and the README's co-simulation study (steps 0.625 ... 20 s
    against 0.078125 s, 30 minutes simulated)."""
    from millfmu.cli import main

    out = tmp_path / "report"
    assert main(["report", "--out", str(out)]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "Full report" in page and "--dem-runs" in page
    pbm = json.loads((out / "pbm_integrators.json").read_text())
    for case in ("smooth", "stiff"):
        o = pbm[case]["orders"]
        assert 1.9 < o["exact step"] < 2.2 and 1.9 < o["adaptive exponential"] < 2.4, o
    assert 0.95 < pbm["smooth"]["orders"]["Taylor 1"] < 1.1 and 1.9 < pbm["smooth"]["orders"]["Taylor 2"] < 2.2
    cosim = json.loads((out / "cosim_wp.json").read_text())
    small = [r["order_to_previous"] for r in cosim["rows"] if "order_to_previous" in r and r["step_s"] <= 5.0]
    assert len(small) == 3 and all(0.9 < o < 1.3 for o in small), cosim
