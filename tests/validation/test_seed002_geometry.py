"""Seed 002's unstated dimensions (validation/seed002_geometry.py): each probe is the shipped
slice at the reference case with exactly its one scene value changed; the verdicts are
computed from the kept summary, and the page's table is that summary's."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from validation import seed002 as S2
from validation import seed002_geometry as G

PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation-seed002-geometry.md"


def _differ(a, b) -> dict:
    return {f.name: (getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
            if repr(getattr(a, f.name)) != repr(getattr(b, f.name))}


def test_each_probe_changes_its_one_value():
    base = G.scene("shipped slice")
    assert base.geometry.sector_deg == G.SECTOR_DEG and base.rotor_speed_rpm == pytest.approx(1200.0)
    assert _differ(base, S2.scene_for(*G.CASE, sector_deg=G.SECTOR_DEG)) == {}
    rim = G.scene("rim 26 mm")
    assert set(_differ(rim, base)) == {"geometry", "tip_speed_m_per_s"}
    assert set(_differ(rim.geometry, base.geometry)) == {"disc_radius_m"} and rim.geometry.disc_radius_m == 0.026
    # the same rotor speed: the tip speed follows the rim
    assert rim.rotor_speed_rpm == pytest.approx(1200.0)
    # the rotor pitch is the slice's axial period, the geometry's height
    for probe, field, value in (("channel 5 mm", "channel_height_m", 0.005),
                                ("pitch 20 mm", "height_m", 0.020)):
        sc = G.scene(probe)
        assert set(_differ(sc, base)) == {"geometry"}, probe
        d = _differ(sc.geometry, base.geometry)
        assert set(d) == {field} and d[field][0] == value, probe
    ke = G.scene("k-epsilon")
    assert set(_differ(ke, base)) == {"coupling"}
    assert _differ(ke.coupling, base.coupling) == {"turbulence": ("k_epsilon", "laminar")}
    with pytest.raises(ValueError, match="probe 'baffles': allowed"):
        G.scene("baffles")


def test_a_change_to_an_unknown_key_is_refused_by_the_scene():
    with pytest.raises(ValueError, match=r"mill.rotor_radius: unknown key for accelerator_slice"):
        S2.scene_for(*G.CASE, changes={"mill.rotor_radius": 0.026})


def _fake_stats(R, profile):
    st = json.loads(json.dumps(S2._summary_doc()["campaigns"]["physical, model B"]["runs"]["1200 rpm, 80 %"]["stats"]))
    st["flow"]["seed002"]["radial_speed_profile"]["speed_over_tip_speed"] = profile
    st["flow"]["seed002"]["rotor_throughflow_m3_per_s"] = 1e-6
    st["flow"]["seed002"]["return_leg"] = {"k_beads": 0.7, "k_liquid": 0.75, "solids_fraction": 0.6, "R": R,
                                           "k_for_R_1": 0.5, "k_beads_profile": {}}
    st["flow"]["angular_momentum_budget"] = {"closure_rel": 1e-5}
    st.update(tip_speed_m_per_s=2.79, beads=4000)
    return st


def test_verdicts_follow_the_kept_figures(tmp_path):
    """A probe whose return leg has R < 1 circulates; row 1 holds only where the fastest bin
    is beyond Z'/R 0.69 and the beads near the shaft are faster than at the wall."""
    z = 20
    rising = [0.3 + 0.02 * i for i in range(z)]
    flat_wall = [0.7] * (z - 3) + [None] * 3
    for probe in G.PROBES:
        st = _fake_stats(0.8 if probe == "pitch 20 mm" else 3.0, rising if probe == "k-epsilon" else flat_wall)
        d = G.case_dir(tmp_path, probe)
        d.mkdir(parents=True)
        (d / "stats.json").write_text(json.dumps(st))
    doc = json.loads(G.summarize(tmp_path, path=tmp_path / "kept.json").read_text())
    v = G.verdicts(doc)
    assert [p for p in v if v[p]["circulates"]] == ["pitch 20 mm"]
    assert [p for p in v if v[p]["row_1"]] == ["k-epsilon"]
    assert math.isnan(v["shipped slice"]["shaft_over_wall"])
    assert len(G.markdown(doc).splitlines()) == 2 + len(G.PROBES)
    with pytest.raises(FileNotFoundError, match="no stats.json"):
        G.summarize(tmp_path / "none", path=tmp_path / "none.json")


def test_the_page_shows_the_kept_probes():
    doc = json.loads(G.SUMMARY.read_text())
    assert list(doc["probes"]) == list(G.PROBES)
    for probe, p in doc["probes"].items():
        assert p["changes"] == G.PROBES[probe]
        assert abs(p["budget_closure_rel"]) < 1e-3, probe
    page = PAGE.read_text(encoding="utf-8")
    for line in G.markdown(doc).splitlines():
        assert line in page, line


def test_summarize_on_the_command_line_keeps_and_shows_or_names_what_is_missing(tmp_path, capsys):
    """The studies' shared summarize step (validation.run_summary.keep_and_show): the
    table and where it is kept, or 1 with the missing runs named and nothing written."""
    from validation import seed002_sector_size as W
    from validation.run_summary import keep_and_show

    assert G.main(["summarize", "--out", str(tmp_path / "none")]) == 1
    assert W.main(["compare", "--out", str(tmp_path / "none")]) == 1
    assert "no stats.json" in capsys.readouterr().err
    kept = tmp_path / "kept.json"
    kept.write_text(json.dumps({"runs": {"a": 1}}))
    assert keep_and_show(lambda out: kept, tmp_path, lambda doc: f"table of {sorted(doc['runs'])}") == 0
    assert capsys.readouterr().out == f"table of ['a']\nkept in {kept}\n"
