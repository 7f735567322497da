"""The four shipped flowsheets with FMI 3.0 unit FMUs (``--fmi-version 3``) in the fmpy
master, each in a fresh process: the same results and mass-balance residuals as with the
FMI 2.0 units, the units' FMI 3.0 descriptions, the retry of a discarded step through FMI
3.0 FMU states, and a refused parameter stopping the run with the unit's message."""

from __future__ import annotations

import numpy as np
import pytest

from ..integration.fmu_support import need_fmi3
from .support import FLOWSHEETS, cli, run
from .test_flowsheets import NAMES, RETRY


@pytest.fixture(scope="module")
def fmu3_dir(tmp_path_factory):
    """FMI 3.0 unit FMUs for this module (the session's fmu_dir holds the FMI 2.0 ones)."""
    need_fmi3()
    return tmp_path_factory.mktemp("flowsheet_fmus3")


@pytest.fixture(scope="module")
def runs(tmp_path_factory, fmu_dir, fmu3_dir):
    d = tmp_path_factory.mktemp("runs3")
    return {n: {2: run(FLOWSHEETS / f"{n}.toml", d / f"{n}2", fmu_dir),
                3: run(FLOWSHEETS / f"{n}.toml", d / f"{n}3", fmu3_dir, "--fmi-version", "3")} for n in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_units_give_the_results_and_mass_balance_of_the_fmi2_units(runs, name):
    r2, r3 = runs[name][2], runs[name][3]
    assert r3["summary"]["fmi_version"] == "3.0" and r2["summary"]["fmi_version"] == "2.0"
    mb2, mb3 = r2["summary"]["mass_balance"], r3["summary"]["mass_balance"]
    assert mb3["relative_residual"] < 1e-9, mb3
    assert mb3["relative_residual"] == pytest.approx(mb2["relative_residual"], rel=1e-6, abs=1e-16)
    a, b = r2["data"], r3["data"]
    assert a.dtype.names == b.dtype.names
    rel = max(np.abs(a[c] - b[c]).max() / max(np.abs(a[c]).max(), 1e-300) for c in a.dtype.names)
    print(f"{name}: largest relative difference FMI 3.0 - FMI 2.0 units {rel:.1e}; residuals "
          f"{mb2['relative_residual']:.2e}, {mb3['relative_residual']:.2e}")
    assert rel <= 1e-12
    assert "FMI 3.0 units" in r3["stdout"]


def test_fmi3_unit_fmus_validate_with_units_descriptions_and_arrays(runs, fmu3_dir):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    fmus = sorted(fmu3_dir.glob("*.fmu"))
    assert {f.name.split("_")[0] for f in fmus} == {"mill", "feed", "tank", "classifier", "pi"}
    for f in fmus:
        assert validate_fmu(str(f)) == [], f.name
        md = read_model_description(str(f))
        assert md.fmiVersion == "3.0"
        defined = {u.name for u in md.unitDefinitions}
        for v in md.modelVariables:
            assert v.description, (f.name, v.name)
            if v.type == "Float64":
                assert v.unit in defined, (f.name, v.name)
        arrays = [v.name for v in md.modelVariables if v.dimensions]
        assert all("psd" in a for a in arrays) and bool(arrays) == (not f.name.startswith("pi_")), (f.name, arrays)
        assert any(v.name == "n_classes" for v in md.modelVariables) == bool(arrays), f.name


def test_a_discarded_step_is_retried_through_fmi3_states(tmp_path, fmu3_dir):
    f = tmp_path / "retry.toml"
    f.write_text(RETRY.format(halvings=3))
    s = run(f, tmp_path / "out", fmu3_dir, "--fmi-version", "3")["summary"]
    assert [(x["t_s"], x["step_s"], x["unit"]) for x in s["retries"]] == [(20.0, 5.0, "feed")], s["retries"]
    assert "jump of the feed at t = 22.5 s" in s["retries"][0]["message"]
    assert s["steps"] == 12 + 1 and s["mass_balance"]["relative_residual"] < 1e-9
    assert s["mass_balance"]["fed_kg"] == pytest.approx(22.5 * 2e-3 + 37.5 * 4e-3, rel=1e-13)


def test_a_refused_parameter_stops_the_run_at_initialization_naming_unit_and_value(tmp_path, fmu3_dir):
    """FMI 3.0: the tank answers a negative pump flow with fmi3Error at
    fmi3ExitInitializationMode; the master stops there, names the unit and writes nothing."""
    f = tmp_path / "bad.toml"
    f.write_text((FLOWSHEETS / "circuit.toml").read_text() + "\n[units.tank.start]\npump_mass_flow = -1.0\n")
    r = cli("run", f, "--out", tmp_path / "out", "--fmu-dir", fmu3_dir, "--no-plots", "--fmi-version", "3")
    assert r.returncode == 1, r.stderr
    assert ("unit tank refused its initialization (status 3)" in r.stderr
            and "pump_mass_flow = -1.0: must be >= 0 kg/s" in r.stderr), r.stderr
    assert not (tmp_path / "out").exists()
