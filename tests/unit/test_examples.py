"""Shipped example scenes load, run and keep their mass balance; the model never imports numba."""

import subprocess
import sys
from importlib import resources

import numpy as np
import pytest

from millfmu.runner import simulate
from millfmu.scene import load_scene

EXAMPLES = sorted(p.name for p in resources.files("millfmu.data").joinpath("examples").iterdir()
                  if p.name.endswith(".toml"))


def test_examples_present():
    assert {"yeast_disruption.toml", "yeast_disruption_detailed.toml", "limestone_continuous.toml",
            "limestone_detailed.toml", "limestone_rampup.toml", "austin_generic.toml"} <= set(EXAMPLES)
    assert "limestone_simple.toml" not in EXAMPLES  # the default scene is that case


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_runs_and_balances(name):
    scene = load_scene(resources.files("millfmu.data").joinpath("examples", name))
    model, recs, psds = simulate(scene, progress=False)
    last = recs[-1]
    assert last["t_s"] == pytest.approx(scene.run.t_end_s)
    assert abs(last["total_mass_kg"] - (model.m0_kg + model.fed_kg)) <= 1e-12 * (model.m0_kg + model.fed_kg)
    assert last["x50_m"] < recs[0]["x50_m"] or "disrupted_fraction" in last
    assert np.all(np.diff(psds[-1]) >= 0.0) and psds[-1][-1] == pytest.approx(1.0)
    if "disrupted_fraction" in last:
        assert 0.5 < last["disrupted_fraction"] < 1.0


def test_rampup_follows_profile():
    scene = load_scene(resources.files("millfmu.data").joinpath("examples", "limestone_rampup.toml"))
    _, recs, _ = simulate(scene, progress=False)
    v = {r["t_s"]: r["tip_speed_m_per_s"] for r in recs}
    assert v[0.0] == 0.0 and v[20.0] == pytest.approx(20.0 / 6.0) and v[600.0] == 10.0
    # Energy: the power rises with the tip speed over the ramp.
    assert recs[1]["power_W"] < recs[2]["power_W"] < recs[3]["power_W"] == recs[-1]["power_W"]


def test_model_and_cli_never_import_numba():
    """The default scene (simple model) does not even load the table reader, only
    MillModel's table rules; the detailed example reads the DEM table (the table reader,
    millfmu.stress_tables: no numba, nothing under millfmu.dem). (The command line's parser
    loads ``millfmu tables``'s module, millfmu.dem.tables.cli, and with it the tables
    package, whose names load their modules only when used.)"""
    detailed = resources.files("millfmu.data").joinpath("examples", "limestone_detailed.toml")
    code = (
        "import sys, millfmu.cli, millfmu.mill, millfmu.runner;"
        "millfmu.cli.build_parser();"
        "from millfmu.mill import MillModel; from millfmu.scene import load_scene;"
        "MillModel(load_scene()).step(1.0);"
        "dem = ('millfmu.dem.engine.kernels', 'millfmu.dem.engine.sim', 'millfmu.dem.run');"
        "cli = 'millfmu.dem.tables.cli';"
        "bad = [m for m in sys.modules if m.split('.')[0] == 'numba' or m in dem"
        " or m.startswith('millfmu.dem.tables.') and m != cli];"
        "assert not bad, bad;"
        "tabs = sorted(m for m in sys.modules if m.startswith('millfmu.stress_tables.'));"
        "assert tabs == ['millfmu.stress_tables.rules'], tabs;"
        f"MillModel(load_scene({str(detailed)!r})).step(1.0);"
        "bad = [m for m in sys.modules if m.split('.')[0] == 'numba' or m in dem"
        " or m.startswith('millfmu.dem.tables.') and m != cli];"
        "assert not bad, bad;"
        "tabs = sorted(m for m in sys.modules if m.startswith('millfmu.stress_tables.'));"
        "assert tabs == ['millfmu.stress_tables.' + m for m in ('files', 'rules', 'spec', 'stress_source', 'table')], "
        "tabs"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
