"""Calibration: fitting scene constants to measured batch data with 95 % intervals
(millfmu.calibrate, `millfmu calibrate`), its refusals, and the shipped calibrations."""

import json
import math
import re
import subprocess
import sys
from importlib import resources

import numpy as np
import pytest

import millfmu
from millfmu import calibration as cal
from millfmu.mill import MillModel
from millfmu.scene import number_key

YEAST, LIMESTONE = cal.SHIPPED
#: The default case on the detailed model (the coupled table; f_Mat fitted to the stand-in curve).
DETAILED = "limestone_detailed.toml"
ROOT_PKG = resources.files("millfmu.calibration")
TIMES = (60, 300, 900, 1800, 3600, 7200, 14400, 28800)


def synthetic(scene, times, noise, columns=cal.SIZE_COLUMNS, seed=1) -> str:
    """The model's own ``columns`` at ``times`` with multiplicative log-normal noise (a
    fraction capped at 1)."""
    rng = np.random.default_rng(seed)
    m, prev, lines = MillModel(scene), 0.0, ["t_s," + ",".join(columns)]
    for t in times:
        out = m.step(t - prev)
        prev = t
        vals = [out[k] * math.exp(noise * rng.standard_normal()) for k in columns]
        lines.append(f"{t}," + ",".join(f"{min(v, 1.0) if k == 'disrupted_fraction' else v:.9e}"
                                        for k, v in zip(columns, vals)))
    return "\n".join(lines) + "\n"


def _recover(true_scene, start_scene, keys, make, noise):
    c = cal.calibrate(start_scene, make(true_scene, noise), keys)
    for k in keys:
        lo, hi = c.constants[k].ci95
        truth = number_key(true_scene, k)
        assert lo < truth < hi, (k, truth, lo, hi, noise)
    return c


def _shrinks(true_scene, start_scene, keys, make):
    wide = _recover(true_scene, start_scene, keys, make, 0.02)
    narrow = _recover(true_scene, start_scene, keys, make, 0.01)
    for k in keys:
        w, n = (math.log(c.constants[k].ci95[1] / c.constants[k].ci95[0]) for c in (wide, narrow))
        assert n < 0.75 * w, (k, w, n)


def test_recovers_threshold_and_f_mat_with_intervals_that_shrink_with_the_noise():
    """The mineral pair on the coupled table: x W_m,min = 0.01 J m/kg and f_Mat = 30 kg/(J m)
    (where x10/x50/x90 over 8 h tell them apart: correlation 0.96 at the truth; nearer
    saturation, f_Mat = 100-150, it rises to 0.99 and the pair is refused), fitted from a
    decade off, 2 % and 1 % multiplicative noise."""
    base = cal.example_scene(DETAILED)
    keys = ["material.x_w_min_J_m_per_kg", "material.f_mat_kg_per_J_m"]
    true = cal.with_values(base, {keys[0]: 0.01, keys[1]: 30.0})
    start = cal.with_values(base, {keys[0]: 0.001, keys[1]: 3.0})
    _shrinks(true, start, keys, lambda s, e: synthetic(s, TIMES, e))


def test_recovers_energy_transfer():
    base = cal.example_scene("yeast_disruption_detailed.toml")
    true = cal.with_values(base, {"kinetics.energy_transfer": 0.3})
    start = cal.with_values(base, {"kinetics.energy_transfer": 0.03})
    _shrinks(true, start, ["kinetics.energy_transfer"], lambda s,
             e: synthetic(s, (30, 60, 120, 240, 480, 900), e, ("disrupted_fraction",), seed=2))


def test_recovers_stress_frequency_factor():
    base = millfmu.load_scene()  # the default scene: the simple model
    true = cal.with_values(base, {"mill.stress_frequency_factor": 2.0})
    start = cal.with_values(base, {"mill.stress_frequency_factor": 0.2})
    _shrinks(true, start, ["mill.stress_frequency_factor"], lambda s, e: synthetic(s, TIMES[:4], e))


def test_one_value_cannot_pin_two_constants():
    data = "t_s,x50_m\n1800,2.88e-6\n"
    with pytest.raises(cal.CalibrationError, match="1 measured value.*cannot pin 2 constants"):
        cal.calibrate(cal.example_scene(DETAILED), data, ["material.x_w_min_J_m_per_kg",
                                                          "material.f_mat_kg_per_J_m"])


def test_out_of_reach_at_the_bound_names_the_bound_and_the_constant_to_free():
    """Limestone with the earlier assumed threshold (0.2 J m/kg): the coupled energies break
    nothing, even with the whole collision energy."""
    scene = cal.with_values(cal.example_scene(DETAILED), {"material.x_w_min_J_m_per_kg": 0.2,
                                                          "kinetics.energy_transfer": 0.5})
    with resources.as_file(LIMESTONE.data_path()) as p:
        with pytest.raises(cal.CalibrationError) as e:
            cal.calibrate(scene, cal.read_data(p), ["kinetics.energy_transfer"])
    msg = str(e.value)
    assert "out of reach" in msg and "its upper bound" in msg and "energy_transfer = 1" in msg
    assert "free material.x_w_min_J_m_per_kg or material.f_mat_kg_per_J_m" in msg


def test_a_correlated_pair_is_refused_naming_what_to_fit_instead():
    with resources.as_file(LIMESTONE.data_path()) as p:
        with pytest.raises(cal.CalibrationError, match="not pinned|cannot tell the two apart|do not pin the pair"):
            cal.calibrate(millfmu.load_scene(millfmu.example_path(DETAILED),
                                             overrides={"material.x_w_min_J_m_per_kg": 1e-3}), cal.read_data(p),
                          ["material.f_mat_kg_per_J_m", "material.x_w_min_J_m_per_kg"])


@pytest.mark.parametrize("text, match", [
    ("x50_m\n2e-6\n", "needs t_s"),
    ("t_s,x50_m,Q3\n1,2e-6,0.5\n", "not a mix"),
    ("t_s,x50_m\n10,abc\n", "line 2: column x50_m = 'abc': not a number"),
    ("t_s,x50_m\n10,nan\n", "must be finite"),
    ("t_s,x50_m\n-1,2e-6\n", "t_s = -1"),
    ("t_s,x_m,Q3\n10,1e-6,1.5\n", r"Q3 = 1.5: must lie in \[0, 1\]"),
    ("t_s,x50_m\n10,2e-6,3\n", "3 cells, the header has 2"),
    ("t_s,x50_m\n0,10e-6\n", "no measured values after t_s = 0"),
])
def test_malformed_data_are_refused_by_line_and_column(text, match):
    with pytest.raises(cal.CalibrationError, match=match):
        cal.calibrate(millfmu.load_scene(), text, ["material.f_mat_kg_per_J_m"])


def test_data_outside_the_size_grid_and_wrong_quantities_are_refused():
    with pytest.raises(cal.CalibrationError, match="outside the scene's size grid"):
        cal.calibrate(millfmu.load_scene(), "t_s,x90_m\n60,5e-3\n", ["material.f_mat_kg_per_J_m"])
    with pytest.raises(cal.CalibrationError, match="needs a cell scene"):
        cal.calibrate(millfmu.load_scene(), "t_s,disrupted_fraction\n60,0.5\n", ["material.f_mat_kg_per_J_m"])
    with pytest.raises(cal.CalibrationError, match="has no effect in scene"):
        cal.calibrate(millfmu.load_scene(), "t_s,x50_m\n60,5e-6\n", ["material.burst_energy_median_J"])
    with pytest.raises(cal.CalibrationError, match="has no effect in scene"):  # the simple model has no eta_E
        cal.calibrate(millfmu.load_scene(), "t_s,x50_m\n60,5e-6\n", ["kinetics.energy_transfer"])
    with pytest.raises(cal.CalibrationError, match="needs a positive start"):  # x W_m,min = 0 there
        cal.calibrate(cal.example_scene(DETAILED), "t_s,x50_m\n60,5e-6\n", ["material.x_w_min_J_m_per_kg"])


def test_q3_data_fit_the_same_constant_as_sizes():
    """Q3 as a run writes it (psd.csv, Result.q3: the mass below the grid at the lowest edge,
    counted once) at three output times and four sizes gives back the constant."""
    true = cal.with_values(cal.example_scene(DETAILED), {"material.f_mat_kg_per_J_m": 200.0})
    res = millfmu.run(true)
    e, lines = np.log(res.edges_m), ["t_s,x_m,Q3"]
    for t in (120, 600, 1800):
        q3 = res.q3[int(np.flatnonzero(res.t_s == t)[0])]
        for x in (1e-6, 2e-6, 4e-6, 8e-6):
            lines.append(f"{t},{x},{np.interp(math.log(x), e, q3):.10f}")
    c = cal.calibrate(cal.example_scene(DETAILED), "\n".join(lines) + "\n", ["material.f_mat_kg_per_J_m"])
    assert c.value("material.f_mat_kg_per_J_m") == pytest.approx(200.0, rel=1e-5)


def test_the_default_scene_is_the_fit_to_its_shipped_standin_curve():
    """The default scene (simple model): k_c fitted to the stand-in curve with its 95 %
    interval, the record the band carries."""
    scene = millfmu.load_scene()
    assert scene.kinetics.model == "simple" and scene.scene.fitted == ["mill.stress_frequency_factor"]
    with resources.as_file(LIMESTONE.data_path()) as p:
        c = cal.calibrate(scene, cal.read_data(p), ["mill.stress_frequency_factor"])
    k = c.constants["mill.stress_frequency_factor"]
    assert k.value == pytest.approx(scene.mill.stress_frequency_factor, rel=1e-4)
    assert k.ci95 == pytest.approx((scene.scene.fitted_ci95_low[0], scene.scene.fitted_ci95_high[0]), rel=1e-4)
    assert not c.lack_of_fit  # the stand-in curve is this model's own
    assert "STAND-IN" in p.read_text() and "STAND-IN" in millfmu.default_scene_text()


def test_the_detailed_example_is_the_fit_to_the_shipped_standin_curve():
    scene = cal.example_scene(DETAILED)
    assert scene.kinetics.stress_distribution.table == "coupled" and scene.kinetics.energy_transfer == 1.0
    with resources.as_file(LIMESTONE.data_path()) as p:
        c = cal.calibrate(scene, cal.read_data(p), [LIMESTONE.detailed_key])
    f = c.constants[LIMESTONE.detailed_key]
    assert f.value == pytest.approx(scene.material.f_mat_kg_per_J_m, rel=2e-3)
    assert f.ci95[0] < f.value < f.ci95[1] < MAX_FACTOR * f.ci95[0]
    assert "STAND-IN" in p.read_text() and "STAND-IN" in millfmu.example_path(DETAILED).read_text()


MAX_FACTOR = cal.MAX_INTERVAL_FACTOR


def test_shipped_pairs_simple_k_c_is_its_one_datum_fit_and_detailed_constant_its_curve_fit():
    for pair in cal.SHIPPED:
        c = cal.check(pair)
        assert c["simple"] == pytest.approx(c["datum"], rel=0.01), pair.material
        assert c["k_c"] == pytest.approx(c["k_c_fit"], rel=5e-3), pair.material
        assert c["detailed_constant"] == pytest.approx(c["detailed_constant_fit"], rel=2e-3), pair.material
        lo, hi = c["detailed_constant_ci95"]
        assert lo < c["detailed_constant"] < hi
        assert c["energy_transfer"] == 1.0


def test_yeast_fit_counts_the_whole_collision_energy_the_consistent_choice():
    """With the normal impact energy alone the fitted burst energy is 231 times below the
    sourced 2.8e-10 J; with the whole collision energy 4.1 times below (the choice shipped)."""
    det = cal.example_scene("yeast_disruption_detailed.toml")
    assert det.kinetics.stress_distribution.component == "total"
    with resources.as_file(YEAST.data_path()) as p:
        data = cal.read_data(p)
    tn = cal.calibrate(millfmu.load_scene(det, overrides={"kinetics.stress_distribution.component": "tn"}), data,
                       ["material.burst_energy_median_J"]).value("material.burst_energy_median_J")
    total = det.material.burst_energy_median_J
    sourced = cal.example_scene("yeast_disruption.toml").material.burst_energy_median_J
    assert sourced / tn > 50.0 and 2.0 < sourced / total < 6.0


def test_cli_writes_a_calibrated_scene_and_the_record(tmp_path):
    with resources.as_file(LIMESTONE.data_path()) as p:
        r = subprocess.run([sys.executable, "-m", "millfmu.cli", "calibrate", str(millfmu.example_path(DETAILED)),
                            "--data", str(p), "--fit",
                            "material.f_mat_kg_per_J_m", "--start", "material.f_mat_kg_per_J_m=50", "--out",
                            str(tmp_path / "o")],
                           capture_output=True, text=True)
        digest = cal.read_data(p).sha256
    assert r.returncode == 0, r.stderr
    assert "calibrate: iteration 1" in r.stderr  # a progress line per evaluation batch
    doc = json.loads((tmp_path / "o" / "calibration.json").read_text())
    k = doc["constants"]["material.f_mat_kg_per_J_m"]
    assert k["ci95"][0] < k["value"] < k["ci95"][1] and doc["data"]["sha256"] == digest
    assert len(doc["residuals"]) == 21 and doc["degrees_of_freedom"] == 20
    text = (tmp_path / "o" / "calibrated.toml").read_text()
    assert digest in text and "limestone_standin_batch.csv" in text
    scene = millfmu.load_scene(str(tmp_path / "o" / "calibrated.toml"))
    assert scene.material.f_mat_kg_per_J_m == k["value"]
    assert "When to use it" in text  # the scene's own comments are kept


def test_a_calibrated_scene_calibrated_again_carries_one_head_and_no_stale_value_comment(tmp_path):
    key = "mill.stress_frequency_factor"
    with resources.as_file(LIMESTONE.data_path()) as p:
        data = cal.read_data(p)
    first = cal.calibrate(millfmu.load_scene(), data, [key])
    cal.write(first, tmp_path / "a", scene_path="default")
    a = tmp_path / "a" / "calibrated.toml"
    # a value line with a comment of its own, as a hand-kept scene has one
    a.write_text(a.read_text().replace("\nstress_frequency_factor = ", "\nstress_frequency_factor = 7.0  # k_c of May\n"
                                       "#stress_frequency_factor = ", 1))
    assert "k_c of May" in a.read_text()
    again = cal.calibrate(millfmu.load_scene(str(a)), data, [key])
    cal.write(again, tmp_path / "b", scene_path=str(a))
    text = (tmp_path / "b" / "calibrated.toml").read_text()
    assert text.count(cal.scene_file.HEAD_START) == 1 and text.startswith(cal.scene_file.HEAD_START)
    assert "these values replace it" in text
    v = again.constants[key].value
    assert f"#   {key} = {v:.6g}, 95 % interval [" in text  # no unit for a number without one
    assert "k_c of May" not in text and f"stress_frequency_factor = {v!r}  # fitted: see the head of this file" in text
    assert millfmu.load_scene(str(tmp_path / "b" / "calibrated.toml")).mill.stress_frequency_factor == v


def test_cli_refusal_exits_2_and_writes_nothing(tmp_path):
    bad = tmp_path / "d.csv"
    bad.write_text("t_s,x50_m\n1800,2.88e-6\n")
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "calibrate", "--data", str(bad), "--fit",
                        "material.f_mat_kg_per_J_m,material.x_w_min_J_m_per_kg", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "cannot pin 2 constants" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


def test_refusals_name_the_api_arguments_and_the_command_its_options(tmp_path, capsys):
    """The library's refusal names calibrate's arguments (fit, start, data, error_model) and
    scene keys; `millfmu calibrate` words the same refusal with its options."""
    from millfmu.cli import main

    key = "material.x_w_min_J_m_per_kg"  # 0 in the detailed example: no start for a fit in ln(key)
    with pytest.raises(cal.CalibrationError) as e:
        cal.calibrate(cal.example_scene(DETAILED), "t_s,x50_m\n60,5e-6\n", [key])
    assert str(e.value) == (f"fit {key}: starts from 0 J m/kg, the scene's value; a fit in ln({key}) needs a positive "
                            f"start: set one in the scene (or start={{{key!r}: VALUE}})")
    assert (e.value.argument, e.value.subject, e.value.start_key) == ("fit", key, key)
    f = tmp_path / "d.csv"
    f.write_text("t_s,x50_m\n60,5e-6\n")
    assert main(["calibrate", str(millfmu.example_path(DETAILED)), "--data", str(f), "--fit", key, "-q"]) == 2
    assert capsys.readouterr().err.strip() == (f"millfmu: error: --fit {key}: starts from 0 J m/kg, the scene's value; "
                                               f"a fit in ln({key}) needs a positive start: set one in the scene (or "
                                               f"--start {key}=VALUE)")
    with pytest.raises(cal.CalibrationError, match=r"^fit 'a,b,c': give one or two"):
        cal.calibrate(millfmu.load_scene(), "t_s,x50_m\n60,5e-6\n", "a,b,c")
    with pytest.raises(cal.CalibrationError, match=r"^data .*missing.csv: cannot be read"):
        cal.read_data(tmp_path / "missing.csv")
    assert main(["calibrate", "--data", str(tmp_path / "missing.csv"), "--fit", key, "-q"]) == 2
    assert f"millfmu: error: --data {tmp_path / 'missing.csv'}: cannot be read" in capsys.readouterr().err
    # the library names no option
    for name in ("__init__", "measured", "fitting", "intervals", "scene_file", "shipped"):
        assert not re.search(r"--(fit|data|start|errors|out)\b", (ROOT_PKG / f"{name}.py").read_text()), name


def test_set_toml_values_keeps_comments_and_adds_missing_keys():
    text = "[material]\nf_mat_kg_per_J_m = 1.0   # note\n\n[mill]\ntip_speed_m_per_s = 8.0\n"
    out = cal.set_toml_values(text, {"material.f_mat_kg_per_J_m": 2.5, "mill.stress_frequency_factor": 3.0,
                                     "kinetics.energy_transfer": 0.5})
    assert "f_mat_kg_per_J_m = 2.5   # note" in out
    s = millfmu.load_scene(out)
    assert (s.material.f_mat_kg_per_J_m, s.mill.stress_frequency_factor, s.kinetics.energy_transfer) == (2.5, 3.0, 0.5)


# ---- what a laboratory's CSV brings -------------------------------------------------------------
def test_a_byte_order_mark_is_accepted():
    from millfmu.calibration import parse_data

    d = parse_data("\ufefft_s,x50_m\n0,1e-5\n60,8e-6\n", "bom.csv")
    assert d.rows == ((60.0, "x50_m", None, 8e-6),) and d.notes == ()


def test_a_row_without_values_a_rising_size_and_a_time_no_run_reaches_are_said():
    from millfmu.calibration import CalibrationError, parse_data

    # a row with its time only: left out, with a note naming its line (not silently)
    d = parse_data("t_s,x50_m\n0,1e-5\n600,\n1800,2.88e-6\n", "blank.csv")
    assert d.rows == ((1800.0, "x50_m", None, 2.88e-6),)
    assert d.notes == ("blank.csv line 3: t_s = 600 has no measured value (an empty cell is a value not measured); "
                       "the row is left out",)
    # a size that grows later in the test (more than 10 % over its smallest before): noted once
    d = parse_data("t_s,x50_m,x90_m\n600,4e-6,9e-6\n1800,2.88e-6,8e-6\n3600,9e-6,1.2e-5\n", "grow.csv")
    assert d.notes[0] == ("grow.csv: x50_m rises from 2.88e-06 m at t_s = 1800 to 9e-06 m at t_s = 3600: breakage "
                          "makes particles only finer, so no constant of the model follows this rise (agglomeration? "
                          "samples mixed up? a value in another unit?)")
    assert len(d.notes) == 2 and d.notes[1].startswith("grow.csv: x90_m rises from 8e-06 m at t_s = 1800 to 1.2e-05")
    assert parse_data("t_s,x50_m\n600,4e-6\n1800,4.3e-6\n", "scatter.csv").notes == ()  # within 10 %
    with pytest.raises(CalibrationError, match=r"line 2: column t_s = 1e\+09: must be <= 1e\+08 s \(about 3.2 "
                       r"years, the longest run a scene may make\); t_s is in seconds"):
        parse_data("t_s,x50_m\n1e9,4.3e-6\n", "bigt.csv")
    with pytest.raises(CalibrationError, match="hdr.csv: a header and no data rows"):
        parse_data("t_s,x50_m\n# nothing yet\n", "hdr.csv")


@pytest.mark.parametrize("text, words", [
    ("t_s,x10_m,x50_m,x90_m\n60,3e-6,2e-6,9e-6\n", "line 2: x10_m = 3e-06 m is larger than x50_m = 2e-06 m"),
    ("t_s,x50_m,x90_m\n60,9e-6,8e-6\n", "x50_m = 9e-06 m is larger than x90_m = 8e-06 m"),
    ("t_s,x50_m\n60,25\n",
     "column x50_m = 25 m: larger than 0.01 m, which no bead mill grinds; the column is in metres "
                           "(if 25 is in micrometres, write 2.5e-05)"),
    ("t_s,x_m,Q3\n60,12,0.5\n", "column x_m = 12 m: larger than 0.01 m"),
])
def test_sizes_out_of_order_or_in_micrometres_are_refused_by_line(text, words):
    from millfmu.calibration import CalibrationError, parse_data

    with pytest.raises(CalibrationError) as e:
        parse_data(text, "lab.csv")
    assert words in str(e.value)


def test_a_measurement_given_twice_is_noted(tmp_path, capsys):
    from millfmu.calibration import parse_data
    from millfmu.cli import main

    text = "t_s,x50_m\n0,1e-5\n300,5e-6\n300,5.2e-6\n600,4e-6\n"
    d = parse_data(text, "lab.csv")
    assert len(d.rows) == 3 and len(d.notes) == 1 and "x50_m at t_s = 300 is given more than once" in d.notes[0]
    f = tmp_path / "lab.csv"
    f.write_text(text)
    assert main(["calibrate", "--data", str(f), "--fit", "mill.stress_frequency_factor", "-q"]) == 0
    assert "warning: " in capsys.readouterr().err


def test_q3_that_falls_with_size_is_refused_by_line():
    from millfmu.calibration import CalibrationError, parse_data

    ok = "t_s,x_m,Q3\n60,1e-6,0.2\n60,2e-6,0.5\n60,4e-6,0.5\n120,1e-6,0.4\n"
    assert len(parse_data(ok, "lab.csv").rows) == 4  # equal neighbours and another time's lower value pass
    with pytest.raises(CalibrationError) as e:  # the lines in any order: sorted by size per time
        parse_data("t_s,x_m,Q3\n60,4e-6,0.45\n60,1e-6,0.2\n60,2e-6,0.5\n", "lab.csv")
    assert ("lab.csv line 2: Q3 = 0.45 at x_m = 4e-06 m is below Q3 = 0.5 at x_m = 2e-06 m (line 4), both at "
            "t_s = 60: Q3 is a cumulative distribution and must not fall with size") in str(e.value)
    with pytest.raises(CalibrationError, match="line 3: Q3 = 0.1"):  # the feed's rows are checked too
        parse_data("t_s,x_m,Q3\n0,1e-6,0.2\n0,2e-6,0.1\n60,2e-6,0.5\n", "lab.csv")


def test_a_measured_feed_unlike_the_scenes_is_noted():
    """Rows at t_s = 0 are not fitted; where they differ from the scene's feed (which the fit
    starts from) by more than 10 % in size, the calibration says so, naming each."""
    scene = millfmu.load_scene()
    feed = MillModel(scene).outputs()
    text = synthetic(scene, (120, 600, 1800), 0.0, columns=("x50_m",))
    same = text.replace("t_s,x50_m\n", f"t_s,x50_m\n0,{feed['x50_m'] * 1.05:.6e}\n")
    c = cal.calibrate(scene, same, ["mill.stress_frequency_factor"])
    assert not any("measured feed" in n for n in c.notes)
    other = text.replace("t_s,x50_m\n", "t_s,x50_m\n0,2e-5\n")
    c = cal.calibrate(scene, other, ["mill.stress_frequency_factor"])
    (note,) = [n for n in c.notes if "measured feed" in n]
    assert f"x50_m 2e-05 against {feed['x50_m']:.4g}" in note and "set [feed] to the measured one" in note
    assert c.value("mill.stress_frequency_factor") == pytest.approx(number_key(scene, "mill.stress_frequency_factor"),
                                                                    rel=1e-6)  # the feed row is not fitted


def test_sizes_at_the_grids_edge_as_psd_csv_writes_them_are_accepted():
    """psd.csv's header writes the grid's edges with 6 significant digits; the top edge so
    written lies just above the grid, and is taken as the edge."""
    from millfmu.calibration.fitting import Predictor

    scene = millfmu.load_scene()
    hi = MillModel(scene).grid.edges_m[-1]
    top = float(f"{hi:.6g}")
    assert top > hi
    text = f"t_s,x_m,Q3\n60,{top:.6g},1\n60,5e-6,0.5\n"
    Predictor(scene, cal.parse_data(text))  # accepted
    with pytest.raises(cal.CalibrationError, match=f"x_m = {hi * 1.001:.6g} m at t_s = 60: outside the scene's "
                                                   rf"size grid \[2e-08, {hi:.6g}\] m"):
        Predictor(scene, cal.parse_data(f"t_s,x_m,Q3\n60,{hi * 1.001:.6g},1\n"))


def test_a_semicolon_separated_file_gets_the_separator_named():
    with pytest.raises(cal.CalibrationError, match="separated by ';': separate them by commas"):
        cal.parse_data("t_s;x50_m\n60;5e-6\n", "lab.csv")


def test_a_dimensionless_constant_is_printed_without_a_unit(capsys):
    from millfmu.cli import main

    assert main(["calibrate", "--data", "limestone_standin_batch.csv", "--fit", "mill.stress_frequency_factor",
                 "-q"]) == 0
    assert "  mill.stress_frequency_factor = 1.0013  (95 % interval [0.9968, 1.006]" in capsys.readouterr().out


def test_a_misspelt_shipped_data_file_is_answered_with_its_name(tmp_path, monkeypatch, capsys):
    from millfmu.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["calibrate", "--data", "limestone_standin.csv", "--fit", "mill.stress_frequency_factor"]) == 2
    assert ("--data limestone_standin.csv: cannot be read (No such file or directory; did you mean "
            "limestone_standin_batch.csv, a shipped example?)") in capsys.readouterr().err
