"""The mill FMU in the co-simulation masters people use: libcosimpy (Open Simulation Platform)
and ecospy, each in a fresh interpreter without millfmu, compared with MillModel run directly.

Both masters step with a fixed step; libcosim counts time in nanoseconds."""

from __future__ import annotations

import ctypes.util
import importlib.util

import numpy as np
import pytest

from .fmu_support import build, isolated_python, reference, run_py

NAMES = ["x50", "holdup", "power", "specific_energy", "psd[5]", "psd[20]"]
STEPS = 5


def _want(steps):
    ref = reference(None, [1.0] * steps)
    return np.column_stack([ref["x50"], ref["holdup"], ref["power"], ref["specific_energy"], ref["psd"][:, 4], ref["psd"][:, 19]])


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("masters")
    return {"dir": d, "fmu": build(None, d / "mill.fmu"), "python": isolated_python(d)}


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


@pytest.mark.skipif(importlib.util.find_spec("ecospy") is None, reason="ecospy not installed (test extras)")
@pytest.mark.skipif(ctypes.util.find_library("tbb") is None, reason="ecospy needs Debian's libtbb12 (apt-get install libtbb12)")
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
