"""How often a host process that loads FMUs dies when it exits normally.

``python -m fmu_build.exit_study A.fmu B.fmu C.fmu --processes 200`` starts that many
separate interpreters; each loads every FMU with fmpy (FMI 2.0 or 3.0, as each FMU's
description says), instantiates, initializes, steps each three times, terminates and frees
them, and then exits normally (interpreter teardown included, no ``os._exit``). With
``--refused-state`` each instance is also handed a state it must refuse before it is freed
(its own state, serialized, with the FMU's name changed and the checksum made to match:
fmi3SetFMUState refuses it, fmi2DeSerializeFMUstate already), the sequence after which FMI
3.0 hosts aborted at exit. Prints how many processes exited 0 and how many did not (killed
by a signal, e.g. SIGABRT from glibc's heap checks, or another status), with the first
lines of their stderr. Used to measure pythonfmu's and pythonfmu3's wrappers before and
after millfmu's fixes (see ``fmu_build.wrapper`` and ``fmu_build.fmi3_wrapper``).
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import os
import subprocess
import sys

DRIVER = r"""
import hashlib, json, sys
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

refuse = sys.argv[1] == "1"

def bad_state(f, v3):
    # The instance's own state, serialized, claimed for another FMU with a matching sha256:
    # well-formed, and refused only for what it says (fmi3SetFMUState / fmi2DeSerializeFMUstate).
    get, ser, des = ((f.getFMUState, f.serializeFMUState, f.deserializeFMUState) if v3 else
                     (f.getFMUstate, f.serializeFMUstate, f.deSerializeFMUstate))
    s = get()
    blob = json.loads(bytes(ser(s)).decode())
    (f.freeFMUState if v3 else f.freeFMUstate)(s)
    blob["state"]["fmu"] = "another FMU"
    blob["sha256"] = hashlib.sha256(json.dumps(blob["state"], sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    try:
        s = des(json.dumps(blob).encode())
        (f.setFMUState if v3 else f.setFMUstate)(s)
    except FMICallException as e:
        assert e.status == 3, e.status  # refused with fmi2Error / fmi3Error
    else:
        raise SystemExit("a state of another FMU was accepted")

fmus = []
for k, path in enumerate(sys.argv[2:]):
    md = read_model_description(path)
    v3 = md.fmiVersion.startswith("3")
    f = (FMU3Slave if v3 else FMU2Slave)(guid=md.guid, unzipDirectory=extract(path),
                                         modelIdentifier=md.coSimulation.modelIdentifier, instanceName="i%d" % k)
    f.instantiate()
    if v3:
        f.enterInitializationMode(startTime=0.0)
    else:
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
    f.exitInitializationMode()
    fmus.append((f, v3))
for step in range(3):
    for f, _ in fmus:
        f.doStep(float(step), 1.0)
for f, v3 in fmus:
    if refuse:
        bad_state(f, v3)
    f.terminate()
    f.freeInstance()
print("DONE", flush=True)
"""  # noqa: E501


def one(python: str, fmus: list, env: dict, refused_state: bool = False) -> tuple:
    """Run the driver once: (return code, printed DONE, first stderr line)."""
    r = subprocess.run([python, "-c", DRIVER, "1" if refused_state else "0", *map(str, fmus)], capture_output=True,
                       text=True,
                       env=env, timeout=600)
    err = next((ln for ln in r.stderr.splitlines() if ln.strip()), "")
    return r.returncode, "DONE" in r.stdout, err


def study(fmus: list, processes: int = 200, workers: int = 2, python: str | None = None, out=print,
          refused_state: bool = False) -> dict:
    """Run ``processes`` driver processes, ``workers`` at a time; returns the counts."""
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    python = python or sys.executable
    codes: collections.Counter = collections.Counter()
    errors: collections.Counter = collections.Counter()
    done_then_died = 0
    with concurrent.futures.ThreadPoolExecutor(workers) as ex:
        for rc, done, err in ex.map(lambda _: one(python, fmus, env, refused_state), range(processes)):
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


def valgrind_errors(fmus: list, python: str | None = None, refused_state: bool = True, timeout: float = 600) -> tuple:
    """Run the driver once under valgrind's memcheck: (its return code, the error records
    valgrind printed that have a frame in an FMU's binary, i.e. in the wrapper). The other
    records come from the interpreter and its extension modules (run without valgrind's
    Python suppressions) and are not the wrapper's. RuntimeError without valgrind."""
    import re
    import shutil

    vg = shutil.which("valgrind")
    if vg is None:
        raise RuntimeError("valgrind is not installed (Debian: apt-get install valgrind)")
    env = dict(os.environ, PYTHONMALLOC="malloc")  # every Python allocation seen by memcheck
    r = subprocess.run([vg, "--error-limit=no", python or sys.executable, "-c", DRIVER, "1" if refused_state else "0",
                        *map(str, fmus)], capture_output=True, text=True, env=env, timeout=timeout)
    records, cur = [], []
    for line in r.stderr.splitlines():
        body = re.sub(r"^==\d+== ?", "", line)
        if not body.strip():
            if cur:
                records.append(cur)
            cur = []
        elif line.startswith("=="):
            cur.append(body)
    if cur:
        records.append(cur)
    # An FMU's binary is <unzip folder>/binaries/<platform>/<model identifier>.so.
    ours = [rec for rec in records
            if not rec[0].startswith(("HEAP SUMMARY", "LEAK SUMMARY", "Memcheck", "Using Valgrind", "Command",
                                      "ERROR SUMMARY"))
            and any(re.search(r"\(in \S*/binaries/[^/]+/[^/]+\.so\)", ln) for ln in rec)]
    return r.returncode, ["\n".join(rec) for rec in ours]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m fmu_build.exit_study", description=__doc__.split("\n\n")[0])
    p.add_argument("fmus", nargs="+", help="FMU files loaded together in every process")
    p.add_argument("--processes", type=int, default=200)
    p.add_argument("--workers", type=int, default=2, help="processes run at a time")
    p.add_argument("--refused-state", action="store_true",
                   help="hand each instance a state it must refuse before freeing it")
    p.add_argument("--valgrind", action="store_true",
                   help="instead: one process under valgrind; print the errors in the FMUs' binaries")
    a = p.parse_args(argv)
    if a.valgrind:
        rc, errors = valgrind_errors(a.fmus, refused_state=a.refused_state)
        print(f"valgrind, one process x {len(a.fmus)} FMUs: exit status {rc}, {len(errors)} errors in the FMUs' "
              "binaries")
        for e in errors:
            print(e + "\n")
        return 0 if rc == 0 and not errors else 1
    r = study(a.fmus, a.processes, a.workers, refused_state=a.refused_state)
    return 0 if r["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
