"""Cache mechanics with the analytic builder: hit, miss, stale key, truncated file, flipped
byte, concurrent builders, atomic entries."""

from __future__ import annotations

import json
import multiprocessing as mp
import shutil
import subprocess
import sys

import numpy as np
import pytest

from millfmu.dem import tables as T
from tests.tables._builders import analytic_builder, count, spec


@pytest.fixture
def cache(tmp_path):
    return tmp_path / "cache"


def _same(a: T.Table, b: T.Table):
    assert a.zone_names == b.zone_names
    for k in T.FIELDS:
        np.testing.assert_array_equal(a.data[k], b.data[k])


def test_import_does_not_load_numba():
    code = ("import sys, millfmu.dem.tables as t; t.dem_kernel_version(); "
            "assert 'numba' not in sys.modules, 'numba imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_miss_then_hit(cache, tmp_path):
    cf = str(tmp_path / "builds")
    s = spec(count_file=cf)
    assert T.load_cached(s, cache) is None
    t1 = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9  # one build of 3 x 3 points
    entry = cache / s.key()
    assert sorted(p.name for p in entry.iterdir()) == sorted(
        [T.TABLE_FILE, T.MANIFEST_FILE, T.MANIFEST_SUM_FILE])
    m = json.loads((entry / T.MANIFEST_FILE).read_text())
    assert m["key"] == s.key() and m["kernel_version"] == "test-kernel-1"
    assert m["files"][T.TABLE_FILE]["sha256"] == T.sha256_file(entry / T.TABLE_FILE)
    t2 = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9  # hit: nothing built
    _same(t1, t2)
    # grid order: point (i, j) holds the builder's result at (v_i, phi_j)
    want = analytic_builder({}, {"tip_speed_m_per_s": 10.0, "filling": 0.9})
    np.testing.assert_array_equal(t2.data["collision_frequency_norm"][1, 2],
                                  want["collision_frequency_norm"])


def test_env_and_explicit_cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("MILLFMU_CACHE_DIR", str(tmp_path / "env"))
    assert T.default_cache_dir() == tmp_path / "env"
    assert T.resolve_cache_dir(tmp_path / "cli") == tmp_path / "cli"
    monkeypatch.delenv("MILLFMU_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert T.default_cache_dir() == tmp_path / "xdg" / "millfmu" / "tables"
    s = spec()
    T.get_table(s, analytic_builder, executor="serial", progress=False)
    assert (tmp_path / "xdg" / "millfmu" / "tables" / s.key() / T.TABLE_FILE).exists()


def test_key_depends_on_scene_grid_kernel():
    base = spec()
    assert spec().key() == base.key()
    assert spec(kernel_version="test-kernel-2").key() != base.key()
    assert spec(extra=1).key() != base.key()
    assert spec(grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7, 0.8]}
                ).key() != base.key()
    # the order in which axes or scene keys are given does not matter
    assert spec(grid={"filling": [0.5, 0.7, 0.9], "tip_speed_m_per_s": [6, 10, 14]}
                ).key() == base.key()


def test_stale_entry_is_rebuilt(cache, tmp_path):
    cf = str(tmp_path / "builds")
    old, new = spec(count_file=cf), spec(count_file=cf, kernel_version="test-kernel-2")
    T.get_table(old, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9
    # A new kernel version is a new key: a miss.
    assert T.load_cached(new, cache) is None
    # An old entry sitting under the new key (e.g. copied or left by an older millfmu):
    # detected as stale, rebuilt.
    shutil.copytree(cache / old.key(), cache / new.key())
    with pytest.raises(T.TableError, match="stale"):
        T.read_table(cache / new.key(), expect_key=new.key())
    assert T.load_cached(new, cache) is None
    t = T.get_table(new, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 18
    assert t.manifest["kernel_version"] == "test-kernel-2"
    assert T.read_table(cache / new.key(), expect_key=new.key()).manifest["key"] == new.key()


def _rebuilds_after(damage, cache, tmp_path, match):
    cf = str(tmp_path / "builds")
    s = spec(count_file=cf)
    good = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    damage(cache / s.key())
    with pytest.raises(T.TableError, match=match):
        T.read_table(cache / s.key(), expect_key=s.key())
    assert T.load_cached(s, cache) is None  # never used
    t = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9  # rebuilt from the finished points, none run again
    _same(good, t)
    T.read_table(cache / s.key(), expect_key=s.key())
    # without the finished points, every point runs again
    damage(cache / s.key())
    shutil.rmtree(cache / T.POINTS_DIR)
    t = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 18
    _same(good, t)


def test_truncated_file_is_rebuilt(cache, tmp_path):
    def damage(d):
        p = d / T.TABLE_FILE
        data = p.read_bytes()
        p.write_bytes(data[: len(data) // 2])
    _rebuilds_after(damage, cache, tmp_path, "truncated")


def test_flipped_byte_is_rebuilt(cache, tmp_path):
    def damage(d):
        p = d / T.TABLE_FILE
        data = bytearray(p.read_bytes())
        data[len(data) // 2] ^= 0x01
        p.write_bytes(bytes(data))
    _rebuilds_after(damage, cache, tmp_path, "corrupted")


def test_flipped_byte_in_manifest_is_rebuilt(cache, tmp_path):
    def damage(d):
        p = d / T.MANIFEST_FILE
        data = bytearray(p.read_bytes())
        i = data.index(b"test-kernel-1") + 5
        data[i] ^= 0x01
        p.write_bytes(bytes(data))
    _rebuilds_after(damage, cache, tmp_path, "corrupted")


def test_missing_file_is_rebuilt(cache, tmp_path):
    _rebuilds_after(lambda d: (d / T.TABLE_FILE).unlink(), cache, tmp_path, "missing")


def _build_in_child(cache, cf, q):
    s = spec(count_file=cf, sleep_s=0.2)
    t = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    q.put((s.key(), float(t.data["collision_frequency_norm"].sum())))


def test_concurrent_builders_leave_one_good_entry(cache, tmp_path):
    cf = str(tmp_path / "builds")
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    procs = [ctx.Process(target=_build_in_child, args=(cache, cf, q)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    got = [q.get(timeout=5) for _ in procs]
    assert got[0] == got[1]
    # 9 points x 0.2 s: the second process waited on the lock and found the entry.
    assert count(cf) == 9
    entries = [p.name for p in cache.iterdir() if p.is_dir() and p.name != T.POINTS_DIR]
    assert entries == [got[0][0]]  # no temporary folders left behind
    assert not list((cache / T.POINTS_DIR).glob(".tmp-*"))
    T.read_table(cache / got[0][0], expect_key=got[0][0])


def test_status_and_clear(cache, tmp_path):
    a, b = spec(), spec(kernel_version="test-kernel-2")
    for s in (a, b):
        T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    (cache / b.key() / T.TABLE_FILE).write_bytes(b"not a table")
    states = {e["key"]: e["state"] for e in T.cache_entries(cache, kernel_version="x")}
    assert states == {a.key(): "ok", b.key(): "bad"}
    assert T.clear_cache(cache, only_not_ok=True, kernel_version="x") == [b.key()]
    assert [e["key"] for e in T.cache_entries(cache, kernel_version="x")] == [a.key()]
    removed = T.clear_cache(cache, kernel_version="x")
    # the analytic builder's points are not the DEM's: kept by --stale, removed by a clear
    assert removed[0] == a.key() and len(removed) == 1 + 18
    assert all(r.startswith(T.POINTS_DIR + "/") for r in removed[1:])
    assert T.cache_entries(cache, kernel_version="x") == []


def test_spec_rejects_bad_grid():
    with pytest.raises(T.TableError, match="grid axis 'speed': unknown"):
        spec(grid={"speed": [1.0]})
    with pytest.raises(T.TableError, match="strictly ascending"):
        spec(grid={"filling": [0.8, 0.6]})


def _fail_at_fill_09(scene, point):
    if point["tip_speed_m_per_s"] == 10.0 and point["filling"] == 0.9:
        raise RuntimeError("cut off")
    return analytic_builder(scene, point)


def test_cut_build_resumes_with_its_finished_points(cache, tmp_path):
    cf = str(tmp_path / "builds")
    s = spec(count_file=cf)
    with pytest.raises(T.TableError, match=r"grid point \{'tip_speed_m_per_s': 10.0, 'filling': "
                       r"0.9\}: RuntimeError: cut off; the 5 finished points are kept"):
        T.get_table(s, _fail_at_fill_09, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 5  # grid order: (6, *), (10, 0.5), (10, 0.7) finished, then the cut
    assert T.load_cached(s, cache) is None  # no half-written entry
    assert len(list((cache / T.POINTS_DIR).glob("*.json"))) == 5
    t = T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9  # only the 4 missing points ran
    assert t.manifest["points_run"] == 4 and t.manifest["points_reused"] == 5
    want = analytic_builder({}, {"tip_speed_m_per_s": 6.0, "filling": 0.5})
    np.testing.assert_array_equal(t.data["se_density"][0, 0], want["se_density"])
    # force runs every point again; a table sharing points runs only its new ones
    T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False,
                force=True)
    assert count(cf) == 18
    wider = spec(count_file=cf, grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0, 18.0],
                                      "filling": [0.5, 0.7, 0.9]})
    T.get_table(wider, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 21
    # a point file that does not hold its key's content is not used
    f = sorted((cache / T.POINTS_DIR).glob("*.json"))[0]
    f.write_text(f.read_text().replace('"format": 2', '"format": 0'))
    store = T.PointStore(cache / T.POINTS_DIR)
    damaged = [p for p in wider.points() if store.key(wider, p) == f.stem]
    assert len(damaged) == 1 and store.get(wider, damaged[0]) is None
    # --stale drops the point of another format (the damaged one), keeps the others
    T.clear_cache(cache, only_not_ok=True, kernel_version="test-kernel-1")
    assert len(list((cache / T.POINTS_DIR).glob("*.json"))) == 11
    assert not (cache / T.POINTS_DIR / f.name).exists()
    T.clear_cache(cache)
    assert not list((cache / T.POINTS_DIR).glob("*.json"))


def test_parallel_build_keeps_the_points_that_finished(cache, tmp_path):
    cf = str(tmp_path / "builds")
    s = spec(count_file=cf)
    with pytest.raises(T.TableError, match="RuntimeError: cut off; the 8 finished points"):
        T.get_table(s, _fail_at_fill_09, cache_dir=cache, executor="processes", workers=2,
                    progress=False)
    assert len(list((cache / T.POINTS_DIR).glob("*.json"))) == 8
    T.get_table(s, analytic_builder, cache_dir=cache, executor="serial", progress=False)
    assert count(cf) == 9  # 8 before the failure was reported, 1 on the resume
