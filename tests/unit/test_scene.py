"""Scenes: defaults load; every kind of bad value stops with a message naming key, value and what is allowed."""

import json
import subprocess
import sys

import pytest

from millfmu.scene import SceneError, load_scene, scene_from_dict
from tests.conftest import make_scene


def test_default_scene_loads_in_si():
    s = load_scene()
    assert s.beads.diameter_m == 0.8e-3
    assert s.mill.tip_speed_m_per_s == 10.0
    assert s.material.model == "mineral"


@pytest.mark.parametrize(
    "section, values, key, words",
    [
        ("mill", {"tip_speed_m_per_s": -3.0}, "mill.tip_speed_m_per_s", ">= 0"),
        ("mill", {"tip_speed_m_per_s": "fast"}, "mill.tip_speed_m_per_s", "a number"),
        ("mill", {"bead_filling": 1.0}, "mill.bead_filling", "< 1"),
        ("mill", {"n_discs": 2.5}, "mill.n_discs", "integer"),
        ("mill", {"tip_sped_m_per_s": 3.0}, "mill.tip_sped_m_per_s", "unknown key"),
        ("beads", {"diameter_m": 0.0}, "beads.diameter_m", ">= 1e-05"),
        ("material", {"model": "granite"}, "material.model", "one of"),
        ("kinetics", {"model": "none"}, "kinetics.model", "austin"),
        ("feed", {"kind": "rrsb", "x63_m": 1e-5}, "feed.n", "required"),
        ("feed", {"kind": "table", "sizes_m": [1e-6, 2e-6], "Q3": [0.5, 0.9]}, "feed.Q3", "end at 1"),
        ("feed", {"kind": "table", "sizes_m": [2e-6, 1e-6], "Q3": [0.5, 1.0]}, "feed.sizes_m", "ascending"),
        ("run", {"dt_s": 10000.0}, "run.dt_s", "t_end_s"),
        ("grid", {"x_max_m": 0.01e-6}, "grid.x_max_m", "x_min_m"),
    ],
)
def test_bad_values_name_key_value_allowed(scene_dict, section, values, key, words):
    with pytest.raises(SceneError) as e:
        make_scene(scene_dict, **{section: values})
    assert e.value.key == key
    msg = str(e.value)
    assert key in msg and words in msg
    bad = values.get(key.split(".")[-1])
    if bad is not None:
        assert repr(bad) in msg


def test_unknown_section(scene_dict):
    scene_dict["mil"] = {}
    with pytest.raises(SceneError, match="mil.*unknown key"):
        scene_from_dict(scene_dict)


def test_cli_bad_scene_exit_2_and_nothing_written(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[mill]\ntip_speed_m_per_s = -1.0\n")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", str(bad), "--out", str(out)], capture_output=True,
                       text=True)
    assert r.returncode == 2
    assert "mill.tip_speed_m_per_s" in r.stderr and "-1.0" in r.stderr and ">= 0" in r.stderr
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.toml"]


def test_cli_syntax_error_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[mill\n")
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "TOML" in r.stderr


def test_cli_run_default_writes_results(tmp_path):
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", "--out", str(out), "-q"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    assert {p.name for p in out.iterdir()} == {"result.json", "psd.csv", "psd.png", "sizes.png"}
    res = json.loads((out / "result.json").read_text())
    assert res["scene"]["eta_eff_Pa_s"] > 0 and res["scene"]["reynolds"] > 0
    recs = res["outputs"]
    assert recs[0]["t_s"] == 0.0 and recs[-1]["t_s"] == pytest.approx(1800.0)
    for k in ("x10_m", "x50_m", "x90_m", "total_mass_kg", "se_beads_J", "sf_per_s", "specific_energy_J_per_kg"):
        assert k in recs[-1]
    assert recs[-1]["x50_m"] < recs[0]["x50_m"]
    assert recs[-1]["total_mass_kg"] == pytest.approx(recs[0]["total_mass_kg"], rel=1e-12)
    lines = (out / "psd.csv").read_text().splitlines()
    assert len(lines) == len(recs) + 1
    assert "x50" in r.stdout


# ---- issue 27: refusals naming the file, key, value and what is allowed -------------------
def _cli(capsys, *args):
    from millfmu.cli import main

    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def test_a_scene_file_that_is_not_utf8_is_refused_naming_the_file_and_byte_offset(tmp_path, capsys):
    p = tmp_path / "latin1.toml"
    p.write_bytes("[scene]\nname = \"Mühle\"\n".encode("latin-1"))
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert str(p) in str(e.value) and "byte offset 17" in str(e.value) and "UTF-8" in str(e.value)
    code, err = _cli(capsys, "run", "-q", p, "--out", tmp_path / "out")
    assert code == 2 and "byte offset 17 (line 2)" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_an_unknown_similar_axis_is_refused_by_load_scene_listing_the_allowed_axes(tmp_path, capsys):
    p = tmp_path / "axes.toml"
    p.write_text('[kinetics.stress_distribution]\nsimilar_axes = ["tip_speed_m_per_s", "nonsense_axis"]\n')
    with pytest.raises(SceneError) as e:
        load_scene(p)
    msg = str(e.value)
    assert "kinetics.stress_distribution.similar_axes[1] = 'nonsense_axis'" in msg
    for ax in ("tip_speed_m_per_s", "bead_diameter_m", "bead_density_kg_per_m3", "viscosity_Pa_s"):
        assert ax in msg
    code, err = _cli(capsys, "run", "-q", p, "--out", tmp_path / "out")
    assert code == 2 and "nonsense_axis" in err


def test_similar_axes_allowed_by_the_scene_are_those_the_table_extends():
    from millfmu.stress_tables.table import EXTRAPOLABLE_AXES
    from millfmu.scene import StressDistribution
    from dataclasses import fields

    md = next(f.metadata for f in fields(StressDistribution) if f.name == "similar_axes")
    assert tuple(md["choices"]) == tuple(EXTRAPOLABLE_AXES)


@pytest.mark.parametrize("sel", [{"a_per_s": 1e300}, {"x0_m": 1e-300}, {"alpha": 20.0, "x0_m": 1e-9}, {"alpha": -10.0},
                                 {"a_per_s": 1e300, "x0_m": 1e-300, "alpha": 20.0}])
def test_austin_selection_that_cannot_be_computed_is_refused_naming_the_keys(tmp_path, capsys, sel):
    lines = "\n".join(f"{k} = {v!r}" for k, v in sel.items())
    p = tmp_path / "austin.toml"
    p.write_text(f'[material]\nmodel = "austin"\n[material.selection]\n{lines}\n[kinetics]\nmodel = "none"\n')
    code, err = _cli(capsys, "run", "-q", p, "--out", tmp_path / "out")
    assert code == 2 and "Traceback" not in err, err
    assert ("material.selection.a_per_s" in err and "x0_m" in err and "alpha" in err
            and "must stay below 1e+20 1/s" in err)


def test_austin_selection_up_to_the_limit_runs():
    from millfmu.mill import MillModel
    from millfmu.scene import scene_from_dict

    m = MillModel(scene_from_dict({"material": {"model": "austin",
                                                "selection": {"a_per_s": 1e20, "x0_m": 200e-6, "alpha": 4.85}},
                                   "kinetics": {"model": "none"}}, "t"))
    for h in (1e-3, 1.0, 1000.0):
        m.step(h)
