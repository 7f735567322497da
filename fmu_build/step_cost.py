"""``millfmu bench fmu``: cost of one doStep plus reading all outputs of the mill FMU, against
a trivial FMU of the same FMI version with as many output values (a do_step that does
nothing), both measured in the same run through fmpy: FMI 2.0 (pythonfmu, fmi2GetReal of
every Real) and FMI 3.0 (pythonfmu3 with millfmu's wrapper, fmi3GetFloat64 of every
variable, the size distribution as one array). Each trivial FMU is its library's floor: its
C-Python round trips per call. Printed as ratios; never asserted.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

#: The FMI 2.0 floor: n Real outputs held in attributes (pythonfmu's default getters), a
#: do_step that does nothing.
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

#: The FMI 3.0 floor, shaped like the mill FMU: an array of n_classes outputs and the scalar
#: outputs, held in attributes (pythonfmu3's default getters), a do_step that does nothing.
_FLOOR3 = '''"""Trivial pythonfmu3 FMU: the per-call floor of pythonfmu3."""
import numpy as np
from pythonfmu3 import Dimension, Fmi3Causality, Fmi3Initial, Fmi3Slave, Fmi3Variability, Float64, UInt64


class {name}(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous, getter=lambda: 0.0))
        self.n = {classes}
        self.register_variable(UInt64("n", causality=Fmi3Causality.structuralParameter, variability=Fmi3Variability.fixed,
                                      initial=Fmi3Initial.exact, start={classes}))
        self.a = np.arange({classes}, dtype=float)
        self.register_variable(Float64("a", causality=Fmi3Causality.output, variability=Fmi3Variability.continuous,
                                       initial=Fmi3Initial.calculated, dimensions=[Dimension(valueReference="1")]))
        for i in range({scalars}):
            setattr(self, "y%d" % i, float(i))
            self.register_variable(Float64("y%d" % i, causality=Fmi3Causality.output, variability=Fmi3Variability.continuous,
                                           initial=Fmi3Initial.calculated))

    def do_step(self, current_time, step_size):
        return True
'''  # noqa: E501
def _scene_text(n_classes: int, continuous: bool) -> str:
    import tomllib

    from millfmu.scene import default_scene_text

    from .build import toml_text

    d = tomllib.loads(default_scene_text())
    # n classes over the default scene's size range (20 nm to 200 um), so that the grinding
    # of the timed steps stays on the grid as in the default scene (a lower edge of 0.1 um
    # put 1 % of the mass below it within 362 s, and the FMU warned in the middle of the table)
    g = d["grid"]
    g["classes_per_octave"] = n_classes / math.log2(g["x_max_m"] / g["x_min_m"])
    d["scene"]["name"] = f"bench-{n_classes}-{'continuous' if continuous else 'batch'}"
    if continuous:
        d["operation"] = {"mode": "continuous", "n_tanks": 1, "feed_mass_flow_kg_per_s": 1e-3}
    return toml_text(d)


def _open(path: Path, name: str):
    """Instantiate through exitInitializationMode: (fmu, reader of all outputs, seconds)."""
    from fmpy import extract, read_model_description

    md = read_model_description(str(path))
    args = dict(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName=name)
    outs = [v for v in md.modelVariables if v.causality == "output"]
    vrs = [v.valueReference for v in outs]
    t0 = time.perf_counter()
    if md.fmiVersion.startswith("3"):
        from fmpy.fmi3 import FMU3Slave

        fmu = FMU3Slave(**args)
        fmu.instantiate()
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        n = sum(int(next(x.start for x in md.modelVariables if x.valueReference == v.dimensions[0].valueReference))
                if v.dimensions else 1
                for v in outs)
        read = lambda: fmu.getFloat64(vrs, n)  # noqa: E731
    else:
        from fmpy.fmi2 import FMU2Slave

        fmu = FMU2Slave(**args)
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        n = len(vrs)
        read = lambda: fmu.getReal(vrs)  # noqa: E731
    return fmu, read, n, time.perf_counter() - t0


def _per_step(fmu, read, steps, repeats, dt=1.0):
    best = float("inf")
    t = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            fmu.doStep(t, dt)
            read()
            t += dt
        best = min(best, (time.perf_counter() - t0) / steps)
    return best


def _floor(tmp: Path, fmi_version: int, classes: int, n_values: int, n_scalars: int) -> Path:
    """Build the trivial FMU of an FMI version with as many output values as the mill's."""
    from .build import write_fmu

    if fmi_version == 3:
        from pythonfmu3 import FmuBuilder

        from . import fmi3_wrapper

        name = f"MillBenchFloor3_{classes}"
        text = _FLOOR3.format(name=name, classes=classes, scalars=n_scalars)
    else:
        from pythonfmu import FmuBuilder

        name = f"MillBenchFloor{n_values}"
        text = _FLOOR.format(name=name, n=n_values)
    src = tmp / f"floor{fmi_version}" / f"{name}.py"
    src.parent.mkdir()
    src.write_text(text)
    built = FmuBuilder.build_FMU(src, dest=src.parent / "built")
    out = tmp / f"{name}.fmu"
    # The FMI 3.0 floor runs on the same wrapper as the mill FMU.
    write_fmu(built, out, fmi3_wrapper.fmu_replacements(name) if fmi_version == 3 else None)
    return out


def bench_fmu(classes=100, steps=2000, repeats=5, out=print, fmi_versions=(2, 3), required=False,
              figures: dict | None = None) -> int:
    """Print the table; ``required``: an FMI 3.0 FMU that cannot be built here is an error
    (else that version is skipped with the reason). ``figures``: a dict that receives, per
    FMI version v and mode (batch, continuous), ``fmi{v}_{mode}_over_floor`` [-] and
    ``fmi{v}_{mode}_step_us``, ``fmi{v}_floor_step_us`` and ``fmi{v}_{mode}_model_step_us``
    (MillModel.step alone) [us]."""
    figures = {} if figures is None else figures
    from millfmu.mill import MillModel
    from millfmu.scene import load_scene

    from .build import build_fmu

    with tempfile.TemporaryDirectory(prefix="millfmu_bench_") as tmp:
        tmp = Path(tmp)
        out(f"FMU doStep + reading all outputs, {classes} size classes, fmpy host; best of {repeats} x {steps} steps "
            "of 1 s")
        for v in fmi_versions:
            if v == 3 and not required:
                from .fmi3_wrapper import WrapperError, wrapper_library

                try:
                    wrapper_library()
                except WrapperError as e:
                    out(f"FMI 3.0: not measured: {e}")
                    continue
            rows = []
            for continuous in (False, True):
                scene = tmp / f"scene_{int(continuous)}.toml"
                scene.write_text(_scene_text(classes, continuous))
                r = build_fmu(scene, tmp / f"mill{v}_{int(continuous)}.fmu", fmi_version=v)
                if r.n_classes != classes:
                    raise RuntimeError(f"bench scene has {r.n_classes} classes, wanted {classes}")
                rows.append((scene, r))
            mill, _, n_values, _ = _open(rows[0][1].fmu, "mill")
            mill.terminate()
            mill.freeInstance()
            floor_fmu = _floor(tmp, v, classes, n_values, n_values - classes)
            lib = "pythonfmu3" if v == 3 else "pythonfmu"
            out(f"FMI {v}.0 ({lib}{', millfmu wrapper' if v == 3 else ''})")
            floor, f_read, f_n, f_inst = _open(floor_fmu, "floor")
            assert f_n == n_values
            t_floor = _per_step(floor, f_read, steps, repeats)
            out(f"{'FMU':34s} {'values':>7s} {'per step [us]':>14s} {'/ floor':>8s} {'instantiate [ms]':>17s}")
            out(f"{f'trivial {lib} FMU (floor)':34s} {f_n:7d} {t_floor * 1e6:14.1f} {1.0:8.2f} {f_inst * 1e3:17.1f}")
            figures[f"fmi{v}_floor_step_us"] = round(t_floor * 1e6, 2)
            for scene, r in rows:
                fmu, read, n, t_inst = _open(r.fmu, "mill")
                t_mill = _per_step(fmu, read, steps, repeats)
                model = MillModel(load_scene(scene))
                model.step(1.0)  # builds the cached propagator, as the FMU's first step did
                t_model = float("inf")
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    for _ in range(steps):
                        model.step(1.0)
                    t_model = min(t_model, (time.perf_counter() - t0) / steps)
                mode = load_scene(scene).operation.mode
                label = f"mill, {mode}"
                figures[f"fmi{v}_{mode}_over_floor"] = round(t_mill / t_floor, 2)  # as printed
                figures[f"fmi{v}_{mode}_step_us"] = round(t_mill * 1e6, 2)
                figures[f"fmi{v}_{mode}_model_step_us"] = round(t_model * 1e6, 2)
                out(f"{label:34s} {n:7d} {t_mill * 1e6:14.1f} {t_mill / t_floor:8.2f} {t_inst * 1e3:17.1f}")
                out(f"{'  (MillModel.step alone, in-process)':34s} {'':7s} {t_model * 1e6:14.1f} "
                    f"{t_model / t_floor:8.2f}")
                fmu.terminate()
                fmu.freeInstance()
            floor.terminate()
            floor.freeInstance()
    out("aim: the mill FMU within 1.5 times the floor with FMI 2.0 and 2 times with FMI 3.0")
    return 0
