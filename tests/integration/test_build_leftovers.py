"""millfmu build-fmu (issue 27): an output it cannot write is refused with exit status 2
before anything is built; what a killed build leaves behind (the FMU's part file, temporary
folders) is removed by the next build; the first build of the C++ wrapper says what it does."""

from __future__ import annotations

import os
import subprocess
import sys

from fmu_build.leftovers import clean, tag

from .fmu_support import ROOT


def _build(*args, env=None):
    return subprocess.run([sys.executable, "-m", "millfmu.cli", "build-fmu", *map(str, args)], capture_output=True,
                          text=True,
                          cwd=ROOT, env=env)


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_an_output_that_cannot_be_written_is_exit_2_without_traceback(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    for out, why in (("/proc/x.fmu", "-o /proc/x.fmu: cannot write there"), (f / "sub" / "x.fmu", "cannot write there"),
                     (tmp_path, "is a folder; give a file name ending in .fmu"),
                     ("", "-o '': is empty; give a file name ending in .fmu"),
                     (tmp_path / "x.txt", "must end in .fmu"),
                     ("/proc/x.fmu", "making a file in /proc failed")):
        r = _build("-o", out)
        assert r.returncode == 2 and "Traceback" not in r.stderr and why in r.stderr, r.stderr
    d = tmp_path / "d.fmu"
    d.mkdir()
    r = _build("-o", d)
    assert r.returncode == 2 and "is a folder" in r.stderr
    # the current folder, as "." or "./": a folder, not an empty name
    for dot in (".", "./"):
        r = _build("-o", dot)
        assert r.returncode == 2 and "-o .: is a folder; give a file name ending in .fmu" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.fmu", "file"]


def test_the_next_build_removes_what_a_killed_build_left(tmp_path):
    dead = _dead_pid()
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "x.fmu"
    left = [tmp_path / "x.fmu.part", tmp_path / f".x.fmu.{dead}_part", tmp / f"millfmu_fmu_{dead}_abc"]
    left[0].write_bytes(b"PK half")
    left[1].write_bytes(b"PK half")
    left[2].mkdir()
    (left[2] / "stage").write_text("x")
    alive = tmp / f"millfmu_fmu_{os.getpid()}_busy"  # a build that still runs keeps its folder
    alive.mkdir()
    r = _build("-o", out, env={**os.environ, "TMPDIR": str(tmp)})
    assert r.returncode == 0, r.stderr
    assert out.is_file() and not any(p.exists() for p in left), [p for p in left if p.exists()]
    assert alive.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tmp", "x.fmu"]


def test_clean_removes_only_entries_of_processes_that_no_longer_run(tmp_path):
    dead = _dead_pid()
    (tmp_path / f"p_{dead}_a").mkdir()
    (tmp_path / f"p_{dead}_b").write_text("x")
    (tmp_path / tag("p_")).mkdir()
    (tmp_path / "p_x_c").mkdir()
    (tmp_path / "other").mkdir()
    assert sorted(p.name for p in clean(tmp_path, "p_")) == [f"p_{dead}_a", f"p_{dead}_b"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([tag("p_"), "p_x_c", "other"])


def test_a_first_wrapper_build_says_what_it_does(tmp_path, monkeypatch):
    from fmu_build import wrapper

    heard = []

    def fake_build(dest, progress=None):
        progress("building pythonfmu's C++ wrapper")
        raise RuntimeError("stopped by the test")

    monkeypatch.setattr(wrapper, "build_wrapper", fake_build)
    monkeypatch.setattr(wrapper, "wrapper_dir", lambda: tmp_path)
    monkeypatch.delenv("MILLFMU_STOCK_WRAPPER", raising=False)
    wrapper.fixed_wrapper.cache_clear()
    try:
        assert wrapper.choose_wrapper(log=lambda m: None, progress=heard.append) is None
    finally:
        wrapper.fixed_wrapper.cache_clear()
    if heard:  # only where pythonfmu's version and the platform allow the fixed wrapper
        assert "wrapper" in heard[0]
