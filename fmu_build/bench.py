"""``millfmu bench fmu``: cost of fmi2DoStep plus fmi2GetReal of all outputs of the mill FMU,
against a trivial pythonfmu FMU with as many Real outputs (a do_step that does nothing), both
measured in the same run through fmpy. The trivial FMU is pythonfmu's floor: its C-Python
round trips per call. Printed as a ratio; never asserted.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

#: The floor FMU: n Real outputs held in attributes (pythonfmu's default getters), a do_step
#: that does nothing.
_FLOOR = '''"""Trivial pythonfmu FMU: the per-call floor of pythonfmu."""
import ctypes

from pythonfmu import Fmi2Causality, Fmi2Slave, Real

_SPARE_REFERENCE = globals()  # see fmu_build.build.SCRIPT


class {name}(Fmi2Slave):
    def __init__(self, **kwargs):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))
        super().__init__(**kwargs)
        for i in range({n}):
            setattr(self, "y%d" % i, float(i))
            self.register_variable(Real("y%d" % i, causality=Fmi2Causality.output, description="constant", getter=None))

    def do_step(self, current_time, step_size):
        return True
'''


def _scene_text(n_classes: int, continuous: bool) -> str:
    import tomllib

    from millfmu.scene import default_scene_text

    from .build import toml_text

    d = tomllib.loads(default_scene_text())
    # n classes: x_max = x_min 2^(n / classes_per_octave) with 10 classes per octave.
    d["grid"] = {"x_min_m": 0.1e-6, "x_max_m": 0.1e-6 * 2 ** (n_classes / 10.0), "classes_per_octave": 10.0}
    d["feed"]["x50_m"] = min(d["feed"]["x50_m"], 0.1e-6 * 2 ** (n_classes / 10.0) / 8)
    d["scene"]["name"] = f"bench-{n_classes}-{'continuous' if continuous else 'batch'}"
    if continuous:
        d["operation"] = {"mode": "continuous", "n_tanks": 1, "feed_mass_flow_kg_per_s": 1e-3}
    return toml_text(d)


def _open(path: Path, name: str):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    t0 = time.perf_counter()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    t_inst = time.perf_counter() - t0
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    return fmu, outs, t_inst


def _per_step(fmu, outs, steps, repeats, dt=1.0):
    best = float("inf")
    t = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            fmu.doStep(t, dt)
            fmu.getReal(outs)
            t += dt
        best = min(best, (time.perf_counter() - t0) / steps)
    return best


def bench_fmu(classes=100, steps=2000, repeats=5, out=print) -> int:
    from pythonfmu import FmuBuilder

    from millfmu.mill import MillModel
    from millfmu.scene import load_scene

    from .build import build_fmu

    with tempfile.TemporaryDirectory(prefix="millfmu_bench_") as tmp:
        tmp = Path(tmp)
        rows = []
        for continuous in (False, True):
            scene = tmp / f"scene_{int(continuous)}.toml"
            scene.write_text(_scene_text(classes, continuous))
            r = build_fmu(scene, tmp / f"mill_{int(continuous)}.fmu")
            if r.n_classes != classes:
                raise RuntimeError(f"bench scene has {r.n_classes} classes, wanted {classes}")
            rows.append((scene, r))
        mill, outs, t_inst = _open(rows[0][1].fmu, "mill")
        n_out = len(outs)
        mill.terminate()
        mill.freeInstance()
        floor_name = f"MillBenchFloor{n_out}"
        src = tmp / "floor" / f"{floor_name}.py"
        src.parent.mkdir()
        src.write_text(_FLOOR.format(name=floor_name, n=n_out))
        floor_fmu = FmuBuilder.build_FMU(src, dest=tmp / f"{floor_name}.fmu")

        out(f"FMU doStep + fmi2GetReal of all outputs, {classes} size classes, fmpy host; best of {repeats} x {steps} steps of 1 s")
        floor, f_outs, f_inst = _open(floor_fmu, "floor")
        assert len(f_outs) == n_out
        t_floor = _per_step(floor, f_outs, steps, repeats)
        out(f"{'FMU':34s} {'outputs':>7s} {'per step [us]':>14s} {'/ floor':>8s} {'instantiate [ms]':>17s}")
        out(f"{'trivial pythonfmu FMU (floor)':34s} {len(f_outs):7d} {t_floor * 1e6:14.1f} {1.0:8.2f} {f_inst * 1e3:17.1f}")
        for scene, r in rows:
            fmu, outs, t_inst = _open(r.fmu, "mill")
            t_mill = _per_step(fmu, outs, steps, repeats)
            model = MillModel(load_scene(scene))
            model.step(1.0)  # builds the cached propagator, as the FMU's first step did
            t_model = float("inf")
            for _ in range(repeats):
                t0 = time.perf_counter()
                for _ in range(steps):
                    model.step(1.0)
                t_model = min(t_model, (time.perf_counter() - t0) / steps)
            label = f"mill, {load_scene(scene).operation.mode}"
            out(f"{label:34s} {len(outs):7d} {t_mill * 1e6:14.1f} {t_mill / t_floor:8.2f} {t_inst * 1e3:17.1f}")
            out(f"{'  (MillModel.step alone, in-process)':34s} {'':7s} {t_model * 1e6:14.1f} {t_model / t_floor:8.2f}")
            fmu.terminate()
            fmu.freeInstance()
        floor.terminate()
        floor.freeInstance()
    out("aim: the mill FMU within 3 times the floor")
    return 0
