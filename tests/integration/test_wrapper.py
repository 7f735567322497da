"""pythonfmu's C++ wrapper rebuilt with millfmu's fixes (fmu_build.wrapper): FMUs carry it,
and host processes that load several FMUs exit normally (with pythonfmu 0.7.0's own wrapper,
62 of 200 such processes aborted in glibc at exit)."""

from __future__ import annotations

import shutil
import zipfile

import pytest

from fmu_build import wrapper as W

from .fmu_support import CONTINUOUS, DETAILED, build, isolated_python, scene_text

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

CAN_BUILD = (W._cmake() is not None and any(shutil.which(c) for c in ("c++", "g++", "clang++"))
             and W._platform_dir() is not None)
needs_build = pytest.mark.skipif(not CAN_BUILD,
                                 reason="no C++ compiler or CMake (or not linux64): FMUs keep pythonfmu's own wrapper")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("wrapper")
    (d / "c.toml").write_text(scene_text(**CONTINUOUS))
    (d / "d.toml").write_text(scene_text(**DETAILED))
    return d, [build(None, d / "b.fmu"), build(d / "c.toml", d / "c.fmu"), build(d / "d.toml", d / "d.fmu")]


def test_edits_apply_once_each_and_name_what_they_fix(tmp_path):
    """Each edit must match exactly once; on other sources it fails loudly (-> stock wrapper)."""
    root = tmp_path / "export"
    for rel, old, _ in W.EDITS:
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text((p.read_text() if p.exists() else "") + "\n" + old + "\n")
    W.apply_edits(root)
    text = (root / "src/pythonfmu/PySlaveInstance.cpp").read_text()
    assert "Py_DECREF(pGlobals)" not in text and "Py_Finalize" not in text and "fatal_error(" not in text
    with pytest.raises(RuntimeError, match="expected the text to fix once"):
        W.apply_edits(root)


@needs_build
def test_fmus_carry_the_fixed_wrapper(fmus):
    _, paths = fmus
    lib, why = W.fixed_wrapper()
    assert lib is not None, why
    for p in paths:
        z = zipfile.ZipFile(p)
        assert z.read("resources/wrapper.txt").decode().strip() == "fixed"
        (so,) = [n for n in z.namelist() if n.startswith("binaries/linux64/")]
        assert z.read(so) == lib.read_bytes()


@needs_build
def test_host_processes_exit_normally(fmus):
    """20 processes, each loading the three FMUs, stepping, freeing them and exiting through
    interpreter teardown: none may die (with the stock wrapper about a third did)."""
    from fmu_build.exit_study import study

    d, paths = fmus
    r = study(paths, processes=20, python=isolated_python(d), out=lambda *_: None)
    assert r["failed"] == 0, r


@pytest.mark.slow
@needs_build
def test_two_hundred_host_processes_exit_normally(fmus):
    from fmu_build.exit_study import study

    d, paths = fmus
    r = study(paths, processes=200, python=isolated_python(d))
    assert r["failed"] == 0, r


def test_stock_wrapper_build_warns_and_refusals_are_logged_errors(tmp_path):
    """Without the fixed wrapper (MILLFMU_STOCK_WRAPPER=1 here) build-fmu warns, and the FMU
    never raises into pythonfmu's wrapper (which would make it fmi2Fatal): a damaged state is
    a logged error and is not applied, the instance goes on."""
    import os
    import subprocess
    import sys

    from .fmu_support import ROOT, run_py

    out = tmp_path / "stock.fmu"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", "-o", str(out)], capture_output=True,
                       text=True, cwd=ROOT,
                       env={**os.environ, "MILLFMU_STOCK_WRAPPER": "1"})
    assert r.returncode == 0 and "pythonfmu's own C++ wrapper kept (MILLFMU_STOCK_WRAPPER=1)" in r.stderr
    assert zipfile.ZipFile(out).read("resources/wrapper.txt").decode().strip() == "stock"
    res = run_py(isolated_python(tmp_path), f"""
f = open_fmu({str(out)!r})
assert step(f, 0.0, 1.0) == 0
before = outputs(f)
s = f.deSerializeFMUstate(b"not a state")
f.setFMUstate(s)
errors = [m[3] for m in LOG if m[1] >= 3]
same = outputs(f) == before
off = step(f, 7.0, 1.0)
ok = step(f, 1.0, 1.0)
done({{"errors": errors, "same": same, "off": off, "ok": ok}})
""", tmp_path)
    assert any("state refused, nothing applied" in m for m in res["errors"]), res["errors"]
    assert res["same"] and res["off"] == 2 and res["ok"] == 0


def _binary_platforms(path) -> list:
    return sorted(n.split("/")[1] for n in zipfile.ZipFile(path).namelist() if n.startswith("binaries/")
                  and not n.endswith("/"))


def test_fmi2_fmus_carry_no_windows_binary(fmus, tmp_path):
    """pythonfmu's win64 wrapper is its stock one, without the fixes the linux64 binary
    carries: FMUs built with either wrapper carry linux64 only, and build-fmu says so."""
    import os
    import subprocess
    import sys

    from .fmu_support import ROOT

    _, paths = fmus
    for p in paths:
        assert _binary_platforms(p) == ["linux64"], p
    out = tmp_path / "stock.fmu"
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", "-o", str(out)], capture_output=True,
                       text=True, cwd=ROOT,
                       env={**os.environ, "MILLFMU_STOCK_WRAPPER": "1"})
    assert r.returncode == 0, r.stderr
    assert "platforms: x86_64 Linux only" in r.stdout, r.stdout
    assert _binary_platforms(out) == ["linux64"]
