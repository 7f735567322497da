"""The first DEM run with the installed kernel sources says that it compiles them first."""

import subprocess
import sys

CODE = r"""
import os, pathlib, sys
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
from millfmu.dem.first_compile import kernel_cache_is_cold, say_if_compiling
lines = []
cold = kernel_cache_is_cold()
said = say_if_compiling(coupled=True, log=lines.append)
pathlib.Path(cold, "x").mkdir(parents=True)
pathlib.Path(cold, "x", "kernels.step-1.py311.nbi").write_bytes(b"")
print(repr((str(cold), said, lines, kernel_cache_is_cold(), say_if_compiling(coupled=False, log=lines.append))))
"""


def test_a_cold_kernel_cache_is_announced_and_a_warm_one_is_not(tmp_path):
    r = subprocess.run([sys.executable, "-c", CODE, str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    cold, said, lines, warm, said_again = eval(r.stdout.strip().splitlines()[-1])
    assert cold.startswith(str(tmp_path)) and said and warm is None and said_again is False
    assert len(lines) == 1 and "compiling the kernels with the coupled liquid" in lines[0]
    assert "about 150 s on 2 cores: the DEM's" in lines[0] and cold in lines[0]


WATCH = r"""
import numba
import millfmu.dem.first_compile as fc
fc.SAY_ABOVE_S = 0.0
lines = []
fc.watch_compiles(lines.append)
fc.watch_compiles(lines.append)  # once per process: no second line per compilation

@numba.njit
def twice(a):
    return 2 * a

twice(1)
twice(2)  # compiled already: no line
print(repr(lines))
"""


def test_each_long_compilation_is_named_with_its_time():
    r = subprocess.run([sys.executable, "-c", WATCH], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = eval(r.stdout.strip().splitlines()[-1])
    assert len(lines) == 1 and lines[0].startswith("millfmu: compiled __main__.twice in ")
    assert lines[0].endswith(" s")


def test_dem_run_says_it_before_the_run(monkeypatch, capsys, tmp_path):
    import millfmu.dem.first_compile as fc
    import millfmu.dem.run as run
    from millfmu.cli import main

    monkeypatch.setattr(fc, "kernel_cache_is_cold", lambda: tmp_path)

    def stop(*a, **kw):
        raise run.DemRunError("stopped by the test")

    monkeypatch.setattr(run, "run_scene", stop)
    assert main(["dem", "run", "annulus", "--fluid", "none", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.index("compiling the kernels of the DEM") < err.index("stopped by the test")
