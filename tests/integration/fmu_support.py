"""Helpers for the FMU tests: scenes, builds, an interpreter without millfmu, and a driver
prelude run in fresh subprocesses (one Python interpreter per process: FMUs are never loaded
into the pytest process itself)."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np

from fmu_build.build import toml_text
from millfmu.mill import MillModel
from millfmu.scene import default_scene_text, load_scene

ROOT = Path(__file__).resolve().parents[2]


def scene_text(**sections) -> str:
    """The default scene with sections updated: scene_text(operation={"mode": "continuous"})."""
    d = copy.deepcopy(tomllib.loads(default_scene_text()))
    for sec, vals in sections.items():
        d.setdefault(sec, {}).update(vals)
    return toml_text(d)


# The default scene (Kwade's simple model) and these two use no DEM data at all: the
# simple model continuous, and the detailed model with a log-normal stress-energy
# distribution. TABLE_SCENE reads the shipped coupled DEM-CFD table: the detailed example.
TABLE_SCENE = ROOT / "millfmu" / "data" / "examples" / "limestone_detailed.toml"
CONTINUOUS = dict(scene={"name": "pm1-limestone-continuous"},
                  operation={"mode": "continuous", "n_tanks": 3, "feed_mass_flow_kg_per_s": 1e-3},
                  kinetics={"model": "simple"})
DETAILED = dict(scene={"name": "pm1-limestone-detailed"},
                kinetics={"model": "detailed", "stress_distribution": {"source": "lognormal"}})


def build(scene_path, out: Path, fmi_version: int = 2) -> Path:
    cmd = [sys.executable, "-m", "millfmu.cli",
           "build-fmu"] + ([str(scene_path)] if scene_path else []) + ["-o", str(out)]
    cmd += ["--fmi-version", str(fmi_version)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return out


def fmi3_missing():
    """Why FMI 3.0 FMUs cannot be built here (pythonfmu3, and a C++ compiler and this
    Python's headers for its fixed wrapper), or None when they can."""
    import importlib.util

    if importlib.util.find_spec("pythonfmu3") is None:
        return "pythonfmu3 not installed (fmu or test extras)"
    from fmu_build.fmi3_wrapper import WrapperError, wrapper_library

    try:
        wrapper_library()
    except WrapperError as e:
        return str(e)
    return None


def need_fmi3():
    """Skip the calling test (or fixture) when FMI 3.0 FMUs cannot be built here."""
    import pytest

    missing = fmi3_missing()
    if missing:
        pytest.skip(f"FMI 3.0 FMUs cannot be built here: {missing}")


def isolated_python(where: Path) -> str:
    """A fresh virtual environment that sees this environment's third-party packages
    (numpy, scipy, fmpy) but not millfmu: its editable-install hook lives in a .pth file that
    is processed only in a site directory, and here the packages come in as a plain path."""
    env_dir = where / "venv-no-millfmu"
    if not env_dir.exists():
        venv.EnvBuilder(with_pip=False, symlinks=True).create(env_dir)
        purelib = sysconfig.get_paths()["purelib"]
        site = next((env_dir / "lib").glob("python*/site-packages"))
        (site / "host_packages.pth").write_text(purelib + "\n")
    py = str(env_dir / "bin" / "python")
    r = subprocess.run([py, "-c",
                        "import importlib.util as u; print(u.find_spec('millfmu') is None, u.find_spec('fmpy') is not "
                        "None)"],
                       capture_output=True, text=True, cwd=str(where),
                       env={k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")})
    assert r.stdout.split() == ["True", "True"], (r.stdout, r.stderr)
    return py


def run_py(python: str, code: str, cwd: Path, timeout=300, fmi_version: int = 2) -> dict:
    """Run the prelude of the FMI version (PRELUDE, PRELUDE3) + code in a fresh interpreter;
    the code ends with done(obj)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    prelude = {2: PRELUDE, 3: PRELUDE3}[fmi_version]
    r = subprocess.run([python, "-c", prelude + code], capture_output=True, text=True, cwd=str(cwd), timeout=timeout,
                       env=env)
    assert r.returncode == 0, f"subprocess failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]  # masters log to stdout too
    assert lines, r.stdout[-3000:]
    return json.loads(lines[-1][len("RESULT "):])


def reference(scene_path, steps, inputs_per_step=None):
    """MillModel run directly: outputs after each step, as FMI name -> list."""
    from millfmu.fmi.variables import DISRUPTED, OUTPUTS

    model = MillModel(load_scene(scene_path))
    keys = OUTPUTS + ((DISRUPTED,) if "disrupted_fraction" in model.outputs() else ())
    rec = {"psd": []}
    rec.update({name: [] for name, _, _, _ in keys})
    for k, dt in enumerate(steps):
        outs = model.step(dt, **((inputs_per_step or {}).get(k, {})))
        rec["psd"].append(outs["psd"].tolist())
        for name, key, _, _ in keys:
            rec[name].append(float(outs[key]))
    return {k: np.array(v) for k, v in rec.items()}


#: Code run first in every FMU subprocess: open an FMU with fmpy, log capture, helpers.
PRELUDE = r'''
import json, math, os, sys
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, calloc, free)

LOG = []

def _logger(env, instance, status, category, message):
    LOG.append([instance.decode(), int(status), (category or b"").decode(), (message or b"").decode().replace("%%", "%")])

CB = fmi2CallbackFunctions()
CB.logger = fmi2CallbackLoggerTYPE(_logger)
CB.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
CB.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
_DIRS = {}

def open_fmu(path, name="mill", logging=True, start=None, init=True):
    md = read_model_description(path)
    d = _DIRS.get(path) or _DIRS.setdefault(path, extract(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate(callbacks=CB, loggingOn=logging)
    fmu.md, fmu.vr = md, vr
    if init:
        assert initialize(fmu, start) == 0
    fmu.out_names = [v.name for v in md.modelVariables if v.causality == "output"]
    fmu.out_vrs = [vr[n] for n in fmu.out_names]
    return fmu

def initialize(fmu, start=None, start_time=0.0):
    """setupExperiment .. exitInitializationMode with start values; exitInitializationMode's
    status (0 ok, 3 error)."""
    fmu.setupExperiment(startTime=start_time)
    fmu.enterInitializationMode()
    for k, v in (start or {}).items():
        fmu.setReal([fmu.vr[k]], [v])
    try:
        fmu.exitInitializationMode()
        return 0
    except FMICallException as e:
        return e.status

def outputs(fmu):
    return dict(zip(fmu.out_names, fmu.getReal(fmu.out_vrs)))

def step(fmu, t, dt, inputs=None):
    """doStep with inputs (a list sets name[1..n]); returns the status (0 ok, 2 discard, ...)."""
    for k, v in (inputs or {}).items():
        if isinstance(v, list):
            fmu.setReal([fmu.vr[f"{k}[{i}]"] for i in range(1, len(v) + 1)], v)
        else:
            fmu.setReal([fmu.vr[k]], [v])
    try:
        fmu.doStep(t, dt)
        return 0
    except FMICallException as e:
        return e.status

def record(rec, fmu):
    o = outputs(fmu)
    rec.setdefault("psd", []).append([o[n] for n in fmu.out_names if n.startswith("psd[")])
    for n, v in o.items():
        if not n.startswith("psd["):
            rec.setdefault(n, []).append(v)

# FMU state and reset under one name for both FMI versions (see PRELUDE3).
get_state, set_state, free_state = FMU2Slave.getFMUstate, FMU2Slave.setFMUstate, FMU2Slave.freeFMUstate
serialize_state, deserialize_state = FMU2Slave.serializeFMUstate, FMU2Slave.deSerializeFMUstate

def reset(fmu):
    fmu.reset()
    fmu.setupExperiment(startTime=0.0); fmu.enterInitializationMode(); fmu.exitInitializationMode()

def done(obj):
    print("RESULT " + json.dumps(obj), flush=True)
    # Leave without interpreter teardown: with several pythonfmu 0.7 FMUs loaded, the
    # process sometimes aborts in glibc ("corrupted double-linked list") while Python
    # finalizes, after every instance was freed and everything checked here had passed.
    # That is a pythonfmu/host teardown issue (see README, FMU), not one of the steps tested.
    sys.stderr.flush()
    os._exit(0)
'''  # noqa: E501


#: The same helpers for FMI 3.0 FMUs (fmpy's FMU3Slave): outputs() names an array's values
#: name[1] ... name[n] as the FMI 2.0 FMU does, so records of both versions compare as they
#: are; step() sets a list as a whole array; call() returns the status of any FMI call.
PRELUDE3 = r'''
import json, math, os, sys
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

LOG = []
_DIRS = {}

def call(f, *args):
    """Status of an FMI call (0 ok, 2 discard, 3 error, ...) and its result."""
    try:
        return 0, f(*args)
    except FMICallException as e:
        return e.status, None

def open_fmu(path, name="mill", logging=True, start=None, init=True):
    md = read_model_description(path)
    d = _DIRS.get(path) or _DIRS.setdefault(path, extract(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    def logger(env, status, category, message, name=name):
        LOG.append([name, int(status), (category or b"").decode(), (message or b"").decode()])
    fmu.instantiate(loggingOn=logging, logMessage=logger)
    n = int(next(v.start for v in md.modelVariables if v.name == "n_classes"))
    fmu.md, fmu.vr, fmu.n = md, vr, n
    fmu.size = {v.name: (n if v.dimensions else 1) for v in md.modelVariables if v.type == "Float64"}
    fmu.out_names = [v.name for v in md.modelVariables if v.causality == "output"]
    fmu.out_vrs = [vr[k] for k in fmu.out_names]
    if init:
        fmu.enterInitializationMode(startTime=0.0)
        for k, v in (start or {}).items():
            fmu.setFloat64([vr[k]], v if isinstance(v, list) else [v])
        fmu.exitInitializationMode()
    return fmu

def outputs(fmu):
    vals = fmu.getFloat64(fmu.out_vrs, sum(fmu.size[k] for k in fmu.out_names))
    out, pos = {}, 0
    for k in fmu.out_names:
        if fmu.size[k] > 1 or k == "psd":
            out.update({"%s[%d]" % (k, i + 1): vals[pos + i] for i in range(fmu.size[k])})
        else:
            out[k] = vals[pos]
        pos += fmu.size[k]
    return out

def step(fmu, t, dt, inputs=None):
    """doStep with inputs (a list sets a whole array); returns the status (0 ok, 2 discard, ...)."""
    for k, v in (inputs or {}).items():
        fmu.setFloat64([fmu.vr[k]], v if isinstance(v, list) else [v])
    return call(fmu.doStep, t, dt)[0]

def record(rec, fmu):
    o = outputs(fmu)
    rec.setdefault("psd", []).append([o[k] for k in o if k.startswith("psd[")])
    for k, v in o.items():
        if not k.startswith("psd["):
            rec.setdefault(k, []).append(v)

get_state, set_state, free_state = FMU3Slave.getFMUState, FMU3Slave.setFMUState, FMU3Slave.freeFMUState
serialize_state, deserialize_state = FMU3Slave.serializeFMUState, FMU3Slave.deserializeFMUState

def reset(fmu):
    fmu.reset()
    fmu.enterInitializationMode(startTime=0.0); fmu.exitInitializationMode()

def done(obj):
    print("RESULT " + json.dumps(obj), flush=True)
    sys.stderr.flush()
    os._exit(0)  # as in PRELUDE: no interpreter teardown with FMUs loaded
'''


def run_isolated_and_compare(fmu: Path, scene_path, d: Path, outs, stop_time=20.0,
                             step_size=2.0) -> dict:
    """Simulate ``fmu`` with fmpy in a Python without millfmu (and without numba loaded),
    and compare its outputs with the model run directly on the same steps to 1e-12.
    Returns the FMU's results."""
    py = isolated_python(d)
    res = run_py(py, f"""
import importlib.util
assert importlib.util.find_spec("millfmu") is None
from fmpy import simulate_fmu
r = simulate_fmu({str(fmu)!r}, stop_time={stop_time!r}, step_size={step_size!r}, output={list(outs)!r})
assert not any(m.startswith("numba") for m in sys.modules)
done({{"time": r["time"].tolist(), **{{k: r[k].tolist() for k in {list(outs)!r}}}}})
""", d)
    ref = reference(scene_path, np.diff(res["time"]).tolist())
    for k in outs:
        np.testing.assert_allclose(res[k][1:], ref[k], rtol=1e-12, atol=0, err_msg=k)
    return res
