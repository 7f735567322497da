"""The prediction band: the stress-energy table's stated error carried into the outputs
(millfmu.runner.prediction_band, result.json's prediction_band, `millfmu rates`' band), on
the detailed example (limestone_detailed.toml: the table and f_Mat's interval), and the
calibration's interval on the default scene (simple model: k_c's interval alone)."""

import json
import subprocess
import sys

import numpy as np
import pytest

import millfmu
from millfmu.mill import MillModel
from millfmu.runner import prediction_band, simulate


DETAILED = millfmu.example_path("limestone_detailed.toml")


def detailed_scene(overrides=None):
    return millfmu.load_scene(DETAILED, overrides=overrides)


@pytest.fixture(scope="module")
def detailed_band():
    return prediction_band(detailed_scene())


def test_band_brackets_the_run_and_comes_from_the_stated_error(detailed_band):
    scene = detailed_scene()
    _, records, _ = simulate(scene, progress=False)
    b = detailed_band
    assert b["t_s"] == records[-1]["t_s"] == scene.run.t_end_s
    for k in ("x10_m", "x50_m", "x90_m"):
        lo, hi = b["outputs"][k]
        assert lo < records[-1][k] < hi, k
    # per zone: the lookup's bound plus the work-precision expected error, all positive
    assert b["zones"] == ["V1", "V2", "V3", "V4"]
    assert all(0.0 < e < 1.0 for e in b["collision_frequency_relative_error"] + b["se_median_relative_error"])


def test_widening_the_stated_error_widens_the_band(detailed_band):
    wide = prediction_band(detailed_scene(), multiple=2.0)
    for k in ("x10_m", "x50_m", "x90_m"):
        (lo1, hi1), (lo2, hi2) = detailed_band["outputs"][k], wide["outputs"][k]
        assert lo2 < lo1 and hi2 > hi1, k


def test_zone_statistics_move_by_their_stated_error():
    scene = detailed_scene()
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


def test_a_run_without_a_band_says_so(tmp_path, capsys):
    """A scene of its own material (no fitted constant of its own, no table): the run says
    that no band is carried, and why, instead of printing nothing."""
    from millfmu.cli import main

    f = tmp_path / "s.toml"
    f.write_text("[material]\nf_mat_kg_per_J_m = 0.01\nx_w_min_J_m_per_kg = 1.0\n")
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 0
    assert "prediction band: none (the scene records no fitted constant" in capsys.readouterr().out
    assert json.loads((tmp_path / "o" / "result.json").read_text())["prediction_band"] is None


def test_result_json_carries_the_band_and_the_calibration_record(tmp_path):
    """The default scene (simple model): the band is its k_c interval's part alone."""
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", "-q", "--no-plots", "--out", str(tmp_path)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "prediction band at t = 1800 s" in r.stdout and "(calibration)" in r.stdout
    res = json.loads((tmp_path / "result.json").read_text())
    lo, hi = res["prediction_band"]["outputs"]["x50_m"]
    assert lo < res["outputs"][-1]["x50_m"] < hi
    assert set(res["prediction_band"]["parts"]) == {"calibration"}
    prov = res["provenance"]
    record = prov["scene"]["scene"]["calibration"]
    assert "STAND-IN" in record and "stress_frequency_factor" in record
    assert "table" not in prov  # the simple model reads no stress-energy table


def test_the_detailed_examples_result_json_names_its_table(tmp_path):
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", str(DETAILED), "-q", "--no-plots", "--out",
                        str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    prov = json.loads((tmp_path / "result.json").read_text())["provenance"]
    assert "STAND-IN" in prov["scene"]["scene"]["calibration"] and "f_mat_kg_per_J_m" in prov["scene"]["scene"][
        "calibration"]
    from millfmu.stress_tables.table import read_table_ref

    assert prov["table"]["ref"] == "coupled" and prov["table"]["key"] == read_table_ref("coupled").manifest["key"]


def test_the_calibrations_interval_is_a_part_of_the_band_and_the_whole_holds_both(detailed_band):
    """The detailed example lists f_Mat's 95 % interval (scene.fitted): the calibration part
    is the two runs at its ends; the whole spans both parts and the two worst-case corners."""
    scene = detailed_scene()
    assert scene.scene.fitted == ["material.f_mat_kg_per_J_m"]
    parts = detailed_band["parts"]
    assert set(parts) == {"table", "calibration"}
    ends = []
    for v in (scene.scene.fitted_ci95_low[0], scene.scene.fitted_ci95_high[0]):
        _, rec, _ = simulate(detailed_scene({"material.f_mat_kg_per_J_m": v}), progress=False)
        ends.append(rec[-1]["x50_m"])
    assert parts["calibration"]["outputs"]["x50_m"] == [min(ends), max(ends)]
    assert ends[0] > ends[1]  # a smaller f_Mat breaks less: coarser
    assert parts["calibration"]["constants"] == [{"key": "material.f_mat_kg_per_J_m", "value": 179.5,
                                                  "ci95": [119.0, 271.0]}]
    lo, hi = detailed_band["outputs"]["x50_m"]
    for part in parts.values():
        plo, phi = part["outputs"]["x50_m"]
        assert lo < plo and phi < hi  # the corners reach beyond either part alone
    # the table's figures stay at the top of the band too
    assert detailed_band["collision_frequency_relative_error"] == parts["table"]["collision_frequency_relative_error"]


def test_the_default_scenes_band_is_its_k_c_interval():
    """The default scene (simple model, k_c fitted to the stand-in curve): one part, the two
    runs at the ends of k_c's 95 % interval, narrow because the stand-in curve is the model's
    own."""
    scene = millfmu.load_scene()
    assert scene.kinetics.model == "simple" and scene.scene.fitted == ["mill.stress_frequency_factor"]
    b = prediction_band(scene)
    assert set(b["parts"]) == {"calibration"} and "zones" not in b
    ends = []
    for v in (scene.scene.fitted_ci95_low[0], scene.scene.fitted_ci95_high[0]):
        _, rec, _ = simulate(millfmu.load_scene(overrides={"mill.stress_frequency_factor": v}), progress=False)
        ends.append(rec[-1]["x50_m"])
    assert ends[0] > ends[1]  # fewer stresses: coarser
    assert b["outputs"]["x50_m"] == [min(ends), max(ends)]
    _, rec, _ = simulate(scene, progress=False)
    lo, hi = b["outputs"]["x50_m"]
    assert lo < rec[-1]["x50_m"] < hi and hi / lo < 1.01


def test_a_simple_scene_with_a_fitted_constant_has_a_calibration_band():
    scene = millfmu.load_scene(overrides={"kinetics.model": "simple", "scene.fitted": ["mill.stress_frequency_factor"],
                                          "scene.fitted_ci95_low": [0.8], "scene.fitted_ci95_high": [1.25]})
    b = prediction_band(scene)
    assert set(b["parts"]) == {"calibration"} and "zones" not in b
    lo, hi = b["outputs"]["x50_m"]
    _, rec, _ = simulate(scene, progress=False)
    assert lo < rec[-1]["x50_m"] < hi and b["outputs"] == b["parts"]["calibration"]["outputs"]


def test_calibrate_writes_the_interval_the_band_then_carries(tmp_path):
    """The README's command: the default scene's k_c to the stand-in curve, its interval
    the scene's record."""
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "calibrate", "--data", "limestone_standin_batch.csv",
                        "--fit", "mill.stress_frequency_factor", "--out", str(tmp_path / "cal"), "-q"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    scene = millfmu.load_scene(tmp_path / "cal" / "calibrated.toml")
    (lo,), (hi,) = scene.scene.fitted_ci95_low, scene.scene.fitted_ci95_high
    assert scene.scene.fitted == ["mill.stress_frequency_factor"] and lo < scene.mill.stress_frequency_factor < hi
    default = millfmu.load_scene()
    assert scene.mill.stress_frequency_factor == pytest.approx(default.mill.stress_frequency_factor, abs=5e-5)
    assert (lo, hi) == pytest.approx((default.scene.fitted_ci95_low[0], default.scene.fitted_ci95_high[0]), abs=5e-5)
    assert prediction_band(scene)["parts"]["calibration"]["constants"][0]["ci95"] == [lo, hi]


def test_a_fitted_constant_set_outside_its_interval_is_left_out_with_a_note():
    scene = detailed_scene({"scene.calibration": "mine", "scene.fitted": ["material.f_mat_kg_per_J_m"],
                            "scene.fitted_ci95_low": [141.1], "scene.fitted_ci95_high": [228.6],
                            "material.f_mat_kg_per_J_m": 30.0})
    b = prediction_band(scene)
    assert set(b["parts"]) == {"table"}
    assert b["notes"] == ["material.f_mat_kg_per_J_m = 30 lies outside its recorded 95 % interval [141.1, 228.6], "
                          "which belongs to another value of it: not carried into the band"]


def test_a_zone_that_collides_without_a_stated_error_is_named_in_the_bands_notes(monkeypatch, detailed_band):
    """Where no check of the table measured an axis at the point, a colliding zone has no
    stated error and the table's part of the band leaves it unmoved: the notes say so (and
    result.json lists its error as null); the detailed example states every zone."""
    from tests._stated_error import density_unmeasured

    assert "notes" not in detailed_band
    density_unmeasured(monkeypatch, "se_median")
    b = prediction_band(detailed_scene({"beads": {"density_kg_per_m3": 6040.0}}))
    assert b["se_median_relative_error"] == [None, None, None, None]
    assert any(n.startswith("zones V1, V2, V3, V4 collide but have no stated error at the last operating point")
               for n in b["notes"])
