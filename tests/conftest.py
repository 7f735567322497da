import os

# The model's matrices are small (tens to hundreds of rows): multithreaded BLAS only adds
# overhead, and on a loaded 2-core machine oversubscription slows expm a hundredfold.
# Set before numpy loads; subprocesses (FMU runs) inherit it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import copy
import sys

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from millfmu.scene import default_scene_text, scene_from_dict


@pytest.fixture
def scene_dict():
    """The default scene as a dict, to be modified by a test."""
    return copy.deepcopy(tomllib.loads(default_scene_text()))


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
