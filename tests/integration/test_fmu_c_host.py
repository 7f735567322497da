"""A C host (compiled here with the system C compiler) loads the mill FMU's binary with dlopen,
in the environment printed by ``millfmu host-env``, instantiates, steps and reads outputs."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from .fmu_support import ROOT, build, reference

pytest.importorskip("pythonfmu")

C_HOST = r"""
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

/* The FMI 2.0 types this host needs (fmi2TypesPlatform.h / fmi2FunctionTypes.h). */
typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef int fmi2Status;
typedef struct {
    void (*logger)(void *, const char *, fmi2Status, const char *, const char *, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, fmi2Status);
    void *componentEnvironment;
} fmi2CallbackFunctions;
typedef fmi2Component (*InstantiateT)(const char *, int, const char *, const char *, const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupT)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
typedef fmi2Status (*ModeT)(fmi2Component);
typedef fmi2Status (*DoStepT)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef fmi2Status (*RealsT)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef void (*FreeInstanceT)(fmi2Component);

static void logger(void *env, const char *name, fmi2Status status, const char *category, const char *message, ...) {
    va_list ap;
    printf("LOG %d ", status);
    va_start(ap, message);
    vprintf(message, ap);
    va_end(ap);
    printf("\n");
}

#define SYM(type, name) type##T name = (type##T)dlsym(lib, "fmi2" #name); if (!name) { printf("missing fmi2" #name "\n"); return 3; }

/* argv: library, resource URI, guid, tip_speed vr, n steps, output vrs... */
int main(int argc, char **argv) {
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("dlopen: %s\n", dlerror()); return 2; }
    SYM(Instantiate, Instantiate) SYM(Setup, SetupExperiment) SYM(Mode, EnterInitializationMode)
    SYM(Mode, ExitInitializationMode) SYM(DoStep, DoStep) SYM(Reals, GetReal) SYM(Reals, SetReal)
    SYM(Mode, Terminate) SYM(FreeInstance, FreeInstance)
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = Instantiate("chost", 1 /* fmi2CoSimulation */, argv[3], argv[2], &cb, 0, 1);
    if (!c) { printf("instantiate failed\n"); return 4; }
    if (SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0) || EnterInitializationMode(c) || ExitInitializationMode(c)) return 5;
    fmi2ValueReference vr_tip = (fmi2ValueReference)atoi(argv[4]);
    int steps = atoi(argv[5]), n = argc - 6;
    fmi2ValueReference *vrs = malloc(n * sizeof *vrs);
    fmi2Real *v = malloc(n * sizeof *v);
    for (int i = 0; i < n; i++) vrs[i] = (fmi2ValueReference)atoi(argv[6 + i]);
    double t = 0.0;
    for (int k = 0; k < steps; k++) {
        fmi2Status s = DoStep(c, t, 1.0, 1);
        if (s) { printf("doStep status %d\n", s); return 6; }
        t += 1.0;
        GetReal(c, vrs, n, v);
        printf("OUT");
        for (int i = 0; i < n; i++) printf(" %.17g", v[i]);
        printf("\n");
    }
    fmi2Real bad = -5.0;
    SetReal(c, &vr_tip, 1, &bad);
    printf("BAD %d\n", DoStep(c, t, 1.0, 1));
    Terminate(c);
    FreeInstance(c);
    printf("DONE\n");
    return 0;
}
"""


@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the host test uses the linux64 binary")
def test_c_host_loads_steps_and_reads_outputs(tmp_path):
    fmu = build(None, tmp_path / "mill.fmu")
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "host-env", str(fmu)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    env = {}
    for line in r.stdout.splitlines():
        if line.startswith("export "):
            k, v = line[len("export "):].split("=", 1)
            env[k] = v.strip("'")
    assert set(env) == {"LD_PRELOAD", "PYTHONHOME", "PYTHONPATH"}
    cc = shutil.which("gcc") or shutil.which("cc")
    (tmp_path / "host.c").write_text(C_HOST)
    subprocess.run([cc, "-O1", "-o", str(tmp_path / "host"), str(tmp_path / "host.c"), "-ldl"], check=True)
    d = tmp_path / "unzipped"
    zipfile.ZipFile(fmu).extractall(d)
    md = ET.parse(d / "modelDescription.xml").getroot()
    svs = list(md.iter("ScalarVariable"))
    vr = {sv.get("name"): sv.get("valueReference") for sv in svs}
    names = ["x50", "holdup", "power", "specific_energy", "psd[5]", "psd[20]"]
    lib = d / "binaries" / "linux64" / (md.find("CoSimulation").get("modelIdentifier") + ".so")
    steps = 4
    run = subprocess.run([str(tmp_path / "host"), str(lib), (d / "resources").as_uri(), md.get("guid"), vr["tip_speed"], str(steps)]
                         + [vr[n] for n in names], capture_output=True, text=True, env={"PATH": "/usr/bin:/bin", **env}, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    got = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("OUT")])
    ref = reference(None, [1.0] * steps)
    want = np.column_stack([ref["x50"], ref["holdup"], ref["power"], ref["specific_energy"], ref["psd"][:, 4], ref["psd"][:, 19]])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    assert "BAD 2" in lines  # tip speed -5 m/s: fmi2Discard
    assert any(ln.startswith("LOG 2") and "tip_speed = -5.0" in ln for ln in lines), lines
    assert lines[-1] == "DONE"
