"""An FMU whose scene allows on-demand builds (on_outside = 'build') carries the table that
covers its operating point, built at build-fmu time, and never runs the DEM: inside it a
point outside that table is refused, saying that the FMU carries no DEM."""

from __future__ import annotations

from functools import partial

import pytest

from fmu_build.build import _export_table_slice, covering_table
from millfmu.dem import tables as T
from millfmu.dem.tables import cache
from millfmu.dem.tables.dem_builder import rebuild_including
from millfmu.mill import InputError, MillModel
from millfmu.scene import SceneError, scene_from_dict
from tests.tables._builders import FakeDemBuilder


def _coupled(**sections):
    d = {"kinetics": {"model": "detailed", "stress_distribution": {"source": "table", "table": "coupled",
                                                                   "on_outside": "build"}}}
    d.update(sections)
    return scene_from_dict(d)


def _no_build(*a, **k):
    raise AssertionError("an FMU's model must not start a build")


def test_fmu_model_refuses_a_point_outside_its_table_naming_why(monkeypatch):
    import millfmu.dem.tables.dem_builder as db

    monkeypatch.setattr(db, "rebuild_including", _no_build)
    with pytest.raises(SceneError) as e:
        MillModel(_coupled(beads={"diameter_m": 1.4e-3}), no_dem=True)
    msg = str(e.value)
    assert "beads.diameter_m = 0.0014" in msg and "allowed 0.0005 to 0.0012 m" in msg
    assert "an FMU carries no DEM" in msg
    # on the grid the FMU's model runs; an input outside is refused, not built
    m = MillModel(_coupled(), no_dem=True)
    m.step(1.0)
    with pytest.raises(InputError, match="bead_filling = 0.95.*carries no DEM"):
        m.step(1.0, bead_filling=0.95)


def test_build_fmu_carries_the_table_that_covers_the_scene(tmp_path, monkeypatch):
    """A scene at 16 m/s on a 6-14 m/s table: the covering table is built once at build
    time (one point), exported as the FMU's slice, and the FMU's model reads it."""
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k")
    s = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0],
                                                         "filling": [0.5, 0.7, 0.9]},
                    kernel_version="k", builder_id=T.DEM_BUILDER_ID)
    T.get_table(s, FakeDemBuilder(), cache_dir=tmp_path / "c", executor="serial", progress=False).export(tmp_path / "t")
    d = {"kinetics": {"model": "detailed", "stress_distribution": {"source": "table", "table": str(tmp_path / "t"),
                                                                   "on_outside": "build", "similar_axes": []}},
         "mill": {"tip_speed_m_per_s": 16.0, "bead_filling": 0.7}}
    scene = scene_from_dict(d)
    model = MillModel(scene)
    events = []
    model.source.rebuild = partial(rebuild_including, builder=FakeDemBuilder(events), cache_dir=tmp_path / "c",
                                   executor="serial", progress=False, log=lambda m: events.append(("log", m)))
    table = covering_table(scene, model)
    assert [e[0] for e in events] == ["log", "build", "build", "build"]  # 16 m/s at the 3 fillings
    files = _export_table_slice(scene, tmp_path / "fmu" / "table", table)
    assert [f.name for f in files] == ["table.npz", "table.json"]
    d["kinetics"]["stress_distribution"]["table"] = str(tmp_path / "fmu" / "table")
    fmu_model = MillModel(scene_from_dict(d), no_dem=True)
    assert list(fmu_model.source.table.axes["tip_speed_m_per_s"]) == [6.0, 10.0, 14.0, 16.0]
    fmu_model.step(1.0)


def test_a_point_the_dem_cannot_build_is_refused_before_the_run(monkeypatch):
    """With on_outside = 'build' the scene's own point is built before a run
    (cover_scene_point, which every run's simulate calls first), so a build that fails (e.g.
    1.4 mm beads that do not fit the table's 10-degree cell) is a SceneError naming
    on_outside and the reason, never an error inside the first step."""
    import millfmu.dem.tables.dem_builder as db
    from millfmu.stress_tables.spec import TableError

    def failing(table, point, **k):
        raise TableError(f"grid point {point}: GeometryError: the cell holds at most 1159 beads")

    monkeypatch.setattr(db, "rebuild_including", failing)
    with pytest.raises(SceneError) as e:
        MillModel(_coupled(beads={"diameter_m": 1.4e-3})).cover_scene_point()
    assert e.value.key == "kinetics.stress_distribution.on_outside"
    assert "could not be extended" in str(e.value) and "GeometryError" in str(e.value)
