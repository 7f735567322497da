"""How often a host process that loads FMUs dies when it exits normally.

``python -m fmu_build.exit_study A.fmu B.fmu C.fmu --processes 200`` starts that many
separate interpreters; each loads every FMU with fmpy, instantiates, initializes, steps
each three times, terminates and frees them, and then exits normally (interpreter
teardown included, no ``os._exit``). Prints how many processes exited 0 and how many did
not (killed by a signal, e.g. SIGABRT from glibc's heap checks, or another status), with
the first lines of their stderr. Used to measure pythonfmu's wrapper before and after
millfmu's fix (see ``fmu_build.wrapper``).
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import os
import subprocess
import sys

DRIVER = r"""
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

fmus = []
for k, path in enumerate(sys.argv[1:]):
    md = read_model_description(path)
    f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="i%d" % k)
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    fmus.append(f)
for step in range(3):
    for f in fmus:
        f.doStep(currentCommunicationPoint=float(step), communicationStepSize=1.0)
for f in fmus:
    f.terminate()
    f.freeInstance()
print("DONE", flush=True)
"""


def one(python: str, fmus: list, env: dict) -> tuple:
    """Run the driver once: (return code, printed DONE, first stderr line)."""
    r = subprocess.run([python, "-c", DRIVER, *map(str, fmus)], capture_output=True, text=True, env=env, timeout=600)
    err = next((ln for ln in r.stderr.splitlines() if ln.strip()), "")
    return r.returncode, "DONE" in r.stdout, err


def study(fmus: list, processes: int = 200, workers: int = 2, python: str | None = None, out=print) -> dict:
    """Run ``processes`` driver processes, ``workers`` at a time; returns the counts."""
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    python = python or sys.executable
    codes: collections.Counter = collections.Counter()
    errors: collections.Counter = collections.Counter()
    done_then_died = 0
    with concurrent.futures.ThreadPoolExecutor(workers) as ex:
        for rc, done, err in ex.map(lambda _: one(python, fmus, env), range(processes)):
            codes[rc] += 1
            if rc != 0:
                errors[err[:120]] += 1
                done_then_died += done
    bad = processes - codes[0]
    out(f"{processes} processes x {len(fmus)} FMUs: {codes[0]} exited 0, {bad} did not "
        f"({done_then_died} of them after every FMU had been freed)")
    for rc, n in sorted(codes.items()):
        if rc != 0:
            out(f"  exit status {rc}: {n}")
    for err, n in errors.most_common(5):
        out(f"  {n} x stderr: {err}")
    return {"processes": processes, "ok": codes[0], "failed": bad, "after_free": done_then_died,
            "codes": dict(codes)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m fmu_build.exit_study", description=__doc__.split("\n\n")[0])
    p.add_argument("fmus", nargs="+", help="FMU files loaded together in every process")
    p.add_argument("--processes", type=int, default=200)
    p.add_argument("--workers", type=int, default=2, help="processes run at a time")
    a = p.parse_args(argv)
    r = study(a.fmus, a.processes, a.workers)
    return 0 if r["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
