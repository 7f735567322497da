"""What a new user meets first: every help page, a scene section given as a value, a
stirrer at rest on a table, host-env on a file that is not an FMU, output folders' modes,
an unwritable output folder named, long on-demand builds asked first, a bead size the DEM
cell cannot hold refused before its cost is said, and tip speeds beyond a table noted."""

from __future__ import annotations

import argparse
import json
import os
import re
import stat
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from millfmu.cli import build_parser, main
from millfmu.scene import SceneError, scene_from_dict

EXAMPLE = Path(__file__).resolve().parents[2] / "millfmu" / "data" / "examples" / "limestone_detailed.toml"


def _parsers(p: argparse.ArgumentParser, path=("millfmu",)):
    yield path, p
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sub in a.choices.items():
                yield from _parsers(sub, path + (name,))


def test_every_help_page_formats():
    """`millfmu --help` and every command's: a bare "%" in a help text breaks argparse."""
    pages = list(_parsers(build_parser()))
    assert len(pages) > 20
    for path, p in pages:
        text = p.format_help()
        assert text.startswith("usage: " + " ".join(path)), path
    # the top page lists the commands with their help texts
    top = " ".join(pages[0][1].format_help().split())
    assert "calibrate" in top and "(with 95 % intervals)" in top


def test_help_exits_0(capsys):
    for argv in (["--help"], ["-h"], ["calibrate", "--help"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 0, argv
    assert "Traceback" not in capsys.readouterr().err


def test_a_scene_outside_its_table_is_refused_with_its_file_and_the_ways_out(tmp_path, capsys):
    """The refusal names the file beside the scene's name, and what the user can do: let the
    DEM extend the table, take the nearest edge where the axis allows it, or run the simple
    model."""
    text = EXAMPLE.read_text()
    for key, value, shown, similar in (("bead_filling", "0.45", "mill.bead_filling = 0.45", None),
                                       ("diameter_m", "0.3e-3", "beads.diameter_m = 0.0003", "bead_diameter_m")):
        f = tmp_path / f"{key}.toml"
        f.write_text(re.sub(rf"^{key} = [0-9.e-]+", f"{key} = {value}", text, count=1, flags=re.M))
        assert main(["run", str(f), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert f"{f}: limestone-detailed: {shown}" in err, err
        assert "on_outside = 'build'" in err and "kinetics.model = 'simple'" in err
        assert ("similar_axes" in err) is (similar is not None), err
        if similar:
            assert f"similar_axes = ['{similar}']" in err
        assert not (tmp_path / "out").exists()


def test_a_run_that_breaks_almost_nothing_says_so(tmp_path, capsys):
    """A 0.1 um feed in the default mill: x50 moves by 2e-5 of itself in 30 minutes; the run
    says so with the stress frequency at x50 against 1/t. The default feed gets no such word."""
    f = tmp_path / "fine.toml"
    f.write_text("[feed]\nx50_m = 0.1e-6\n")
    assert main(["run", str(f), "--out", str(tmp_path / "fine"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "the stress model breaks almost nothing here" in err and "1/t = 0.000556 1/s" in err, err
    warned = json.loads((tmp_path / "fine" / "result.json").read_text())["warnings"]
    assert any("breaks almost nothing" in w for w in warned)
    assert main(["run", "--out", str(tmp_path / "default"), "-q"]) == 0
    assert "breaks almost nothing" not in capsys.readouterr().err


@pytest.mark.parametrize("text, words", [
    ("[mill]\ntip_speed_m_per_s = 0.0\n", "the stirrer does not turn (tip speed 0 m/s throughout"),
    ("[operation]\nmode = \"continuous\"\n",
     "operation.mode = 'continuous' with operation.feed_mass_flow_kg_per_s = 0: nothing flows through the mill"),
])
def test_a_still_stirrer_or_a_continuous_mill_without_feed_is_said(text, words, tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text(text + "[run]\nt_end_s = 60.0\n")
    assert main(["run", str(f), "--out", str(tmp_path / "o"), "-q", "--no-plots"]) == 0
    assert f"millfmu: warning: {words}" in capsys.readouterr().err
    assert any(words in w for w in json.loads((tmp_path / "o" / "result.json").read_text())["warnings"])


def test_python_dash_m_millfmu_is_the_command():
    """Where the environment's scripts folder is not on the PATH, ``python -m millfmu`` runs
    the same command."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "millfmu", "--help"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("usage: millfmu"), r.stdout[:80]


def test_the_version_is_asked_as_usual(capsys):
    import millfmu

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out == f"millfmu {millfmu.__version__}\n"


def test_one_value_and_one_degree_of_freedom_are_singular(tmp_path, capsys):
    data = tmp_path / "d.csv"
    data.write_text("t_s,x50_m\n300,5.277e-6\n1800,2.875e-6\n")
    assert main(["calibrate", "--data", str(data), "--fit", "mill.stress_frequency_factor", "-q"]) == 0
    out = capsys.readouterr().out
    assert "(2 values, 1 degree of freedom)" in out and "Student's t with 1 degree of freedom" in out, out


@pytest.mark.parametrize("value", [5, True, 1.5, "x", [1, 2]])
@pytest.mark.parametrize("section", ["mill", "scene", "material", "kinetics", "run", "beads"])
def test_a_section_given_as_a_value_is_refused_by_name(section, value):
    with pytest.raises(SceneError) as e:
        scene_from_dict({section: value})
    assert str(e.value).startswith(f"scene: {section} = ") and "must be a table" in str(e.value)


def test_cli_exits_2_for_a_section_given_as_a_value(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text("mill = 5\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "mill = 5: must be a table" in err and not (tmp_path / "out").exists()


def test_stirrer_at_rest_on_a_table_has_a_zero_width_band(tmp_path, capsys):
    """Detailed model on the coupled table (the detailed example) at tip speed 0: no
    collisions, no lookup, so the table's error reaches no result (the band's two runs agree)."""
    from millfmu import api

    r = api.run(EXAMPLE, overrides={"mill.tip_speed_m_per_s": 0.0, "run.t_end_s": 60.0, "run.dt_s": 10.0})
    files = r.write(tmp_path / "api", plots=False)
    band = json.loads((tmp_path / "api" / "result.json").read_text())["prediction_band"]
    lo, hi = band["outputs"]["x50_m"]
    assert lo == hi and band["collision_frequency_relative_error"] == [None] * 4 and files
    scene = tmp_path / "s.toml"
    scene.write_text("[kinetics]\nmodel = 'detailed'\n[mill]\ntip_speed_m_per_s = 0.0\n[run]\nt_end_s = 60.0\n"
                     "dt_s = 10.0\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "cli"), "-q", "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "no zone had collisions (the stirrer at rest)" in out and "+--" not in out


@pytest.mark.parametrize("content, words", [
    (b"plain text\n", "not a zip archive, so not an FMU"),
    ({"a.txt": "x"}, "a zip archive without modelDescription.xml"),
    ({"modelDescription.xml": "<fmi"}, "its modelDescription.xml is not well-formed XML"),
    ({"modelDescription.xml": '<fmiModelDescription fmiVersion="2.0"/>', "resources/pythonfmu/x": ""},
     "declares no CoSimulation modelIdentifier"),
])
def test_host_env_on_a_file_that_is_not_an_fmu(tmp_path, capsys, content, words):
    f = tmp_path / "x.fmu"
    if isinstance(content, bytes):
        f.write_bytes(content)
    else:
        with zipfile.ZipFile(f, "w") as z:
            for name, text in content.items():
                z.writestr(name, text)
    assert main(["host-env", str(f)]) == 2
    err = capsys.readouterr().err
    assert words in err and str(f) in err and "Traceback" not in err


@pytest.fixture
def umask_027():
    old = os.umask(0o027)
    yield 0o027
    os.umask(old)


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_output_folders_keep_the_users_umask_and_an_existing_folders_mode(tmp_path, umask_027, capsys):
    args = [str(EXAMPLE), "-q", "--no-plots"]
    assert main(["run", *args, "--out", str(tmp_path / "new")]) == 0
    assert _mode(tmp_path / "new") == 0o750
    assert _mode(tmp_path / "new" / "result.json") == 0o640
    existing = tmp_path / "existing"
    existing.mkdir()
    existing.chmod(0o775)
    for _ in range(2):  # the first run moves a new folder in; the second swaps it with the first's
        assert main(["run", *args, "--out", str(existing)]) == 0
        assert _mode(existing) == 0o775
    assert main(["calibrate", "--data", str(EXAMPLE.parent / "limestone_standin_batch.csv"), "--fit",
                 "mill.stress_frequency_factor", "--out", str(tmp_path / "a" / "b" / "cal"), "-q"]) == 0
    assert (_mode(tmp_path / "a" / "b" / "cal") == 0o750
            and _mode(tmp_path / "a" / "b" / "cal" / "calibrated.toml") == 0o640)
    assert main(["rates", str(EXAMPLE), "--out", str(tmp_path / "rates"), "--no-plots"]) == 0
    assert {_mode(f) for f in (tmp_path / "rates").iterdir()} == {0o640}


def test_an_unwritable_output_folder_is_the_one_named(tmp_path, monkeypatch):
    """--out into an existing folder that takes no new entries, beside which a folder can be
    made: the message names that folder, not its (writable) parent."""
    from millfmu import runner

    out = tmp_path / "ro"
    out.mkdir()
    real = tempfile.mkdtemp

    def mkdtemp(*a, dir=None, **kw):  # a folder of mode 555, as a user other than root sees it
        if dir is not None and Path(dir) == out:
            raise PermissionError(13, "Permission denied")
        return real(*a, dir=dir, **kw)

    monkeypatch.setattr(runner.tempfile, "mkdtemp", mkdtemp)
    with pytest.raises(runner.OutputError) as e:
        runner.check_out_dir(out)
    msg = str(e.value)
    assert f"making a folder in {out} failed: Permission denied)" in msg and f"in {tmp_path} beside it" not in msg


def test_a_bead_size_the_dem_cell_cannot_hold_is_refused_before_its_cost(tmp_path, capsys):
    """4 mm beads on the coupled table (on_outside = 'build'): no sector of up
    to 90 degrees holds them, so they are refused by the bead size, before a build line or any
    DEM run."""
    scene = tmp_path / "s.toml"
    scene.write_text('[beads]\ndiameter_m = 4e-3\n[kinetics]\nmodel = "detailed"\n'
                     '[kinetics.stress_distribution]\nsource = "table"\ntable = "coupled"\non_outside = "build"\n')
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "beads.diameter_m = 0.004: the DEM scene disc_slice" in err, err
    assert "holds at most 352 beads of 4 mm placed without overlap in a sector of 90 degrees" in err
    assert "a filling of 0.6 needs 353" in err  # the sub-grid's first filling it cannot hold
    assert "building a table" not in err and "lower the filling" not in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


# ---- long on-demand builds ask first ------------------------------------------------------------
@pytest.fixture
def slow_table(tmp_path):
    """A 'DEM' table of 3 points built by kernel 'k-old', whose points took 2 s per cost unit."""
    from millfmu.dem import tables as T
    from tests.tables._builders import FakeDemBuilder

    s = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0]}, kernel_version="k-old",
                    builder_id=T.DEM_BUILDER_ID)
    return T.get_table(s, FakeDemBuilder(), cache_dir=tmp_path / "a", executor="serial", progress=False)


def _extend(table, tmp_path, policy, **kw):
    from millfmu.dem.tables.dem_builder import rebuild_including
    from tests.tables._builders import FakeDemBuilder

    events = []
    fb = FakeDemBuilder(events)
    t = rebuild_including(table, {"tip_speed_m_per_s": 16.0}, builder=fb, cache_dir=tmp_path / "b", executor="serial",
                          workers=1, progress=False, on_stale=policy, log=lambda m: events.append(("log", m)), **kw)
    return t, events


def test_a_rebuild_over_the_limit_is_refused_without_a_terminal(slow_table, tmp_path, monkeypatch):
    from millfmu.dem.tables import cache
    from millfmu.dem.tables.on_demand import BuildNotConfirmedError

    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k-new")
    # all 4 points again: 0.8 x (6 + 10 + 14 + 16) = 36.8 units of 2 s = 74 s on one worker
    monkeypatch.setenv("MILLFMU_BUILD_LIMIT_S", "60")
    with pytest.raises(BuildNotConfirmedError) as e:
        _extend(slow_table, tmp_path, "rebuild")
    msg = str(e.value)
    assert "would take about 74 s on 1 worker, over the 60 s" in msg and "MILLFMU_BUILD_LIMIT_S" in msg
    assert "--yes" in msg
    # under the limit, or with no limit (what --yes sets), it runs
    monkeypatch.setenv("MILLFMU_BUILD_LIMIT_S", "inf")
    t, events = _extend(slow_table, tmp_path, "rebuild")
    assert [x[0] for x in events].count("build") == 4 and t.spec().kernel_version == "k-new"


def test_a_build_over_the_limit_runs_when_confirmed_and_not_when_declined(slow_table, tmp_path, monkeypatch):
    from millfmu.dem.tables import cache, on_demand
    from millfmu.dem.tables.on_demand import BuildNotConfirmedError

    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k-old")
    monkeypatch.setenv("MILLFMU_BUILD_LIMIT_S", "10")  # the one new point: 0.8 x 16 x 2 s = 26 s
    asked = []
    monkeypatch.setattr(on_demand, "_ask_at_terminal", lambda q: asked.append(q) or False)
    monkeypatch.setattr(on_demand.sys, "stdin", _Tty())
    monkeypatch.setattr(on_demand.sys, "stderr", _Tty())
    with pytest.raises(BuildNotConfirmedError):
        _extend(slow_table, tmp_path, "refuse")
    assert len(asked) == 1 and "about 26 s on 1 worker" in asked[0]
    monkeypatch.setattr(on_demand, "_ask_at_terminal", lambda q: True)
    t, events = _extend(slow_table, tmp_path, "refuse")
    assert [x for x in events if x[0] == "build"] == [("build", {"tip_speed_m_per_s": 16.0})]


class _Tty:
    def isatty(self):
        return True

    def write(self, s):
        return len(s)

    def flush(self):
        pass


@pytest.mark.parametrize("value", ["abc", "-5", "nan"])
def test_a_bad_build_limit_is_refused_by_name(monkeypatch, value):
    from millfmu.dem.tables.on_demand import build_limit_s
    from millfmu.stress_tables.spec import TableError

    monkeypatch.setenv("MILLFMU_BUILD_LIMIT_S", value)
    with pytest.raises(TableError,
                       match=f"MILLFMU_BUILD_LIMIT_S = '{value}': allowed a number of seconds >= 0, or inf"):
        build_limit_s()


def test_run_refuses_the_stale_coupled_tables_full_rebuild_without_yes(tmp_path, capsys, monkeypatch):
    """--on-stale rebuild of the coupled table (73 DEM points with the steel beads, hours): refused before any point
    runs, naming the cost, the limit and --yes."""
    from millfmu.dem.tables import cache

    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "sha256:" + "0" * 64)
    monkeypatch.delenv("MILLFMU_BUILD_LIMIT_S", raising=False)
    scene = tmp_path / "s.toml"
    scene.write_text('[beads]\ndensity_kg_per_m3 = 7800.0\n[kinetics]\nmodel = "detailed"\n'
                     '[kinetics.stress_distribution]\nsource = "table"\ntable = "coupled"\non_outside = "build"\n')
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q", "--no-plots", "--on-stale", "rebuild"]) == 2
    err = capsys.readouterr().err
    assert ("73 points, 0 already built, 73 to run" in err
            and "over the 30 min a build may take without confirmation" in err)
    assert "--yes" in err and "Traceback" not in err and not (tmp_path / "out").exists()


# ---- tip speeds beyond the table ------------------------------------------------------------------
def test_tip_speeds_beyond_the_table_are_warned_about_in_the_results(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text("[kinetics]\nmodel = 'detailed'\n[mill]\ntip_speed_m_per_s = 16.0\n[run]\nt_end_s = 60.0\n"
                     "dt_s = 10.0\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q", "--no-plots"]) == 0
    err = capsys.readouterr().err
    words = "tip_speed_m_per_s = 16 lies outside the table's range 6 to 14"
    assert words in err and "similarity assumed" in err
    res = json.loads((tmp_path / "out" / "result.json").read_text())
    assert any(words in w and "prediction band do not cover this" in w for w in res["warnings"])


def test_a_ramp_through_the_table_edge_is_warned_once_with_its_range():
    from millfmu.mill import MillModel
    from millfmu.runner import run_warnings

    m = MillModel(scene_from_dict({"kinetics": {"model": "detailed"}}))  # the default scene's table
    assert m.similarity_warnings() == {}
    for v in (10.0, 15.0, 17.5, 12.0):
        m.step(1.0, tip_speed_m_per_s=v)
    w = m.similarity_warnings()
    assert list(w) == ["tip_speed_m_per_s"] and "tip_speed_m_per_s = 15 to 17.5 lies outside" in w["tip_speed_m_per_s"]
    assert sum("tip_speed_m_per_s = 15 to 17.5" in x for x in run_warnings(m, [])) == 1
    assert np.isfinite(m.outputs()["x50_m"])
