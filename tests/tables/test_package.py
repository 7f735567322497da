"""The tables package: the names of the former single module resolve from millfmu.dem.tables,
and the modules an FMU carries (fmu_build.build.ALLOWED) load neither numba nor the DEM nor
the table builder."""

from __future__ import annotations

import importlib
import json
import pickle
import subprocess
import sys

import pytest

from fmu_build.build import ALLOWED, FORBIDDEN
from millfmu.dem import tables as T

READERS = sorted(m for m in ALLOWED if m.startswith("millfmu.dem.tables"))


def test_fmu_carries_only_the_reading_modules():
    assert READERS == ["millfmu.dem.tables", "millfmu.dem.tables.files", "millfmu.dem.tables.spec",
                       "millfmu.dem.tables.stress_source", "millfmu.dem.tables.table"]


@pytest.mark.parametrize("module", READERS)
def test_reading_module_imports_no_numba_dem_or_builder(module):
    """Each module an FMU may carry, imported alone in a fresh interpreter: every millfmu.dem
    module it loads is one of ALLOWED, and nothing else of FORBIDDEN (numba, matplotlib, tqdm)
    is loaded, as fmu_build checks for a scene's model."""
    code = ("import importlib, json, sys; importlib.import_module(sys.argv[1]);"
            "print(json.dumps(sorted(sys.modules)))")
    r = subprocess.run([sys.executable, "-c", code, module], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    loaded = json.loads(r.stdout)
    assert module in loaded
    assert not any(m.split(".")[0] == "numba" for m in loaded)
    assert not {"millfmu.dem.engine.sim", "millfmu.dem.engine.kernels", "millfmu.dem.run"} & set(loaded)
    bad = [m for m in loaded if m not in ALLOWED and any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert not bad, bad


def test_old_names_resolve_to_their_modules():
    """Every name of the package's namespace is the object its module defines."""
    for name, mod in T._EXPORTS.items():
        assert getattr(T, name) is getattr(importlib.import_module(f"millfmu.dem.tables.{mod}"), name), name
    assert T._builder_id is T.builder_id_of
    from millfmu.dem.tables import DemBuilder, TableStressSource

    assert DemBuilder.__module__ == "millfmu.dem.tables.dem_builder"
    assert TableStressSource.__module__ == "millfmu.dem.tables.stress_source"

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
