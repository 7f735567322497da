"""The shipped examples by name: ``millfmu.example_path`` finds scenes and the stand-in batch
data, and the commands take a shipped example's bare file name where no such file exists,
so that the README's tour runs from any folder, not only from a checkout's root."""

import json
from pathlib import Path

import pytest

import millfmu
from millfmu.cli import main, shipped_example

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "millfmu" / "data" / "examples"


def test_example_path_finds_the_stand_in_data_too(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("limestone_standin_batch.csv", "yeast_standin_batch.csv"):
        p = millfmu.example_path(name)
        assert p.is_absolute() and p.is_file() and p.read_bytes() == (EXAMPLES / name).read_bytes()
    assert millfmu.example_path("limestone_detailed").name == "limestone_detailed.toml"
    with pytest.raises(millfmu.SceneError, match="limestone_standin_batch.csv"):
        millfmu.example_path("limestone_standin_batch.toml")


def test_a_bare_name_is_the_shipped_example_unless_a_file_of_that_name_exists(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = str(millfmu.example_path("limestone_detailed.toml"))
    assert shipped_example("limestone_detailed.toml") == shipped
    assert shipped_example("limestone_detailed") == shipped
    assert shipped_example("limestone_standin_batch.csv") == str(millfmu.example_path("limestone_standin_batch.csv"))
    # The user's own file, a path with a folder, an unknown name: left as given.
    assert shipped_example("elsewhere/limestone_detailed.toml") == "elsewhere/limestone_detailed.toml"
    assert shipped_example("nonsense.toml") == "nonsense.toml"
    assert shipped_example(None) is None
    (tmp_path / "limestone_detailed.toml").write_text("[scene]\nname = 'mine'\n")
    assert shipped_example("limestone_detailed.toml") == "limestone_detailed.toml"


def test_calibrate_and_run_take_the_shipped_examples_by_name_from_any_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    rc = main(["calibrate", "--data", "limestone_standin_batch.csv", "--fit", "mill.stress_frequency_factor",
               "--out", "out-cal", "-q"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "shipped example" in err and "limestone_standin_batch.csv" in err
    assert "mill.stress_frequency_factor = 1.0013" in out  # the README's figure
    cal = json.loads((tmp_path / "out-cal" / "calibration.json").read_text())
    assert "limestone_standin_batch.csv" in json.dumps(cal)
    rc = main(["run", "limestone_detailed", "--out", "out-detailed", "--no-plots", "-q"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert json.loads((tmp_path / "out-detailed" / "result.json").read_text())["provenance"]["scene"]["scene"][
        "name"] == "limestone-detailed"
    # A name that is neither a file nor an example is still refused as a missing file.
    assert main(["run", "limestone_detailde.toml", "--out", "x", "-q"]) == 2
    assert "cannot be read" in capsys.readouterr().err


def test_examples_lists_every_shipped_file_with_its_path(capsys):
    assert main(["examples"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [ln.split(maxsplit=1) for ln in lines if ln.endswith((".toml", ".csv"))]
    listed = {name: Path(path) for name, path in rows}
    assert set(listed) == {p.name for p in EXAMPLES.iterdir() if p.suffix in (".toml", ".csv")}
    assert all(p.is_absolute() and p.is_file() for p in listed.values())


def test_build_fmu_and_rates_take_names_too_and_the_dem_keeps_its_own_scenes(tmp_path, monkeypatch):
    from millfmu.cli import _use_shipped_examples, build_parser

    pytest.importorskip("fmu_build.cli")
    monkeypatch.chdir(tmp_path)
    parse = build_parser().parse_args
    shipped = str(millfmu.example_path("limestone_detailed.toml"))
    a = parse(["build-fmu", "limestone_detailed.toml", "-o", "m.fmu"])
    _use_shipped_examples(a)
    assert a.scene == shipped
    a = parse(["rates", "limestone_detailed", "mine.toml"])
    _use_shipped_examples(a)
    assert a.scene == [shipped, "mine.toml"]
    a = parse(["dem", "run", "annulus", "--out", "d"])  # a DEM scene name, resolved by the DEM
    _use_shipped_examples(a)
    assert a.scene == "annulus"
