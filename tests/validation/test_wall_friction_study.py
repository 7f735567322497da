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
