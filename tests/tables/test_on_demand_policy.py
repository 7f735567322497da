"""Builds on demand: where the installed DEM's kernel version differs from the table's, a
line says so before anything runs, with the cost of the full rebuild, and the policy
(on_stale: refuse / rebuild / accept) is followed; a point the table's DEM scene cannot run
is refused when the scene is loaded, naming both ranges; the progress of a build states the
running point's share and the time left."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.dem.tables import cache
from millfmu.dem.tables.build import BuildProgress
from millfmu.dem.tables.dem_builder import rebuild_including
from millfmu.dem.tables.on_demand import StaleTableError
from millfmu.kinetics.rates import OperatingPoint
from tests.tables._builders import D_GB_M, POROSITY, R_DISC_M, RHO_KG_PER_M3, FakeDemBuilder


def _op(v, phi=0.8):
    return OperatingPoint(tip_speed_m_per_s=v, filling=phi, porosity=POROSITY, r_stirrer_m=R_DISC_M, d_gb_m=D_GB_M,
                          rho_gb_kg_per_m3=RHO_KG_PER_M3, y_gb_Pa=63e9, y_p_Pa=70e9, rho_p_kg_per_m3=2710.0,
                          rho_l_kg_per_m3=998.0, eta_susp_Pa_s=1e-3, solids_mass_fraction=0.2)


@pytest.fixture
def old_table(tmp_path):
    """A 'DEM' table of 3 points built by kernel 'k-old' (the fake DEM, 2 s per cost unit)."""
    s = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0]}, kernel_version="k-old",
                    builder_id=T.DEM_BUILDER_ID)
    return T.get_table(s, FakeDemBuilder(), cache_dir=tmp_path / "a", executor="serial", progress=False)


def _extend(table, tmp_path, policy, events):
    fb = FakeDemBuilder(events)
    return rebuild_including(table, {"tip_speed_m_per_s": 16.0}, builder=fb, cache_dir=tmp_path / "b",
                             executor="serial", progress=False, on_stale=policy,
                             log=lambda m: events.append(("log", m)))


def test_same_kernel_runs_only_the_new_point_and_says_so_first(old_table, tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k-old")
    events = []
    t = _extend(old_table, tmp_path, "refuse", events)
    assert [e[0] for e in events] == ["log", "build"]
    # 4 points, 3 from the table; the new one costs 0.8 x 16 units of 2 s
    assert "4 points, 3 already built, 1 to run (about 26 s of point runs" in events[0][1]
    assert t.spec().kernel_version == "k-old"


def test_stale_kernel_refuse_rebuild_accept(old_table, tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k-new")
    # refuse: one line, no build; it names both versions and the cost of the full rebuild
    events = []
    with pytest.raises(StaleTableError) as e:
        _extend(old_table, tmp_path, "refuse", events)
    assert [x[0] for x in events] == ["log"]
    line = events[0][1]
    assert "\n" not in line and "k-old" in line and "k-new" in line
    # all 4 points: 0.8 x (6 + 10 + 14 + 16) = 36.8 units of 2 s
    assert "4 points, 0 already built, 4 to run (about 74 s of point runs" in line
    assert "on_stale = 'rebuild'" in line and "'accept'" in line and str(e.value) == line
    # rebuild: the same line first, then every point with the installed kernel
    events = []
    t = _extend(old_table, tmp_path, "rebuild", events)
    assert events[0][0] == "log" and "rebuilding" in events[0][1]
    assert [x[0] for x in events[1:]].count("build") == 4 and all(x[0] == "log" for x in events[:2])
    assert t.spec().kernel_version == "k-new"
    # accept: the table's points as they are, only the new point runs
    events = []
    t = _extend(old_table, tmp_path, "accept", events)
    assert events[0][0] == "log" and "on_stale = 'accept'" in events[0][1]
    assert "1 to run" in events[0][1]
    assert [x for x in events if x[0] == "build"] == [("build", {"tip_speed_m_per_s": 16.0})]
    assert t.spec().kernel_version == "k-old"
    for k in T.FIELDS:
        np.testing.assert_array_equal(t.data[k][:3], old_table.data[k])
    assert t.manifest["on_demand"]["installed_kernel_version"] == "k-new"
    assert t.manifest["on_demand"]["points_run_with_installed"] == [{"tip_speed_m_per_s": 16.0}]


def test_stale_refusal_is_up_front_in_the_source_check(old_table, monkeypatch):
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "k-new")
    calls = []
    src = T.TableStressSource(old_table, on_outside="build", rebuild=lambda t, p: calls.append(p))
    src.check(_op(10.0))  # inside the grid: nothing to build
    with pytest.raises(T.OutsideGridError, match="tip_speed_m_per_s = 16.0.*k-old.*refused"):
        src.check(_op(16.0))
    assert calls == []
    T.TableStressSource(old_table, on_outside="build", on_stale="accept").check(_op(16.0))  # accepted


def test_coupled_table_refuses_a_filling_the_dem_cannot_run():
    """The coupled table (disc_slice) holds fillings 0.5-0.9, which is what disc_slice runs:
    0.45 is refused up front, naming the table's range and the DEM's, without the DEM engine."""
    import subprocess

    code = ("import sys\n"
            "from millfmu.dem import tables as T\n"
            "from millfmu.scene import scene_from_dict, SceneError\n"
            "from millfmu.mill import MillModel\n"
            "d = {'kinetics': {'model': 'detailed', 'stress_distribution': {'source': 'table', 'table': 'coupled', "
            "'on_outside': 'build'}}, 'mill': {'bead_filling': 0.45}}\n"
            "try:\n"
            "    MillModel(scene_from_dict(d))\n"
            "except SceneError as e:\n"
            "    print(e)\n"
            "print(sorted(m for m in sys.modules if m.startswith(('numba', 'millfmu.dem.engine', "
            "'millfmu.dem.scene'))))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    msg, mods = r.stdout.strip().splitlines()
    assert "mill.bead_filling = 0.45" in msg
    assert "allowed 0.5 to 0.9" in msg  # the table's range
    assert "disc_slice" in msg and "builds 0.5 to 0.9 only" in msg  # the DEM's
    assert mods == "[]"


def test_run_exits_2_before_running_for_a_filling_the_dem_cannot_run(tmp_path, capsys):
    from millfmu.cli import main

    scene = tmp_path / "s.toml"
    scene.write_text('[mill]\nbead_filling = 0.45\n[kinetics]\nmodel = "detailed"\n'
                     '[kinetics.stress_distribution]\nsource = "table"\ntable = "coupled"\non_outside = "build"\n')
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "mill.bead_filling = 0.45" in err and "allowed 0.5 to 0.9" in err and "builds 0.5 to 0.9 only" in err
    assert "Traceback" not in err and not (tmp_path / "out" / "result.json").exists()


def test_run_with_a_stale_kernel_on_the_coupled_table(tmp_path, capsys, monkeypatch):
    """A new bead size on the coupled table with another kernel: refused before running,
    naming the full rebuild's cost from the table's recorded wall times; --on-stale accept
    would run only the new point (not run here: it is a DEM run)."""
    from millfmu.cli import main

    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "sha256:" + "0" * 64)
    scene = tmp_path / "s.toml"
    scene.write_text('[beads]\ndiameter_m = 1.4e-3\n[kinetics]\nmodel = "detailed"\n'
                     '[kinetics.stress_distribution]\nsource = "table"\ntable = "coupled"\non_outside = "build"\n')
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "beads.diameter_m = 0.0014" in err and "73 points, 0 already built, 73 to run" in err
    assert "h of point runs" in err and "refused" in err


def test_build_progress_eta_arithmetic():
    """Costs 3, 1, 1 (the costliest first); one worker; 10 s per cost unit measured."""
    now = [0.0]
    p = BuildProgress(total=5, done=2, costs={0: 3.0, 1: 1.0, 2: 1.0}, seconds_per_cost=None, workers=1,
                      clock=lambda: now[0])
    assert p.eta_s() is None and p.text() == "2/5 points"  # nothing to calibrate from yet
    p.start(0)
    assert p.share(0) == pytest.approx(0.6) and "running 1 point of 60% of the build's cost" in p.text()
    now[0] = 30.0
    p.finish(0)  # 30 s for 3 units: 10 s per unit
    p.start(1)
    assert p.seconds_per_cost() == pytest.approx(10.0)
    assert p.eta_s() == pytest.approx(20.0)
    now[0] = 34.0  # point 1 has run 4 of its 10 s
    assert p.eta_s() == pytest.approx(16.0)
    assert p.text() == "3/5 points, running 1 point of 20% of the build's cost, about 16 s left"
    # a prior from the manifest before any point finishes; two workers share the rest,
    # never less than the longest point left
    q = BuildProgress(total=3, done=0, costs={0: 3.0, 1: 1.0, 2: 1.0}, seconds_per_cost=100.0, workers=2,
                      clock=lambda: 0.0)
    assert q.eta_s() == pytest.approx(300.0)  # max(500 / 2, 300)
    q.finish(0, wall_s=600.0)  # the recorded wall time recalibrates: 200 s per unit
    assert q.eta_s() == pytest.approx(200.0)  # max(400 / 2, 200)


def test_run_points_shows_the_eta_on_its_bar(tmp_path, capsys):
    s = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0]}, kernel_version="k",
                    builder_id=T.DEM_BUILDER_ID)
    T.get_table(s, FakeDemBuilder(), cache_dir=tmp_path, executor="serial", progress=True, seconds_per_cost=2.0)
    err = capsys.readouterr().err
    assert "running 1 point of 62% of the build's cost, about 26 s left" in err  # 8 of 12.8 units first
