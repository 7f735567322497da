"""A detailed-model FMU reading a DEM table (the detailed example limestone_detailed.toml:
the default case on the coupled table) carries the table slice its scene needs and runs
without millfmu."""

import zipfile

import pytest

from tests.integration.fmu_support import TABLE_SCENE, build, run_isolated_and_compare

SCENE = TABLE_SCENE  # the detailed example: detailed model on the shipped coupled table
OUTS = ["x10", "x50", "x90", "sf", "holdup"]


@pytest.fixture(scope="module")
def table_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("table_fmu")
    return d, build(SCENE, d / "detailed_table.fmu")


def test_carries_table_slice_and_reader_only(table_fmu):
    _, fmu = table_fmu
    names = zipfile.ZipFile(fmu).namelist()
    assert "resources/table.npz" in names and "resources/table.json" in names
    code = [n.split("/", 2)[2] for n in names if n.startswith("resources/_millfmu_")]
    # The table's reader only (millfmu.stress_tables), nothing under dem/: no builder, cache or
    # DEM kernels, no numba.
    assert not [n for n in code if n.startswith("dem/")]
    assert sorted(n for n in code if n.startswith("stress_tables/")) == [
        "stress_tables/__init__.py", "stress_tables/files.py", "stress_tables/rules.py", "stress_tables/spec.py",
        "stress_tables/stress_source.py", "stress_tables/table.py"]
    from millfmu.stress_tables.table import read_table

    with zipfile.ZipFile(fmu) as z:
        z.extract("resources/table.npz", fmu.parent)
        z.extract("resources/table.json", fmu.parent)
    t = read_table(npz=fmu.parent / "resources/table.npz",
                   manifest_path=fmu.parent / "resources/table.json")  # verifies checksums
    # the example's table is the coupled DEM-CFD one: the FMU carries a slice of it
    from millfmu.stress_tables.table import read_table_ref

    coupled = read_table_ref("coupled").manifest["key"]
    assert t.manifest.get("slice_of", t.manifest["key"]) == coupled  # the whole table where the scene fixes no axis
    assert t.manifest["scene"]["fluid"]["mode"] == "coupled"


def test_description_names_the_table_and_the_stand_in_calibration(table_fmu):
    _, fmu = table_fmu
    from fmpy import read_model_description

    text = read_model_description(str(fmu)).description
    from millfmu.stress_tables.table import read_table_ref

    key = read_table_ref("coupled").manifest["key"][:12]
    assert f"DEM table {key} (disc_slice, fluid coupled" in text and "STAND-IN" in text and "f_mat_kg_per_J_m" in text
    # the band of the scene's own run, computed at the build: table, calibration and whole
    import millfmu
    from millfmu.runner import prediction_band

    b = prediction_band(millfmu.load_scene(SCENE))
    lo, hi = b["outputs"]["x50_m"]
    assert f"prediction band of the scene's own run at t = 1800 s: x50_m in [{lo:.4g}, {hi:.4g}] m (table [" in text
    assert "calibration [" in text


def test_runs_without_millfmu_and_matches_model(table_fmu):
    d, fmu = table_fmu
    res = run_isolated_and_compare(fmu, SCENE, d, OUTS)
    assert res["x50"][-1] < res["x50"][0]


def test_tip_speeds_beyond_the_table_are_a_warning_once(table_fmu):
    """similar_axes = tip_speed_m_per_s: steps at 15 and 16 m/s run, and the log says it once."""
    from tests.integration.fmu_support import isolated_python, run_py

    d, fmu = table_fmu
    res = run_py(isolated_python(d), f"""
f = open_fmu({str(fmu)!r}, "w")
st = [step(f, float(k), 1.0, {{"tip_speed": v}}) for k, v in enumerate((12.0, 15.0, 16.0, 10.0))]
done({{"st": st, "warn": [e[3] for e in LOG if e[0] == "w" and e[1] == 1]}})
""", d)
    assert res["st"] == [0, 0, 0, 0]
    hits = [w for w in res["warn"] if "tip_speed_m_per_s" in w and "lies outside the table's range 6 to 14" in w]
    assert len(hits) == 1 and "similarity assumed" in hits[0], res["warn"]
