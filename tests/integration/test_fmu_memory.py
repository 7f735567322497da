"""FMU instances leave nothing behind (issue 27): 250 cycles of instantiate, 10 steps, free
grow the host's memory no more than a trivial FMU of the same library does (within 2 kB per
cycle), both over the first 250 cycles and once the heap has settled, and the FMI 2.0
script's class is made once per process, not once per instance. After 1000 cycles the
host's memory no longer grows at all (issue 55: the wrappers' own leaks, which a trivial FMU
carrying the same wrapper shares, are measured against zero)."""

from __future__ import annotations

import json
import subprocess

import pytest

from .fmu_support import build, isolated_python, need_fmi3

pytest.importorskip("fmpy")

#: Run in a fresh interpreter without millfmu: RSS growth per cycle [kB] over the 250 cycles
#: after the first (the issue's protocol, the heap's settling included), then in four windows
#: (a leak grows in every window; the heap's settling does not: the least is compared), and
#: how many slave classes of the FMU's model identifier exist.
#: RSS growth per cycle [kB] in four windows of ``cycles`` cycles each (both scripts).
WINDOWS = r'''
windows = []
for w in range(4):
    gc.collect(); r0 = rss()
    for _ in range(cycles):
        cycle()
    gc.collect(); windows.append((rss() - r0) / cycles)
'''
CYCLES = r'''
import gc, json, sys
from fmpy import extract, read_model_description
path, cycles = sys.argv[1], int(sys.argv[2])
md = read_model_description(path)
v3 = md.fmiVersion.startswith("3")
if v3:
    from fmpy.fmi3 import FMU3Slave as S
else:
    from fmpy.fmi2 import FMU2Slave as S
f = S(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
def rss():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS"))
def cycle():
    f.instantiate()
    if v3:
        f.enterInitializationMode(startTime=0.0)
    else:
        f.setupExperiment(startTime=0.0); f.enterInitializationMode()
    f.exitInitializationMode()
    t = 0.0
    for k in range(10):
        f.doStep(t, 1.0); t += 1.0
    f.terminate(); f.freeInstance()
cycle()
gc.collect(); r0 = rss()
for _ in range(250):  # the issue's protocol: 250 cycles after the first; the heap settles
    cycle()           # (fragmentation, first-use caches) within them
gc.collect(); first = (rss() - r0) / 250
''' + WINDOWS + r'''ident = md.coSimulation.modelIdentifier
n_classes = sum(1 for o in gc.get_objects() if isinstance(o, type) and o.__name__ == ident)
print("RESULT " + json.dumps({"kB_per_cycle": min(windows), "windows": windows, "first_250": first,
                              "classes": n_classes}), flush=True)
# Out without the interpreter's finalization: the FMI 2.0 trivial FMU runs pythonfmu's own
# wrapper, whose exit may abort (fmu_build.wrapper, fix 5); the exit is not what this measures.
import os
os._exit(0)
'''


def _growth(python, fmu, cwd, cycles=150):
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    r = subprocess.run([python, "-c", CYCLES, str(fmu), str(cycles)], capture_output=True, text=True, cwd=str(cwd),
                       env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_instances_leave_no_more_behind_than_a_trivial_fmu(tmp_path, fmi_version):
    if fmi_version == 3:
        need_fmi3()
    from fmu_build.step_cost import _floor

    mill = build(None, tmp_path / f"mill{fmi_version}.fmu", fmi_version=fmi_version)
    floor = _floor(tmp_path, fmi_version, 100, 114, 14)
    python = isolated_python(tmp_path)
    m, t = _growth(python, mill, tmp_path), _growth(python, floor, tmp_path)
    print(f"FMI {fmi_version}: RSS growth per cycle over the first 250 cycles: mill {m['first_250']:.2f} kB, trivial "
          f"FMU {t['first_250']:.2f} kB; least of 4 windows of 150 cycles after them: mill {m['kB_per_cycle']:.2f} kB "
          f"{m['windows']}, trivial FMU {t['kB_per_cycle']:.2f} kB {t['windows']}")
    assert m["first_250"] <= t["first_250"] + 2.0, (m, t)
    assert m["kB_per_cycle"] <= t["kB_per_cycle"] + 2.0, (m, t)
    if fmi_version == 2:
        assert m["classes"] == 1, m  # the script's class, made once


def test_models_of_a_process_share_one_read_only_table(detailed_scene_dict):
    """Each FMU instance builds a MillModel; the table it reads (the detailed example's) is
    read once per process and files (re-reading, verifying and allocating it per instance
    made the heap grow)."""
    import numpy as np

    from millfmu.mill import MillModel
    from tests.conftest import make_scene

    a, b = MillModel(make_scene(detailed_scene_dict)), MillModel(make_scene(detailed_scene_dict))
    assert a.source.table is b.source.table
    arr = next(iter(a.source.table.data.values()))
    with pytest.raises(ValueError):
        arr[(0,) * arr.ndim] = np.nan


#: After 1000 cycles: RSS growth per cycle [kB] in four windows of 250 cycles, how often the
#: FMU's resources folder is in sys.path, and how the reference count of the slave's base
#: class changed over the windows (a leaked reference to it, e.g. in a leaked MRO list, is
#: counted exactly, unlike RSS, which grows by pages).
LATE = CYCLES.split("cycle()\ngc.collect(); r0 = rss()")[0] + r'''
for _ in range(1000):
    cycle()
ident = md.coSimulation.modelIdentifier
base = getattr(sys.modules[ident], ident).__mro__[1]
gc.collect(); refs0 = sys.getrefcount(base)
''' + WINDOWS + r'''extract_dir = str(f.unzipDirectory)
print("RESULT " + json.dumps({"windows": windows, "base_refs": sys.getrefcount(base) - refs0, "base": base.__name__,
                              "in_sys_path": sum(1 for p in sys.path if p.startswith(extract_dir))}), flush=True)
import os
os._exit(0)
'''


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_no_growth_per_cycle_after_a_thousand_cycles(tmp_path, fmi_version):
    """pythonfmu's wrapper put the resources folder into sys.path at every fmi2Instantiate
    and leaked, per instance, the MRO lists (each holding the slave's classes), reprs and
    bytes of the script's classes: 1 to 2 kB RSS per cycle in every late window."""
    import os

    if fmi_version == 3:
        need_fmi3()
    mill = build(None, tmp_path / f"mill{fmi_version}.fmu", fmi_version=fmi_version)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    r = subprocess.run([isolated_python(tmp_path), "-c", LATE, str(mill), "250"], capture_output=True, text=True,
                       cwd=str(tmp_path),
                       env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads([ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")][-1][len("RESULT "):])
    print(f"FMI {fmi_version}, after 1000 cycles: RSS growth per cycle {res['windows']} kB, "
          f"references to {res['base']} {res['base_refs']:+d} over 1000 cycles, resources in sys.path "
          f"{res['in_sys_path']} x")
    assert res["in_sys_path"] == 1, res
    assert res["base_refs"] == 0, res
    assert sum(res["windows"]) / 4 <= 0.25, res
