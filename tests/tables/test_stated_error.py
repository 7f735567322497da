"""What a table lookup's stated error holds beyond interpolation and DEM sampling: the spread
of independent DEM realizations, and off the anchor the one-at-a-time axes' separability
error measured by the table's checks; and that the stated error covers every check the
shipped tables record (measured on the table's own DEM kernels)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from millfmu.stress_tables.stress_source import TableStressSource
from millfmu.stress_tables.table import read_table_ref


@pytest.fixture(scope="module")
def coupled():
    return read_table_ref("coupled")


def _with_checks(table, checks, spread=None):
    t = copy.copy(table)
    t.manifest = dict(table.manifest, separability_check={"measure": "test", "points": checks})
    if spread is not None:
        t.manifest["realization_spread"] = spread
    else:
        t.manifest.pop("realization_spread", None)
    return t


def _check(point, cf, se):
    return {"point": point, "collision_frequency_norm": {"lookup_rel_diff": cf},
            "se_tn_q50_norm": {"lookup_rel_diff": se}}


def test_separability_error_grows_with_the_distances_from_the_anchor_and_the_reference(coupled):
    """b = b_c (g / g_c) (h / h_c): b_c = max(l/r, r/l) - 1 at the check (lookup twice the
    run and half of it both give 1), g the largest distance from the anchor (10 m/s, 80 %)
    in units of each grid axis's range, h = |ln(d / 0.8 mm)|."""
    c = _check({"tip_speed_m_s": 6.0, "filling": 0.5, "bead_diameter_m": 1.2e-3},
               [1.0, -0.5, 0.0, None], [0.25, -0.2, None, None])
    t = _with_checks(coupled, [c])
    d12 = {"bead_diameter_m": 1.2e-3, "bead_density_kg_m3": 2510.0}
    at_check = t.separability_error({"tip_speed_m_s": 6.0, "filling": 0.5, **d12})
    assert np.allclose(at_check["collision_frequency"][:3], [1.0, 1.0, 0.0])
    assert math.isnan(at_check["collision_frequency"][3])  # a zone the check found empty
    assert np.allclose(at_check["se_median"][:2], [0.25, 0.25])
    # the anchor itself (the side table's own point) and the axes' references add nothing
    for p in ({"tip_speed_m_s": 10.0, "filling": 0.8, **d12},
              {"tip_speed_m_s": 6.0, "filling": 0.5, "bead_diameter_m": 0.8e-3,
               "bead_density_kg_m3": 2510.0}):
        e = t.separability_error(p)
        assert np.all(e["collision_frequency"] == 0.0) and np.all(e["se_median"] == 0.0)
    # a third of the check's distance from the anchor: g = 0.25 against 0.75
    e = t.separability_error({"tip_speed_m_s": 10.0, "filling": 0.7, **d12})
    assert np.allclose(e["collision_frequency"][:2], [1 / 3, 1 / 3])
    # farther along the axis than the check: ln(0.8 / 0.5) / ln(1.2 / 0.8)
    e = t.separability_error({"tip_speed_m_s": 6.0, "filling": 0.5, "bead_diameter_m": 0.5e-3,
                              "bead_density_kg_m3": 2510.0})
    assert e["collision_frequency"][0] == pytest.approx(math.log(1.6) / math.log(1.5))
    # an axis off its reference that no check measured: not stated (NaN)
    e = t.separability_error({"tip_speed_m_s": 6.0, "filling": 0.5, "bead_diameter_m": 0.8e-3,
                              "bead_density_kg_m3": 6040.0})
    assert np.all(np.isnan(e["collision_frequency"]))


def test_realization_error_is_the_manifests_spread_times_its_factor(coupled):
    spread = {"relative_sd": {"collision_frequency_norm": [0.02, 0.05, 0.03, 0.04],
                              "se_tn_q50_norm": [0.04, 0.14, 0.11, None]},
              "prediction_factor": 3.93}
    t = _with_checks(coupled, [], spread)
    e = t.realization_error()
    assert np.allclose(e["collision_frequency"], 3.93 * np.array([0.02, 0.05, 0.03, 0.04]))
    assert np.allclose(e["se_median"][:3], 3.93 * np.array([0.04, 0.14, 0.11]))
    assert math.isnan(e["se_median"][3])
    src = TableStressSource(t)
    at = {"tip_speed_m_s": 10.0, "filling": 0.8, "bead_diameter_m": 0.8e-3,
          "bead_density_kg_m3": 2510.0}
    with_spread = src.relative_error(t.lookup(at))
    without = TableStressSource(_with_checks(coupled, [])).relative_error(t.lookup(at))
    assert np.allclose(with_spread["collision_frequency"] - without["collision_frequency"],
                       e["collision_frequency"])
