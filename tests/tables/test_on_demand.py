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
    s = spec(grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0]}, count_file=cf)
    small = T.get_table(s, analytic_builder, cache_dir=tmp_path / "a", executor="serial", progress=False)
    assert count(cf) == 3
    # another machine: an empty cache, only the finished table at hand
    fresh = tmp_path / "b"
    big = rebuild_including(small, {"tip_speed_m_per_s": 16.0}, builder=analytic_builder, cache_dir=fresh,
                            executor="serial", progress=False)
    assert count(cf) == 4  # exactly one run: the new point
    assert list(big.axes["tip_speed_m_per_s"]) == [6.0, 10.0, 14.0, 16.0]
    for k in T.FIELDS:
        np.testing.assert_array_equal(big.data[k][:3], small.data[k])  # bit for bit
    again = rebuild_including(small, {"tip_speed_m_per_s": 16.0}, builder=analytic_builder, cache_dir=fresh,
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
        np.testing.assert_array_equal(re.one_at_a_time[name].data["se_density"],
                                      t.one_at_a_time[name].data["se_density"])


def test_refining_the_coupled_table_reuses_its_points(tmp_path):
    """A finer grid along tip speed (1 m/s steps) over the same DEM scene and kernel, as the
    shipped table was refined from 6/10/14 m/s: of its 81 points the 61 of the shipped
    table are found in a fresh point store."""
    t = T.read_table_ref("coupled")
    old = t.spec()
    grid = dict(old.grid, tip_speed_m_per_s=[6.0 + k for k in range(9)])
    new = T.TableSpec(scene=old.scene, grid=grid, kernel_version=old.kernel_version, builder_id=old.builder_id,
                      one_at_a_time=old.one_at_a_time, across=old.across)
    from millfmu.dem.tables.cache import seed_tables

    assert any(x.manifest["key"] == t.manifest["key"] for x in seed_tables(new))
    store = PointStore(tmp_path / "points")
    assert store.seed(t) == 61 and store.seed(t) == 0
    found = stored_results(new, store)
    assert sum(r is not None for r in found) == 61 and len(found) == 81


def test_the_progress_line_counts_down_while_a_point_runs(tmp_path, monkeypatch, capsys):
    """The time left is refreshed between finished points (a point can run for an hour)."""
    import millfmu.dem.tables.build as B

    monkeypatch.setattr(B, "PROGRESS_REFRESH_S", 0.05)

    class Slow:
        def relative_cost(self, scene, point):
            return 1.0

        def __call__(self, scene, point):
            import time

            time.sleep(0.4)
            return analytic_builder(scene, point)

    s = spec(grid={"tip_speed_m_per_s": [6.0, 10.0]})
    B.run_points(s, Slow(), executor="serial", progress=True, seconds_per_cost=10.0)
    err = capsys.readouterr().err
    lefts = [line for line in err.replace("\r", "\n").splitlines() if "left" in line]
    assert len(lefts) >= 10  # refreshed while the points ran (measured 21), not only when one finished (6)


def test_a_build_over_a_finished_table_knows_its_seconds_per_cost(tmp_path, monkeypatch):
    """The time left of a build that extends a finished table (a refine command, an
    on-demand point) starts from what that table's points took, before its own first point."""
    import millfmu.dem.tables.cache as C
    from tests.tables._builders import FakeDemBuilder

    monkeypatch.setattr(C, "dem_kernel_version", lambda: "k")
    small = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0]}, kernel_version="k",
                        builder_id=T.DEM_BUILDER_ID)
    done = T.get_table(small, FakeDemBuilder(), cache_dir=tmp_path / "a", executor="serial", progress=False)
    seen, real = {}, C.build_table

    def capture(spec, builder, **kw):
        seen.update(kw)
        return real(spec, builder, **kw)

    monkeypatch.setattr(C, "build_table", capture)
    big = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0]}, kernel_version="k",
                      builder_id=T.DEM_BUILDER_ID)
    T.get_table(big, FakeDemBuilder(), cache_dir=tmp_path / "b", executor="serial", progress=False, seed_from=(done,))
    assert seen["seconds_per_cost"] == FakeDemBuilder.seconds_per_cost


def test_an_extended_table_keeps_what_its_stated_error_reads(tmp_path):
    """A table extended on demand keeps the checks and the realization spread of the table it
    extends (same scene, settings and DEM), so that its stated error does not shrink."""
    cf = str(tmp_path / "builds")
    s = spec(grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0]}, count_file=cf)
    small = T.get_table(s, analytic_builder, cache_dir=tmp_path / "a", executor="serial", progress=False)
    shipped = T.read_table_ref("coupled").manifest
    for k in ("interpolation_check", "separability_check", "realization_spread"):
        small.manifest[k] = shipped[k]
    big = rebuild_including(small, {"tip_speed_m_per_s": 16.0}, builder=analytic_builder, cache_dir=tmp_path / "b",
                            executor="serial", progress=False)
    for k in ("interpolation_check", "separability_check", "realization_spread"):
        assert big.manifest[k] == shipped[k], k
    assert big.realization_error() is not None
