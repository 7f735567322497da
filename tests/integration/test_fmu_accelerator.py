"""A detailed-model FMU of the accelerator mill (seed 002) reading the shipped accelerator
table: validates, carries the table slice, runs in fmpy without millfmu and matches the
model run directly."""

import zipfile
from pathlib import Path

import numpy as np
import pytest

from tests.integration.fmu_support import build, isolated_python, reference, run_py

SCENE = Path(__file__).resolve().parents[2] / "millfmu/data/examples/accelerator_detailed.toml"
OUTS = ["x10", "x50", "x90", "sf", "holdup"]


@pytest.fixture(scope="module")
def acc_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("acc_fmu")
    return d, build(SCENE, d / "accelerator.fmu")


def test_validates_and_carries_the_accelerator_table(acc_fmu):
    from fmpy.validation import validate_fmu

    from millfmu.dem.tables import read_table
    from millfmu.dem.tables.table import read_table_ref

    _, fmu = acc_fmu
    assert validate_fmu(str(fmu)) == []
    with zipfile.ZipFile(fmu) as z:
        z.extract("resources/table.npz", fmu.parent)
        z.extract("resources/table.json", fmu.parent)
    t = read_table(npz=fmu.parent / "resources/table.npz",
                   manifest_path=fmu.parent / "resources/table.json")
    assert t.zone_names == ("SEV_1", "SEV_2", "SEV_3", "SEV_4")
    assert read_table_ref("accelerator").zone_names == t.zone_names


def test_runs_in_fmpy_and_matches_the_model(acc_fmu):
    d, fmu = acc_fmu
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
