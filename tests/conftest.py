import os

# The model's matrices are small (tens to hundreds of rows): multithreaded BLAS only adds
# overhead, and on a loaded 2-core machine oversubscription slows expm a hundredfold.
# Set before numpy loads; subprocesses (FMU runs) inherit it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import copy
import sys

import pytest


def pytest_configure(config):
    """System packages some tests need (libtbb12 for ecospy; g++ and CMake for the rebuilt
    pythonfmu wrapper), installed by .ci/system-deps where missing and apt-get runs as root,
    so that the README's test command tests what CI tests. MILLFMU_NO_APT=1 leaves the
    system alone (the tests concerned then skip with the reason)."""
    import ctypes.util
    import shutil
    import subprocess
    from pathlib import Path

    if (os.environ.get("MILLFMU_NO_APT") == "1" or os.name != "posix"
            or getattr(config, "workerinput", None) is not None):
        return
    script = Path(__file__).resolve().parents[1] / ".ci" / "system-deps"
    cmake = shutil.which("cmake") or shutil.which("cmake", path=str(Path(sys.executable).parent))
    missing = ctypes.util.find_library("tbb") is None or shutil.which("c++") is None or cmake is None
    if not (missing and script.is_file() and shutil.which("apt-get") and os.geteuid() == 0):
        return
    r = subprocess.run(["bash", str(script)], capture_output=True, text=True,
                       env={**os.environ, "PYTHON": sys.executable})
    for line in (r.stdout + r.stderr).splitlines():
        print(f"millfmu tests: {line} (.ci/system-deps; MILLFMU_NO_APT=1 skips this)", file=sys.stderr)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from millfmu.scene import default_scene_text, scene_from_dict


@pytest.fixture
def scene_dict():
    """The default scene (Kwade's simple model) as a dict, to be modified by a test."""
    return copy.deepcopy(tomllib.loads(default_scene_text()))


@pytest.fixture
def detailed_scene_dict():
    """The detailed example (the default case with the detailed model on the shipped coupled
    DEM-CFD table, limestone_detailed.toml) as a dict, to be modified by a test."""
    from millfmu.scene import example_path

    return copy.deepcopy(tomllib.loads(example_path("limestone_detailed.toml").read_text()))


def make_scene(d, **sections):
    """Scene from dict ``d`` with sections updated: make_scene(d, mill={"tip_speed_m_per_s": 6})."""
    d = copy.deepcopy(d)
    for sec, vals in sections.items():
        if vals is None:
            d.pop(sec, None)
            continue
        d.setdefault(sec, {})
        for k, v in vals.items():
            if isinstance(v, dict) and isinstance(d[sec].get(k), dict):
                d[sec][k].update(v)
            else:
                d[sec][k] = v
    return scene_from_dict(d)
