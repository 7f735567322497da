"""An FMU built from a scene that allows on-demand builds (on_outside = 'build'), at a point
on the shipped coupled table's grid: it carries the table slice and no builder, runs, and
refuses a bead size outside the table at initialization (saying that it carries no DEM)
instead of starting a DEM run inside a step."""

from __future__ import annotations

import zipfile

import pytest

from .fmu_support import build, isolated_python, run_py

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

SCENE = """[scene]
name = "coupled-on-demand"
[kinetics]
model = "detailed"
[kinetics.stress_distribution]
source = "table"
table = "coupled"
on_outside = "build"
"""


def test_on_demand_scene_fmu_carries_its_table_and_never_builds(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    fmu = build(scene, tmp_path / "on_demand.fmu")
    names = zipfile.ZipFile(fmu).namelist()
    assert "resources/table.npz" in names
    assert not any(n.endswith(("dem_builder.py", "cache.py", "build.py", "on_demand.py", "limits.py")) for n in names)
    res = run_py(isolated_python(tmp_path), f"""
f = open_fmu({str(fmu)!r}, "f")
ok = step(f, 0.0, 1.0)
g = open_fmu({str(fmu)!r}, "g", init=False)
del LOG[:]
ex = initialize(g, {{"bead_diameter": 1.4e-3}})
msgs = [m[3] for m in LOG if m[1] >= 3]
st = step(g, 0.0, 1.0)
mods = sorted(m for m in sys.modules if m.startswith("numba") or m.endswith((".dem_builder", ".cache", ".on_demand")))
done({{"ok": ok, "ex": ex, "st": st, "msgs": msgs, "mods": mods}})
""", tmp_path)
    assert res["ok"] == 0
    assert res["ex"] == 3 and res["st"] != 0
    assert any("bead_diameter = 0.0014" in m and "allowed 0.0005 to 0.0012 m" in m and "carries no DEM" in m
               for m in res["msgs"]), res["msgs"]
    assert res["mods"] == []
