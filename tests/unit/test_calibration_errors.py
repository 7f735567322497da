"""Calibration's error models (issue 58): intervals that allow an error shared by one
sample's x10/x50/x90 (cluster-robust over measurement times), the lack-of-fit warning and
the refusal of a constant on a plateau. Synthetic data from the model itself (the detailed
example limestone_detailed.toml, f_Mat known) at the shipped stand-in curve's times."""

import json
import math
from importlib import resources

import numpy as np
import pytest

import millfmu
from millfmu import calibration as cal
from millfmu.mill import MillModel

KEY = "material.f_mat_kg_per_J_m"
TIMES = (60, 120, 300, 600, 900, 1200, 1800)
LIMESTONE = cal.SHIPPED[1]
#: The default case on the detailed model, whose material constant f_Mat these fits recover.
DETAILED = "limestone_detailed.toml"


def model_sizes(scene) -> np.ndarray:
    m, prev, out = MillModel(scene), 0.0, []
    for t in TIMES:
        o = m.step(t - prev)
        prev = t
        out.append([o[c] for c in cal.SIZE_COLUMNS])
    return np.array(out)


def csv_text(v) -> str:
    return "t_s,x10_m,x50_m,x90_m\n" + "".join(f"{t},{a:.9e},{b:.9e},{c:.9e}\n" for t, (a, b, c) in zip(TIMES, v))


def noisy(base, rng, shared, independent) -> str:
    """``base`` times exp(an error shared by each time's three sizes + independent ones)."""
    e = shared * rng.standard_normal((len(TIMES), 1)) + independent * rng.standard_normal(base.shape)
    return csv_text(base * np.exp(e))


@pytest.fixture(scope="module")
def truth():
    scene = cal.example_scene(DETAILED)
    return scene, model_sizes(scene)


def _width(c):
    lo, hi = c.constants[KEY].ci95
    return math.log(hi / lo)


def _width_ratios(scene, base, shared, independent, draws=6):
    out = []
    for seed in range(draws):
        text = noisy(base, np.random.default_rng(seed), shared, independent)
        ind = cal.calibrate(scene, text, [KEY], error_model="independent")
        per = cal.calibrate(scene, text, [KEY], error_model="per_sample")
        assert not per.lack_of_fit and not ind.lack_of_fit, (seed, per.lack_of_fit)  # the model is right: no warning
        out.append(_width(per) / _width(ind))
    return math.exp(np.mean(np.log(out)))


def test_per_sample_intervals_widen_with_shared_errors_and_not_without(truth):
    """Shared 5 % + independent 2 %: the per-sample interval about twice the independent one
    (the held-out study's standard error 1.7 times too small); independent 3 % only: about
    equal (geometric mean over 6 draws; no lack-of-fit warning in any)."""
    scene, base = truth
    assert _width_ratios(scene, base, 0.05, 0.02) > 1.4
    assert 0.7 < _width_ratios(scene, base, 0.0, 0.03) < 1.3


def test_the_error_model_is_the_default_chosen_and_stated(truth):
    scene, base = truth
    text = noisy(base, np.random.default_rng(7), 0.05, 0.02)
    c = cal.calibrate(scene, text, [KEY])
    assert c.error_model == "per_sample" and c.interval_dof == len(TIMES) - 1
    d = c.to_dict()
    assert d["error_model"] == "per_sample" and "cluster-robust" in d["method"] and d[
        "interval_degrees_of_freedom"] == 6
    assert "errors: per-sample" in c.summary()
    json.dumps(d)
    one = "t_s,x50_m\n" + "".join(f"{t},{v:.9e}\n" for t, v in zip(TIMES, base[:, 1]))
    c1 = cal.calibrate(scene, one, [KEY])  # one quantity per time: independent errors
    assert c1.error_model == "independent" and c1.interval_dof == len(TIMES) - 1
    c2 = cal.calibrate(scene, one, [KEY], error_model="per-sample")
    assert c2.error_model == "independent" and any("one quantity" in n for n in c2.notes)
    with pytest.raises(cal.CalibrationError, match="error_model 'shared': allowed 'independent', 'per_sample'"):
        cal.calibrate(scene, text, [KEY], error_model="shared")


def test_cli_errors_option(tmp_path, capsys):
    from millfmu.cli import main

    with resources.as_file(LIMESTONE.data_path()) as p:
        assert main(["calibrate", str(millfmu.example_path(DETAILED)), "--data", str(p), "--fit", KEY, "-q",
                     "--errors", "independent"]) == 0
    out = capsys.readouterr().out
    assert "errors: independent" in out and "Student's t with 20 degrees of freedom" in out


def test_lack_of_fit_is_named_on_the_shipped_limestone_fit():
    """The detailed example fitted to the stand-in curve the simple model made:
    residuals fall with time (+0.16 at 60 s, -0.16 at 1800 s) and x90's lie above x10's at
    every time."""
    with resources.as_file(LIMESTONE.data_path()) as p:
        c = cal.calibrate(cal.example_scene(DETAILED), cal.read_data(p), [KEY])
    text = " ".join(c.lack_of_fit)
    assert len(c.lack_of_fit) == 2, c.lack_of_fit
    assert "residuals fall with time" in text and "x10 +++----" in text
    assert "size columns lie off each other" in text and "wider than the data's" in text
    assert "warning: lack of fit: residuals fall with time" in c.summary()
    assert c.to_dict()["lack_of_fit"] == c.lack_of_fit


def test_a_constant_on_a_plateau_is_refused_by_name():
    """The simple model with f_Mat = 1000 kg/(J m): every stress breaks, the sizes no longer
    depend on f_Mat (above about 0.1). Fitted from 0.03 with small errors, the optimum lands
    on the shoulder, where the local slope gave a finite interval that excludes the truth;
    the objective at the search range's upper end is within the noise of it: refused."""
    simple = cal.with_model(cal.example_scene(DETAILED), "simple")  # x W_m,min = 0, k_c = 1
    plateau = model_sizes(cal.with_values(simple, {KEY: 1e3}))
    shared = np.array([0.04, -0.02, 0.01, -0.01, 0.02, -0.03, 0.0])[:, None]
    ind = 0.01 * np.array([[1, -1, 0], [0, 1, -1], [-1, 0, 1], [1, 0, -1], [0, -1, 1], [-1, 1, 0], [1, -1, 0]])
    text = csv_text(plateau * np.exp(shared + ind))
    start = cal.with_values(simple, {KEY: 0.03})
    with pytest.raises(cal.CalibrationError, match=rf"^fit {KEY}: lies on a plateau.*bound it from below only"):
        cal.calibrate(start, text, [KEY], error_model="independent")
    with pytest.raises(cal.CalibrationError, match=rf"^fit {KEY}: (lies on a plateau|not pinned)"):
        cal.calibrate(start, text, [KEY])


@pytest.mark.slow
def test_coverage_with_shared_errors(truth):
    """Coverage of the 95 % interval over 100 draws of shared 5 % + independent 2 % errors:
    per-sample (cluster-robust, CR2) at least 90 %, independent well below (the issue's 70 %).
    Measured with these draws: per-sample 96/100, independent 76/100; over 700 draws (seeds 58
    and 4058) 675 (96.4 %) against 543 (77.6 %), CR1 674; with independent 3 % errors only
    (200 draws) per-sample 188 (94 %), independent 192 (96 %). About 20 s."""
    scene, base = truth
    f_true = scene.material.f_mat_kg_per_J_m
    rng = np.random.default_rng(58)
    hits = {"independent": 0, "per_sample": 0}
    draws = 100
    for _ in range(draws):
        text = noisy(base, rng, 0.05, 0.02)
        for em in hits:
            lo, hi = cal.calibrate(scene, text, [KEY], error_model=em).constants[KEY].ci95
            hits[em] += lo < f_true < hi
    assert hits["per_sample"] >= 0.90 * draws, hits
    assert hits["independent"] <= 0.85 * draws, hits
