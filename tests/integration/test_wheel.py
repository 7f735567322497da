"""millfmu as a user installs a release: a wheel built from the tracked files, installed (not
editable) into a fresh virtual environment. The wheel must hold every file the package can
open by its own path, and the README's quick start and tour must run from a folder outside
the checkout with that installation alone (a checkout's files are not there to fall back
on). The tour's commands are read from README.md, so the README and this test cannot drift.

Cost: the wheel build, a new environment and ``pip install WHEEL[fmu]`` (pip's cache makes
the dependencies' downloads a one-time cost), then the tour's seconds; about half a minute
on a 2-core machine with a warm cache."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: the packages the wheel ships (pyproject's packages.find)
PACKAGES = ("millfmu", "fmu_build", "flowsheets")


def _tracked_files() -> list[str]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout: the wheel is built from its tracked files")
    r = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    return [f for f in r.stdout.decode().split("\0") if f and (ROOT / f).is_file()]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel, built by pip from a copy of the tracked files (what a release is built
    from: nothing generated or left over in the checkout can slip into it)."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    for f in _tracked_files():
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, src / f)
    dist = base / "dist"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(src)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    (whl,) = dist.glob("millfmu-*.whl")
    return whl


def test_the_wheel_holds_every_file_of_the_packages(wheel):
    """Every tracked file inside the packages ships: code, the default scene, the
    stress-energy tables, the examples' scenes and stand-in data, the DEM scenes, the
    flowsheets. Left out only: the Markdown notes for readers of the source, which the code
    never opens."""
    names = set(zipfile.ZipFile(wheel).namelist())
    wanted = {f for f in _tracked_files() if f.split("/")[0] in PACKAGES and not f.endswith(".md")}
    assert {"millfmu/data/examples/limestone_standin_batch.csv", "millfmu/data/default_scene.toml",
            "flowsheets/circuit.toml"} <= wanted
    missing = sorted(wanted - names)
    assert not missing, f"not in the wheel (pyproject.toml's package-data): {missing}"


def test_the_wheel_leaves_out_the_checkouts_measuring_code(wheel):
    """The paper campaigns, equivalence runs and peer benches (validation/, benchmarks/) run
    from a checkout: no file of theirs ships, nor the tests."""
    names = zipfile.ZipFile(wheel).namelist()
    tracked = _tracked_files()
    assert any(f.startswith("validation/") for f in tracked) and any(f.startswith("benchmarks/") for f in tracked)
    shipped = sorted({n.split("/")[0] for n in names if n.split("/")[0] in ("validation", "benchmarks", "tests")})
    assert not shipped, shipped
    assert not [n for n in names if n.startswith("millfmu/dem/studies/")]


def readme_tour() -> list[list[str]]:
    """The millfmu and Python commands of the README's quick start (its first code block) and
    of its tour, each as an argument list with ``.venv/bin/`` left in front. Installs are
    dropped (the test installs the wheel), and so is the report, which needs the test extra
    and has its own test (tests/integration/test_report.py)."""
    text = (ROOT / "README.md").read_text()
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    tour = text.split("## A five-minute tour", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```bash\n(.*?)```", quick, re.S)[:1] + re.findall(r"```bash\n(.*?)```", tour, re.S)
    cmds = []
    for line in "\n".join(blocks).splitlines():
        for part in line.split(" && "):
            argv = shlex.split(part)
            if not argv or argv[0] in ("python3", ".venv/bin/pip") or argv[:2] == [".venv/bin/millfmu", "report"]:
                continue
            assert argv[0] in (".venv/bin/millfmu", ".venv/bin/python"), part
            cmds.append(argv)
    return cmds


def test_the_readme_tour_commands_are_the_ones_this_test_checks():
    firsts = [c[1] if c[0].endswith("millfmu") else "python" for c in readme_tour()]
    assert firsts == ["run", "run", "build-fmu", "python", "calibrate"], firsts


def test_the_readme_tour_runs_from_an_installed_wheel(wheel, tmp_path):
    venv = tmp_path / "venv"
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PATH"] = str(bindir) + os.pathsep + env.get("PATH", "")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = bindir / "python"
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", f"{wheel}[fmu]"], capture_output=True, text=True,
                       env=env, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    work = tmp_path / "user"  # outside the checkout: no millfmu/ folder to read examples from
    work.mkdir()
    where = subprocess.run([str(py), "-c", "import millfmu; print(millfmu.__file__)"], capture_output=True,
                           text=True, cwd=work, env=env, check=True).stdout.strip()
    assert Path(where).resolve().is_relative_to(venv.resolve()), where  # the installed copy, not the checkout

    outputs = []
    for argv in readme_tour():
        argv = [str(bindir / Path(argv[0]).name), *argv[1:]]
        r = subprocess.run(argv, capture_output=True, text=True, cwd=work, env=env, timeout=600)
        assert r.returncode == 0, f"{shlex.join(argv)}\n{r.stdout}\n{r.stderr}"
        outputs.append(r.stdout)

    # What the README says each command prints and writes.
    default = json.loads((work / "out" / "result.json").read_text())
    assert default["outputs"][-1]["t_s"] == 1800.0
    assert default["outputs"][-1]["x50_m"] == pytest.approx(2.875e-6, rel=1e-3)  # "x50 2.875 um after 30 minutes"
    lo, hi = default["prediction_band"]["outputs"]["x50_m"]
    assert (lo, hi) == pytest.approx((2.869e-6, 2.880e-6), rel=5e-4)  # "[2.869, 2.880] um from k_c"
    for name in ("result.json", "psd.csv", "psd.png", "sizes.png"):
        assert (work / "out-detailed" / name).is_file(), name
    detailed = json.loads((work / "out-detailed" / "result.json").read_text())
    assert detailed["outputs"][-1]["x50_m"] == pytest.approx(2.39e-6, rel=0.01)  # "the detailed example: 2.39 um"
    assert any("energy-limited" in w for w in detailed["warnings"])  # "it warns that it is energy-limited here"
    assert (work / "mill.fmu").is_file() and zipfile.is_zipfile(work / "mill.fmu")
    x50_fmu = [float(v) for v in re.findall(r"[0-9.]+e[-+]\d+", outputs[3])]
    assert x50_fmu == pytest.approx([1.0e-5, 4.3e-6], rel=0.02), outputs[3]  # "about 1.0e-05 and 4.3e-06"
    assert "mill.stress_frequency_factor = 1.0013" in outputs[4] and "[0.9968, 1.006]" in outputs[4]
    assert (work / "out-cal" / "calibrated.toml").is_file() and (work / "out-cal" / "calibration.json").is_file()
