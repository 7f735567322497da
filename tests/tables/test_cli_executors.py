"""``millfmu tables`` on its own parser; process pool and Dask paths equal the serial one."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.dem.tables import cli as tables_cli
from tests.tables import _builders
from tests.tables._builders import analytic_builder, spec

TINY = {"tip_speed_m_per_s": [6.0, 10.0], "filling": [0.6, 0.8]}


def _cli(argv):
    ap = argparse.ArgumentParser(prog="millfmu")
    tables_cli.register(ap.add_subparsers(dest="command"))
    args = ap.parse_args(argv)
    return args.func(args)


def _assert_same(a, b):
    for k in T.FIELDS:
        np.testing.assert_array_equal(a.data[k], b.data[k])
    for k in a.refs:
        np.testing.assert_array_equal(a.refs[k], b.refs[k])


def test_process_pool_equals_serial():
    s = spec(grid=TINY)
    ser = T.build_table(s, analytic_builder, executor="serial", progress=False)
    par = T.build_table(s, analytic_builder, executor="processes", workers=2, progress=False)
    _assert_same(ser, par)


def test_dask_local_cluster_equals_serial():
    pytest.importorskip("distributed")
    import cloudpickle

    # Workers are separate processes: send the test builder by value, not by module name.
    cloudpickle.register_pickle_by_value(_builders)
    try:
        s = spec(grid=TINY)
        ser = T.build_table(s, analytic_builder, executor="serial", progress=False)
        dsk = T.build_table(s, analytic_builder, executor="dask", workers=2, progress=False)
    finally:
        cloudpickle.unregister_pickle_by_value(_builders)
    _assert_same(ser, dsk)


def test_dask_scheduler_address_equals_serial(tmp_path, capsys):
    """--scheduler ADDRESS: grid points go to an existing cluster (here one on loopback)."""
    pytest.importorskip("distributed")
    import cloudpickle
    from dask.distributed import LocalCluster

    cloudpickle.register_pickle_by_value(_builders)
    try:
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          host="127.0.0.1", dashboard_address=None) as cluster:
            addr = cluster.scheduler_address
            assert addr.startswith("tcp://127.0.0.1:")
            s = spec(grid=TINY)
            via = T.build_table(s, analytic_builder, scheduler=addr, progress=False)
            cache = str(tmp_path / "cache")
            assert _cli(["tables", "build", "--tip-speed", "8,12", "--filling", "0.6,0.8",
                         "--sector-deg", "10", "--no-gravity", "--cache-dir", cache,
                         "--scheduler", addr, "--no-progress",
                         "--builder", "tests.tables._builders:analytic_builder"]) == 0
    finally:
        cloudpickle.unregister_pickle_by_value(_builders)
    _assert_same(T.build_table(s, analytic_builder, executor="serial", progress=False), via)
    assert "2 x 2 points" in capsys.readouterr().out


def test_cli_build_status_verify_clear(tmp_path, capsys):
    cache = str(tmp_path / "cache")
    argv = ["tables", "build", "--scene", "disc_slice", "--tip-speed", "8,12",
            "--filling", "0.6,0.8", "--sector-deg", "10", "--no-gravity", "--record", "0.01",
            "--cache-dir", cache, "--executor", "serial", "--no-progress",
            "--builder", "tests.tables._builders:analytic_builder",
            "--export", str(tmp_path / "exp" / "t")]
    assert _cli(argv) == 0
    out = capsys.readouterr().out
    assert "2 x 2 points" in out and "exported" in out
    m = json.loads((tmp_path / "exp" / "t.json").read_text())
    assert m["rebuild_command"].startswith("millfmu tables build --scene disc_slice --tip-speed 8,12 --filling 0.6,0.8")
    assert _cli(["tables", "status", "--cache-dir", cache, "--json"]) == 0
    entries = json.loads(capsys.readouterr().out)
    assert len(entries) == 1 and entries[0]["state"] == "ok"
    assert entries[0]["scene"] == "disc_slice" and entries[0]["shape"] == [2, 2]
    m = json.loads((tmp_path / "exp" / "t.json").read_text())
    assert m["scene"]["run"]["record_s"] == 0.01 and m["scene"]["mill"]["sector_deg"] == 10.0
    assert _cli(["tables", "verify", "--cache-dir", cache, str(tmp_path / "exp" / "t")]) == 0
    # corrupt the cache entry: verify fails, clear --stale removes it
    entry = tmp_path / "cache" / entries[0]["key"]
    (entry / T.TABLE_FILE).write_bytes(b"x")
    capsys.readouterr()
    assert _cli(["tables", "verify", "--cache-dir", cache]) == 1
    assert "bad" in capsys.readouterr().out
    assert _cli(["tables", "clear", "--stale", "--cache-dir", cache]) == 0
    assert not entry.exists()


def test_cli_errors_name_the_problem(tmp_path, capsys):
    cache = str(tmp_path / "cache")
    assert _cli(["tables", "build", "--cache-dir", cache]) == 2
    assert "no grid given" in capsys.readouterr().err
    assert _cli(["tables", "build", "--tip-speed", "4,8", "--cache-dir", cache,
                 "--sector-deg", "10", "--no-gravity"]) == 2
    assert "tip_speed_m_per_s = 4.0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _cli(["tables", "build", "--tip-speed", "8,x"])


ORDER_GRID = {"tip_speed_m_per_s": [6.0, 10.0], "filling": [0.5, 0.7, 0.9]}


def _run_order(path) -> list:
    """(tip speed, filling, process id) of each call, in the order the calls started."""
    return [tuple(float(x) for x in line.split()) for line in open(path).read().splitlines()]


def _costed_spec(tmp_path):
    s = spec(grid=ORDER_GRID, count_file=str(tmp_path / "order.txt"))
    return T.TableSpec(scene=s.scene, grid=s.grid, kernel_version=s.kernel_version,
                       builder_id=_builders.CostedBuilder.builder_id)


def test_serial_build_runs_the_costliest_points_first(tmp_path):
    """A builder that estimates its points' cost has them run costliest first (the cost
    here is the filling); the table is the same as in grid order."""
    s = _costed_spec(tmp_path)
    tab = T.build_table(s, _builders.CostedBuilder(), executor="serial", progress=False)
    fill = [f for _, f, _ in _run_order(tmp_path / "order.txt")]
    assert fill == [0.9, 0.9, 0.7, 0.7, 0.5, 0.5]
    ref = T.build_table(spec(grid=ORDER_GRID), analytic_builder, executor="serial",
                        progress=False)
    _assert_same(ref, tab)


def _dask_build(s, builder, workers):
    pytest.importorskip("distributed")
    import cloudpickle

    cloudpickle.register_pickle_by_value(_builders)
    try:
        T.build_table(s, builder, executor="dask", workers=workers, progress=False)
    finally:
        cloudpickle.unregister_pickle_by_value(_builders)


def test_dask_runs_the_costliest_points_first(tmp_path):
    """On one Dask worker the points run in the order of falling cost."""
    _dask_build(_costed_spec(tmp_path), _builders.CostedBuilder(), workers=1)
    fill = [f for _, f, _ in _run_order(tmp_path / "order.txt")]
    assert fill == [0.9, 0.9, 0.7, 0.7, 0.5, 0.5]

