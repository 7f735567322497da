"""The public Python API (millfmu/__init__) and the README's example, which runs here."""

import re
from pathlib import Path

import numpy as np
import pytest

import millfmu

ROOT = Path(__file__).resolve().parents[2]


def test_readme_python_example_runs(tmp_path, monkeypatch, capsys):
    text = (ROOT / "README.md").read_text()
    m = re.search(r"<!-- python-api-example -->\s*```python\n(.*?)```", text, re.S)
    assert m, "README lost its Python API example"
    monkeypatch.chdir(tmp_path)  # outside the repository: the example names no relative path
    exec(compile(m.group(1), "README.md", "exec"), {"__name__": "readme"})
    out = capsys.readouterr().out
    assert "x50 " in out and "holdup" in out and "mill.bead_filling 1.2" in out
    assert (tmp_path / "out-api" / "psd.png").stat().st_size > 1000


def test_importing_the_package_loads_no_model_code():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c",
                        "import millfmu, sys; print(sorted(m for m in sys.modules if m.startswith('millfmu') or m in "
                        "('numpy', 'scipy')))"],
                       capture_output=True, text=True)
    assert r.stdout.strip() == "['millfmu']", r.stdout


def test_load_scene_sources_and_overrides(tmp_path):
    text = "[mill]\ntip_speed_m_per_s = 6.0\n"
    f = tmp_path / "s.toml"
    f.write_text(text)
    a, b = millfmu.load_scene(text), millfmu.load_scene(f)
    c = millfmu.load_scene({"mill": {"tip_speed_m_per_s": 6.0}})
    d = millfmu.load_scene(None, {"mill.tip_speed_m_per_s": 6.0})
    e = millfmu.load_scene(str(f), {"mill": {"bead_filling": 0.7}})
    assert a == b == c == d and e.mill.tip_speed_m_per_s == 6.0 and e.mill.bead_filling == 0.7
    assert millfmu.load_scene(a, {"run.dt_s": 2.0}).run.dt_s == 2.0
    with pytest.raises(millfmu.SceneError) as err:
        millfmu.load_scene(overrides={"mill.tip_speed_m_per_s": -1.0})
    assert err.value.key == "mill.tip_speed_m_per_s" and err.value.value == -1.0
    with pytest.raises(millfmu.SceneError, match="valid TOML"):
        millfmu.load_scene("[mill\n")
    with pytest.raises(millfmu.SceneError, match="cannot be read"):
        millfmu.load_scene(tmp_path / "missing.toml")


def test_run_result_series_q3_and_write(tmp_path):
    r = millfmu.run(overrides={"run": {"t_end_s": 120.0, "output_interval_s": 30.0}})
    assert r.t_s.tolist() == [0.0, 30.0, 60.0, 90.0, 120.0]
    assert r["x50_m"].shape == (5,) and np.all(np.diff(r["x50_m"]) < 0) and r.units["x50_m"] == "m"
    assert r.q3.shape == (5, len(r.edges_m)) and np.allclose(r.q3[:, -1], 1.0)
    assert np.all(np.diff(r.q3, axis=1) >= 0.0)
    np.testing.assert_allclose(r.q3[:, 0], r["below_grid_fraction"])
    files = r.write(tmp_path / "out", plots=False)
    assert {p.name for p in files} == {"result.json", "psd.csv"}
    assert r.provenance["scene"]["run"]["t_end_s"] == 120.0
    model = millfmu.MillModel(r.scene)
    with pytest.raises(millfmu.InputError, match="tip_speed_m_per_s"):
        model.step(1.0, tip_speed_m_per_s=float("nan"))


def test_example_path_finds_the_shipped_examples_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = millfmu.example_path("limestone_continuous")
    assert p.is_absolute() and p.name == "limestone_continuous.toml" and p.is_file()
    with pytest.raises(millfmu.SceneError) as e:
        millfmu.example_path("nonsense")
    assert "accelerator_detailed.toml" in str(e.value)
