"""The first DEM run with the installed kernel sources says that it compiles them first, and
compiles them in several processes from the shipped plan."""

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(code, *args, env=None):
    e = dict(os.environ, **(env or {}))
    r = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True,
                       text=True, env=e, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return eval(r.stdout.strip().splitlines()[-1])


NO_PLAN = r"""
import os, pathlib, sys
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
from millfmu.dem.first_compile import kernel_cache_is_cold, compile_if_cold
lines = []
cold = kernel_cache_is_cold()
said = compile_if_cold(coupled=True, log=lines.append, plan=pathlib.Path(sys.argv[1], "none.json"))
pathlib.Path(cold, "x").mkdir(parents=True)
pathlib.Path(cold, "x", "kernels.step-1.py311.nbi").write_bytes(b"")
again = compile_if_cold(coupled=False, log=lines.append, plan=pathlib.Path(sys.argv[1], "none.json"))
print(repr((str(cold), said, lines, kernel_cache_is_cold(), again)))
"""


def test_without_a_plan_a_cold_cache_is_announced_and_a_warm_one_is_not(tmp_path):
    cold, said, lines, warm, said_again = _run(NO_PLAN, tmp_path)
    assert cold.startswith(str(tmp_path)) and said and warm is None and said_again is False
    assert len(lines) == 1 and "compiling the kernels with the coupled liquid" in lines[0]
    assert "about 165 s on one core" in lines[0] and cold in lines[0]


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
    lines = _run(WATCH)
    assert len(lines) == 1 and lines[0].startswith("millfmu: compiled __main__.twice in ")
    assert lines[0].endswith(" s")


def test_dem_run_says_it_before_the_run(monkeypatch, capsys, tmp_path):
    import millfmu.dem.first_compile as fc
    import millfmu.dem.run as run
    from millfmu.cli import main

    monkeypatch.setattr(fc, "load_plan", lambda what, plan: None)
    monkeypatch.setattr(fc, "kernel_cache_is_cold", lambda: tmp_path)

    def stop(*a, **kw):
        raise run.DemRunError("stopped by the test")

    monkeypatch.setattr(run, "run_scene", stop)
    assert main(["dem", "run", "annulus", "--fluid", "none", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.index("compiling the kernels of the DEM") < err.index("stopped by the test")


# -- the plan ------------------------------------------------------------------------------

def _jobs(*spec):
    """jobs from (seconds, after) pairs"""
    return [{"kernel": f"k{i}", "args": [], "seconds": s, "after": list(a)}
            for i, (s, a) in enumerate(spec)]


def test_the_schedule_starts_the_longest_chain_first_and_waits_for_callees():
    from millfmu.dem.first_compile import estimate_s, order, priorities

    # k0 (1 s) and k1 (4 s) are called by k2 (3 s); k3 (5 s) stands alone
    jobs = _jobs((1, ()), (4, ()), (3, (0, 1)), (5, ()))
    assert priorities(jobs) == [4, 7, 3, 5]
    assert order(jobs, 1) == ([1, 3, 0, 2], 13)  # one process: the sum
    # two: k1 and k3 first; k0 when k1 is done (4 s), k2 when k0 is (5 s): 8 s, not 6
    assert order(jobs, 2) == ([1, 3, 0, 2], 8)
    assert order(jobs, 4) == ([1, 3, 0, 2], 7)  # the chain k1 -> k2 bounds it
    assert estimate_s(jobs, 1) == 13 and estimate_s(jobs, 2) > 8


def test_the_argument_types_round_trip():
    from numba.core import types

    from millfmu.dem.first_compile import decode_type, encode_type

    a = types.Array(types.float64, 3, "C")
    ts = [types.float64, types.int64, types.boolean, types.int8, types.literal(True),
          types.literal(False), a, types.Array(types.uint8, 1, "C", readonly=True),
          types.UniTuple(a, 27), types.Tuple([a, types.int64, types.UniTuple(types.boolean, 2)])]
    for t in ts:
        x = encode_type(t)
        assert decode_type(json.loads(json.dumps(x))) == t, t
    with pytest.raises(ValueError, match="holds no argument of type"):
        encode_type(types.unicode_type)


def test_the_shipped_plan_is_of_the_installed_kernel_sources():
    from millfmu.dem.engine._jit import sources_key
    from millfmu.dem.first_compile import PLAN_FILE, _dispatcher, decode_type, load_plan

    plan = json.loads(PLAN_FILE.read_text())
    assert plan["sources_key"] == sources_key(), (
        "the kernel sources changed: record the plan again "
        "(python -m millfmu.dem.first_compile record)")
    for what in ("dem", "coupled", "coupled_calls"):
        jobs = load_plan(what)
        assert jobs and all(k < i for i, j in enumerate(jobs) for k in j["after"])
        for j in jobs:
            assert _dispatcher(j["kernel"]).py_func.__qualname__ == j["kernel"].rpartition(".")[2]
            [decode_type(a) for a in j["args"]]
    coupled = {j["kernel"] for j in load_plan("coupled")}
    assert "millfmu.dem.coupling.fused_exchange.coupled_intervals" in coupled
    assert "millfmu.dem.engine.kernels.compute_forces" in coupled
    calls = {j["kernel"] for j in load_plan("coupled_calls")}
    assert "millfmu.dem.engine.kernels.compute_forces" in calls
    assert not any(k.startswith("millfmu.dem.coupling.fused_exchange.") for k in calls)
    took = {w: sum(j["seconds"] for j in load_plan(w)) for w in ("coupled", "coupled_calls")}
    assert took["coupled_calls"] < 0.75 * took["coupled"], took  # what the short run is spared


TOY = r"""
import json, os, sys
from pathlib import Path
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
from numba.core import types
import millfmu.dem.first_compile as fc
from millfmu.dem.engine._jit import sources_key
a = types.Array(types.float64, 1, "C")
jobs = [{"kernel": "tests.dem._plan_kernels.inner", "args": [fc.encode_type(a), "bool"],
         "seconds": 1.0, "after": []},
        {"kernel": "tests.dem._plan_kernels.outer",
         "args": [fc.encode_type(a), fc.encode_type(types.UniTuple(a, 2))],
         "seconds": 1.0, "after": [0]}]
plan = Path(sys.argv[1], "plan.json")
plan.write_text(json.dumps({"sources_key": sources_key(), "runs": {"dem": {"jobs": jobs}}}))
lines = []
said = fc.compile_if_cold(False, log=lines.append, processes=2, plan=plan)
again = fc.compile_if_cold(False, log=lines.append, processes=2, plan=plan)
# a plan with one more job (another signature of inner): only that one is compiled and counted
jobs.append({"kernel": "tests.dem._plan_kernels.inner",
             "args": [fc.encode_type(types.Array(types.float32, 1, "C")), "bool"],
             "seconds": 7.0, "after": []})
plan.write_text(json.dumps({"sources_key": sources_key(), "runs": {"dem": {"jobs": jobs}}}))
more = []
fc.compile_if_cold(False, log=more.append, processes=2, plan=plan)
print(repr((said, again, lines, more)))
"""

LOAD = r"""
import os, sys
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
import numpy as np
from numba.core import event
compiled = []
class L(event.Listener):
    def on_start(self, ev): compiled.append(ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev): pass
event.register("numba:compile", L())
from tests.dem._plan_kernels import outer
x = np.arange(3.0)
print(repr((outer(x, (x, x)), compiled)))
"""


def test_a_plan_compiled_in_two_processes_is_loaded_by_the_run(tmp_path):
    said, again, lines, more = _run(TOY, tmp_path)
    assert said and not again
    assert "in 2 processes" in lines[0] and lines[-1].startswith("millfmu: compiled 2 kernels in ")
    assert "left to the run" not in lines[-1]
    # what was compiled before is neither estimated nor compiled again
    assert "(1 of 3 not compiled yet; about 8 s on 2 free cores" in more[0], more
    assert more[-1].startswith("millfmu: compiled 1 kernel in "), more
    value, compiled = _run(LOAD, tmp_path)
    assert value == 5.0 + 3.0 and compiled == []  # both loaded from the cache, none compiled


COVERED = r"""
import os, sys, tempfile
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
from numba.core import event
import millfmu.dem.first_compile as fc
lines = []
# a long run's form (the fused exchange) for "coupled", a short run's for "coupled_calls"
run_s = 0.004 if sys.argv[2] == "coupled_calls" else None
assert fc.compile_if_cold(sys.argv[2] != "dem", log=lines.append, processes=2, run_s=run_s)
compiled = []
class L(event.Listener):
    def on_start(self, ev):
        f = ev.data["dispatcher"].py_func
        compiled.append(f.__module__ + "." + f.__qualname__)
    def on_end(self, ev): pass
event.register("numba:compile", L())
from millfmu.cli import main
with tempfile.TemporaryDirectory() as tmp:
    rc = main(["dem", "run", *fc.PLAN_RUNS[sys.argv[2]], "--out", tmp + "/r", "--no-progress"])
print(repr((rc, lines, [c for c in compiled if c.startswith("millfmu.")])))
"""


WARM = r"""
import os, sys
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]
import millfmu.dem.first_compile as fc
lines = []
run_s = 0.004 if sys.argv[2] == "coupled_calls" else None
print(repr((fc.compile_if_cold(sys.argv[2] != "dem", log=lines.append, run_s=run_s), lines)))
"""


@pytest.mark.parametrize("what", ["dem", pytest.param("coupled", marks=pytest.mark.slow),
                                  pytest.param("coupled_calls", marks=pytest.mark.slow)])
def test_the_shipped_plan_covers_its_run(tmp_path, what):
    """Compiled from the plan in 2 processes, the plan's own short run compiles no kernel of
    the package (numba's helpers it may): with the fused exchange compiled first (as for a
    long run) the short run takes it; with the plan's short form, the exchange by calls.
    dem: about 25 s on 2 cores; coupled: about 100 s; coupled_calls: about 70 s.
    A new process then finds the kernels cached and says nothing (the check loads no kernel:
    a cached parallel kernel loaded before numba's threading layer had started aborted the
    process)."""
    rc, lines, compiled = _run(COVERED, tmp_path, what)
    assert rc == 0 and compiled == [], (lines, compiled)
    assert "left to the run" not in lines[-1]
    assert _run(WARM, tmp_path, what) == (False, [])


def test_dem_run_compiles_in_as_many_processes_as_its_threads(monkeypatch, tmp_path):
    """``dem run --threads N``: the first run's compilation takes the N cores the run was
    given, not all of them; without --threads, all (the count left to compile_if_cold)."""
    import millfmu.dem.first_compile as fc
    import millfmu.dem.run as run
    from millfmu.cli import main

    asked = []
    monkeypatch.setattr(fc, "compile_if_cold", lambda coupled, **kw: asked.append(kw) or False)

    def stop(*a, **kw):
        raise run.DemRunError("stopped by the test")

    monkeypatch.setattr(run, "run_scene", stop)
    for extra, want in ((["--threads", "1"], 1), ([], None)):
        assert main(["dem", "run", "annulus", "--fluid", "none", "--out", str(tmp_path / "o"), *extra]) == 2
        assert asked.pop()["processes"] == want


def test_a_resumed_run_compiles_a_cold_cache_first(monkeypatch, tmp_path):
    """``dem run --resume DIR`` on a cold kernel cache: the stopped run's scene decides what
    is compiled (coupled or not), in as many processes as --threads gives, before the run
    goes on; on a warm cache the checkpoint is not read for it; a folder without a
    checkpoint is refused by the resume, nothing compiled."""
    import millfmu.dem.first_compile as fc
    import millfmu.dem.run as run
    from millfmu.cli import main
    from millfmu.dem.scene import load_scene

    asked, read = [], []
    monkeypatch.setattr(fc, "compile_if_cold", lambda coupled, **kw: asked.append((coupled, kw)) or False)
    monkeypatch.setattr(fc, "missing", lambda jobs: True)
    assert main(["dem", "run", "--resume", str(tmp_path)]) == 2  # no checkpoint there
    assert asked == []
    scene = load_scene("disc_slice")
    assert scene.fluid_mode == "coupled"

    def stopped(out_dir):
        read.append(out_dir)
        return {"kernel_version": run._kernel_version(), "scene": scene, "sim": types.SimpleNamespace(),
                "window_s": None, "contacts": False}

    def stop(*a, **kw):
        raise run.DemRunError("stopped by the test")

    monkeypatch.setattr(run, "load_checkpoint", stopped)
    monkeypatch.setattr(run, "run_scene", stop)
    assert main(["dem", "run", "--resume", str(tmp_path), "--threads", "1"]) == 2
    assert asked == [(True, {"processes": 1})]
    monkeypatch.setattr(fc, "missing", lambda jobs: False)
    read.clear()
    assert main(["dem", "run", "--resume", str(tmp_path)]) == 2
    assert len(asked) == 1 and len(read) == 1  # read by the resume only


def test_the_variable_sets_the_compiling_processes_whatever_cores_the_run_has(monkeypatch):
    """MILLFMU_COMPILE_PROCESSES, where set, wins over the cores a run was given (dem run
    --threads), so that 1 compiles in the run's own process; unset, those cores are taken;
    not a whole number, it is named and the cores are taken."""
    from millfmu.dem import first_compile as fc

    monkeypatch.delenv("MILLFMU_COMPILE_PROCESSES", raising=False)
    assert fc.processes_here(cores=2) == 2 and fc.processes_here(cores=99) == fc.MAX_PROCESSES
    monkeypatch.setenv("MILLFMU_COMPILE_PROCESSES", "1")
    assert fc.processes_here(cores=2) == 1
    said = []
    monkeypatch.setenv("MILLFMU_COMPILE_PROCESSES", "two")
    assert fc.processes_here(log=said.append, cores=3) == 3
    assert said and "MILLFMU_COMPILE_PROCESSES = 'two' is not a whole number" in said[0]


def test_a_short_coupled_run_takes_the_exchange_by_calls_until_the_fused_one_is_compiled(monkeypatch):
    """The fused exchange (the same results to the bit) is taken by a run of FUSED_FROM_S
    or longer, or where its kernels are compiled, or where no plan tells them; a shorter run
    on a cold cache takes the exchange by calls, with two fifths less to compile; the
    variable decides instead where set to 0 or 1, another value is named and ignored."""
    from millfmu.dem import first_compile as fc

    monkeypatch.delenv(fc.FUSED_ENV, raising=False)
    monkeypatch.setattr(fc, "missing", lambda jobs: True)  # the fused kernels not compiled
    assert fc.fused_exchange(None) and fc.fused_exchange(fc.FUSED_FROM_S)
    assert not fc.fused_exchange(0.004)
    assert fc.fused_exchange(0.004, plan=Path("no-such-plan.json"))  # nothing to tell them by
    monkeypatch.setattr(fc, "missing", lambda jobs: False)  # compiled
    assert fc.fused_exchange(0.004)
    monkeypatch.setenv(fc.FUSED_ENV, "0")
    assert not fc.fused_exchange(None)
    monkeypatch.setenv(fc.FUSED_ENV, "1")
    monkeypatch.setattr(fc, "missing", lambda jobs: True)
    assert fc.fused_exchange(0.004)
    said = []
    monkeypatch.setenv(fc.FUSED_ENV, "yes")
    monkeypatch.setattr(fc, "_named", set())
    assert not fc.fused_exchange(0.004, log=said.append)
    assert not fc.fused_exchange(0.004, log=said.append)  # named once: compilation and run both ask
    assert said == [f"millfmu: {fc.FUSED_ENV} = 'yes': 0 (the exchange by calls) or 1 (fused); ignored"]


def test_the_run_and_its_compilation_take_the_same_form(monkeypatch, tmp_path):
    """``dem run`` compiles the plan of the form the run then takes: the run's simulated
    seconds (spin-up and recording) go to both decisions, compile_if_cold's and run_scene's
    on the coupling."""
    import millfmu.dem.first_compile as fc
    import millfmu.dem.run as run
    from millfmu.cli import main

    asked, decided, taken = [], [], []
    monkeypatch.setattr(fc, "compile_if_cold", lambda coupled, **kw: asked.append(kw) or False)
    monkeypatch.setattr(fc, "fused_exchange", lambda run_s, *a, **kw: decided.append(run_s) or False)

    def record(scene, sim, cpl, *a, **kw):
        taken.append(cpl.fused)
        raise run.DemRunError("stopped by the test")

    monkeypatch.setattr(run, "_record", record)
    assert main(["dem", "run", "disc_slice", "--out", str(tmp_path / "o"), "--sector-deg", "10",
                 "--no-gravity", "--spin-up", "0.002", "--record", "0.002"]) == 2
    assert asked[0]["run_s"] == pytest.approx(0.004) and decided == [pytest.approx(0.004)]
    assert taken == [False]
