"""Helpers: run ``python -m flowsheets.cli`` in a fresh process (FMUs are never loaded into
the pytest process), with one BLAS thread, and read its results."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FLOWSHEETS = ROOT / "flowsheets"


def cli(*args, timeout=600):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["OPENBLAS_NUM_THREADS"] = "1"
    return subprocess.run([sys.executable, "-m", "flowsheets.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT,
                          timeout=timeout, env=env)


def run(path, out: Path, fmu_dir: Path, *extra) -> dict:
    r = cli("run", path, "--out", out, "--fmu-dir", fmu_dir, "--no-plots", *extra)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    data = np.genfromtxt(out / "results.csv", delimiter=",", names=True, deletechars="")
    return {"summary": summary, "data": data, "stdout": r.stdout}
