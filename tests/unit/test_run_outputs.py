"""millfmu run: the output folder (issue 11, cases 1 and 6) and the provenance that
reproduces a run (case 8)."""

import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from millfmu.runner import simulate
from millfmu.scene import scene_from_dict

SHORT = "[run]\nt_end_s = 60.0\ndt_s = 10.0\noutput_interval_s = 30.0\n"


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "millfmu.cli", "run", "-q", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd)


@pytest.fixture
def short(tmp_path):
    p = tmp_path / "short.toml"
    p.write_text(SHORT)
    return p


def test_out_is_an_existing_file(tmp_path, short):
    f = tmp_path / "result.txt"
    f.write_text("keep me")
    r = _run(short, "--out", f)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert f"--out {f}: exists and is not a folder" in r.stderr
    assert f.read_text() == "keep me"


def test_out_cannot_be_written(tmp_path, short):
    # A folder below a file cannot be made (a permission test would pass as root).
    f = tmp_path / "file"
    f.write_text("x")
    r = _run(short, "--out", f / "sub")
    assert r.returncode == 2 and "Traceback" not in r.stderr and f"--out {f / 'sub'}: cannot write there" in r.stderr
    r = _run(short, "--out", "/proc/millfmu-out")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    # /proc exists: the message says a folder could not be made in it, not that it is missing
    assert "cannot write there (making a folder in /proc failed:" in r.stderr, r.stderr


def test_rerun_without_plots_leaves_no_plots_of_the_earlier_run(tmp_path, short):
    out = tmp_path / "out"
    assert _run(short, "--out", out).returncode == 0
    assert {p.name for p in out.iterdir()} == {"result.json", "psd.csv", "psd.png", "sizes.png"}
    (out / "notes.txt").write_text("mine")
    first = json.loads((out / "result.json").read_text())
    assert _run(short, "--out", out, "--no-plots").returncode == 0
    assert {p.name for p in out.iterdir()} == {"result.json", "psd.csv", "notes.txt"}
    assert json.loads((out / "result.json").read_text())["outputs"] == first["outputs"]


def test_a_refused_run_keeps_the_earlier_results(tmp_path, short):
    out = tmp_path / "out"
    assert _run(short, "--out", out).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    bad = tmp_path / "bad.toml"
    bad.write_text("[mill]\ntip_speed_m_per_s = 99.0\n")
    assert _run(bad, "--out", out).returncode == 2
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize("case", ["default", "detailed"])
def test_result_json_reproduces_its_run(tmp_path, short, case):
    """The default scene (simple model: no table) and the detailed example (its table's
    identity and stated error in the provenance)."""
    import millfmu

    if case == "detailed":
        example = millfmu.example_path("limestone_detailed.toml").read_text()
        short.write_text(example[:example.index("\n[run]")] + "\n" + SHORT)
    out = tmp_path / "out"
    assert _run(short, "--out", out).returncode == 0
    res = json.loads((out / "result.json").read_text())
    prov = res["provenance"]

    assert prov["millfmu_version"] == millfmu.__version__ and prov["numpy_version"] == np.__version__
    assert prov["python_version"].count(".") == 2 and prov["wall_time_s"] > 0.0
    if case == "default":
        assert "table" not in prov and prov["scene"]["kinetics"]["model"] == "simple"
    else:
        t = prov["table"]
        assert t["ref"] == "coupled" and len(t["key"]) == 64 and len(t["files"]["table.npz"]["sha256"]) == 64
        assert set(t["stated_error"]["zones"]) == {"V1", "V2", "V3", "V4"}
        assert all(0.0 < e < 1.0 for e in t["stated_error"]["collision_frequency_relative"])
    # Every scene key is there, and the resolved scene alone gives the same outputs.
    scene = scene_from_dict(prov["scene"])
    assert prov["scene"]["run"]["t_end_s"] == 60.0 and "bead_filling" in prov["scene"]["mill"]
    _, recs, _ = simulate(scene, progress=False)
    assert recs == res["outputs"]
    assert "below_grid_fraction" in res["units"] and res["outputs"][0]["below_grid_fraction"] >= 0.0


# ---- issue 27: atomic result folders, leftovers, nothing created on refusal ---------------
KILL_DURING_SWITCH = """
import os, signal, sys
from millfmu import cli, runner
stage = sys.argv[1]
def hook(s):
    if s == stage:
        os.kill(os.getpid(), signal.SIGKILL)
runner._switch_hook = hook
sys.exit(cli.main(["run", "-q", *sys.argv[2:]]))
"""


def _kill_at(stage, *args):
    return subprocess.run([sys.executable, "-c", KILL_DURING_SWITCH, stage, *map(str, args)], capture_output=True,
                          text=True)


def _folder(p):
    return {f.name: f.read_bytes() for f in p.iterdir()}


@pytest.mark.parametrize("stage", ["carried", "switched", "moved-away"])
def test_a_run_killed_while_switching_results_in_leaves_the_old_or_the_new_set(tmp_path, short, stage, monkeypatch):
    out = tmp_path / "out"
    assert _run(short, "--out", out).returncode == 0
    (out / "notes.txt").write_text("mine")
    old = _folder(out)
    longer = tmp_path / "longer.toml"
    longer.write_text(SHORT.replace("60.0", "90.0"))
    if stage == "moved-away":  # the fallback where the file system cannot exchange two folders
        env_code = "runner._exchange = lambda a, b: False\n"
        code = KILL_DURING_SWITCH.replace("runner._switch_hook = hook\n", "runner._switch_hook = hook\n" + env_code)
        r = subprocess.run([sys.executable, "-c", code, stage, longer, "--out", out], capture_output=True, text=True)
    else:
        r = _kill_at(stage, longer, "--out", out)
    assert r.returncode == -9, r.stderr
    hidden = [p.name for p in tmp_path.iterdir() if p.name.startswith(".millfmu-")]
    assert hidden  # the killed run's temporary folder
    if stage == "moved-away":
        assert not out.exists()  # between the fallback's two renames: the next run renames the old set back
    else:
        now = _folder(out)
        assert now == old or (set(now) == set(old) and now["result.json"] != old["result.json"]
                              and json.loads(now["result.json"])["outputs"][-1]["t_s"] == 90.0), sorted(now)
        assert now["notes.txt"] == b"mine"
    # The next run removes the leftovers (restoring an old set first) and writes a complete set.
    other = tmp_path / "other"
    assert _run(short, "--out", other).returncode == 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".millfmu-")] == []
    if stage == "moved-away":
        assert _folder(out) == old
    assert _run(longer, "--out", out).returncode == 0
    assert set(_folder(out)) == set(old) and json.loads((out / "result.json").read_text())["outputs"][-1]["t_s"] == 90.0


def test_a_folder_with_sub_folders_is_updated_file_by_file_under_a_marker(tmp_path, short):
    out = tmp_path / "out"
    (out / "mine").mkdir(parents=True)
    r = _kill_at("file", short, "--out", out)
    assert r.returncode == -9
    assert (out / ".millfmu-incomplete").exists()
    r = _run(short, "--out", out)
    assert r.returncode == 0 and "was stopped while it replaced the result files" in r.stderr
    assert set(_folder_names(out)) == {"mine", "result.json", "psd.csv", "psd.png", "sizes.png"}


def _folder_names(p):
    return [f.name for f in p.iterdir()]


def test_a_refused_or_interrupted_run_creates_no_folder(tmp_path, short):
    bad = tmp_path / "bad.toml"
    bad.write_text("[mill]\ntip_speed_m_per_s = 99.0\n")
    assert _run(bad, "--out", tmp_path / "np1" / "deep" / "sub").returncode == 2
    code = ("import sys\nfrom millfmu import cli, runner\n"
            "def stop(*a, **k):\n    raise KeyboardInterrupt\n"
            "runner.simulate = stop\nsys.exit(cli.main(['run', '-q', sys.argv[1], '--out', sys.argv[2]]))\n")
    r = subprocess.run([sys.executable, "-c", code, str(short), str(tmp_path / "np1" / "deep" / "sub")],
                       capture_output=True, text=True)
    assert r.returncode == 130, r.stderr
    f = tmp_path / "file"
    f.write_text("x")
    assert _run(short, "--out", f / "deep" / "sub").returncode == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "file", "short.toml"]


def test_a_parent_that_takes_no_new_folder_is_refused_saying_where_the_temporary_folder_goes(tmp_path, monkeypatch):
    """An --out folder that exists and is writable in a parent that is not (mode 555; made
    here by refusing folders in the parent, since root may write anywhere)."""
    import tempfile

    from millfmu import runner

    out = tmp_path / "out"
    out.mkdir()
    real = tempfile.mkdtemp

    def mkdtemp(prefix="", dir=None):
        if dir is not None and Path(dir) == tmp_path:
            raise PermissionError(13, "Permission denied")
        return real(prefix=prefix, dir=dir)

    monkeypatch.setattr(runner.tempfile, "mkdtemp", mkdtemp)
    with pytest.raises(runner.OutputError) as e:
        runner.check_out_dir(out)
    msg = str(e.value)
    assert f"--out {out}" in msg and "Permission denied" in msg
    assert f"hidden folder .millfmu-* in {tmp_path}" in msg and "one rename" in msg
