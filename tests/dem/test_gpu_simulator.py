"""The numba.cuda path of the DEM, tested without a GPU: the cases of gpu_cases.py run in
a process with NUMBA_ENABLE_CUDASIM=1 (numba's CUDA simulator must be chosen before
numba.cuda is first imported, hence the separate process)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")


def test_gpu_path_under_the_cuda_simulator():
    here = Path(__file__).resolve().parent
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        str(here / "gpu_cases.py")], cwd=here.parent.parent, env=env,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-6000:] + r.stderr[-2000:]
    assert " passed" in r.stdout and "skipped" not in r.stdout
