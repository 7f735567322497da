"""The mill FMU in the co-simulation masters people use: libcosimpy (Open Simulation Platform)
and ecospy, each in a fresh interpreter without millfmu, compared with MillModel run directly.

Both masters step with a fixed step; libcosim counts time in nanoseconds. FMI 3.0: ecos runs
the FMI 3.0 FMU's scalar variables (it reads every FMI 3.0 variable as one value, so arrays
are not for ecos: see README, FMI 3.0); libcosim refuses FMI 3.0 FMUs ("Unsupported FMI
version") and libcosimpy 0.0.6 then crashes, so it is not tried here."""

from __future__ import annotations

import ctypes.util
import importlib.util

import numpy as np
import pytest

from .fmu_support import build, isolated_python, need_fmi3, reference, run_py

NAMES = ["x50", "holdup", "power", "specific_energy", "psd[5]", "psd[20]"]
STEPS = 5


def _want(steps):
    ref = reference(None, [1.0] * steps)
    return np.column_stack([ref["x50"], ref["holdup"], ref["power"], ref["specific_energy"], ref["psd"][:, 4],
                            ref["psd"][:, 19]])


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("masters")
    return {"dir": d, "fmu": build(None, d / "mill.fmu"), "python": isolated_python(d)}


HAS_ECOS = importlib.util.find_spec("ecospy") is not None and ctypes.util.find_library("tbb") is not None


@pytest.mark.skipif(importlib.util.find_spec("libcosimpy") is None, reason="libcosimpy not installed (test extras)")
def test_libcosimpy_runs_the_mill(setup):
    res = run_py(setup["python"], f"""
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
path = {str(setup["fmu"])!r}
vr = {{v.name: v.valueReference for v in read_model_description(path).modelVariables}}
ex = CosimExecution.from_step_size(step_size=10**9)  # 1 s in nanoseconds
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
i = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name="mill"))
rec = []
for k in range({STEPS}):
    assert ex.step(1)
    rec.append(obs.last_real_values(i, [vr[n] for n in {NAMES!r}]))
done({{"rec": rec, "t_ns": ex.status().current_time}})
""", setup["dir"])
    assert res["t_ns"] == STEPS * 10**9
    np.testing.assert_allclose(np.array(res["rec"]), _want(STEPS), rtol=1e-12, atol=0)


@pytest.mark.skipif(not HAS_ECOS, reason="ecospy (test extras) and Debian's libtbb12 (apt-get install libtbb12) needed")
def test_ecospy_runs_the_mill(setup):
    res = run_py(setup["python"], f"""
from ecospy.EcosSimulation import EcosSimulation
from ecospy.EcosSimulationStructure import EcosSimulationStructure
ss = EcosSimulationStructure()
ss.add_model("mill", {str(setup["fmu"])!r})
sim = EcosSimulation(structure=ss, step_size=1.0)
sim.init()
rec = []
for k in range({STEPS}):
    sim.step()
    rec.append([sim.get_real("mill::" + n) for n in {NAMES!r}])
sim.terminate()
done({{"rec": rec}})
""", setup["dir"])
    np.testing.assert_allclose(np.array(res["rec"]), _want(STEPS), rtol=1e-12, atol=0)


@pytest.mark.skipif(not HAS_ECOS, reason="ecospy (test extras) and Debian's libtbb12 (apt-get install libtbb12) needed")
def test_ecospy_runs_the_fmi3_mill(setup):
    """The FMI 3.0 FMU of the default scene in ecos: scalar outputs read through ecos's
    buffered reads, the tip speed set between steps; equal to MillModel to 1e-12."""
    need_fmi3()
    fmu3 = build(None, setup["dir"] / "mill3.fmu", fmi_version=3)
    names = ["x50", "holdup", "power", "specific_energy", "sf"]
    res = run_py(setup["python"], f"""
from ecospy.EcosSimulation import EcosSimulation
from ecospy.EcosSimulationStructure import EcosSimulationStructure
ss = EcosSimulationStructure()
ss.add_model("mill", {str(fmu3)!r})
sim = EcosSimulation(structure=ss, step_size=1.0)
sim.init()
rec = []
for k in range({STEPS}):
    if k == 2:
        sim.set_real("mill::tip_speed", 12.0)
    sim.step()
    rec.append([sim.get_real("mill::" + n) for n in {names!r}])
sim.terminate()
sim.free()
done({{"rec": rec}})
""", setup["dir"], fmi_version=3)
    ref = reference(None, [1.0] * STEPS, {2: {"tip_speed_m_per_s": 12.0}})
    want = np.column_stack([ref[k] for k in names])
    np.testing.assert_allclose(np.array(res["rec"]), want, rtol=1e-12, atol=0)
    assert res["rec"][-1][2] > res["rec"][1][2]  # the tip speed set in ecos did act (power)
