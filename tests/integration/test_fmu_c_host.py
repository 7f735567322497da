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

from .fmu_support import ROOT, build, need_fmi3, reference

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
"""  # noqa: E501


@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the host test uses the linux64 binary")
def test_c_host_loads_steps_and_reads_outputs(tmp_path):
    fmu = build(None, tmp_path / "mill.fmu")
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "host-env", str(fmu)], capture_output=True, text=True,
                       cwd=ROOT)
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
    run = subprocess.run([str(tmp_path / "host"), str(lib), (d / "resources").as_uri(), md.get("guid"), vr["tip_speed"],
                          str(steps)]
                         + [vr[n] for n in names], capture_output=True, text=True, env={"PATH": "/usr/bin:/bin", **env},
                         timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    got = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("OUT")])
    ref = reference(None, [1.0] * steps)
    want = np.column_stack([ref["x50"], ref["holdup"], ref["power"], ref["specific_energy"], ref["psd"][:, 4],
                            ref["psd"][:, 19]])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    assert "BAD 2" in lines  # tip speed -5 m/s: fmi2Discard
    assert any(ln.startswith("LOG 2") and "tip_speed = -5.0" in ln for ln in lines), lines
    assert lines[-1] == "DONE"


C_HOST3 = r"""
#include <dlfcn.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>

/* The FMI 3.0 types this host needs (fmi3PlatformTypes.h / fmi3FunctionTypes.h). */
typedef void *fmi3Instance;
typedef unsigned int fmi3ValueReference;
typedef double fmi3Float64;
typedef bool fmi3Boolean;
typedef int fmi3Status;
typedef void (*LogT)(void *, fmi3Status, const char *, const char *);
typedef fmi3Instance (*InstantiateT)(const char *, const char *, const char *, fmi3Boolean, fmi3Boolean, fmi3Boolean, fmi3Boolean,
                                     const fmi3ValueReference *, size_t, void *, LogT, void *);
typedef fmi3Status (*EnterT)(fmi3Instance, fmi3Boolean, fmi3Float64, fmi3Float64, fmi3Boolean, fmi3Float64);
typedef fmi3Status (*ModeT)(fmi3Instance);
typedef fmi3Status (*DoStepT)(fmi3Instance, fmi3Float64, fmi3Float64, fmi3Boolean, fmi3Boolean *, fmi3Boolean *, fmi3Boolean *, fmi3Float64 *);
typedef fmi3Status (*FloatsT)(fmi3Instance, const fmi3ValueReference *, size_t, fmi3Float64 *, size_t);
typedef void (*FreeInstanceT)(fmi3Instance);

static void logger(void *env, fmi3Status status, const char *category, const char *message) {
    printf("LOG %d %s\n", status, message);
}

#define SYM(type, name) type##T name = (type##T)dlsym(lib, "fmi3" #name); if (!name) { printf("missing fmi3" #name "\n"); return 3; }

/* argv: library, resource folder, token, tip_speed vr, n steps, n values read, output vrs... */
int main(int argc, char **argv) {
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("dlopen: %s\n", dlerror()); return 2; }
    SYM(Instantiate, InstantiateCoSimulation) SYM(Enter, EnterInitializationMode) SYM(Mode, ExitInitializationMode)
    SYM(DoStep, DoStep) SYM(Floats, GetFloat64) SYM(Floats, SetFloat64) SYM(Mode, Terminate) SYM(FreeInstance, FreeInstance)
    /* The second instance has no logMessage callback (FMI 3.0 allows NULL). */
    fmi3Instance c = InstantiateCoSimulation("chost", argv[3], argv[2], false, true, false, false, NULL, 0, NULL, logger, NULL);
    fmi3Instance q = InstantiateCoSimulation("quiet", argv[3], argv[2], false, true, false, false, NULL, 0, NULL, NULL, NULL);
    if (!c || !q) { printf("instantiate failed\n"); return 4; }
    if (EnterInitializationMode(c, false, 0.0, 0.0, false, 0.0) || ExitInitializationMode(c)) return 5;
    if (EnterInitializationMode(q, false, 0.0, 0.0, false, 0.0) || ExitInitializationMode(q)) return 5;
    fmi3ValueReference vr_tip = (fmi3ValueReference)atoi(argv[4]);
    int steps = atoi(argv[5]), nv = atoi(argv[6]), n = argc - 7;
    fmi3ValueReference *vrs = malloc(n * sizeof *vrs);
    fmi3Float64 *v = malloc(nv * sizeof *v);
    for (int i = 0; i < n; i++) vrs[i] = (fmi3ValueReference)atoi(argv[7 + i]);
    double t = 0.0;
    for (int k = 0; k < steps; k++) {
        fmi3Boolean event = true, terminate = true, early = true; /* the FMU must write all three */
        fmi3Float64 last = -1.0;
        fmi3Status s = DoStep(c, t, 1.0, true, &event, &terminate, &early, &last);
        if (s) { printf("doStep status %d\n", s); return 6; }
        if (event || terminate || early || last != t + 1.0) { printf("doStep flags %d %d %d %g\n", event, terminate, early, last); return 7; }
        t += 1.0;
        if (GetFloat64(c, vrs, n, v, nv)) return 8;
        printf("OUT");
        for (int i = 0; i < nv; i++) printf(" %.17g", v[i]);
        printf("\n");
    }
    fmi3Float64 bad = -5.0;
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    SetFloat64(c, &vr_tip, 1, &bad, 1);
    printf("BAD %d\n", DoStep(c, t, 1.0, true, &event, &terminate, &early, &last));
    SetFloat64(q, &vr_tip, 1, &bad, 1);
    printf("QUIET %d\n", DoStep(q, 0.0, 1.0, true, &event, &terminate, &early, &last));
    printf("FEW %d\n", GetFloat64(c, vrs, n, v, nv - 1)); /* nValues one short: fmi3Error, nothing read */
    Terminate(c);
    FreeInstance(c);
    FreeInstance(q);
    printf("DONE\n");
    return 0;
}
"""  # noqa: E501


@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the host test uses the x86_64-linux binary")
def test_c_host_runs_the_fmi3_fmu(tmp_path):
    """An FMI 3.0 C host: arrays read with the other outputs in one fmi3GetFloat64, doStep's
    output flags written by the FMU, an instance without logMessage callback refusing a
    step without crashing, a wrong nValues answered with fmi3Error."""
    need_fmi3()
    fmu = build(None, tmp_path / "mill3.fmu", fmi_version=3)
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "host-env", str(fmu)], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "binaries/x86_64-linux/" in r.stdout
    env = {k: v.strip("'")
           for k, v in (ln[len("export "):].split("=", 1) for ln in r.stdout.splitlines() if ln.startswith("export "))}
    cc = shutil.which("gcc") or shutil.which("cc")
    (tmp_path / "host3.c").write_text(C_HOST3)
    subprocess.run([cc, "-O1", "-o", str(tmp_path / "host3"), str(tmp_path / "host3.c"), "-ldl"], check=True)
    d = tmp_path / "unzipped"
    zipfile.ZipFile(fmu).extractall(d)
    md = ET.parse(d / "modelDescription.xml").getroot()
    vr = {el.get("name"): el.get("valueReference") for el in md.find("ModelVariables")}
    n = int(md.find("ModelVariables/UInt64").get("start"))
    names = ["x50", "psd", "holdup", "power"]
    lib = d / "binaries" / "x86_64-linux" / (md.find("CoSimulation").get("modelIdentifier") + ".so")
    steps = 4
    run = subprocess.run([str(tmp_path / "host3"), str(lib), str(d / "resources") + "/", md.get("instantiationToken"),
                          vr["tip_speed"], str(steps),
                          str(n + 3)] + [vr[k] for k in names], capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin", **env}, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    got = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("OUT")])
    ref = reference(None, [1.0] * steps)
    want = np.column_stack([ref["x50"], ref["psd"], ref["holdup"], ref["power"]])
    print(f"C host, FMI 3.0: largest relative difference to MillModel {np.max(np.abs(got - want) / np.abs(want)):.1e}")
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)
    assert "BAD 2" in lines and "QUIET 2" in lines  # fmi3Discard; no callback, no crash
    assert any(ln.startswith("LOG 2") and "tip_speed = -5.0" in ln for ln in lines), lines
    assert "FEW 3" in lines and any(ln.startswith("LOG 3")
                                    and f"nValues = {n + 2}, but the value references name {n + 3} values" in ln
                                    for ln in lines), lines
    assert lines[-1] == "DONE"
