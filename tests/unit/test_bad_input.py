"""Bad input as a careless first user gives it, command by command: each is refused with exit
status 2 and one message naming the item, the value and what is allowed (no traceback),
before anything is built, run or written; a folder that is not the tables cache's keeps its
contents. All fast: every case is refused before a model or DEM runs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from millfmu.cli import main
from millfmu.scene import SceneError, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
SHORT = "[run]\nt_end_s = 4.0\ndt_s = 1.0\noutput_interval_s = 2.0\n"
MINI_FLOWSHEET = """products = ["tank0.outflow_mass_flow"]
[flowsheet]
t_end_s = 10.0
step_s = 5.0

[units.tank0]
type = "tank"
pump_mass_flow_kg_per_s = 0.0
initial_holdup_kg = 1.0
initial_solids_mass_fraction = 0.2
"""


def _refused(argv, capsys) -> str:
    """stderr of ``millfmu ARGV``, which must exit 2 without a traceback."""
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's refusal of an option value
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2, (argv, err)
    assert "Traceback" not in err
    return err


# ---- scene files ----------------------------------------------------------------------------
def test_a_scene_with_a_byte_order_mark_reads_as_without(tmp_path):
    """Windows editors save UTF-8 with a byte-order mark: read as the same scene."""
    plain, bom = tmp_path / "plain.toml", tmp_path / "bom.toml"
    plain.write_text(SHORT + "[mill]\ntip_speed_m_per_s = 8.0\n")
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes().replace(b"\n", b"\r\n"))
    assert load_scene(bom) == load_scene(plain)


def test_build_fmu_of_a_scene_with_a_byte_order_mark(tmp_path, capsys):
    """The FMU carries the scene without the mark (which the TOML reader refuses)."""
    import zipfile

    scene = tmp_path / "bom.toml"
    scene.write_bytes(b"\xef\xbb\xbf" + SHORT.encode())
    assert main(["build-fmu", str(scene), "-o", str(tmp_path / "m.fmu")]) == 0, capsys.readouterr().err
    with zipfile.ZipFile(tmp_path / "m.fmu") as z:
        assert z.read("resources/scene.toml") == SHORT.encode()


@pytest.mark.parametrize("key, hint", [("tip_sped_m_per_s", "tip_speed_m_per_s"), ("Tip_Speed_m_per_s",
                                                                                    "tip_speed_m_per_s"),
                                       ("tip_speed", "tip_speed_m_per_s"), ("bead_fill", "bead_filling"),
                                       ("colour", None)])
def test_an_unknown_key_names_the_allowed_one_closest_to_it(key, hint):
    with pytest.raises(SceneError) as e:
        scene_from_dict({"mill": {key: 5.0}})
    msg = str(e.value)
    assert msg.startswith(f"scene: mill.{key} = 5.0: unknown key") and "; allowed: bead_filling" in msg
    assert (f"(did you mean {hint}?)" in msg) if hint else "did you mean" not in msg


@pytest.mark.parametrize("table, where", [
    ({"tip_speed_m_per_s": 8.0}, "tip_speed_m_per_s = 8.0: unknown key here: it is a key of [mill] (write it there)"),
    ({"mill": {"f_mat_kg_per_J_m": 9.0}}, "mill.f_mat_kg_per_J_m = 9.0: unknown key here: it is a key of [material]"),
    ({"mill": {"density_kg_per_m3": 9.0}}, "it is a key of [beads] and of [material] (write it there)"),
])
def test_a_key_in_the_wrong_section_is_sent_to_its_own(table, where):
    with pytest.raises(SceneError) as e:
        scene_from_dict(table)
    assert where in str(e.value)


def test_an_unknown_section_names_the_section_closest_to_it():
    with pytest.raises(SceneError, match=r"mil = \{'n_discs': 3\}: unknown key \(did you mean mill\?\)"):
        scene_from_dict({"mil": {"n_discs": 3}})


def test_a_misspelt_example_name_is_answered_with_the_example(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    err = _refused(["run", "limestone_detaild", "--out", "o"], capsys)
    assert "cannot be read: No such file or directory (did you mean limestone_detailed.toml, a shipped example?)" \
        in err
    assert not (tmp_path / "o").exists()


def test_an_empty_out_is_refused_not_the_current_folder(tmp_path, monkeypatch, capsys):
    """``--out "$DIR"`` with DIR unset: refused, not written into the current folder."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(SHORT)
    err = _refused(["run", "s.toml", "--out", "", "-q"], capsys)
    assert "--out '': is empty; give a folder" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_an_earlier_spelling_warns_in_one_line_without_millfmus_source(tmp_path):
    """The note on an earlier release's key spelling: "millfmu: warning: ..." on one line,
    not a FutureWarning with millfmu's file, line and code."""
    from millfmu.unit_names import earlier_name

    old = earlier_name("tip_speed_m_per_s")  # built, so that the sources keep the current spelling
    scene = tmp_path / "old.toml"
    scene.write_text(f"[mill]\n{old} = 8.0\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "millfmu", "calibrate", str(scene), "--data", str(tmp_path / "no.csv"),
                        "--fit", "mill.stress_frequency_factor"], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith("millfmu: warning: ") and f"mill.{old} -> tip_speed_m_per_s" in lines[0], lines
    assert "FutureWarning" not in r.stderr and "scene.py" not in r.stderr and "Traceback" not in r.stderr
    assert lines[1].startswith("millfmu: error: --data ") and len(lines) == 2, lines


# ---- table files ----------------------------------------------------------------------------
def test_a_table_whose_manifest_is_a_folder_is_refused_by_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "t.npz").mkdir()
    (tmp_path / "t.json").mkdir()
    (tmp_path / "s.toml").write_text(SHORT + '[kinetics]\nmodel = "detailed"\n[kinetics.stress_distribution]\n'
                                             'table = "t"\n')
    err = _refused(["run", "s.toml", "--out", "o", "-q"], capsys)
    assert "kinetics.stress_distribution.table = 't': cannot be used: t.json: cannot be read (Is a directory)" in err
    assert not (tmp_path / "o").exists()


def test_tables_clear_removes_only_cache_entries(tmp_path, capsys):
    """A --cache-dir that names the wrong folder: its folders are not the cache's entries and
    stay; only folders named as entries (a table's sha256) go."""
    from millfmu.dem.tables import cache_entries, clear_cache

    (tmp_path / "project" / "data").mkdir(parents=True)
    (tmp_path / "project" / "data" / "run1.csv").write_text("t_s,x50_m\n")
    (tmp_path / "project" / "notes.txt").write_text("mine")
    entry = tmp_path / "project" / ("ab" * 32)
    entry.mkdir()
    (entry / "table.npz").write_bytes(b"not a table")
    assert [e["key"] for e in cache_entries(tmp_path / "project", kernel_version="k")] == ["ab" * 32]
    assert main(["tables", "clear", "--cache-dir", str(tmp_path / "project")]) == 0
    assert (tmp_path / "project" / "data" / "run1.csv").read_text() == "t_s,x50_m\n"
    assert (tmp_path / "project" / "notes.txt").exists() and not entry.exists()
    assert clear_cache(tmp_path / "project", kernel_version="k") == []


@pytest.mark.parametrize("what", ["status", "verify", "clear"])
def test_a_cache_dir_that_is_a_file_is_refused(what, tmp_path, capsys):
    f = tmp_path / "cache"
    f.write_text("mine")
    err = _refused(["tables", what, "--cache-dir", str(f)], capsys)
    assert f"tables cache {f}: not a folder" in err and f.read_text() == "mine"


# ---- calibrate and rates --------------------------------------------------------------------
DATA = "t_s,x10_m,x50_m,x90_m\n60,3.089e-6,7.593e-6,13.60e-6\n300,1.416e-6,5.277e-6,9.073e-6\n"


@pytest.mark.parametrize("start, shown", [
    ("mill.stress_frequency_factor=inf", "VALUE = inf: must be a finite number > 0"),
    ("mill.stress_frequency_factor=-1", "VALUE = -1.0: must be a finite number"),
    ("material.f_mat_kg_per_J_m=2", "a start value of a constant not fitted")])
def test_calibrate_refuses_a_start_it_cannot_use(start, shown, tmp_path, capsys):
    data = tmp_path / "d.csv"
    data.write_text(DATA)
    err = _refused(["calibrate", "--data", str(data), "--fit", "mill.stress_frequency_factor", "--start", start,
                    "-q", "--out", str(tmp_path / "o")], capsys)
    assert f"--start {start.partition('=')[0]}=VALUE: {shown}" in err, err
    assert not (tmp_path / "o").exists()


def test_calibrate_names_the_fittable_constant_closest_to_a_misspelt_one(tmp_path, capsys):
    data = tmp_path / "d.csv"
    data.write_text(DATA)
    err = _refused(["calibrate", "--data", str(data), "--fit", "mill.stress_frequency_factr", "-q"], capsys)
    assert "(did you mean mill.stress_frequency_factor?)" in err


@pytest.mark.parametrize("argv, shown", [(["--sizes", "10"], "if 10 is in micrometres, write 1e-05"),
                                         (["--values", "tip_speed=6,8", "--values", "tip_speed=10"],
                                          "tip_speed is given twice"),
                                         (["--values", "tip_sped=6"], "(did you mean tip_speed?)"),
                                         (["--sizes", "-1e-6"], "--sizes = '-1e-06': must be positive sizes in m"),
                                         (["--sizes", "2e-6", "-.5"], "--sizes = '2e-06,-0.5': must be positive")])
def test_rates_refuses_sizes_in_micrometres_and_a_parameter_given_twice(argv, shown, tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SHORT)
    err = _refused(["rates", str(scene), "--out", str(tmp_path / "o"), "--no-plots", *argv], capsys)
    assert shown in err and not (tmp_path / "o").exists()


# ---- flowsheets -----------------------------------------------------------------------------
@pytest.fixture
def flowsheet(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "f.toml").write_text(MINI_FLOWSHEET)
    (tmp_path / "afile").write_text("mine")
    return tmp_path


@pytest.mark.parametrize("argv, shown", [
    (["run", "f.toml", "--step", "inf"], "--step = inf: must be a finite number > 0 s"),
    (["run", "f.toml", "--output-interval", "inf"], "--output-interval = inf: must be a finite number > 0 s"),
    (["run", "f.toml", "--out", "afile/o"], "--out = 'afile/o': cannot write there ("),
    (["run", "f.toml", "--fmu-dir", "afile"], "--fmu-dir = 'afile': must be a folder (it is a file)"),
    (["export-ssp", "f.toml", "-o", "adir.ssp"], "-o = 'adir.ssp': is a folder"),
    (["export-ssp", "f.toml", "-o", "afile/x.ssp"],
     "-o = 'afile/x.ssp': its folder afile: must be a folder (it is a file)"),
    (["wp", "f.toml", "--steps", "0", "5"], "--steps/--reference = 0.0: each must be > 0 s"),
    (["wp", "f.toml", "--t-end", "inf"], "--t-end = inf: must be a finite number > 0 s"),
    (["wp", "f.toml", "--steps", "5", "10", "--reference", "2.5", "--variable", "mill.x50"],
     "--variable = 'mill.x50': must be UNIT.VARIABLE with UNIT among the flowsheet's units (tank0) or total"),
    (["run", "circut"], "cannot be read (No such file or directory; did you mean circuit, a shipped flowsheet?)"),
])
def test_flowsheet_options_are_refused_before_anything_is_built(flowsheet, argv, shown, capsys):
    (flowsheet / "adir.ssp").mkdir()
    err = _refused(["flowsheet", *argv], capsys)
    assert shown in err, err
    assert sorted(p.name for p in flowsheet.iterdir()) == ["adir.ssp", "afile", "f.toml"]
    assert not any((flowsheet / "adir.ssp").iterdir()) and (flowsheet / "afile").read_text() == "mine"


def test_a_flowsheet_file_that_is_not_utf8_is_refused_and_one_with_a_bom_read(flowsheet, capsys):
    from flowsheets.spec import load_flowsheet

    (flowsheet / "bin.toml").write_bytes(bytes(range(256)))
    err = _refused(["flowsheet", "run", "bin.toml"], capsys)
    assert "file = 'bin.toml': is not UTF-8 text (byte 128, line 2)" in err
    (flowsheet / "bom.toml").write_bytes(b"\xef\xbb\xbf" + MINI_FLOWSHEET.encode())
    assert load_flowsheet(flowsheet / "bom.toml").units.keys() == {"tank0"}


# ---- the DEM and the benchmarks: refusals before any run ------------------------------------
def test_dem_run_refusals_before_a_run(tmp_path, capsys):
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "bin.toml").write_bytes(bytes(range(256)))
    out = str(tmp_path / "o")
    for argv, shown in ((["annulus", "--out", str(tmp_path / "afile")], "exists and is not a folder"),
                        (["annulus", "--out", str(tmp_path / "afile" / "o")], "cannot write there"),
                        ([str(tmp_path / "bin.toml"), "--out", out], "not UTF-8 text at byte 128 (line 2)"),
                        (["annulus", "--out", out, "--filling", "1.5"],
                         "beads.filling = 1.5: this scene places its beads on a lattice"),
                        (["annulus", "--out", out, "--threads", "0"], "argument --threads: '0': allowed a whole number "
                                                                      "from 1 to"),
                        (["annulus", "--out", out, "--threads", "-1"], "allowed a whole number from 1")):
        assert shown in _refused(["dem", "run", *argv], capsys), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "bin.toml"]


@pytest.mark.parametrize("argv", [["pbm", "--classes", "-5"], ["pbm", "--repeats", "0"], ["pbm", "--hours", "0"],
                                  ["pbm", "--hours", "nan"], ["pbm", "--hours", "0.0001"], ["fmu", "--steps", "-1"],
                                  ["fmu", "--classes", "x"]])
def test_bench_refuses_counts_and_times_it_cannot_use(argv, capsys):
    err = _refused(["bench", *argv], capsys)
    assert "allowed" in err


def test_host_env_of_a_missing_file_says_so(tmp_path, capsys):
    err = _refused(["host-env", str(tmp_path / "no.fmu")], capsys)
    assert f"{tmp_path / 'no.fmu'}: cannot be read (No such file or directory)" in err
