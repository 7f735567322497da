"""The scenes behind the seed validation pages' full-slice columns (validation/scenes/): they
load, hold seed 002's configuration (the whole slice, gravity across the axis) and differ
from the shipped sector scene in nothing else."""

from __future__ import annotations

import tomllib
from pathlib import Path

from millfmu.dem.mills.geometry import bead_count_for_filling, placement_capacity
from millfmu.dem.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
FULL = ROOT / "validation" / "scenes" / "accelerator_full_gravity.toml"
SECTOR = ROOT / "millfmu" / "dem" / "scenes" / "accelerator_slice.toml"


def test_the_accelerator_full_slice_is_seed_002s_configuration():
    s = load_scene(str(FULL))
    assert s.geometry.sector_deg == 360.0 and tuple(s.gravity_m_s2) == (0.0, -9.81, 0.0)
    # the bead count docs/validation-seed002.md reports for its full-slice run (80 %)
    n = bead_count_for_filling(s.geometry, 0.8, s.bead_diameter_m, s.bulk_porosity)
    assert n == 52_704 and n <= placement_capacity(s.geometry, 0.5 * s.bead_diameter_m)


def test_the_full_slice_differs_from_the_sector_only_in_name_sector_and_gravity():
    full, sector = (tomllib.loads(p.read_text()) for p in (FULL, SECTOR))
    assert (full["name"], full["mill"]["sector_deg"], full["run"]["gravity_m_s2"]) == \
        ("accelerator_full_gravity", 360.0, [0.0, -9.81, 0.0])
    for d in (full, sector):
        del d["name"], d["mill"]["sector_deg"], d["run"]["gravity_m_s2"]
    assert full == sector
