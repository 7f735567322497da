"""The tables' two packages: the reader (millfmu.stress_tables, what an FMU carries) loads
neither numba nor anything of millfmu.dem nor of the table builder, and the names of the
former single module still resolve from millfmu.dem.tables, the builder's package."""

from __future__ import annotations

import importlib
import json
import pickle
import subprocess
import sys
from importlib import resources

import pytest

from fmu_build.build import FORBIDDEN
from millfmu.dem import tables as T

READERS = sorted(["millfmu.stress_tables"] + [
    f"millfmu.stress_tables.{p.name[:-3]}" for p in resources.files("millfmu.stress_tables").iterdir()
    if p.name.endswith(".py") and p.name != "__init__.py"])


def test_reader_package_holds_the_reading_modules():
    assert READERS == ["millfmu.stress_tables", "millfmu.stress_tables.files", "millfmu.stress_tables.rules",
                       "millfmu.stress_tables.spec", "millfmu.stress_tables.stress_source",
                       "millfmu.stress_tables.table"]
    # The builder's side keeps none of them.
    builder = sorted(p.name for p in resources.files("millfmu.dem.tables").iterdir() if p.name.endswith(".py"))
    assert builder == ["__init__.py", "build.py", "cache.py", "cells.py", "cli.py", "dem_builder.py", "equivalence.py",
                       "on_demand.py", "point_folders.py", "point_work.py", "state_files.py",
                       "warm_start.py"]


@pytest.mark.parametrize("module", READERS)
def test_reading_module_imports_no_numba_dem_or_builder(module):
    """Each module of the reader, imported alone in a fresh interpreter, loads nothing of
    FORBIDDEN (numba, millfmu.dem, matplotlib, tqdm), as fmu_build checks for a scene's model."""
    code = ("import importlib, json, sys; importlib.import_module(sys.argv[1]);"
            "print(json.dumps(sorted(sys.modules)))")
    r = subprocess.run([sys.executable, "-c", code, module], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    loaded = json.loads(r.stdout)
    assert module in loaded
    bad = [m for m in loaded if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert not bad, bad
    assert "millfmu.dem" in FORBIDDEN and "numba" in FORBIDDEN


def test_old_names_resolve_to_their_modules():
    """Every name of the builder package's namespace is the object its module defines, the
    reader's names those of millfmu.stress_tables."""
    for name, mod in T._EXPORTS.items():
        pkg = "millfmu.stress_tables" if mod in T._READER else "millfmu.dem.tables"
        assert getattr(T, name) is getattr(importlib.import_module(f"{pkg}.{mod}"), name), name
    assert T._builder_id is T.builder_id_of
    from millfmu.dem.tables import DemBuilder, TableStressSource

    assert DemBuilder.__module__ == "millfmu.dem.tables.dem_builder"
    assert TableStressSource.__module__ == "millfmu.stress_tables.stress_source"

    with pytest.raises(AttributeError, match="no_such_name"):
        T.no_such_name


def test_dem_builder_pickles_by_its_new_and_its_old_path():
    """Process pools and Dask pickle the builder; a pickle naming the former module still loads,
    and the builder's id (part of every DEM table's key) is the former one."""
    b = T.DemBuilder(threads=1)
    assert pickle.loads(pickle.dumps(b)) == b
    old = pickle.dumps(b, protocol=0).replace(b"millfmu.dem.tables.dem_builder\n", b"millfmu.dem.tables\n")
    assert b"millfmu.dem.tables\nDemBuilder" in old
    assert pickle.loads(old) == b
    assert T.builder_id_of(b) == T.DemBuilder.builder_id == "millfmu.dem.tables.DemBuilder"


def test_stepping_a_table_scene_loads_nothing_of_the_dem():
    """The detailed example (the default case on the shipped coupled DEM-CFD table), made and
    stepped in a fresh interpreter, loads the reader and nothing under millfmu.dem (neither
    the DEM nor the table builder), nor numba."""
    code = (
        "import json, sys\n"
        "from millfmu.mill import MillModel\n"
        "from millfmu.scene import example_path, load_scene\n"
        "s = load_scene(example_path('limestone_detailed.toml'))\n"
        "m = MillModel(s)\n"
        "assert m.kinetics_model == 'detailed' and s.kinetics.stress_distribution.table == 'coupled', s\n"
        "assert type(m.source).__name__ == 'TableStressSource'\n"
        "for _ in range(5):\n"
        "    m.step(s.run.dt_s)\n"
        "assert m.source.last_lookup is not None\n"  # the table was looked up, not just read
        "print(json.dumps(sorted(sys.modules)))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    loaded = json.loads(r.stdout.strip().splitlines()[-1])
    assert "millfmu.stress_tables.stress_source" in loaded
    bad = [m for m in loaded if m == "millfmu.dem" or m.startswith("millfmu.dem.") or m.split(".")[0] == "numba"]
    assert not bad, bad
