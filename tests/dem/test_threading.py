"""The DEM's parallel launches must not accumulate cost: a run's cost stays linear in its
simulated time (numba's TBB layer kept memory per launch and slowed down with each)."""

import os
import subprocess
import sys

import pytest

pytest.importorskip("numba")

CODE = r"""
import numpy as np, numba
from millfmu.dem.geometry import MillGeometry, place_beads
from millfmu.dem.params import BeadMaterial
from millfmu.dem.sim import DemSimulation
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
    assert layer == "workqueue"
    # TBB kept about 7 kB per launch: 40 MB here
    assert int(grown_kb) < 4000
