"""Regenerated on demand: a new operating point costs its own runs, not the whole grid. A
build seeds its point store with the points of the table it extends and of the shipped
tables of the same DEM scene and kernel (PointStore.seed, cache.seed_tables)."""

from __future__ import annotations

import numpy as np

from millfmu.dem import tables as T
from millfmu.dem.tables.build import PointStore, stored_results, unstack
from millfmu.dem.tables.dem_builder import rebuild_including
from tests.tables._builders import analytic_builder, count, spec


def test_one_new_point_runs_once_old_points_stay_bit_identical(tmp_path):
    cf = str(tmp_path / "builds")
    s = spec(grid={"tip_speed_m_s": [6.0, 10.0, 14.0]}, count_file=cf)
    small = T.get_table(s, analytic_builder, cache_dir=tmp_path / "a", executor="serial", progress=False)
    assert count(cf) == 3
    # another machine: an empty cache, only the finished table at hand
    fresh = tmp_path / "b"
    big = rebuild_including(small, {"tip_speed_m_s": 16.0}, builder=analytic_builder, cache_dir=fresh,
                            executor="serial", progress=False)
    assert count(cf) == 4  # exactly one run: the new point
    assert list(big.axes["tip_speed_m_s"]) == [6.0, 10.0, 14.0, 16.0]
    for k in T.FIELDS:
        np.testing.assert_array_equal(big.data[k][:3], small.data[k])  # bit for bit
    again = rebuild_including(small, {"tip_speed_m_s": 16.0}, builder=analytic_builder, cache_dir=fresh,
                              executor="serial", progress=False)
    assert count(cf) == 4  # the second time nothing is built
    for k in T.FIELDS:
        np.testing.assert_array_equal(again.data[k], big.data[k])


def test_unstack_inverts_assemble_for_the_shipped_coupled_table(tmp_path):
    t = T.read_table_ref("coupled")
    s = t.spec()
    import json

    by_point = {json.dumps(p, sort_keys=True): r for p, r in unstack(s, t)}  # the anchor comes twice
    assert set(by_point) == {json.dumps(p, sort_keys=True) for p in s.points()}
    re = T.assemble(s, [by_point[json.dumps(p, sort_keys=True)] for p in s.points()])
    for k in t.data:
        np.testing.assert_array_equal(re.data[k], t.data[k])
    for name in s.one_at_a_time:
        np.testing.assert_array_equal(re.one_at_a_time[name].data["se_density"], t.one_at_a_time[name].data["se_density"])


def test_refining_the_coupled_table_reuses_its_points(tmp_path):
    """The refine command's grid (8 and 12 m/s added) over the same DEM scene and kernel: of
    its 28 points the 18 of the shipped table are found in a fresh point store."""
    t = T.read_table_ref("coupled")
    old = t.spec()
    grid = dict(old.grid, tip_speed_m_s=[6.0, 8.0, 10.0, 12.0, 14.0])
    new = T.TableSpec(scene=old.scene, grid=grid, kernel_version=old.kernel_version, builder_id=old.builder_id,
                      one_at_a_time=old.one_at_a_time)
    from millfmu.dem.tables.cache import seed_tables

    assert any(x.manifest["key"] == t.manifest["key"] for x in seed_tables(new))
    store = PointStore(tmp_path / "points")
    assert store.seed(t) == 18 and store.seed(t) == 0
    found = stored_results(new, store)
    assert sum(r is not None for r in found) == 18 and len(found) == 28
