"""Checkpointed table points (millfmu.dem.tables.point_work): a DEM point stopped after a
checkpoint goes on from it when the build runs again and gives the result of the point that
was not stopped, to the digit; a checkpoint that cannot be used starts the point again; a
folder another process holds is left to it; stale folders are cleared."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.dem.tables import point_folders as PF
from millfmu.dem.tables import point_work as PW
from millfmu.dem.tables import warm_start as W
from millfmu.stress_tables.table import read_table_ref

pytest.importorskip("numba")

from millfmu.dem import run as R  # noqa: E402

POINT = {"tip_speed_m_per_s": 10.0, "filling": 0.8, "bead_diameter_m": 0.8e-3,
         "bead_density_kg_per_m3": 2510.0}


class Stopped(Exception):
    """Stands for the build's process being killed right after a checkpoint was written."""


@pytest.fixture(scope="module")
def scene():
    """The coupled table's scene in a 5 degree sector, 0.5 ms spin-up and recording: four
    samples, a checkpoint possible after each of the first three."""
    d = copy.deepcopy(read_table_ref("coupled").spec().scene)
    d["mill"]["sector_deg"] = 5.0
    d["run"].update(spin_up_s=5e-4, record_s=5e-4, sample_every_s=2.5e-4)
    return d


def _without_wall(result: dict) -> dict:
    return {k: v for k, v in result.items() if k != "wall_time_s"}


def _running(store):
    return sorted((store / PW.RUNNING_DIR).iterdir()) if (store / PW.RUNNING_DIR).exists() else []


def test_a_stopped_point_goes_on_from_its_checkpoint(tmp_path, scene, monkeypatch, capsys):
    whole_store = tmp_path / "whole"
    whole = T.DemBuilder(threads=1).with_states(whole_store)(scene, POINT)
    assert _running(whole_store) == []  # the folder goes once the point has run
    store = tmp_path / "store"
    b = T.DemBuilder(threads=1).with_states(store)
    monkeypatch.setattr(PW, "POINT_CHECKPOINT_EVERY_S", 1e-9)  # one at every sample
    write, calls = R._write_checkpoint, []

    def write_then_stop(path, state):
        write(path, state)
        calls.append(path)
        if len(calls) == 3:  # in the recording's first half
            raise Stopped

    monkeypatch.setattr(R, "_write_checkpoint", write_then_stop)
    with pytest.raises(Stopped):
        b(scene, POINT)
    (folder,) = _running(store)
    assert (folder / R.CHECKPOINT).exists() and json.loads((folder / PW.START).read_text()) == whole["start"]
    assert json.loads((folder / PW.META).read_text())["scene"] == T.dem_scene_at_point(scene, POINT)
    assert not list(store.glob("*" + W.STATE_SUFFIX))
    monkeypatch.setattr(R, "_write_checkpoint", write)
    capsys.readouterr()
    resumed = b(scene, POINT)
    err = capsys.readouterr().err
    assert "goes on from its checkpoint (0.00075 of 0.001 s simulated" in err, err
    np.testing.assert_equal(_without_wall(resumed), _without_wall(whole))
    assert resumed["wall_time_s"] > 0.0
    assert _running(store) == []
    # the settled state kept as by the point that was not stopped
    kv = T.dem_kernel_version()
    a, _ = W.read_state(W.state_file(store, T.dem_scene_at_point(scene, POINT), kv), kv)
    b_, _ = W.read_state(W.state_file(whole_store, T.dem_scene_at_point(scene, POINT), kv), kv)
    for k in a:
        np.testing.assert_array_equal(a[k], b_[k], err_msg=k)


def test_an_unusable_checkpoint_starts_the_point_again(tmp_path, scene, monkeypatch, capsys):
    store = tmp_path / "store"
    b = T.DemBuilder(threads=1).with_states(store)
    monkeypatch.setattr(PW, "POINT_CHECKPOINT_EVERY_S", 1e-9)
    write = R._write_checkpoint

    def write_then_stop(path, state):
        write(path, state)
        raise Stopped

    monkeypatch.setattr(R, "_write_checkpoint", write_then_stop)
    with pytest.raises(Stopped):
        b(scene, POINT)
    monkeypatch.setattr(R, "_write_checkpoint", write)
    (folder,) = _running(store)
    good = (folder / R.CHECKPOINT).read_bytes()
    (folder / R.CHECKPOINT).write_bytes(b"not a checkpoint")
    capsys.readouterr()
    again = b(scene, POINT)
    err = capsys.readouterr().err
    assert f"the checkpoint in {folder} is not used (" in err and "the point starts again" in err
    assert again["start"]["start"] == "cold" and sum(again["collision_count"]) > 0
    assert _running(store) == []
    # one of DEM sources that give other results: not used either
    import pickle

    state = pickle.loads(good)
    state["kernel_version"] = "sha256:other"
    folder.mkdir(parents=True)
    R._write_checkpoint(folder / R.CHECKPOINT, state)
    (folder / PW.START).write_text(json.dumps(again["start"]))
    np.testing.assert_array_equal(b(scene, POINT)["collision_count"], again["collision_count"])
    assert "is not used (made by other DEM sources (sha256:other))" in capsys.readouterr().err


def test_a_point_another_process_holds_runs_apart(tmp_path, capsys):
    fcntl = pytest.importorskip("fcntl")
    content = PW.work_key({"a": 1}, "kv", {"window_s": 0.1})
    with PW.point_work(tmp_path, content, "p") as mine:
        assert mine.checkpointed and mine.folder.parent == tmp_path / PW.RUNNING_DIR
        with PW.point_work(tmp_path, content, "p") as other:
            assert not other.checkpointed and tmp_path not in other.folder.parents
        assert "another process runs the table point" in capsys.readouterr().err
        assert mine.folder.exists()
        # clearing leaves a held folder alone
        assert PF.clear_running(tmp_path, False, "kv") == []
    assert not mine.folder.exists()
    # stale folders: another kernel version's goes, this one's stays, a held one stays
    old = PW.work_key({"a": 1}, "kv-old", {})
    for c in (content, old):
        with pytest.raises(Stopped), PW.point_work(tmp_path, c, "p") as w:
            (w.folder / R.CHECKPOINT).write_bytes(b"x")  # kept: a stopped point
            raise Stopped
    names = {json.loads((p / PW.META).read_text())["kernel_version"]: p.name for p in _running(tmp_path)}
    assert set(names) == {"kv", "kv-old"}
    assert PF.clear_running(tmp_path, True, "kv") == [f"{PW.RUNNING_DIR}/{names['kv-old']}"]
    with open(tmp_path / PW.RUNNING_DIR / names["kv"] / PW.LOCK, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        assert PF.clear_running(tmp_path, False, "kv") == []
    assert PF.clear_running(tmp_path, False, "kv") == [f"{PW.RUNNING_DIR}/{names['kv']}"]
    assert _running(tmp_path) == []


def test_tables_status_lists_the_points_running_or_stopped(tmp_path, capsys):
    from millfmu.cli import main

    store = tmp_path / "points"
    sc = {"mill": {"tip_speed_m_per_s": 6.0}, "beads": {"filling": 0.6, "diameter_m": 5e-4,
                                                        "density_kg_per_m3": 2510.0}}
    kv = T.dem_kernel_version()
    with PW.point_work(store, PW.work_key(sc, kv, {}), "p") as held:
        (held.folder / R.CHECKPOINT).write_bytes(b"x")
        with pytest.raises(Stopped), PW.point_work(store, PW.work_key(dict(sc, x=1), "kv-old", {}), "q") as w:
            (w.folder / R.CHECKPOINT).write_bytes(b"x")
            raise Stopped
        (store / "a.json").write_text("{}")
        pts = {p["running"]: p for p in PW.running_points(store)}
        assert pts[True]["values"] == {"tip_speed_m_per_s": 6.0, "filling": 0.6, "bead_diameter_m": 5e-4,
                                       "bead_density_kg_per_m3": 2510.0}
        assert pts[False]["kernel_version"] == "kv-old" and pts[False]["checkpoint_age_s"] >= 0.0
        assert main(["tables", "status", "--cache-dir", str(tmp_path)]) == 0
        out = capsys.readouterr().out
    assert f"points {store}: 1 finished (0 of the installed DEM version)" in out
    assert "6 m/s, filling 0.6, beads 0.5 mm 2510 kg/m3: running, checkpoint 0 min ago" in out
    assert "stopped, checkpoint 0 min ago (another DEM version: tables clear --stale)" in out
    assert f"    millfmu dem progress {held.folder}" in out
