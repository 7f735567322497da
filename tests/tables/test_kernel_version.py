"""The DEM kernel version is that of the shipped coupled table: the layout of millfmu.dem by
role moved the kernel modules without changing what the DEM computes, and the tables built
before (their keys hash the version) stay valid."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from millfmu.dem import tables as T

DATA = Path(__file__).resolve().parents[2] / "millfmu" / "data"


def test_kernel_version_is_the_shipped_coupled_tables():
    m = json.loads((DATA / "coupled_table.json").read_text())
    assert T.dem_kernel_version() == m["kernel_version"]


@pytest.mark.parametrize("name", ["coupled", "accelerator", "default"])
def test_shipped_table_keys_unchanged(name):
    """A shipped table's key is the hash of its spec (kernel version included)."""
    t = T.read_table_ref(name)
    assert t.spec().key() == t.manifest["key"]


def test_kernel_modules_are_found_by_label():
    for label, mod in T.KERNEL_MODULES.items():
        assert label.startswith("millfmu.dem.")
        assert importlib.util.find_spec(mod) is not None, (label, mod)


def test_tables_verify_passes_on_the_shipped_tables():
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "tables", "verify", "--default",
                        str(DATA / "coupled_table"), str(DATA / "accelerator_table"), "prescribed", "default"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    # a shipped table by name, as a scene and tables check name it
    assert "prescribed: ok" in r.stdout and "default: ok" in r.stdout and "5 checked, 0 bad" in r.stdout
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "tables", "verify", "copled"], capture_output=True,
                       text=True)
    assert r.returncode == 1 and "copled: BAD: no copled.npz or copled.json, and not a shipped table's name " \
        "(default, accelerator, coupled, prescribed)" in r.stdout, r.stdout


def test_same_results_as_an_accepted_change_take_its_version(monkeypatch):
    """SAME_DEM_AS may name the source hash of a round-off change accepted on evidence:
    sources the same to the bit as those take the version it was accepted as; a hash that
    is neither stays its own version."""
    from millfmu.dem.tables import cache, equivalence

    monkeypatch.setattr(cache, "kernel_source_hash", lambda: "sha256:bit-identical")
    monkeypatch.setattr(equivalence, "accepted_versions",
                        lambda path=None: {"sha256:accepted-change": "sha256:table-version"})
    monkeypatch.setattr(cache, "SAME_DEM_AS", {"sha256:bit-identical": "sha256:accepted-change"})
    assert cache.dem_kernel_version() == "sha256:table-version"
    monkeypatch.setattr(cache, "SAME_DEM_AS", {"sha256:bit-identical": "sha256:table-version"})
    assert cache.dem_kernel_version() == "sha256:table-version"
    monkeypatch.setattr(cache, "SAME_DEM_AS", {})
    assert cache.dem_kernel_version() == "sha256:bit-identical"
