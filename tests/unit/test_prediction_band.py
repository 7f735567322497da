"""The prediction band: the stress-energy table's stated error carried into the outputs
(millfmu.runner.prediction_band, result.json's prediction_band, `millfmu rates`' band)."""

import json
import subprocess
import sys

import numpy as np
import pytest

import millfmu
from millfmu.mill import MillModel
from millfmu.runner import prediction_band, simulate


@pytest.fixture(scope="module")
def default_band():
    return prediction_band(millfmu.load_scene())


def test_band_brackets_the_run_and_comes_from_the_stated_error(default_band):
    scene = millfmu.load_scene()
    _, records, _ = simulate(scene, progress=False)
    b = default_band
    assert b["t_s"] == records[-1]["t_s"] == scene.run.t_end_s
    for k in ("x10_m", "x50_m", "x90_m"):
        lo, hi = b["outputs"][k]
        assert lo < records[-1][k] < hi, k
    # per zone: the lookup's bound plus the work-precision expected error, all positive
    assert b["zones"] == ["V1", "V2", "V3", "V4"]
    assert all(0.0 < e < 1.0 for e in b["collision_frequency_relative_error"] + b["se_median_relative_error"])


def test_widening_the_stated_error_widens_the_band(default_band):
    wide = prediction_band(millfmu.load_scene(), multiple=2.0)
    for k in ("x10_m", "x50_m", "x90_m"):
        (lo1, hi1), (lo2, hi2) = default_band["outputs"][k], wide["outputs"][k]
        assert lo2 < lo1 and hi2 > hi1, k


def test_zone_statistics_move_by_their_stated_error():
    scene = millfmu.load_scene()
    base, up, down = (MillModel(scene, table_error_multiple=m) for m in (0.0, 1.0, -1.0))
    op = base.operating_point(base.inputs)
    z0, zu, zd = (m.source.zones(op) for m in (base, up, down))
    err = base.source.relative_error()
    for k in range(4):
        f = err["collision_frequency"][k]
        assert zu[k].collision_rate_per_m3_s == pytest.approx(z0[k].collision_rate_per_m3_s * (1 + f), rel=1e-12)
        assert zd[k].collision_rate_per_m3_s == pytest.approx(z0[k].collision_rate_per_m3_s / (1 + f), rel=1e-12)
        np.testing.assert_allclose(zu[k].energy_J, z0[k].energy_J * (1 + err["se_median"][k]), rtol=1e-12)


def test_a_scene_without_a_table_has_no_band():
    assert prediction_band(millfmu.load_scene(overrides={"kinetics.model": "simple"})) is None


def test_result_json_carries_the_band_and_the_calibration_record(tmp_path):
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", "-q", "--no-plots", "--out", str(tmp_path)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "prediction band at t = 1800 s" in r.stdout
    res = json.loads((tmp_path / "result.json").read_text())
    lo, hi = res["prediction_band"]["outputs"]["x50_m"]
    assert lo < res["outputs"][-1]["x50_m"] < hi
    prov = res["provenance"]
    assert "STAND-IN" in prov["scene"]["scene"]["calibration"] and "f_mat_kg_per_J_m" in prov["scene"]["scene"][
        "calibration"]
    from millfmu.stress_tables.table import read_table_ref

    assert prov["table"]["ref"] == "coupled" and prov["table"]["key"] == read_table_ref("coupled").manifest["key"]


def test_the_calibrations_interval_is_a_part_of_the_band_and_the_whole_holds_both(default_band):
    """The default scene lists f_Mat's 95 % interval (scene.fitted): the calibration part is
    the two runs at its ends; the whole spans both parts and the two worst-case corners."""
    scene = millfmu.load_scene()
    assert scene.scene.fitted == ["material.f_mat_kg_per_J_m"]
    parts = default_band["parts"]
    assert set(parts) == {"table", "calibration"}
    ends = []
    for v in (scene.scene.fitted_ci95_low[0], scene.scene.fitted_ci95_high[0]):
        _, rec, _ = simulate(millfmu.load_scene(overrides={"material.f_mat_kg_per_J_m": v}), progress=False)
        ends.append(rec[-1]["x50_m"])
    assert parts["calibration"]["outputs"]["x50_m"] == [min(ends), max(ends)]
    assert ends[0] > ends[1]  # a smaller f_Mat breaks less: coarser
    assert parts["calibration"]["constants"] == [{"key": "material.f_mat_kg_per_J_m", "value": 179.5,
                                                  "ci95": [119.0, 271.0]}]
    lo, hi = default_band["outputs"]["x50_m"]
    for part in parts.values():
        plo, phi = part["outputs"]["x50_m"]
        assert lo < plo and phi < hi  # the corners reach beyond either part alone
    # the table's figures stay at the top of the band too
    assert default_band["collision_frequency_relative_error"] == parts["table"]["collision_frequency_relative_error"]


def test_a_simple_scene_with_a_fitted_constant_has_a_calibration_band():
    scene = millfmu.load_scene(overrides={"kinetics.model": "simple", "scene.fitted": ["mill.stress_frequency_factor"],
                                          "scene.fitted_ci95_low": [0.8], "scene.fitted_ci95_high": [1.25]})
    b = prediction_band(scene)
    assert set(b["parts"]) == {"calibration"} and "zones" not in b
    lo, hi = b["outputs"]["x50_m"]
    _, rec, _ = simulate(scene, progress=False)
    assert lo < rec[-1]["x50_m"] < hi and b["outputs"] == b["parts"]["calibration"]["outputs"]


def test_calibrate_writes_the_interval_the_band_then_carries(tmp_path):
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "calibrate", "--data", "limestone_standin_batch.csv",
                        "--fit",
                        "material.f_mat_kg_per_J_m", "--out", str(tmp_path / "cal"), "-q"], capture_output=True,
                       text=True,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    scene = millfmu.load_scene(tmp_path / "cal" / "calibrated.toml")
    (lo,), (hi,) = scene.scene.fitted_ci95_low, scene.scene.fitted_ci95_high
    assert scene.scene.fitted == ["material.f_mat_kg_per_J_m"] and lo < scene.material.f_mat_kg_per_J_m < hi
    assert (lo, hi) == pytest.approx((119.0, 271.0), abs=0.1)


def test_a_fitted_constant_set_outside_its_interval_is_left_out_with_a_note():
    scene = millfmu.load_scene(overrides={"scene.calibration": "mine", "scene.fitted": ["material.f_mat_kg_per_J_m"],
                                          "scene.fitted_ci95_low": [141.1], "scene.fitted_ci95_high": [228.6],
                                          "material.f_mat_kg_per_J_m": 30.0})
    b = prediction_band(scene)
    assert set(b["parts"]) == {"table"}
    assert b["notes"] == ["material.f_mat_kg_per_J_m = 30 lies outside its recorded 95 % interval [141.1, 228.6], "
                          "which belongs to another value of it: not carried into the band"]
