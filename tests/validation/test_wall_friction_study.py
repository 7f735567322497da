"""The bead-wall friction study (validation/wall_friction.py): each case is the reference
protocol's scene but for its [beads] keys; a summary needs every case run; the kept summary
is its cases' and the page shows its figures."""

from __future__ import annotations

import dataclasses
import json

import pytest

from millfmu.dem.scene import load_scene
from validation import wall_friction as W


def test_each_case_is_the_reference_protocol_but_for_its_friction():
    ref = load_scene("disc_slice").with_overrides(**W.PROTOCOL)
    for label, keys in W.CASES.items():
        sc = W.case_scene(label)
        differ = {f.name for f in dataclasses.fields(sc) if repr(getattr(sc, f.name)) != repr(getattr(ref, f.name))}
        assert differ <= {"material"}, label
        m = sc.material
        assert (m.friction, m.wall_friction, m.wall_rolling_friction) == (
            keys.get("friction", 0.3), keys.get("wall_friction"), keys.get("wall_rolling_friction")), label
        assert m.rolling_friction == 0.10 and sc.fluid_mode == "coupled"
    assert (ref.spin_up_s, ref.record_s, ref.geometry.sector_deg,
            ref.tip_speed_m_per_s) == (0.565, 0.3, 10.0, 10.0)
    assert W.command("walls 0.6").startswith(
        "millfmu dem run disc_slice.toml with [beads] wall_friction = 0.6 --out DIR")
    with pytest.raises(ValueError, match="case 'walls 2': allowed"):
        W.case_scene("walls 2")


def test_a_summary_needs_every_case(tmp_path):
    with pytest.raises(FileNotFoundError, match="cases not run: .*walls 0.6"):
        W.summarize(tmp_path, path=tmp_path / "s.json")
    assert W.main(["summarize", "--out", str(tmp_path)]) == 1
    assert not (tmp_path / "s.json").exists()


def test_the_kept_summary_holds_every_case_by_its_command():
    if not W.SUMMARY.exists():
        pytest.skip("not kept yet")
    doc = json.loads(W.SUMMARY.read_text())
    assert list(doc["runs"]) == list(W.CASES)
    for label, run in doc["runs"].items():
        assert run["command"] == W.command(label)
        assert 0.0 < run["values"]["first bead layer / disc angular velocity"] < 1.0


def test_the_page_shows_the_kept_cases():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "validation-seed001-variants.md").read_text(encoding="utf-8")
    for line in W.markdown(json.loads(W.SUMMARY.read_text())).splitlines():
        assert line in page, line
    assert "python -m validation.wall_friction run" in page


def test_the_table_marks_what_lies_in_seed_001s_bands():
    doc = {"runs": {"a": {"values": {q: 1e-10 for _, q, _ in W.COLUMNS}},
                    "b": {"values": {q: 1e-10 for _, q, _ in W.COLUMNS}}}}
    doc["runs"]["a"]["values"].update({"first bead layer / disc angular velocity": 0.17,
                                       "bead speed / tip speed V1": 0.1611,
                                       "bead speed / tip speed V2": 0.0808,
                                       "bead speed / tip speed V3": 0.0977})
    lines = W.markdown(doc).splitlines()
    # 0.17 is 0.20 less 15 %; 0.1611 lies beyond 0.14 plus 15 % (0.161); V2 and V3 at their edges
    assert lines[2].endswith("| 3 of 4: first layer, V2, V3 |")
    assert "| 0.17 (in band) | 0.161 | 0.0808 (in band) | 0.0977 (in band) |" in lines[2]
    assert lines[3].endswith("| 0 of 4 |")
