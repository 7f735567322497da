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


def test_separability_error_counts_the_distance_along_the_axis_run_across(coupled):
    """Every bead diameter of the coupled table is run across 6/10/14 m/s x 50/60/80/90 %:
    b = b_c (g / g_c) (h / h_c), g the largest distance from where the diameter was run, over
    tip speed and filling from the sub-grid's nearest values and along the diameter from the
    nearest value run (0.5/0.8/1.2 mm), each in units of its range; h = |ln(d / 0.8 mm)|."""
    c = _check({"tip_speed_m_per_s": 6.0, "filling": 0.5, "bead_diameter_m": 0.6e-3},
               [1.0, -0.5, 0.0, None], [0.25, -0.2, None, None])
    t = _with_checks(coupled, [c])

    def sep(v, phi, d, rho=2510.0):
        return t.separability_error({"tip_speed_m_per_s": v, "filling": phi, "bead_diameter_m": d,
                                     "bead_density_kg_per_m3": rho})

    at_check = sep(6.0, 0.5, 0.6e-3)
    assert np.allclose(at_check["collision_frequency"][:3], [1.0, 1.0, 0.0])
    assert math.isnan(at_check["collision_frequency"][3])  # a zone the check found empty
    assert np.allclose(at_check["se_median"][:2], [0.25, 0.25])
    # at the sub-grid's nodes (0.5 and 1.2 mm at 6 m/s, 50 %) and on the references: nothing
    for e in (sep(6.0, 0.5, 0.5e-3), sep(14.0, 0.9, 1.2e-3), sep(8.0, 0.7, 0.8e-3)):
        assert np.all(e["collision_frequency"] == 0.0) and np.all(e["se_median"] == 0.0)
    # 0.6 mm lies 0.1 mm from 0.5 mm (of 0.7 mm): g_c = 1/7 at the check and at the anchor too,
    # which is a node in tip speed and filling only
    assert np.allclose(sep(10.0, 0.8, 0.6e-3)["collision_frequency"][:2], [1.0, 1.0])
    # g = 0.25 (8 m/s: 2 of 8 from 6 and 10 m/s), 1.75 times the check's
    assert np.allclose(sep(8.0, 0.8, 0.6e-3)["collision_frequency"][:2], [1.75, 1.75])
    # 0.7 mm at the check's tip speed and filling: g = g_c, h / h_c = ln(0.8 / 0.7) / ln(0.8 / 0.6)
    assert sep(6.0, 0.5, 0.7e-3)["collision_frequency"][0] == pytest.approx(math.log(8 / 7) / math.log(4 / 3))
    # 1.2 mm between the sub-grid's nodes reads the same check: g / g_c = 1.75, h / h_c =
    # ln(1.5) / ln(4 / 3)
    assert sep(8.0, 0.7, 1.2e-3)["collision_frequency"][0] == pytest.approx(1.75 * math.log(1.5) / math.log(4 / 3))
    # an axis off its reference away from where it was run that no check measured: not
    # stated (NaN); where it was run (the density across 6/10/14 m/s x 50/60/80/90 %): none
    rho = 6040.0
    assert np.all(np.isnan(sep(8.0, 0.6, 0.8e-3, rho)["collision_frequency"]))
    assert np.all(sep(6.0, 0.5, 0.8e-3, rho)["collision_frequency"] == 0.0)


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
    at = {"tip_speed_m_per_s": 10.0, "filling": 0.8, "bead_diameter_m": 0.8e-3,
          "bead_density_kg_per_m3": 2510.0}
    with_spread = src.relative_error(t.lookup(at))
    without = TableStressSource(_with_checks(coupled, [])).relative_error(t.lookup(at))
    assert np.allclose(with_spread["collision_frequency"] - without["collision_frequency"],
                       e["collision_frequency"])


def _kernel_versions_of(table) -> set:
    """The table's kernel version and the source hashes accepted as it."""
    from millfmu.dem.tables.cache import SAME_DEM_AS
    from millfmu.dem.tables.equivalence import accepted_versions

    v = table.manifest["kernel_version"]
    return {v} | {s for s, t in SAME_DEM_AS.items() if t == v} | \
        {s for s, t in accepted_versions().items() if t == v}


def test_every_check_of_the_shipped_coupled_table_ran_on_its_kernels(coupled):
    """A check measures the table's error only with the table's own DEM: no check of another
    kernel version is kept."""
    versions = _kernel_versions_of(coupled)
    checks = [c for k in ("interpolation_check", "separability_check")
              for c in coupled.manifest[k]["points"]]
    assert len(checks) >= 4
    for c in checks:
        assert c.get("run_kernel_version") in versions, c["point"]


def test_the_stated_error_covers_every_check_of_the_shipped_coupled_table(coupled):
    """At each check's point the stated error b (per zone, collision frequency and median
    SE_tn) spans the run: max(l/r, r/l) - 1 <= b, l the lookup now, r the check's DEM run (a
    zone the run found empty has no factor to check)."""
    src = TableStressSource(coupled)
    for kind in ("interpolation_check", "separability_check"):
        for c in coupled.manifest[kind]["points"]:
            lk = coupled.lookup(c["point"])
            b = src.relative_error(lk)
            for key, fld, look in (
                    ("collision_frequency", "collision_frequency_norm",
                     lk.values["collision_frequency_norm"]),
                    ("se_median", "se_tn_q50_norm", lk.values["se_quantiles_norm"][0, :, 1])):
                run = np.array([np.nan if v is None else float(v) for v in c[fld]["run"]])
                with np.errstate(divide="ignore", invalid="ignore"):
                    measured = np.maximum(look / run, run / look) - 1.0
                ok = np.isfinite(measured) & (run > 0)
                assert np.all(measured[ok] <= b[key][ok]), (kind, c["point"], key, measured, b[key])


def test_a_node_run_again_states_its_difference_and_carries_it_to_its_cell(coupled):
    """A check at a grid node (another realization of it): at the node the stated part is
    |l - r| / l per zone, halfway to the next node the weighted |l - r| over the grid's
    interpolant there; a point whose cell holds no checked node gets none."""
    node = {"tip_speed_m_per_s": 12.0, "filling": 0.6, "bead_diameter_m": 0.8e-3,
            "bead_density_kg_per_m3": 2510.0}
    cf = np.array(coupled.lookup(node).values["collision_frequency_norm"], float)
    run = [float(v) for v in cf * np.array([2.0, 1.0, 0.5, 1.0])]
    run[3] = 0.5  # a zone empty in the table's run, filled in the other
    t = copy.copy(coupled)
    t.manifest = dict(coupled.manifest, interpolation_check={"measure": "test", "points": [
        {"point": node, "collision_frequency_norm": {"run": run},
         "se_tn_q50_norm": {"run": [None, None, None, None]}}]})
    e = t.node_check_error(t.lookup(node))
    want = np.abs(cf - np.array(run)) / cf
    np.testing.assert_allclose(e["collision_frequency"], want)
    assert np.all(e["se_median"] == 0.0)  # no run value: nothing measured
    half = dict(node, tip_speed_m_per_s=13.0)
    cf14 = coupled.lookup(dict(node, tip_speed_m_per_s=14.0)).values["collision_frequency_norm"]
    e = t.node_check_error(t.lookup(half))
    np.testing.assert_allclose(e["collision_frequency"],
                               0.5 * np.abs(cf - np.array(run)) / (0.5 * cf + 0.5 * cf14))
    far = t.node_check_error(t.lookup(dict(node, tip_speed_m_per_s=8.0, filling=0.8)))
    assert np.all(far["collision_frequency"] == 0.0)
