"""The mill FMU as FMI 3.0 co-simulation (pythonfmu3 with millfmu's wrapper fixes): its
description, contents, and runs in fmpy in fresh interpreters without millfmu, compared
with the FMI 2.0 FMU of the same scene and with MillModel run directly."""

from __future__ import annotations

import subprocess
import sys
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from millfmu.fmi.variables import UNITS
from millfmu.mill import MillModel
from millfmu.scene import load_scene

from millfmu.scene import default_scene_text

from .fmu_support import (CONTINUOUS, DETAILED, ROOT, TABLE_SCENE, build, isolated_python, need_fmi3, reference, run_py,
                          scene_text)

pytest.importorskip("fmpy")

SCALAR_OUTPUTS = ["x10", "x50", "x90", "holdup", "product_mass_flow", "se_beads", "se_product", "sf", "stress_number",
                  "power", "specific_energy", "eta_eff", "reynolds", "below_grid"]
PARAMS = ["bead_filling", "bead_diameter", "bead_density", "stress_frequency_factor"]
KINDS = ["batch", "continuous", "detailed"]


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    need_fmi3()
    d = tmp_path_factory.mktemp("fmu3")
    scenes = {"batch": None, "continuous": d / "continuous.toml", "detailed": d / "detailed.toml",
              "table": TABLE_SCENE}
    scenes["continuous"].write_text(scene_text(**CONTINUOUS))
    scenes["detailed"].write_text(scene_text(**DETAILED))
    fmus = {k: build(p, d / f"{k}3.fmu", fmi_version=3) for k, p in scenes.items()}
    fmi2 = {k: build(scenes[k], d / f"{k}2.fmu") for k in ("batch", "continuous")}
    return {"dir": d, "scenes": scenes, "fmus": fmus, "fmi2": fmi2, "python": isolated_python(d)}


def _md(path):
    return ET.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))


def _n(scene_path):
    return MillModel(load_scene(scene_path)).grid.n


# ---- description --------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
def test_validate_fmu_reports_nothing(work, kind):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(work["fmus"][kind])) == []
    assert _md(work["fmus"][kind]).get("fmiVersion") == "3.0"


@pytest.mark.parametrize("kind", ["batch", "continuous"])
def test_variables_match_the_fmi2_fmu_with_arrays_sized_by_a_structural_parameter(work, kind):
    n = _n(work["scenes"][kind])
    root = _md(work["fmus"][kind])
    got = [(el.tag, el.get("name"), int(el.get("valueReference")), el.get("causality"))
           for el in root.find("ModelVariables")]
    inputs = ["tip_speed", "solids_mass_fraction"] + (["feed_mass_flow", "psd_in"] if kind == "continuous" else [])
    names = ["time", "n_classes"] + PARAMS + inputs + ["psd"] + SCALAR_OUTPUTS
    assert [g[1] for g in got] == names
    assert [g[2] for g in got] == list(range(len(names)))
    assert got[0] == ("Float64", "time", 0, "independent") and got[1] == ("UInt64", "n_classes", 1,
                                                                          "structuralParameter")
    n_el = root.find("ModelVariables/UInt64")
    assert n_el.get("start") == str(n) and n_el.get("variability") == "fixed"
    for el in root.find("ModelVariables"):
        dims = el.findall("Dimension")
        if el.get("name") in ("psd", "psd_in"):
            assert [d.attrib for d in dims] == [{"valueReference": "1"}], el.get("name")
        else:
            assert dims == []
    # The same parameters, inputs and outputs as the FMI 2.0 FMU, arrays written once.
    md2 = _md(work["fmi2"][kind])
    scalars2 = [sv.get("name").split("[")[0] for sv in md2.iter("ScalarVariable")]
    assert list(dict.fromkeys(scalars2)) == names[2:]
    causality2 = {sv.get("name").split("[")[0]: (sv.get("causality"), sv.get("variability"))
                  for sv in md2.iter("ScalarVariable")}
    assert all((el.get("causality"), el.get("variability")) == causality2[el.get("name")]
               for el in root.find("ModelVariables") if el.get("name") in causality2)


@pytest.mark.parametrize("kind", KINDS)
def test_every_float64_has_a_declared_si_unit_a_description_and_exact_starts(work, kind):
    root = _md(work["fmus"][kind])
    declared = {u.get("name"): u.find("BaseUnit").attrib for u in root.iter("Unit")}
    for el in root.find("ModelVariables"):
        assert el.get("description"), el.get("name")
        if el.tag == "Float64":
            assert el.get("unit") in declared, el.get("name")
    for name, exps in declared.items():
        assert exps == {k: str(v) for k, v in UNITS[name].items()}, name
    units = {el.get("name"): el.get("unit") for el in root.find("ModelVariables")}
    assert units["time"] == "s" and units["x50"] == "m" and units["power"] == "W" and units["psd"] == "1" and units[
        "eta_eff"] == "Pa.s"
    if kind == "continuous":
        # Start values exact (repr), all of them (pythonfmu3 alone prints 16 digits and cuts an
        # array's longer than 1000 characters to one character).
        model = MillModel(load_scene(work["scenes"][kind]))
        start = [float(x) for x in root.find("ModelVariables/Float64[@name='psd_in']").get("start").split()]
        assert start == model.inputs["psd_in"].tolist()


def test_model_structure_and_capabilities(work):
    root = _md(work["fmus"]["continuous"])
    out_vrs = [el.get("valueReference") for el in root.find("ModelVariables") if el.get("causality") == "output"]
    ms = root.find("ModelStructure")
    assert [o.get("valueReference") for o in ms.findall("Output")] == out_vrs
    assert all(o.get("dependencies") == "" for o in ms.findall("Output"))  # no direct feedthrough
    assert [u.get("valueReference") for u in ms.findall("InitialUnknown")] == out_vrs
    cs = root.find("CoSimulation").attrib
    assert cs["canGetAndSetFMUState"] == "true" and cs["canSerializeFMUState"] == "true"
    assert cs["canHandleVariableCommunicationStepSize"] == "true"


@pytest.mark.parametrize("kind", ["continuous", "detailed", "batch", "table"])
def test_fmu_carries_its_scene_and_only_the_code_it_needs(work, kind):
    z = zipfile.ZipFile(work["fmus"][kind])
    names = z.namelist()
    code = [n for n in names if n.startswith("resources/_millfmu_")]
    mods = sorted(n.split("/", 2)[2] for n in code)
    assert "fmi/mill3.py" in mods and "fmi/base3.py" in mods and "fmi/variables.py" in mods
    assert "fmi/mill2.py" not in mods and "fmi/base2.py" not in mods  # the FMI 2.0 adapter stays out
    assert not any(n.startswith("resources/pythonfmu/") for n in names)  # pythonfmu3 only
    assert not [m for m in mods if m.startswith("dem/")]  # nothing of the DEM nor of the table builder
    tables = sorted(m for m in mods if m.startswith("stress_tables/"))
    # MillModel's table rules for every scene; the table reader for a scene with a table
    rules = ["stress_tables/__init__.py", "stress_tables/rules.py"]
    reader = ["stress_tables/__init__.py", "stress_tables/files.py", "stress_tables/rules.py", "stress_tables/spec.py",
              "stress_tables/stress_source.py", "stress_tables/table.py"]
    assert tables == (reader if kind == "table" else rules)  # the default scene (batch) reads no table
    assert ("resources/table.npz" in names) == (kind == "table")
    assert not any("numba" in n or n.endswith(".pyc") or "cli.py" in n or "runner.py" in n for n in names)
    blob = b"".join(z.read(n) for n in code)
    assert b"import numba" not in blob and b"from numba" not in blob
    # The wrapper with millfmu's fixes, for x86_64 Linux only, with the sources it was built from.
    assert sorted(n for n in names
                  if n.startswith("binaries/")) == [
                      f"binaries/x86_64-linux/{_md(work['fmus'][kind]).find('CoSimulation').get('modelIdentifier')}.so"]
    assert b"millfmu:" in z.read("sources/src/pythonfmu/PySlaveInstance.cpp")
    assert z.read("resources/scene.toml").decode() == (work["scenes"][kind].read_text() if work["scenes"][kind]
                                                       else default_scene_text())


# ---- runs ---------------------------------------------------------------------------------
def test_simulate_fmu_without_millfmu_equals_the_fmi2_fmu_and_mill_model(work):
    """fmpy.simulate_fmu in fresh interpreters that cannot import millfmu, FMI 3.0 and 2.0
    FMUs of the default scene (Kwade's simple model); stop time off the step grid."""
    n = _n(None)
    code = """
import importlib.util
assert importlib.util.find_spec("millfmu") is None
from fmpy import simulate_fmu
r = simulate_fmu({path!r}, stop_time=10.5, step_size=1.0, output={names!r})
assert not any(m.startswith("numba") or m.startswith("millfmu") for m in sys.modules)
done({{"time": r["time"].tolist(), **{{k: np.asarray(r[k]).tolist() for k in {names!r}}}}})
"""
    res3 = run_py(work["python"], code.format(path=str(work["fmus"]["batch"]), names=SCALAR_OUTPUTS + ["psd"]),
                  work["dir"], fmi_version=3)
    res2 = run_py(work["python"], code.format(path=str(work["fmi2"]["batch"]),
                                              names=SCALAR_OUTPUTS + [f"psd[{i}]" for i in range(1, n + 1)]),
                  work["dir"])
    assert res3["time"] == res2["time"] and res3["time"][-1] == pytest.approx(10.5)
    ref = reference(None, np.diff(res3["time"]).tolist())
    psd3 = np.array(res3["psd"])
    assert psd3.shape == (len(res3["time"]), n)
    psd2 = np.array([res2[f"psd[{i}]"] for i in range(1, n + 1)]).T
    np.testing.assert_allclose(psd3, psd2, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(psd3[1:], ref["psd"], rtol=1e-12, atol=1e-300)
    for k in SCALAR_OUTPUTS:
        np.testing.assert_allclose(res3[k], res2[k], rtol=1e-12, atol=0, err_msg=k)
        np.testing.assert_allclose(res3[k][1:], ref[k], rtol=1e-12, atol=0, err_msg=k)


#: A continuous run with irregular steps and a changing feed (rate, size distribution),
#: tip speed, solids fraction and filling; a second instance steps differently meanwhile.
DRIVE = """
a = open_fmu({path!r}, "a")
b = open_fmu({path!r}, "b")
steps, inputs = {steps!r}, {{int(k): v for k, v in {inputs!r}.items()}}
ra, t, tb = {{}}, 0.0, 0.0
for k, dt in enumerate(steps):
    assert step(a, t, dt, inputs.get(k)) == 0, LOG
    t += dt
    record(ra, a)
    assert step(b, tb, 10.0, {{"tip_speed": 5.0 + k}}) == 0
    tb += 10.0
rb = outputs(b)
a.terminate(); a.freeInstance(); b.terminate(); b.freeInstance()
done({{"a": ra, "b_x50": rb["x50"]}})
"""


def test_continuous_changing_feed_equals_the_fmi2_fmu_and_mill_model_and_instances_are_independent(work):
    path = work["scenes"]["continuous"]
    n = _n(path)
    steps = [1.0, 0.5, 2.5, 0.25, 3.0, 1.0, 0.125, 7.0, 2.0, 2.0]
    rng = np.random.default_rng(1)
    w = rng.random(n)
    w /= w.sum()
    fmi = {1: {"tip_speed": 12.0}, 3: {"feed_mass_flow": 2e-3, "psd_in": w.tolist()},
           5: {"solids_mass_fraction": 0.3, "bead_filling": 0.7},
           8: {"feed_mass_flow": 0.5e-3}}
    model = {1: {"tip_speed_m_per_s": 12.0}, 3: {"feed_mass_flow_kg_per_s": 2e-3, "psd_in": w},
             5: {"solids_mass_fraction": 0.3, "bead_filling": 0.7},
             8: {"feed_mass_flow_kg_per_s": 0.5e-3}}
    res3 = run_py(work["python"], DRIVE.format(path=str(work["fmus"]["continuous"]), steps=steps, inputs=fmi),
                  work["dir"], fmi_version=3)
    res2 = run_py(work["python"], DRIVE.format(path=str(work["fmi2"]["continuous"]), steps=steps, inputs=fmi),
                  work["dir"])
    ref = reference(path, steps, model)
    a3, a2 = (np.column_stack([r["a"][k] for k in SCALAR_OUTPUTS] + [r["a"]["psd"]]) for r in (res3, res2))
    want = np.column_stack([ref[k] for k in SCALAR_OUTPUTS] + [ref["psd"]])
    scale = np.maximum(np.abs(want), 1e-300)
    print("continuous, changing feed: largest relative difference FMI 3.0 - FMI 2.0 "
          f"{np.max(np.abs(a3 - a2) / scale):.1e}, FMI 3.0 - MillModel {np.max(np.abs(a3 - want) / scale):.1e}")
    for k in SCALAR_OUTPUTS:
        np.testing.assert_allclose(res3["a"][k], res2["a"][k], rtol=1e-12, atol=0, err_msg=k)
        np.testing.assert_allclose(res3["a"][k], ref[k], rtol=1e-12, atol=0, err_msg=k)
    np.testing.assert_allclose(res3["a"]["psd"], res2["a"]["psd"], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(res3["a"]["psd"], ref["psd"], rtol=1e-12, atol=1e-300)
    assert res3["a"]["product_mass_flow"][-1] > 0 and res3["a"]["x50"][4] != res3["a"]["x50"][
        2]  # the feed changes did act
    assert res3["b_x50"] == res2["b_x50"] != res3["a"]["x50"][-1]


#: FMU state round trip: get, set, serialize into a fresh instance, reset; the same code
#: drives the FMI 2.0 and the FMI 3.0 FMU (the preludes name the calls alike).
STATE = """
f = open_fmu({path!r})
t = 0.0
for k in range(5):
    assert step(f, t, 1.0, {{"tip_speed": 10.0 + k}}) == 0; t += 1.0
s = get_state(f)
blob = serialize_state(f, s)
def run_on(fm, t):
    rec = {{}}
    for k in range(6):
        assert step(fm, t, 0.5 + k, {{"tip_speed": 8.0 + k, "feed_mass_flow": 1e-3 * k}}) == 0; t += 0.5 + k
        record(rec, fm)
    return rec
first = run_on(f, t)
set_state(f, s)
second = run_on(f, t)
g = open_fmu({path!r}, "g")
set_state(g, deserialize_state(g, blob))  # into a fresh instance
third = run_on(g, t)
fresh = outputs(open_fmu({path!r}, "fresh"))
reset(f)
after_reset = outputs(f)
free_state(f, s)
done({{"first": first, "second": second, "third": third, "fresh": fresh, "after_reset": after_reset, "fatal": [e for e in LOG if e[1] >= 3]}})
"""  # noqa: E501


def test_state_get_set_serialize_continues_bit_identically_and_reset(work):
    res = {v: run_py(work["python"], STATE.format(path=str(work[k]["continuous"])), work["dir"], fmi_version=v)
           for v, k in ((3, "fmus"), (2, "fmi2"))}
    r = res[3]
    assert r["first"] == r["second"] == r["third"]  # bit-identical (JSON floats round-trip exactly)
    assert r["after_reset"] == r["fresh"]
    assert r["first"]["x50"][0] != r["fresh"]["x50"]
    assert r["fatal"] == []
    assert r["first"] == res[2]["first"] and r["fresh"] == res[2][
        "fresh"]  # and equal to the FMI 2.0 FMU's, bit for bit


BAD = [
    ("tip_speed", float("nan"), "must be finite"),
    ("tip_speed", float("inf"), "must be finite"),
    ("tip_speed", -1.0, "[0, 40]"),
    ("feed_mass_flow", -1e-3, "[0, 1000]"),
    ("solids_mass_fraction", 0.9, "(0, 0.8)"),
    ("bead_filling", 1.0, "(0, 1)"),
    ("bead_filling", 0.0, "(0, 1)"),
]


def test_bad_input_values_discard_the_step_with_a_message_and_keep_the_state(work):
    n = _n(work["scenes"]["continuous"])
    res = run_py(work["python"], f"""
bad = {[(k, repr(v), m) for k, v, m in BAD]!r}
f = open_fmu({str(work["fmus"]["continuous"])!r})
t = 0.0
assert step(f, t, 1.0) == 0; t += 1.0
before = outputs(f)
s = f.getFMUState()
good_psd = f.getFloat64([f.vr["psd_in"]], {n})
out = []
cases = [(k, [float(v)], m) for k, v, m in bad]
w = list(good_psd); w[2] += 0.5
cases.append(("psd_in", w, "sum to 1"))
w = list(good_psd); w[1] = -0.1
cases.append(("psd_in", w, "psd_in[2]"))
for k, v, m in cases:
    del LOG[:]
    good = f.getFloat64([f.vr[k]], len(v))
    status = step(f, t, 1.0, {{k: v}})
    out.append([k, repr(v[0]) if len(v) == 1 else "array", m, status, [e for e in LOG if e[1] >= 2], outputs(f) == before])
    f.setFloat64([f.vr[k]], good)
del LOG[:]
st_dt = step(f, t, -1.0)
dt_msgs = [e for e in LOG if e[1] >= 2]
retry = step(f, t, 1.0)
t2 = outputs(f)
f.setFMUState(s)
assert step(f, t, 1.0) == 0
done({{"bad": out, "dt": [st_dt, dt_msgs], "retry": retry, "same_as_restored": outputs(f) == t2}})
""", work["dir"], fmi_version=3)  # noqa: E501
    for name, value, allowed, status, msgs, unchanged in res["bad"]:
        assert status == 2, (name, value, status)  # fmi3Discard: the master may retry
        assert unchanged, name
        assert len(msgs) == 1 and msgs[0][1] == 2 and msgs[0][2] == "logStatusDiscard", msgs
        text = msgs[0][3]
        assert allowed in text and name in text, text
        if value != "array":
            assert value in text, text
    assert res["dt"][0] == 2 and "communicationStepSize" in res["dt"][1][0][3]
    assert res["retry"] == 0 and res["same_as_restored"]


def test_illegal_calls_answer_fmi3_error_and_leave_the_instance_usable(work):
    """What FMI 3.0 calls illegal is fmi3Error with a message naming the item, the value and
    what is allowed; nothing changes, and the instance steps on exactly as an untouched one."""
    n = _n(work["scenes"]["continuous"])
    res = run_py(work["python"], f"""
path = {str(work["fmus"]["continuous"])!r}
f = open_fmu(path, "f")
ref = open_fmu(path, "ref")
vr = f.vr
# A serialized state with one digit changed is still valid JSON: its sha256 refuses it.
blob = bytes(f.serializeFMUState(f.getFMUState()))
i = blob.index(b'"values":[') + len(b'"values":[')
edited = blob[:i] + (b"7" if blob[i:i + 1] != b"7" else b"8") + blob[i + 1:]
calls = {{
    "set output": (f.setFloat64, [vr["x50"]], [1.0]),
    "set fixed parameter": (f.setFloat64, [vr["bead_diameter"]], [1e-3]),
    "set unknown reference": (f.setFloat64, [999], [1.0]),
    "set array with too few values": (f.setFloat64, [vr["psd_in"]], [0.5, 0.5]),
    "set time": (f.setFloat64, [vr["time"]], [5.0]),
    "get unknown reference": (f.getFloat64, [999]),
    "get array with too few values": (f.getFloat64, [vr["psd"]], 3),
    "change the class count": (f.setUInt64, [vr["n_classes"]], [7]),
    "deserialize garbage": (f.deserializeFMUState, b"not a state"),
    "deserialize an edited state": (f.deserializeFMUState, edited),
}}
out = {{}}
for what, (fn, *args) in calls.items():
    del LOG[:]
    status, _ = call(fn, *args)
    out[what] = [status, [e for e in LOG if e[1] >= 2]]
# A state of another FMU (the batch mill) is refused too.
g = open_fmu({str(work["fmus"]["batch"])!r}, "g")
other = g.getFMUState()
del LOG[:]
status, _ = call(f.setFMUState, other)
out["state of another FMU"] = [status, [e for e in LOG if e[1] >= 2]]
same_n = call(f.setUInt64, [vr["n_classes"]], [{n}])[0]
rf, rr = {{}}, {{}}
for k in range(4):
    assert step(f, float(k), 1.0, {{"tip_speed": 9.0 + k}}) == 0 and step(ref, float(k), 1.0, {{"tip_speed": 9.0 + k}}) == 0
    record(rf, f); record(rr, ref)
n_read = f.getUInt64([vr["n_classes"]])
done({{"calls": out, "same_n": same_n, "equal": rf == rr, "n": n_read, "fatal": [e for e in LOG if e[1] >= 4]}})
""", work["dir"], fmi_version=3)  # noqa: E501
    expect = {
        "set output": "x50 = 1.0 refused: x50 has causality output",
        "set fixed parameter": "parameter bead_diameter = 0.001 refused: a fixed parameter can be set only before "
                               "fmi3ExitInitializationMode",
        "set unknown reference": "no Float64 variable has value reference 999",
        "set array with too few values": f"nValues = 2, but the value references name {n} values",
        "set time": "time = 5.0 refused: time has causality independent",
        "get unknown reference": "no Float64 variable has value reference 999",
        "get array with too few values": f"nValues = 3, but the value references name {n} values",
        "change the class count": f"n_classes = 7 refused: this FMU's size grid has {n} classes",
        "deserialize garbage": "fmi3DeserializeFMUState: 11 bytes that are not a serialized state of this FMU",
        "deserialize an edited state": "the state's sha256 does not match its content",
        "state of another FMU": "is not a state of this FMU",
    }
    for what, text in expect.items():
        status, msgs = res["calls"][what]
        assert status == 3, (what, status)  # fmi3Error, never fmi3Fatal
        assert any(text in m[3] for m in msgs), (what, msgs)
    assert res["same_n"] == 0 and res["n"] == [n]
    assert res["equal"] and res["fatal"] == []


def test_parameters_before_initialization_define_the_operating_point_and_refused_ones_are_errors(work):
    """On the detailed example's FMU (detailed model on the coupled DEM table, 0.5-1.2 mm beads):
    tip speed and filling set before fmi3ExitInitializationMode define the operating point; a
    bead diameter the table does not hold, or a negative one, is fmi3Error there (the value
    named) and every later step is refused; another instance in the process is unaffected."""
    path = str(work["fmus"]["table"])
    res = run_py(work["python"], f"""
f = open_fmu({path!r}, start={{"tip_speed": 8.0, "bead_filling": 0.7}})
o0 = outputs(f)
assert step(f, 0.0, 2.0) == 0
o1 = outputs(f)
out = {{}}
for name, d in (("g", -1.0), ("h", 0.3e-3)):
    g = open_fmu({path!r}, name, init=False)
    g.enterInitializationMode(startTime=0.0)
    g.setFloat64([g.vr["bead_diameter"]], [d])
    st_exit = call(g.exitInitializationMode)[0]
    st_step = step(g, 0.0, 1.0)
    out[name] = [st_exit, st_step, [e for e in LOG if e[0] == name]]
assert step(f, 2.0, 1.0) == 0
done({{"o0": o0, "o1": o1, "out": out}})
""", work["dir"], fmi_version=3)
    import millfmu

    m = MillModel(millfmu.load_scene(TABLE_SCENE, overrides={"mill.tip_speed_m_per_s": 8.0,
                                                             "mill.bead_filling": 0.7}))
    assert res["o0"]["holdup"] == m.outputs()["holdup_kg"] and res["o0"]["se_beads"] == m.outputs()["se_beads_J"]
    o = m.step(2.0)
    assert res["o1"]["x50"] == o["x50_m"] and res["o1"]["power"] == o["power_W"]
    for name, text in (("g", "bead_diameter = -1.0"),
                       ("h", "bead_diameter = 0.0003: outside the stress-energy table's grid; allowed 0.0005 to 0.0012 "
                             "m")):
        st_exit, st_step, log = res["out"][name]
        assert st_exit == 3 and st_step == 3, res["out"][name]
        assert any(e[1] == 3 and "fmi3ExitInitializationMode" in e[3] and text in e[3] for e in log), log
        assert any(e[1] == 3 and "doStep" in e[3] and text in e[3] for e in log), log


def test_fifty_instances_and_fmi2_and_fmi3_mills_in_one_process(work):
    res = run_py(work["python"], f"""
import resource
rss = []
for i in range(50):
    f = open_fmu({str(work["fmus"]["batch"])!r}, "i%d" % i)
    assert step(f, 0.0, 1.0) == 0
    f.terminate(); f.freeInstance()
    rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
b = open_fmu({str(work["fmus"]["batch"])!r}, "b")
c = open_fmu({str(work["fmus"]["continuous"])!r}, "c")
d = open_fmu({str(work["fmus"]["detailed"])!r}, "d")
# The FMI 2.0 FMU of the batch scene beside them (pythonfmu and pythonfmu3 in one process).
from fmpy.fmi2 import FMU2Slave
md2 = read_model_description({str(work["fmi2"]["batch"])!r})
e = FMU2Slave(guid=md2.guid, unzipDirectory=extract({str(work["fmi2"]["batch"])!r}), modelIdentifier=md2.coSimulation.modelIdentifier, instanceName="e")
e.instantiate(); e.setupExperiment(startTime=0.0); e.enterInitializationMode(); e.exitInitializationMode()
vr2 = {{v.name: v.valueReference for v in md2.modelVariables}}
for k in range(3):
    assert step(b, k, 1.0) == 0 and step(c, k, 1.0) == 0 and step(d, k, 1.0) == 0
    e.doStep(float(k), 1.0)
mods = sorted(m for m in sys.modules if m.startswith("Mill_"))
done({{"rss_kib": rss, "b": outputs(b)["x50"], "c": outputs(c)["x50"], "d": outputs(d)["x50"], "e": e.getReal([vr2["x50"]])[0],
       "mods": mods, "sys_path": sum(1 for p in sys.path if "resources" in p), "fatal": [x for x in LOG if x[1] >= 3]}})
""", work["dir"], fmi_version=3)  # noqa: E501
    rss = res["rss_kib"]
    assert rss[-1] - rss[9] < 20 * 1024, rss  # bounded: no per-cycle growth of whole models
    assert res["fatal"] == []
    assert len(res["mods"]) == 4
    assert res["sys_path"] <= 4  # each resources folder once (pythonfmu3 0.3.4 added one per instance)
    for kind, key in (("batch", "b"), ("continuous", "c"), ("detailed", "d")):
        assert res[key] == reference(work["scenes"][kind], [1.0] * 3)["x50"][-1]
    assert res["e"] == res["b"]


def test_build_fmu_3_rejects_a_bad_scene_naming_the_key(tmp_path):
    need_fmi3()
    bad = tmp_path / "bad.toml"
    bad.write_text(scene_text(mill={"bead_filling": 1.5}))
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", str(bad), "--fmi-version", "3", "-o",
                        str(tmp_path / "x.fmu")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "mill.bead_filling = 1.5" in r.stderr, r.stderr
    assert not (tmp_path / "x.fmu").exists()
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", "--fmi-version", "4", "-o",
                        str(tmp_path / "x.fmu")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "--fmi-version" in r.stderr and "4" in r.stderr


# ---- host exit ----------------------------------------------------------------------------
def _fmus3(work):
    return [work["fmus"][k] for k in KINDS]


def test_fifty_host_processes_exit_normally_after_a_refused_state(work):
    """50 processes, each loading the three FMI 3.0 FMUs in fmpy, stepping, handing each
    instance a state it refuses (fmi3Error), freeing them and exiting through interpreter
    teardown: every one exits 0. pythonfmu3's wrapper released its interpreter state a
    second time at exit; hosts aborted in glibc ("corrupted double-linked list") in up to
    one process of three."""
    from fmu_build.exit_study import study

    r = study(_fmus3(work), processes=50, python=work["python"], out=lambda *_: None, refused_state=True)
    assert r["failed"] == 0 and r["ok"] == 50, r


@pytest.mark.slow
def test_two_hundred_host_processes_exit_normally_after_a_refused_state(work):
    from fmu_build.exit_study import study

    r = study(_fmus3(work), processes=200, python=work["python"], refused_state=True)
    assert r["failed"] == 0, r


def test_host_exit_is_clean_under_valgrind(work):
    """One host process (load, step, refused state, free, exit) under valgrind: no invalid
    access with a frame in the FMU's binary. Whether the double release at exit aborts
    depends on the heap's layout; valgrind sees it in every run (an invalid read in
    finalizePythonInterpreter of the block the exit handlers freed)."""
    import shutil

    from fmu_build.exit_study import valgrind_errors

    if shutil.which("valgrind") is None:
        pytest.skip("valgrind is not installed (Debian: apt-get install valgrind)")
    rc, errors = valgrind_errors([work["fmus"]["batch"]], python=work["python"])
    assert rc == 0 and errors == [], "\n\n".join(errors)


def test_do_step_off_the_fmus_time_is_fmi3_error_and_the_instance_goes_on(work):
    """A currentCommunicationPoint that is not the FMU's time (fmi3EnterInitializationMode's
    startTime plus the steps taken, or the time of the state set last; to 1e-9 relative, as
    the FMI 2.0 FMU) is fmi3Error naming the value and the FMU's time; nothing changes."""
    res = run_py(work["python"], f"""
path = {str(work["fmus"]["continuous"])!r}
f = open_fmu(path, "f")
ref = open_fmu(path, "ref")
assert step(f, 0.0, 1.0) == 0 and step(ref, 0.0, 1.0) == 0
s = f.getFMUState()
before = outputs(f)
off = []
for t in (6.0, 3.0, 101.0, -2.0, 0.0, 1.001, float("nan"), float("inf")):
    del LOG[:]
    off.append([repr(t), step(f, t, 1.0), [e[3] for e in LOG if e[1] >= 2], outputs(f) == before,
                f.getFloat64([f.vr["time"]])[0]])
# The masters' round-off of accumulated time is taken as the FMU's time.
near = step(f, 1.0 + 1e-12, 0.5) == 0 and step(ref, 1.0, 0.5) == 0
same = outputs(f) == outputs(ref)
t_now = f.getFloat64([f.vr["time"]])[0]
# After a state is set, its time is the FMU's time.
f.setFMUState(s)
back = [step(f, 1.5, 1.0), step(f, 1.0, 1.0)]
# The start time of fmi3EnterInitializationMode.
g = open_fmu(path, "g", init=False)
g.enterInitializationMode(startTime=5.0); g.exitInitializationMode()
started = [g.getFloat64([g.vr["time"]])[0], step(g, 0.0, 1.0), step(g, 5.0, 1.0), g.getFloat64([g.vr["time"]])[0]]
done({{"off": off, "near": near, "same": same, "t_now": t_now, "back": back, "started": started,
       "fatal": [e for e in LOG if e[1] >= 4]}})
""", work["dir"], fmi_version=3)
    for t, status, msgs, unchanged, time in res["off"]:
        assert status == 3, (t, status)  # fmi3Error, never fmi3Fatal
        assert unchanged and time == 1.0, t
        assert any(f"currentCommunicationPoint = {t} s is not the FMU's time 1.0 s" in m for m in msgs), (t, msgs)
    assert res["near"] and res["same"] and res["t_now"] == 1.5 + 1e-12
    assert res["back"] == [3, 0]
    assert res["started"] == [5.0, 3, 0, 6.0]
    assert res["fatal"] == []


def test_fmi3_time_tolerance_is_the_fmi2_one():
    pytest.importorskip("pythonfmu3")
    pytest.importorskip("pythonfmu")
    from millfmu.fmi import base2, base3

    assert base3.TIME_RTOL == base2.TIME_RTOL


def test_tip_speeds_beyond_the_table_are_a_warning_once(work):
    """The detailed example's FMU (similar_axes = tip_speed_m_per_s on the coupled table, 6-14
    m/s): steps at 15 and 16 m/s run, and the log says once that similarity was assumed."""
    path = str(work["fmus"]["table"])
    res = run_py(work["python"], f"""
f = open_fmu({path!r}, "w")
st = [step(f, float(k), 1.0, {{"tip_speed": v}}) for k, v in enumerate((12.0, 15.0, 16.0, 10.0))]
done({{"st": st, "warn": [e[3] for e in LOG if e[0] == "w" and e[1] == 1]}})
""", work["dir"], fmi_version=3)
    assert res["st"] == [0, 0, 0, 0]
    hits = [w for w in res["warn"] if "tip_speed_m_per_s" in w and "lies outside the table's range 6 to 14" in w]
    assert len(hits) == 1 and "similarity assumed" in hits[0], res["warn"]
