"""Each shipped flowsheet, exported as SSP, runs in libcosimpy and in ecospy (fresh
interpreters without millfmu: the FMUs carry their code) and agrees with the fmpy master.

Tolerances, and why:
- libcosim and ecos are fixed-step Jacobi masters that copy output values to inputs. At a
  fixed step the fmpy master's flow buffers hand over exactly the copied value (flow * h / h,
  which may differ from the flow in the last bit), so against the fmpy master in Jacobi mode
  the only differences are such round-off: required within 1e-9 relative (of the
  variable's largest value over the run).
- The flowsheets whose own algorithm is Gauss-Seidel (passage, closed circuit) are compared
  here in Jacobi mode; that Gauss-Seidel and Jacobi converge to the same solution as the
  step shrinks is tested in test_flowsheets.py.
- Masters are freed explicitly before the interpreter exits: a pythonfmu FMU freed during
  interpreter finalisation (by a master's __del__) can corrupt the heap.
"""

from __future__ import annotations

import ctypes.util
import importlib.util
import os

import numpy as np
import pytest

from flowsheets.spec import load_flowsheet

from ..integration.fmu_support import isolated_python, run_py
from .support import FLOWSHEETS, cli, run

NAMES = ["circuit", "passage", "closed_circuit", "control"]
HAS_LIBCOSIM = importlib.util.find_spec("libcosimpy") is not None
HAS_ECOS = importlib.util.find_spec("ecospy") is not None and ctypes.util.find_library("tbb") is not None


def _variables(data):
    return [c for c in data.dtype.names if (c.endswith("x50") or c.endswith(".holdup")) and not c.startswith("total.")]


@pytest.fixture(scope="module")
def setup(tmp_path_factory, fmu_dir):
    # The masters' subprocesses inherit this: one BLAS thread (small matrices; threads on a
    # loaded machine made runs many times slower).
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    d = tmp_path_factory.mktemp("cross")
    out = {"dir": d, "python": isolated_python(d), "runs": {}}
    for n in NAMES:
        ssp = d / f"{n}.ssp"
        r = cli("export-ssp", FLOWSHEETS / f"{n}.toml", "-o", ssp, "--fmu-dir", fmu_dir)
        assert r.returncode == 0, r.stderr[-3000:]
        fs = load_flowsheet(FLOWSHEETS / f"{n}.toml")
        jac = run(FLOWSHEETS / f"{n}.toml", d / f"{n}_jacobi", fmu_dir, "--algorithm", "jacobi")
        out["runs"][n] = {"ssp": ssp, "jacobi": jac, "step_s": fs.step_s}
    return out


def _fmpy(run_, names):
    d = run_["data"]
    return d["t"], np.column_stack([d[n] for n in names])


def _compare(name, setup, got, first=0):
    """got: rows at the fmpy master's output times, from row ``first`` on."""
    r = setup["runs"][name]
    names = _variables(r["jacobi"]["data"])
    t, want = _fmpy(r["jacobi"], names)
    want = want[first:]
    got = np.array(got)
    assert got.shape == want.shape
    scale = np.abs(want).max(axis=0)
    rel = np.abs(got - want).max(axis=0) / scale
    print(f"{name}: largest relative difference to the fmpy master {rel.max():.2e}")
    assert np.all(rel < 1e-9), dict(zip(names, rel))
    return rel


def _plan(name, setup):
    r = setup["runs"][name]
    names = _variables(r["jacobi"]["data"])
    t = r["jacobi"]["data"]["t"]
    every = int(round((t[1] - t[0]) / r["step_s"]))
    return names, every, len(t) - 1, r["step_s"]


@pytest.mark.skipif(not HAS_LIBCOSIM, reason="libcosimpy not installed (test extras)")
@pytest.mark.parametrize("name", NAMES)
def test_libcosim_agrees_with_the_fmpy_master(setup, name):
    names, every, n_out, h = _plan(name, setup)
    res = run_py(setup["python"], f"""
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
log_output_level(CosimLogLevel.ERROR)
h_ns = round({h!r} * 1e9)
ex = CosimExecution.from_ssp_file({str(setup["runs"][name]["ssp"])!r}, step_size=h_ns)
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
idx = {{s.name.decode(): s.index for s in ex.slave_infos()}}
refs = {{}}
for u, i in idx.items():
    refs[u] = {{v.name.decode(): v.reference for v in ex.slave_variables(i)}}
want = [n.split(".", 1) for n in {names!r}]
def sample():
    return [obs.last_real_values(idx[u], [refs[u][v]])[0] for u, v in want]
rec = []  # libcosim's last-value observer holds values only after the first step
for k in range({n_out}):
    assert ex.step({every})
    rec.append(sample())
t_ns = ex.status().current_time
del obs, ex
import gc; gc.collect()
done({{"rec": rec, "t_ns": t_ns}})
""", setup["dir"])
    assert res["t_ns"] == round(n_out * every * h * 1e9)
    _compare(name, setup, res["rec"], first=1)


@pytest.mark.skipif(not HAS_ECOS, reason="ecospy and Debian's libtbb12 needed")
@pytest.mark.parametrize("name", NAMES)
def test_ecos_agrees_with_the_fmpy_master(setup, name):
    names, every, n_out, h = _plan(name, setup)
    res = run_py(setup["python"], f"""
from ecospy.EcosSimulation import EcosSimulation
sim = EcosSimulation(ssp_path={str(setup["runs"][name]["ssp"])!r}, step_size={h!r})
sim.init()
ids = [n.replace(".", "::", 1) for n in {names!r}]
rec = [[sim.get_real(i) for i in ids]]
for k in range({n_out}):
    for j in range({every}):
        sim.step()
    rec.append([sim.get_real(i) for i in ids])
sim.terminate()
sim.free()
done({{"rec": rec}})
""", setup["dir"])
    _compare(name, setup, res["rec"])
