"""The first DEM run with the installed kernel sources: numba compiles the DEM's kernels
then (a minute or more). Without a word a user takes that for a hang, and one process
compiles them one after another on one core.

numba caches the compiled kernels in :func:`millfmu.dem.engine._jit.kernel_cache_dir`, a
folder keyed by the kernel sources; an index file (``*.nbi``) there means they were
compiled before and load in seconds.

Where the cache is cold, :func:`compile_if_cold` says so on stderr and compiles the kernels
a run needs in several processes at once, from a plan shipped beside this module
(``compile_plan.json``): every kernel and argument types that a short run compiled, with
its own compile time and the kernels it calls. Each process compiles a kernel whose callees
are done (loading those that another process compiled from numba's cache), the longest
chain first, and numba caches each; the run then loads them all. numba compiles one kernel
on one core, so two processes on 2 cores roughly halve the wait (the measure and its
figures: docs/dem-performance.md, "The first run's compilation"). A kernel that the plan
does not hold, or a plan of other sources, is compiled by the run itself, and each kernel
that takes :data:`SAY_ABOVE_S` or more is named on stderr when it is done
(:func:`watch_compiles`).

A short coupled run takes the exchange by calls where the fused exchange's kernels are not
compiled yet (:func:`fused_exchange`): the same results to the bit, two fifths less to
compile. The plan holds both forms.

The plan is made from a checkout with ``python -m millfmu.dem.first_compile record`` (three
short runs on an empty cache, about 8 minutes) whenever the kernel sources change; a test
fails while it names other sources.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

#: Compile times [s] of a short run compiled in one process on 2 cores, by what runs:
#: the estimate where no current plan is shipped (see the module docstring).
SECONDS = {"dem": 30, "coupled": 165, "coupled_calls": 115}
#: the plan of what a short run compiles, shipped with the package
PLAN_FILE = Path(__file__).with_name("compile_plan.json")
#: the short runs the plan is recorded from, by what runs (``millfmu dem run`` arguments)
PLAN_RUNS = {
    "dem": ["disc_slice", "--sector-deg", "10", "--no-gravity", "--fluid", "none",
            "--spin-up", "0.002", "--record", "0.002", "--threads", "2"],
    "coupled": ["disc_slice", "--sector-deg", "10", "--no-gravity", "--fluid", "coupled",
                "--spin-up", "0.002", "--record", "0.002", "--threads", "2"],
}
PLAN_RUNS["coupled_calls"] = PLAN_RUNS["coupled"]
#: how each recorded run's exchange is taken (:data:`FUSED_ENV`): the coupled run's fused,
#: as a long run takes it, the other's by calls, as a short run on a cold cache does
PLAN_FUSED = {"dem": "", "coupled": "1", "coupled_calls": "0"}
#: at most this many compiling processes (each holds numba and LLVM: 290-310 MB resident
#: while compiling, measured)
MAX_PROCESSES = 8
#: seconds a compiling process takes to start: the imports of numba and the kernel modules
#: took 0.33-0.38 s on 2 cores, rounded up for the spawn (the plan's schedule, 86 s on 2
#: processes, against 83-88 s measured)
PROCESS_START_S = 1.0
#: a kernel whose own compilation takes this long [s] or longer is named when it is done
SAY_ABOVE_S = 5.0
#: the listener of :func:`watch_compiles` where one is registered (one per process)
_watching = []
#: a coupled run of at least this many simulated seconds (spin-up and recording) takes the
#: fused exchange (:mod:`millfmu.dem.coupling.fused_exchange`, the same results to the bit
#: as the exchange by calls) even where its kernels are not compiled yet; a shorter run
#: takes it only where they are. The fused kernels are two fifths of the coupled run's
#: compile time (the shipped plan: 156 s in one process by calls, 221 s fused), and a short
#: run, a user's first trial, gains little from them; runs this long (a table point, a
#: campaign's case) are where they pay
FUSED_FROM_S = 0.5
#: the environment variable that decides instead: "1" the fused exchange wherever its form
#: allows, "0" the exchange by calls
FUSED_ENV = "MILLFMU_FUSED_EXCHANGE"
#: the values of FUSED_ENV named as ignored in this process (each once)
_named = set()


def kernel_cache_is_cold() -> Path | None:
    """The kernel cache folder where no kernel of the installed sources has been compiled
    yet, else None. Imports numba (the caller is about to run the DEM)."""
    from .engine._jit import kernel_cache_dir

    d = kernel_cache_dir()
    try:
        if any(d.rglob("*.nbi")):
            return None
    except OSError:
        pass
    return d


def _say(log):
    return log or (lambda m: print(m, file=sys.stderr, flush=True))


# -- the plan: kernels, argument types, compile times -----------------------------------

def encode_type(t) -> str | list:
    """A numba argument type as JSON (scalars by name; arrays, tuples and literal flags as
    lists); ValueError for a kind the plan does not hold."""
    from numba.core import types

    if isinstance(t, types.Literal):
        if isinstance(t.literal_value, (bool, int)):
            return ["literal", t.literal_value]
    elif isinstance(t, types.Array):
        return ["array", encode_type(t.dtype), t.ndim, t.layout, bool(t.mutable), bool(t.aligned)]
    elif isinstance(t, types.UniTuple):
        return ["unituple", encode_type(t.dtype), t.count]
    elif isinstance(t, types.Tuple):
        return ["tuple", [encode_type(x) for x in t.types]]
    elif isinstance(t, (types.Boolean, types.Integer, types.Float)):
        return str(t)
    raise ValueError(f"a compile plan holds no argument of type {t} ({type(t).__name__})")


def decode_type(x):
    """The numba type that :func:`encode_type` wrote as ``x``."""
    from numba.core import types

    if isinstance(x, str):
        t = types.boolean if x == "bool" else getattr(types, x, None)
        if not isinstance(t, types.Type):
            raise ValueError(f"compile plan: no numba scalar type {x!r}")
        return t
    kind = x[0]
    if kind == "literal":
        return types.literal(x[1])
    if kind == "array":
        return types.Array(decode_type(x[1]), x[2], x[3], readonly=not x[4], aligned=x[5])
    if kind == "unituple":
        return types.UniTuple(decode_type(x[1]), x[2])
    if kind == "tuple":
        return types.Tuple([decode_type(y) for y in x[1]])
    raise ValueError(f"compile plan: unknown argument kind {kind!r}")


def _dispatcher(kernel: str):
    """The numba dispatcher named ``module.function`` (a module-level kernel)."""
    import importlib

    module, _, name = kernel.rpartition(".")
    return getattr(importlib.import_module(module), name)


def load_plan(what: str, path: Path = PLAN_FILE) -> list[dict] | None:
    """The shipped plan's jobs for ``what`` ("dem" or "coupled"), each ``{"kernel",
    "args", "seconds", "after"}`` (``after``: indices of earlier jobs it calls), or None
    where there is none for the installed kernel sources. (Recorded with another numba, the
    argument types stay the same; a job whose types a numba no longer makes compiles in
    vain, and the run compiles its own.)"""
    import json

    from .engine._jit import sources_key

    try:
        plan = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if plan.get("sources_key") != sources_key():
        return None
    run = (plan.get("runs") or {}).get(what)
    return None if not run else run["jobs"]


def priorities(jobs: list[dict]) -> list[float]:
    """Each job's longest chain of compile time [s]: its own and that of the jobs that
    call it, up to the last. The longest chain is compiled first."""
    prio = [float(j["seconds"]) for j in jobs]
    for i in range(len(jobs) - 1, -1, -1):
        for k in jobs[i]["after"]:
            prio[k] = max(prio[k], float(jobs[k]["seconds"]) + prio[i])
    return prio


class _Ready:
    """The jobs whose callees are done, the longest chain first (:func:`priorities`): what
    :func:`order` simulates and :func:`compile_plan` runs."""

    def __init__(self, jobs: list[dict]):
        import heapq

        self._heapq = heapq
        self.prio = priorities(jobs)
        self.waiting = [len(j["after"]) for j in jobs]
        self.callers = [[] for _ in jobs]
        for i, j in enumerate(jobs):
            for k in j["after"]:
                self.callers[k].append(i)
        self.heap = [(-self.prio[i], i) for i, n in enumerate(self.waiting) if n == 0]
        heapq.heapify(self.heap)

    def __bool__(self) -> bool:
        return bool(self.heap)

    def pop(self) -> int:
        """The ready job with the longest chain."""
        return self._heapq.heappop(self.heap)[1]

    def done(self, i: int) -> None:
        """Job ``i`` is compiled: its callers whose callees are all done become ready."""
        for c in self.callers[i]:
            self.waiting[c] -= 1
            if self.waiting[c] == 0:
                self._heapq.heappush(self.heap, (-self.prio[c], c))


def order(jobs: list[dict], processes: int) -> tuple[list[int], float]:
    """Simulate compiling ``jobs`` in ``processes`` processes as :func:`compile_plan`
    does, each job taking its ``seconds``: (the order the jobs start in, the wall time
    [s])."""
    import heapq

    ready = _Ready(jobs)
    running, now, started = [], 0.0, []
    while ready or running:
        while ready and len(running) < processes:
            i = ready.pop()
            started.append(i)
            heapq.heappush(running, (now + float(jobs[i]["seconds"]), i))
        now, i = heapq.heappop(running)
        ready.done(i)
    return started, now


def processes_here(log=None, cores: int | None = None) -> int:
    """The compiling processes to start: MILLFMU_COMPILE_PROCESSES where set (1: compile
    in the run's own process), else ``cores`` (the cores the run was given) where given,
    else the cores this process may use; at most :data:`MAX_PROCESSES`. A value that is no
    whole number is named (on stderr or ``log``) and the cores are taken."""
    import os

    if cores is None:
        try:
            cores = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):
            cores = os.cpu_count() or 1
    given = os.environ.get("MILLFMU_COMPILE_PROCESSES", "").strip()
    if given:
        try:
            return max(1, min(MAX_PROCESSES, int(given)))
        except ValueError:
            _say(log)(f"millfmu: MILLFMU_COMPILE_PROCESSES = {given!r} is not a whole number "
                      f"(1 to {MAX_PROCESSES} processes): the cores here are taken")
    return max(1, min(MAX_PROCESSES, int(cores)))


def estimate_s(jobs: list[dict], processes: int) -> float:
    """The plan's wall time [s] in ``processes`` processes, their start included."""
    return order(jobs, processes)[1] + (PROCESS_START_S if processes > 1 else 0.0)


def _compile_job(kernel: str, args: list) -> tuple[float, str]:
    """In a compiling process: compile (or load from numba's cache) ``kernel`` for the
    argument types ``args``; (seconds, "" or the error)."""
    t0 = time.perf_counter()
    try:
        _dispatcher(kernel).compile(tuple(decode_type(a) for a in args))
    except Exception as e:  # noqa: BLE001 - the run compiles it itself then
        return time.perf_counter() - t0, f"{type(e).__name__}: {e}"
    return time.perf_counter() - t0, ""


def _is_cached(job: dict) -> bool:
    """Whether numba's cache index holds the job's kernel for its argument types (the key
    numba's own load looks up; nothing is loaded, so the run loads each kernel once)."""
    try:
        d = _dispatcher(job["kernel"])
        sig = tuple(decode_type(a) for a in job["args"])
        key = d._cache._index_key(sig, d.targetctx.codegen())
        return key in d._cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - an unreadable entry counts as not cached
        return False


def missing(jobs: list[dict]) -> bool:
    """Whether a kernel that the plan's run calls directly (a job that no other job calls)
    is not in numba's cache yet."""
    called = {k for j in jobs for k in j["after"]}
    return not all(_is_cached(j) for i, j in enumerate(jobs) if i not in called)


def compile_plan(jobs: list[dict], processes: int, log=None,
                 skip: frozenset = frozenset()) -> tuple[float, list[str], int]:
    """Compile the plan's jobs in ``processes`` new processes (spawned: the caller may have
    run OpenMP), each job once the jobs it calls are done, the longest chain first; name
    each that took :data:`SAY_ABOVE_S` or more. ``skip``: the indices of jobs compiled
    already (:func:`cached_jobs`), counted as done. (wall time [s], the errors of jobs that
    failed: the run compiles those itself, the jobs compiled)."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    say = _say(log)
    t0 = time.perf_counter()
    ready = _Ready(jobs)
    errors = []
    submitted = 0
    with ProcessPoolExecutor(max_workers=processes, mp_context=mp.get_context("spawn")) as pool:
        running = {}
        while ready or running:
            while ready and len(running) < processes:
                i = ready.pop()
                if i in skip:
                    ready.done(i)
                    continue
                running[pool.submit(_compile_job, jobs[i]["kernel"], jobs[i]["args"])] = i
                submitted += 1
            if not running:
                continue
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for f in done:
                i = running.pop(f)
                took, err = f.result()
                if err:
                    errors.append(f"{jobs[i]['kernel']}: {err}")
                elif took >= SAY_ABOVE_S:
                    name = jobs[i]["kernel"].removeprefix("millfmu.dem.")
                    say(f"millfmu: compiled {name} in {took:.0f} s "
                        f"({time.perf_counter() - t0:.0f} s so far)")
                ready.done(i)
    return time.perf_counter() - t0, errors, submitted


def cached_jobs(jobs: list[dict]) -> frozenset:
    """The indices of the jobs whose kernel and argument types numba's cache holds already
    (a long run after a short one compiles only the fused exchange's kernels)."""
    return frozenset(i for i, j in enumerate(jobs) if _is_cached(j))


def fused_exchange(run_s: float | None, plan: Path = PLAN_FILE, log=None) -> bool:
    """Whether a coupled run of ``run_s`` simulated seconds (None: not known, a long one)
    takes the fused exchange: :data:`FUSED_ENV` where set to 0 or 1 (another value is named
    on stderr or ``log`` once and ignored); else where the run lasts :data:`FUSED_FROM_S` or
    longer, or the fused kernels are compiled already, or no plan is shipped for these
    sources (nothing to tell them by)."""
    import os

    given = os.environ.get(FUSED_ENV, "").strip()
    if given in ("0", "1"):
        return given == "1"
    if given and given not in _named:
        _named.add(given)
        _say(log)(f"millfmu: {FUSED_ENV} = {given!r}: 0 (the exchange by calls) or 1 (fused); "
                  "ignored")
    if run_s is None or run_s >= FUSED_FROM_S:
        return True
    jobs = load_plan("coupled", plan)
    return jobs is None or not missing(jobs)


def compile_if_cold(coupled: bool, log=None, processes: int | None = None,
                    plan: Path = PLAN_FILE, run_s: float | None = None) -> bool:
    """Where the kernels a run needs are not compiled for the installed sources yet: say so
    on stderr (or ``log``), with for about how long and where they are kept; compile them
    in several processes from the shipped plan where there is one for these sources
    (:func:`compile_plan`); name each later long compilation of the run when it is done
    (:func:`watch_compiles`). ``run_s``: the run's simulated seconds, which decide whether
    a coupled run's exchange is fused (:func:`fused_exchange`) and so which kernels it
    needs. True where the kernels were not compiled."""
    from .engine._jit import kernel_cache_dir

    what = "dem"
    if coupled:
        what = "coupled" if fused_exchange(run_s, plan, log) else "coupled_calls"
    jobs = load_plan(what, plan)
    if jobs is None:
        if kernel_cache_is_cold() is None:
            return False
    elif not missing(jobs):
        return False
    say = _say(log)
    d = kernel_cache_dir()
    label = "with the coupled liquid" if coupled else "of the DEM"
    # the variable, where set, says how to compile whatever cores the run was given
    n = processes_here(log, cores=processes)
    skip = frozenset() if jobs is None else cached_jobs(jobs)
    # the estimate counts what is left: those compiled before cost nothing
    todo = None if jobs is None else [dict(j, seconds=0.0) if i in skip else j
                                      for i, j in enumerate(jobs)]
    some = f"{len(jobs) - len(skip)} of {len(jobs)} not compiled yet; " if skip else ""
    if jobs is None or n < 2:
        est = SECONDS[what] if jobs is None else estimate_s(todo, 1)
        say(f"millfmu: compiling the kernels {label} for this machine first ({some}about "
            f"{est:.0f} s on one core; numba, once for these sources): later runs load them "
            f"from {d} in seconds")
        watch_compiles(log)
        return True
    say(f"millfmu: compiling the kernels {label} for this machine first, in {n} processes "
        f"({some}about {estimate_s(todo, n):.0f} s on {n} free cores; numba, once for these "
        f"sources): later runs load them from {d} in seconds")
    took, errors, count = compile_plan(jobs, n, log, skip)
    left = f"; {len(errors)} left to the run ({errors[0]})" if errors else ""
    say(f"millfmu: compiled {count} kernel{'' if count == 1 else 's'} in {took:.0f} s{left}")
    watch_compiles(log)
    return True


def watch_compiles(log=None) -> None:
    """From now on in this process, name on stderr (or ``log``) each kernel whose own
    compilation (without the kernels it calls, which are named themselves) took
    :data:`SAY_ABOVE_S` or more, with its time [s], when it is done: on a cold cache the
    first coupled run compiles for minutes, and these lines show what and how far."""
    from numba.core import event

    if _watching:
        return
    say = _say(log)
    stack = []  # [start, seconds of the callees' compilations] per open compilation

    class Said(event.Listener):
        def on_start(self, ev):
            stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev):
            t0, inner = stack.pop()
            took = time.perf_counter() - t0
            if stack:
                stack[-1][1] += took
            own = took - inner
            if own >= SAY_ABOVE_S:
                f = ev.data["dispatcher"].py_func
                name = f"{f.__module__.removeprefix('millfmu.dem.')}.{f.__qualname__}"
                say(f"millfmu: compiled {name} in {own:.0f} s")

    _watching.append(Said())
    event.register("numba:compile", _watching[0])


# -- recording the plan (from a checkout, when the kernel sources change) ----------------

def _kernel_name(dispatcher) -> str | None:
    """``module.function`` of a module-level millfmu kernel, else None (numba's own
    overloads and nested functions compile inside their callers)."""
    f = dispatcher.py_func
    name = f"{f.__module__}.{f.__qualname__}"
    if not f.__module__.startswith("millfmu.") or "<" in f.__qualname__:
        return None
    try:
        return name if _dispatcher(name) is dispatcher else None
    except (ImportError, AttributeError):
        return None


def jobs_from_tree(roots: list[dict]) -> tuple[list[dict], float]:
    """The plan's jobs from a run's tree of compilations (``{"kernel", "args", "took",
    "children", "links"}``, ``kernel`` or ``args`` None where the plan cannot name it;
    ``links``: the ids of the compiled kernels whose code it links, ``id`` its own), callees
    before their callers. A job's ``seconds`` is its compilation's time less that of the
    jobs below it; it comes ``after`` the jobs below it and those it links (compiled before
    it in the run, so not below it there). Also the seconds compiled outside any job (left
    to the run)."""
    import json

    jobs, index, by_id = [], {}, {}
    left = 0.0

    def visit(node) -> list[tuple[int, float]]:
        below = [jt for c in node["children"] for jt in visit(c)]
        if node["kernel"] is None or node["args"] is None:
            return below
        key = (node["kernel"], json.dumps(node["args"]))
        if key in index:  # a second compilation of the same kernel and types
            return below
        index[key] = len(jobs)
        if node.get("id") is not None:
            by_id[node["id"]] = index[key]
        seconds = node["took"] - sum(t for _, t in below)
        linked = {by_id[x] for x in node.get("links", ()) if x in by_id}
        jobs.append({"kernel": node["kernel"], "args": node["args"],
                     "seconds": round(max(seconds, 0.0), 3),
                     "after": sorted({i for i, _ in below} | linked - {index[key]})})
        return [(index[key], node["took"])]

    for r in roots:
        if not visit(r):
            left += r["took"]
    return jobs, left


def named_callees(jobs: list[dict]) -> list[dict]:
    """``jobs`` with each job also ``after`` the earlier jobs of the kernels its function
    names (a global, or an attribute of a module it names): a kernel inlined into its
    caller (``inline="always"``) links no code of its own, and one compiled before its
    caller in the run was not compiled inside it, so neither shows in the tree; compiled
    in another process first, the caller's process need not compile it again."""
    import types as pytypes

    from numba.core.registry import CPUDispatcher

    at = {}
    for i, j in enumerate(jobs):
        at.setdefault(j["kernel"], []).append(i)
    out = []
    for i, j in enumerate(jobs):
        f = _dispatcher(j["kernel"]).py_func
        names = set(f.__code__.co_names)
        found = set()
        for n in names:
            v = f.__globals__.get(n)
            if isinstance(v, pytypes.ModuleType):
                found |= {getattr(v, m) for m in names if isinstance(getattr(v, m, None), CPUDispatcher)}
            elif isinstance(v, CPUDispatcher):
                found.add(v)
        extra = {k for d in found for k in at.get(f"{d.py_func.__module__}.{d.py_func.__qualname__}", ())
                 if k < i}
        out.append(dict(j, after=sorted(set(j["after"]) | extra)))
    return out


def _record_child(what: str, out: str) -> None:
    """In a process with an empty numba cache: run :data:`PLAN_RUNS` ``[what]`` and write
    its tree of compilations and the plan's jobs to ``out`` (JSON)."""
    import json
    import tempfile

    from numba.core import event

    roots, stack = [], []

    class Record(event.Listener):
        def on_start(self, ev):
            stack.append((time.perf_counter(), []))

        def on_end(self, ev):
            t0, children = stack.pop()
            d = ev.data["dispatcher"]
            kernel = _kernel_name(d)
            try:
                args = [encode_type(a) for a in ev.data["args"]]
            except ValueError:
                args = None
            node = {"kernel": kernel, "args": args, "took": time.perf_counter() - t0,
                    "children": children, "_at": (d, tuple(ev.data["args"]))}
            (stack[-1][1] if stack else roots).append(node)

    event.register("numba:compile", Record())
    import runpy

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        # the command a user runs, python -m millfmu dem run ..., in this process
        sys.argv = ["millfmu", "dem", "run", *PLAN_RUNS[what], "--out", tmp + "/run", "--no-progress"]
        try:
            runpy.run_module("millfmu", run_name="__main__", alter_sys=True)
            rc = 0
        except SystemExit as e:
            rc = e.code or 0
    wall = time.perf_counter() - t0
    if rc:
        raise SystemExit(f"the short run {what!r} failed ({rc})")
    # what each compiled kernel links (its callees' code; numba's CodeLibrary keeps them)
    def tag(node):
        d, args = node.pop("_at")
        cres = d.overloads.get(args)
        lib = getattr(cres, "library", None)
        node["id"] = id(lib) if lib is not None else None
        node["links"] = [id(x) for x in getattr(lib, "_linking_libraries", ())]
        for c in node["children"]:
            tag(c)

    for r in roots:
        tag(r)
    jobs, left = jobs_from_tree(roots)
    jobs = named_callees(jobs)
    Path(out).write_text(json.dumps({"wall_s": round(wall, 1), "left_to_run_s": round(left, 1),
                                     "jobs": jobs}))


def record(path: Path = PLAN_FILE, log=print) -> dict:
    """Record the plan: each run of :data:`PLAN_RUNS` once with an empty numba cache, in
    its own process, one after the other; write it to ``path``."""
    import json
    import os
    import platform
    import subprocess
    import tempfile

    import numba

    from .engine._jit import sources_key

    plan = {"about": "what a short DEM run compiles: each kernel and argument types, its own "
                     "compile time [s] on one core of the machine named, the jobs it calls "
                     "(millfmu.dem.first_compile)",
            "sources_key": sources_key(), "numba": numba.__version__,
            "machine": f"{platform.machine()}, {os.cpu_count()} cores", "runs": {}}
    for what in PLAN_RUNS:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "plan.json"
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "cache"),
                       MILLFMU_COMPILE_PROCESSES="1", **{FUSED_ENV: PLAN_FUSED[what]})
            code = f"from millfmu.dem.first_compile import _record_child; _record_child({what!r}, {str(out)!r})"
            subprocess.run([sys.executable, "-c", code], env=env, check=True)
            run = json.loads(out.read_text())
        run["command"] = "millfmu dem run " + " ".join(PLAN_RUNS[what]) + " --out DIR"
        plan["runs"][what] = run
        log(f"{what}: {len(run['jobs'])} jobs, {sum(j['seconds'] for j in run['jobs']):.0f} s "
            f"compiled in jobs, {run['left_to_run_s']:.0f} s outside them, run {run['wall_s']:.0f} s")
    Path(path).write_text(json.dumps(plan, separators=(",", ":")) + "\n")
    return plan


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(prog="python -m millfmu.dem.first_compile",
                                 description="Record the compile plan shipped with the package "
                                             "(three short DEM runs on an empty cache).")
    ap.add_argument("command", choices=["record"])
    ap.add_argument("--out", default=str(PLAN_FILE), help="where to write the plan (JSON)")
    a = ap.parse_args()
    record(Path(a.out))
