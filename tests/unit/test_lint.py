"""ruff's rule set of pyproject.toml ([tool.ruff.lint]) holds over the packages, the checkout's
measuring code (validation, benchmarks) and the tests."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _ruff() -> str | None:
    here = Path(sys.executable).parent / "ruff"  # the test extra installs it beside this Python
    return str(here) if here.exists() else shutil.which("ruff")


def test_ruff_finds_nothing():
    ruff = _ruff()
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]' brings it)")
    r = subprocess.run([ruff, "check", "--no-cache", "millfmu", "fmu_build", "flowsheets", "validation", "benchmarks",
                        "tests"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]


def test_the_rule_set_is_stated():
    text = (ROOT / "pyproject.toml").read_text()
    assert "[tool.ruff.lint]" in text and "select = [" in text.split("[tool.ruff.lint]", 1)[1]
