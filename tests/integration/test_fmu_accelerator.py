"""A detailed-model FMU of the accelerator mill (seed 002) reading the shipped accelerator
table: validates, carries the table slice, runs in fmpy without millfmu and matches the
model run directly."""

import zipfile
from pathlib import Path

import pytest

from tests.integration.fmu_support import build, run_isolated_and_compare

SCENE = Path(__file__).resolve().parents[2] / "millfmu/data/examples/accelerator_detailed.toml"
OUTS = ["x10", "x50", "x90", "sf", "holdup"]


@pytest.fixture(scope="module")
def acc_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("acc_fmu")
    return d, build(SCENE, d / "accelerator.fmu")


def test_validates_and_carries_the_accelerator_table(acc_fmu):
    from fmpy.validation import validate_fmu

    from millfmu.stress_tables.table import read_table
    from millfmu.stress_tables.table import read_table_ref

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
    res = run_isolated_and_compare(fmu, SCENE, d, OUTS)
    assert res["x50"][-1] < res["x50"][0]
