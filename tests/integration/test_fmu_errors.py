"""FMU calls refused with fmi2Error as FMI 2.0 intends, the reason logged, the instance
usable afterwards and the host process exiting normally (issue 11, case 11): damaged,
edited or foreign serialized states, a communication point off the FMU's time, parameters
the model refuses; a start time other than 0 is honoured."""

from __future__ import annotations


import pytest

from .fmu_support import CONTINUOUS, build, isolated_python, run_py, scene_text

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmu_errors")
    cont = d / "continuous.toml"
    cont.write_text(scene_text(**CONTINUOUS))
    return {"dir": d, "batch": build(None, d / "batch.fmu"), "continuous": build(cont, d / "continuous.fmu"),
            "python": isolated_python(d)}


# Leaves through normal interpreter teardown (not os._exit): the process must not crash.
EXIT_NORMALLY = """
def finish(obj, *fmus):
    for f in fmus:
        f.terminate()
        f.freeInstance()
    print("RESULT " + json.dumps(obj), flush=True)
"""


def test_damaged_edited_and_foreign_states_are_fmi2error_and_the_instance_goes_on(work):
    res = run_py(work["python"], EXIT_NORMALLY + f"""
from fmpy.fmi2 import fmi2Byte
import ctypes
f = open_fmu({str(work["continuous"])!r}, "f")
other = open_fmu({str(work["batch"])!r}, "other")
t = 0.0
for k in range(3):
    assert step(f, t, 1.0) == 0; t += 1.0
s = f.getFMUstate()
blob = bytes(f.serializeFMUstate(s))
before = outputs(f)

def deser(fm, data):
    del LOG[:]
    try:
        st = fm.deSerializeFMUstate(data)
    except FMICallException as e:
        return e.status, [m[3] for m in LOG if m[1] >= 3]
    try:
        fm.setFMUstate(st)
        return 0, []
    except FMICallException as e:
        return e.status, [m[3] for m in LOG if m[1] >= 3]

out = {{}}
out["truncated"] = deser(f, blob[: len(blob) // 2])
out["garbage"] = deser(f, b"\\x00\\xff" * 50)
# One digit of a number changed: still valid JSON, no longer the state that was saved.
i = blob.index(b'"t_s":') + len(b'"t_s":')
digit = blob[i:i + 1]
edited = blob[:i] + (b"7" if digit != b"7" else b"8") + blob[i + 1:]
json.loads(edited)
out["edited"] = deser(f, edited)
out["foreign"] = deser(other, blob)
out["ok_after"] = outputs(f) == before
assert step(f, t, 1.0) == 0
out["good"] = deser(f, blob)  # the intact state still restores
out["after_restore"] = outputs(f) == before
finish(out, f, other)
""", work["dir"])
    for case in ("truncated", "garbage", "edited", "foreign"):
        status, msgs = res[case]
        assert status == 3, (case, status)  # fmi2Error
        assert msgs, case
    assert "sha256 does not match" in " ".join(res["edited"][1])
    assert "Mill_pm1_limestone_continuous" in " ".join(res["foreign"][1])
    assert res["ok_after"] and res["good"] == [0, []] and res["after_restore"]


def test_communication_point_off_the_fmu_time_is_fmi2error(work):
    res = run_py(work["python"], EXIT_NORMALLY + f"""
f = open_fmu({str(work["batch"])!r})
assert step(f, 0.0, 1.0) == 0
before = outputs(f)
del LOG[:]
off = step(f, 6.0, 1.0)
msgs = [m[3] for m in LOG if m[1] >= 3]
same = outputs(f) == before
ok = step(f, 1.0, 1.0)
g = open_fmu({str(work["batch"])!r}, "g", init=False)
initialize(g, start_time=100.0)
late = step(g, 100.0, 1.0)
early = step(g, 0.0, 1.0)
finish({{"off": off, "msgs": msgs, "same": same, "ok": ok, "late": late, "early": early}}, f, g)
""", work["dir"])
    assert res["off"] == 3 and res["same"] and res["ok"] == 0
    assert any("currentCommunicationPoint = 6.0" in m and "1.0" in m for m in res["msgs"]), res["msgs"]
    # said once, in the FMU's words (the wrapper adds no Python call or exception repr)
    said = "doStep refused, state unchanged: currentCommunicationPoint"
    assert len(res["msgs"]) == 1 and res["msgs"][0].startswith(said), res["msgs"]
    assert res["late"] == 0 and res["early"] == 3


def test_refused_parameter_is_fmi2error_and_free_after_it_is_safe(work):
    """The default scene (simple model) refuses a filling outside (0, 1); a table's grid
    refuses more (the detailed example's bead diameter: test_fmu, test_fmu3)."""
    res = run_py(work["python"], EXIT_NORMALLY + f"""
f = open_fmu({str(work["batch"])!r}, init=False)
ex = initialize(f, {{"bead_filling": 1.0}})
msgs = [m[3] for m in LOG if m[1] >= 3]
st = step(f, 0.0, 1.0)
finish({{"ex": ex, "st": st, "msgs": msgs}}, f)
""", work["dir"])
    assert res["ex"] == 3 and res["st"] == 2
    assert any("bead_filling = 1.0: must be a number > 0 and < 1" in m for m in res["msgs"]), res["msgs"]
