"""A detailed-model FMU reading a DEM table (the embedded default scene's) carries the table
slice its scene needs and runs without millfmu."""

import zipfile

import numpy as np
import pytest

from tests.integration.fmu_support import build, isolated_python, reference, run_py

SCENE = None  # the embedded default scene: detailed model on the shipped table
OUTS = ["x10", "x50", "x90", "sf", "holdup"]


@pytest.fixture(scope="module")
def table_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("table_fmu")
    return d, build(SCENE, d / "detailed_table.fmu")


def test_carries_table_slice_and_reader_only(table_fmu):
    _, fmu = table_fmu
    names = zipfile.ZipFile(fmu).namelist()
    assert "resources/table.npz" in names and "resources/table.json" in names
    dem = sorted(n.split("/dem/")[1] for n in names if "/dem/" in n)
    # The table's reading and lookup modules only: no builder, cache or DEM kernels, no numba.
    assert dem == ["__init__.py", "tables/__init__.py", "tables/files.py", "tables/spec.py", "tables/stress_source.py", "tables/table.py"]
    from millfmu.dem.tables import read_table

    with zipfile.ZipFile(fmu) as z:
        z.extract("resources/table.npz", fmu.parent)
        z.extract("resources/table.json", fmu.parent)
    read_table(npz=fmu.parent / "resources/table.npz", manifest_path=fmu.parent / "resources/table.json")  # verifies checksums


def test_runs_without_millfmu_and_matches_model(table_fmu):
    d, fmu = table_fmu
    py = isolated_python(d)
    res = run_py(py, f"""
import importlib.util
assert importlib.util.find_spec("millfmu") is None
from fmpy import simulate_fmu
r = simulate_fmu({str(fmu)!r}, stop_time=20.0, step_size=2.0, output={OUTS!r})
assert not any(m.startswith("numba") for m in sys.modules)
done({{"time": r["time"].tolist(), **{{k: r[k].tolist() for k in {OUTS!r}}}}})
""", d)
    steps = np.diff(res["time"]).tolist()
    ref = reference(SCENE, steps)
    for k in OUTS:
        np.testing.assert_allclose(res[k][1:], ref[k], rtol=1e-12, atol=0, err_msg=k)
    assert res["x50"][-1] < res["x50"][0]
