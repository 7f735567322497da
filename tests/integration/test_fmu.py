"""The mill FMU (FMI 2.0 co-simulation, pythonfmu): description, contents, and runs in fmpy
in fresh interpreters without millfmu, compared with MillModel run directly."""

from __future__ import annotations

import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from millfmu.mill import PSD_SUM_TOL, MillModel
from millfmu.scene import load_scene

from .fmu_support import CONTINUOUS, DETAILED, TABLE_SCENE, build, isolated_python, reference, run_py, scene_text

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

SCALAR_OUTPUTS = ["x10", "x50", "x90", "holdup", "product_mass_flow", "se_beads", "se_product", "sf", "stress_number",
                  "power", "specific_energy", "eta_eff", "reynolds", "below_grid"]
PARAMS = ["bead_filling", "bead_diameter", "bead_density", "stress_frequency_factor"]


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmu")
    scenes = {"batch": None, "continuous": d / "continuous.toml", "detailed": d / "detailed.toml",
              "table": TABLE_SCENE}
    scenes["continuous"].write_text(scene_text(**CONTINUOUS))
    scenes["detailed"].write_text(scene_text(**DETAILED))
    fmus = {k: build(p, d / f"{k}.fmu") for k, p in scenes.items()}
    return {"dir": d, "scenes": scenes, "fmus": fmus, "python": isolated_python(d)}


def _md(path):
    return ET.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))


def _n(scene_path):
    return MillModel(load_scene(scene_path)).grid.n


# ---- description --------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["batch", "continuous", "detailed"])
def test_validate_fmu_reports_nothing(work, kind):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(work["fmus"][kind])) == []


@pytest.mark.parametrize("kind", ["batch", "continuous"])
def test_variable_names_and_value_references_are_pinned(work, kind):
    n = _n(work["scenes"][kind])
    inputs = ["tip_speed", "solids_mass_fraction"] + (["feed_mass_flow"] + [f"psd_in[{i}]" for i in range(1, n + 1)]
                                                      if kind == "continuous" else [])
    expected = PARAMS + inputs + [f"psd[{i}]" for i in range(1, n + 1)] + SCALAR_OUTPUTS
    root = _md(work["fmus"][kind])
    got = [(sv.get("name"), int(sv.get("valueReference"))) for sv in root.iter("ScalarVariable")]
    assert got == [(name, vr) for vr, name in enumerate(expected)]
    causality = {sv.get("name"): sv.get("causality") for sv in root.iter("ScalarVariable")}
    assert [k for k, c in causality.items() if c == "parameter"] == PARAMS
    assert [k for k, c in causality.items() if c == "input"] == inputs


@pytest.mark.parametrize("kind", ["batch", "continuous", "detailed"])
def test_every_real_has_a_declared_unit_and_a_description(work, kind):
    root = _md(work["fmus"][kind])
    declared = {u.get("name") for u in root.iter("Unit")}
    for sv in root.iter("ScalarVariable"):
        real = sv.find("Real")
        assert real is not None, sv.get("name")
        assert real.get("unit") in declared, sv.get("name")
        assert sv.get("description"), sv.get("name")
    units = {sv.get("name"): sv.find("Real").get("unit") for sv in root.iter("ScalarVariable")}
    assert units["x50"] == "m" and units["power"] == "W" and units["sf"] == "1/s" and units["tip_speed"] == "m/s"
    assert units["specific_energy"] == "J/kg" and units["holdup"] == "kg" and units["psd[1]"] == "1"
    j = next(u for u in root.iter("Unit") if u.get("name") == "J").find("BaseUnit").attrib
    assert j == {"kg": "1", "m": "2", "s": "-2"}


def test_model_structure_has_outputs_without_feedthrough_and_initial_unknowns(work):
    root = _md(work["fmus"]["continuous"])
    svs = list(root.iter("ScalarVariable"))
    out_idx = [str(i) for i, sv in enumerate(svs, 1) if sv.get("causality") == "output"]
    outs = root.find("ModelStructure/Outputs")
    assert [u.get("index") for u in outs] == out_idx
    assert all(u.get("dependencies") == "" for u in outs)  # no direct feedthrough: no algebraic loops
    init = root.find("ModelStructure/InitialUnknowns")
    assert [u.get("index") for u in init] == out_idx
    cs = root.find("CoSimulation").attrib
    assert cs["canGetAndSetFMUstate"] == "true" and cs["canSerializeFMUstate"] == "true"
    assert cs["canHandleVariableCommunicationStepSize"] == "true"


@pytest.mark.parametrize("kind", ["batch", "continuous", "detailed"])
def test_fmu_carries_its_scene_and_only_the_code_it_needs(work, kind):
    """Scenes that use no DEM data carry nothing of the DEM, the default scene (batch) among
    them (the detailed example's FMU, which reads the DEM table, carries the table reader
    and its slice: test_fmu_table)."""
    z = zipfile.ZipFile(work["fmus"][kind])
    names = z.namelist()
    scene_path = work["scenes"][kind]
    text = z.read("resources/scene.toml").decode()
    if scene_path is not None:
        assert text == scene_path.read_text()
    else:
        from millfmu.scene import default_scene_text

        assert text == default_scene_text()
    assert not any("/dem/" in n or "numba" in n or n.endswith((".pyc", ".npz")) or "cli.py" in n or "runner.py" in n
                   for n in names)
    code = b"".join(z.read(n) for n in names if n.endswith(".py"))
    assert b"import numba" not in code and b"from numba" not in code and b"millfmu.dem" not in code
    ((md_name,),) = [[n for n in names if n.startswith("binaries/linux64/")]]
    assert md_name.endswith(".so")
    assert _md(work["fmus"][kind]).find("ModelVariables") is not None
    n = _n(scene_path)
    assert sum(1 for sv in _md(work["fmus"][kind]).iter("ScalarVariable") if sv.get("name").startswith("psd[")) == n


def test_the_default_scenes_description_names_its_stand_in_calibration_and_band(work):
    """The default scene (simple model): no table; its description carries the calibration
    record (k_c fitted to the stand-in curve) and the band of its own run, k_c's part alone."""
    from fmpy import read_model_description

    import millfmu
    from millfmu.runner import prediction_band

    text = read_model_description(str(work["fmus"]["batch"])).description
    assert "DEM table" not in text and "STAND-IN" in text and "stress_frequency_factor" in text
    lo, hi = prediction_band(millfmu.load_scene())["outputs"]["x50_m"]
    assert f"prediction band of the scene's own run at t = 1800 s: x50_m in [{lo:.4g}, {hi:.4g}] m" in text
    assert "calibration [" in text and "table [" not in text


# ---- runs ---------------------------------------------------------------------------------
def test_simulate_fmu_matches_mill_model_without_millfmu_installed(work):
    """fmpy.simulate_fmu in a fresh interpreter that cannot import millfmu; stop time off the step grid."""
    n = _n(None)
    res = run_py(work["python"], f"""
import importlib.util
assert importlib.util.find_spec("millfmu") is None
from fmpy import simulate_fmu
names = {SCALAR_OUTPUTS!r} + ["psd[%d]" % i for i in range(1, {n} + 1)]
r = simulate_fmu({str(work["fmus"]["batch"])!r}, stop_time=10.5, step_size=1.0, output=names)
assert not any(m.startswith("numba") or m.startswith("millfmu") for m in sys.modules)
done({{"time": r["time"].tolist(), **{{k: r[k].tolist() for k in names}}}})
""", work["dir"])
    t = np.array(res["time"])
    assert t[-1] == pytest.approx(10.5)
    steps = np.diff(t)
    ref = reference(None, steps.tolist())
    for k in SCALAR_OUTPUTS:
        np.testing.assert_allclose(res[k][1:], ref[k], rtol=1e-12, atol=0, err_msg=k)
    psd = np.array([res[f"psd[{i}]"] for i in range(1, n + 1)]).T[1:]
    np.testing.assert_allclose(psd, ref["psd"], rtol=1e-12, atol=1e-300)


def test_irregular_steps_inputs_and_two_independent_instances(work):
    """Continuous mill driven with irregular steps and changing inputs; a second instance of
    the same FMU in the same process steps differently and must not disturb the first."""
    path = work["scenes"]["continuous"]
    n = _n(path)
    steps = [1.0, 0.5, 2.5, 0.25, 3.0, 1.0, 0.125, 7.0]
    rng = np.random.default_rng(1)
    w = rng.random(n)
    w /= w.sum()
    inputs = {1: {"tip_speed_m_per_s": 12.0}, 3: {"feed_mass_flow_kg_per_s": 2e-3, "psd_in": w},
              5: {"solids_mass_fraction": 0.3, "bead_filling": 0.7}}
    fmi = {1: {"tip_speed": 12.0},
           3: {"feed_mass_flow": 2e-3, **{f"psd_in[{i + 1}]": float(x) for i, x in enumerate(w)}},
           5: {"solids_mass_fraction": 0.3, "bead_filling": 0.7}}
    res = run_py(work["python"], f"""
a = open_fmu({str(work["fmus"]["continuous"])!r}, "a")
b = open_fmu({str(work["fmus"]["continuous"])!r}, "b")
steps, fmi = {steps!r}, {{int(k): v for k, v in {fmi!r}.items()}}
ra, t, tb = {{}}, 0.0, 0.0
for k, dt in enumerate(steps):
    assert step(a, t, dt, fmi.get(k)) == 0
    t += dt
    record(ra, a)
    assert step(b, tb, 10.0, {{"tip_speed": 5.0 + k}}) == 0
    tb += 10.0
rb = outputs(b)
a.terminate(); a.freeInstance(); b.terminate(); b.freeInstance()
done({{"a": ra, "b_x50": rb["x50"]}})
""", work["dir"])
    ref = reference(path, steps, inputs)
    for k in SCALAR_OUTPUTS:
        np.testing.assert_allclose(res["a"][k], ref[k], rtol=1e-12, atol=0, err_msg=k)
    np.testing.assert_allclose(res["a"]["psd"], ref["psd"], rtol=1e-12, atol=1e-300)
    assert res["b_x50"] != res["a"]["x50"][-1]


def test_state_get_set_serialize_continues_bit_identically_and_reset(work):
    res = run_py(work["python"], f"""
import ctypes
f = open_fmu({str(work["fmus"]["continuous"])!r})
t = 0.0
for k in range(5):
    assert step(f, t, 1.0, {{"tip_speed": 10.0 + k}}) == 0; t += 1.0
s = f.getFMUstate()
blob = f.serializeFMUstate(s)
def run_on(fm, t):
    rec = {{}}
    for k in range(6):
        assert step(fm, t, 0.5 + k, {{"tip_speed": 8.0 + k, "feed_mass_flow": 1e-3 * k}}) == 0; t += 0.5 + k
        record(rec, fm)
    return rec
first = run_on(f, t)
f.setFMUstate(s)
second = run_on(f, t)
# Serialized state into a fresh instance.
g = open_fmu({str(work["fmus"]["continuous"])!r}, "g")
g.setFMUstate(g.deSerializeFMUstate(blob))
third = run_on(g, t)
# Reset: back to the state after instantiation.
fresh = outputs(open_fmu({str(work["fmus"]["continuous"])!r}, "fresh"))
f.reset()
f.setupExperiment(startTime=0.0); f.enterInitializationMode(); f.exitInitializationMode()
after_reset = outputs(f)
f.freeFMUstate(s)
done({{"first": first, "second": second, "third": third, "fresh": fresh, "after_reset": after_reset, "nblob": len(blob)}})
""", work["dir"])  # noqa: E501
    assert res["first"] == res["second"] == res["third"]  # bit-identical (JSON floats round-trip exactly)
    assert res["after_reset"] == res["fresh"]
    assert res["first"]["x50"][0] != res["fresh"]["x50"]


BAD = [
    ("tip_speed", float("nan"), "must be finite"),
    ("tip_speed", float("inf"), "must be finite"),
    ("tip_speed", -1.0, "[0, 40]"),
    ("feed_mass_flow", -1e-3, "[0, 1000]"),
    ("solids_mass_fraction", 0.9, "(0, 0.8)"),
    ("bead_filling", 1.0, "(0, 1)"),
    ("bead_filling", 0.0, "(0, 1)"),
    ("psd_in[3]", 0.5, f"sum to 1 within {PSD_SUM_TOL:g}"),
    ("psd_in[2]", -0.1, "psd_in[2]"),
]


def test_bad_inputs_refuse_the_step_with_a_message_and_leave_the_state(work):
    res = run_py(work["python"], f"""
bad = {[(k, repr(v), m) for k, v, m in BAD]!r}
f = open_fmu({str(work["fmus"]["continuous"])!r})
t = 0.0
assert step(f, t, 1.0) == 0; t += 1.0
before = outputs(f)
s = f.getFMUstate()
good = [f.getReal([f.vr[k]])[0] for k, _, _ in bad]
out = []
for (k, v, m), g in zip(bad, good):
    del LOG[:]
    status = step(f, t, 1.0, {{k: float(v)}})
    after = outputs(f)
    msgs = [e for e in LOG if e[1] >= 2]
    out.append([k, v, m, status, msgs, after == before])
    f.setReal([f.vr[k]], [g])
# Bad step size, and the master retrying after the refusal.
del LOG[:]
st_dt = step(f, t, -1.0)
dt_msgs = [e for e in LOG if e[1] >= 2]
retry = step(f, t, 1.0)
t2 = outputs(f)
f.setFMUstate(s)
assert step(f, t, 1.0) == 0
done({{"bad": out, "dt": [st_dt, dt_msgs], "retry": retry, "same_as_restored": outputs(f) == t2}})
""", work["dir"])
    for name, value, allowed, status, msgs, unchanged in res["bad"]:
        assert status == 2, (name, value, status)  # fmi2Discard: the master may retry
        assert unchanged, name
        assert len(msgs) == 1 and msgs[0][1] == 2 and msgs[0][2] == "logStatusDiscard", msgs
        text = msgs[0][3]
        assert allowed in text, text
        assert (name.split("[")[0] if name.startswith("psd_in") else name) in text, text
        if not name.startswith("psd_in"):
            assert value in text or repr(float(value)) in text, text
    assert res["dt"][0] == 2 and "communicationStepSize" in res["dt"][1][0][3]
    assert res["retry"] == 0 and res["same_as_restored"]


def test_logging_off_still_refuses_and_exceptions_never_reach_the_host(work):
    """A master that writes to an output or reads a bad value reference gets no crash."""
    res = run_py(work["python"], f"""
f = open_fmu({str(work["fmus"]["batch"])!r}, logging=False)
s1 = step(f, 0.0, 1.0, {{"tip_speed": float("nan")}})
f.setReal([f.vr["x50"]], [1.0])          # an output: ignored, logged as an error
x50 = f.getReal([f.vr["x50"]])[0]
s2 = step(f, 0.0, 1.0, {{"tip_speed": 10.0}})
done({{"s1": s1, "s2": s2, "x50": x50}})
""", work["dir"])
    assert res["s1"] == 2 and res["s2"] == 0 and res["x50"] != 1.0


def test_parameters_set_before_initialization_define_the_operating_point(work):
    """On the detailed example's FMU (detailed model on the coupled DEM table, bead diameters
    0.5-1.2 mm one at a time): tip speed and filling inside the table define the operating
    point; a bead diameter the table does not hold, or a negative one, is fmi2Error at
    fmi2ExitInitializationMode and refuses every step, with the reason logged."""
    res = run_py(work["python"], f"""
f = open_fmu({str(work["fmus"]["table"])!r}, start={{"tip_speed": 8.0, "bead_filling": 0.7}})
o0 = outputs(f)
assert step(f, 0.0, 2.0) == 0
o1 = outputs(f)
g = open_fmu({str(work["fmus"]["table"])!r}, "g", init=False)
ex_g = initialize(g, {{"bead_diameter": -1.0}})
st = step(g, 0.0, 1.0)
h = open_fmu({str(work["fmus"]["table"])!r}, "h", init=False)
ex_h = initialize(h, {{"bead_diameter": 0.3e-3}})
st_h = step(h, 0.0, 1.0)
done({{"o0": o0, "o1": o1, "st": st, "st_h": st_h, "ex": [ex_g, ex_h], "log": [e for e in LOG if e[0] in ("g", "h")]}})
""", work["dir"])
    assert res["ex"] == [3, 3]  # fmi2Error
    import millfmu

    m = MillModel(millfmu.load_scene(TABLE_SCENE, overrides={"mill.tip_speed_m_per_s": 8.0,
                                                             "mill.bead_filling": 0.7}))
    assert res["o0"]["holdup"] == m.outputs()["holdup_kg"] and res["o0"]["se_beads"] == m.outputs()["se_beads_J"]
    o = m.step(2.0)
    assert res["o1"]["x50"] == o["x50_m"] and res["o1"]["power"] == o["power_W"]
    assert res["st"] == 2 and any(e[0] == "g" and "bead_diameter = -1.0" in e[3] for e in res["log"])
    assert res["st_h"] == 2 and any(e[0] == "h"
                                    and "bead_diameter = 0.0003: outside the stress-energy table's grid; allowed "
                                        "0.0005 to 0.0012 m" in e[3] for e in res["log"]), res["log"]


def test_fifty_instantiate_free_cycles_and_two_different_fmus_in_one_process(work):
    res = run_py(work["python"], f"""
import resource
rss = []
for i in range(50):
    f = open_fmu({str(work["fmus"]["batch"])!r}, "i%d" % i)
    assert step(f, 0.0, 1.0) == 0
    f.terminate(); f.freeInstance()
    rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
# Two differently named mill FMUs (other scenes, other module names) side by side.
b = open_fmu({str(work["fmus"]["batch"])!r}, "b")
c = open_fmu({str(work["fmus"]["continuous"])!r}, "c")
d = open_fmu({str(work["fmus"]["detailed"])!r}, "d")
for k in range(3):
    assert step(b, k, 1.0) == 0 and step(c, k, 1.0) == 0 and step(d, k, 1.0) == 0
mods = sorted(m for m in sys.modules if m.startswith("Mill_"))
done({{"rss_kib": rss, "b": outputs(b)["x50"], "c": outputs(c)["x50"], "d": outputs(d)["x50"], "mods": mods, "fatal": [e for e in LOG if e[1] >= 3]}})
""", work["dir"])  # noqa: E501
    rss = res["rss_kib"]
    assert rss[-1] - rss[9] < 20 * 1024, rss  # bounded: no per-cycle growth of whole models
    assert res["fatal"] == []
    assert len(res["mods"]) == 3
    for kind, key in (("batch", "b"), ("continuous", "c"), ("detailed", "d")):
        assert res[key] == reference(work["scenes"][kind], [1.0] * 3)["x50"][-1]


def test_build_fmu_rejects_a_bad_scene_naming_the_key(tmp_path):
    import subprocess
    import sys

    from .fmu_support import ROOT

    bad = tmp_path / "bad.toml"
    bad.write_text(scene_text(mill={"bead_filling": 1.5}))
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", str(bad), "-o", str(tmp_path / "x.fmu")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "mill.bead_filling = 1.5" in r.stderr, r.stderr
    assert not (tmp_path / "x.fmu").exists()


def test_bench_fmu_command_prints_ratios_against_the_floor(tmp_path):
    """Runs the benchmark with a handful of steps (FMI 2.0 and 3.0): checks what it prints,
    not the timings."""
    import subprocess
    import sys

    from .fmu_support import ROOT

    rec = tmp_path / "bench-fmu.json"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "bench", "fmu", "--steps", "5", "--repeats", "1",
                        "--json", str(rec), "--host", "test"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    # One block per FMI version, each against the trivial FMU of its own version (FMI 3.0
    # where it can be built here, else the reason is printed).
    from .fmu_support import fmi3_missing

    libs = ["pythonfmu"] + ([] if fmi3_missing() else ["pythonfmu3"])
    assert [ln.split()[1] for ln in lines if ln.startswith("trivial ")] == libs
    assert any(ln.startswith("FMI 3.0: not measured") for ln in lines) == (len(libs) == 1)
    rows = [ln for ln in lines if ln.startswith("mill, ")]
    assert [ln.split()[1] for ln in rows] == ["batch", "continuous"] * len(libs)
    assert all(ln.split()[2] == "114" for ln in rows)  # 100 classes + 14 scalar outputs
    # --json: the same figures as one record, each ratio the printed one
    import json

    d = json.loads(rec.read_text())
    assert d["command"] == "millfmu bench fmu" and d["host"] == "test" and d["machine"]["cpus"] >= 1
    versions = [v for v in ("2", "3")[:len(libs)] for _ in range(2)]
    for ln, v in zip(rows, versions):
        assert abs(d["figures"][f"fmi{v}_{ln.split()[1]}_over_floor"] - float(ln.split()[4])) <= 0.0051, ln
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "bench", "fmu", "--json", str(tmp_path / "no" / "x")],
                       capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 2 and "--json" in r.stderr and "does not exist" in r.stderr and "Traceback" not in r.stderr
