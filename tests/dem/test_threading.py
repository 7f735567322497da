"""The DEM's parallel launches must not accumulate cost: a run's cost stays linear in its
simulated time (numba's TBB layer kept memory per launch and slowed down with each)."""

import os
import subprocess
import sys

import pytest

pytest.importorskip("numba")

CODE = r"""
import numpy as np, numba
from millfmu.dem.mills.geometry import MillGeometry, place_beads
from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.engine.sim import DemSimulation
geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
x = place_beads(geom, 700, 0.4e-3, seed=5)
sim = DemSimulation(geom, BeadMaterial(), x, 0.4e-3, 300.0, 5e-6, threads=2)
sim.run(50)
def rss_kb():
    return int(open("/proc/self/status").read().split("VmRSS:")[1].split()[0])
before = rss_kb()
sim.run(3000)  # about 6000 parallel launches
print(numba.threading_layer(), rss_kb() - before)
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs /proc (Linux)")
def test_parallel_launches_keep_no_memory():
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    env["NUMBA_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True,
                         env=env, check=True)
    layer, grown_kb = out.stdout.split()
    assert layer == _expected_layer()
    # TBB kept about 7 kB per launch: 40 MB here
    assert int(grown_kb) < 4000


def _expected_layer() -> str:
    """The layer millfmu.dem chooses: OpenMP where numba's omp layer loads, else workqueue."""
    import importlib

    try:
        importlib.import_module("numba.np.ufunc.omppool")  # needs GNU OpenMP's runtime
    except ImportError:
        return "workqueue"
    return "omp"


POOL_AFTER_DEM = r"""
import os, sys
sys.path.insert(0, os.getcwd())
import numba
from millfmu.dem.mills.geometry import MillGeometry, place_beads
from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.engine.sim import DemSimulation
from millfmu.dem import tables as T
from tests.tables._builders import dem_threads_builder
geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
x = place_beads(geom, 300, 0.4e-3, seed=5)
DemSimulation(geom, BeadMaterial(), x, 0.4e-3, 300.0, 5e-6, threads=2).run(20)
spec = T.TableSpec(scene={"name": "analytic"},
                   grid={"tip_speed_m_per_s": [6.0, 14.0], "filling": [0.5, 0.9]},
                   kernel_version="test-kernel-1",
                   builder_id=T.builder_id_of(dem_threads_builder))
t = T.build_table(spec, dem_threads_builder, executor="processes", workers=2,
                  progress=False)
print(numba.threading_layer(), t.data["collision_count"].shape[:2])
"""


@pytest.mark.skipif(sys.platform != "linux", reason="fork is the default start method on Linux")
def test_tables_process_pool_runs_the_dem_after_the_parent_did():
    """A process that has run the DEM's parallel kernels (an OpenMP team) builds a table
    with the process pool whose workers run them too: the workers are spawned, since a
    forked child of a GNU OpenMP process cannot run OpenMP kernels (numba stops it)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    env["NUMBA_NUM_THREADS"] = "2"
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out = subprocess.run([sys.executable, "-c", POOL_AFTER_DEM], capture_output=True,
                         text=True, env=env, cwd=root, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[0] == _expected_layer()
    assert "(2, 2)" in out.stdout


FIRST_SETTING = r"""
import os
import numba
from millfmu.dem.engine.sim import DemSimulation  # the class only: no kernel module yet
from millfmu.dem.engine._jit import use_threads
os.environ["NUMBA_DEBUG_CACHE"] = "0"  # a NUMBA_ variable changes: numba re-reads them all
numba.core.config.reload_config()
use_threads(2)
print(numba.threading_layer())
"""


def test_the_first_thread_setting_chooses_the_package_layer():
    """The DEM bench set numba's thread count before any kernel module was loaded, which
    settled numba's own first choice (TBB) for the whole process: its millfmu rows and the
    coupled row ran on TBB while `dem run` ran on OpenMP. Setting the count through
    use_threads chooses the package's layer, also after numba has re-read its
    configuration from a changed environment."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")}
    env["NUMBA_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", FIRST_SETTING], capture_output=True,
                         text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == _expected_layer()


def test_the_package_sets_thread_counts_only_through_use_threads():
    """numba.set_num_threads anywhere else in the package could run before the layer is
    set up (see the test above)."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[2] / "millfmu"
    offenders = [str(f.relative_to(root)) for f in root.rglob("*.py")
                 if f.name != "_jit.py" and re.search(r"\bset_num_threads\(", f.read_text())]
    assert offenders == []
