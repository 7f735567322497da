"""Interpolation: exact at grid points, within its stated error at held-back points,
clear refusal outside the grid; the kinetics interface over a table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.kinetics.rates import OperatingPoint
from millfmu.kinetics.stress_distribution import StressEnergySource
from tests.tables._builders import D_GB_M, POROSITY, R_DISC_M, RHO_KG_PER_M3, analytic_builder, spec

GRID = {"tip_speed_m_per_s": [6.0, 8.0, 10.0, 12.0, 14.0], "filling": [0.5, 0.6, 0.7, 0.8, 0.9]}
SCALARS = ("filling_local", "speed_over_tip_speed", "collision_frequency_norm",
           "collision_power_norm", "se_quantiles_norm")


@pytest.fixture(scope="module")
def table():
    s = spec(grid=GRID)
    return T.build_table(s, analytic_builder, executor="serial", progress=False)


def test_grid_points_exact(table):
    for v in GRID["tip_speed_m_per_s"]:
        for phi in GRID["filling"]:
            lk = table.lookup({"tip_speed_m_per_s": v, "filling": phi})
            want = analytic_builder({}, {"tip_speed_m_per_s": v, "filling": phi})
            for k in T.FIELDS:
                np.testing.assert_array_equal(lk.values[k], np.asarray(want[k], float))
                assert np.all(lk.error[k] == 0.0)


@pytest.mark.parametrize("point", [(9.0, 0.65), (7.0, 0.55), (13.3, 0.87), (11.0, 0.8)])
def test_held_back_point_within_stated_error(table, point):
    p = {"tip_speed_m_per_s": point[0], "filling": point[1]}
    lk = table.lookup(p)
    truth = analytic_builder({}, p)
    for k in SCALARS:
        actual = np.abs(lk.values[k] - truth[k])
        assert np.all(actual <= lk.error[k]), (k, actual, lk.error[k])
        # and the estimate is not vacuous: of the order of the real error
        assert np.all(lk.error[k] <= 10.0 * actual + 1e-12 * np.abs(truth[k])), k


def test_held_back_grid_node(tmp_path):
    """Build on every other node; the left-out node is predicted within the error."""
    coarse = {"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7, 0.9]}
    t = T.build_table(spec(grid=coarse), analytic_builder, executor="serial", progress=False)
    p = {"tip_speed_m_per_s": 8.0, "filling": 0.6}
    lk, truth = t.lookup(p), analytic_builder({}, p)
    rel = {}
    for k in SCALARS:
        actual = np.abs(lk.values[k] - truth[k])
        assert np.all(actual <= lk.error[k]), k
        rel[k] = float(np.max(actual / np.abs(truth[k])))
    assert rel["se_quantiles_norm"] < 0.05


def test_two_point_axis_bounds_a_monotone_field():
    """Two nodes hold no curvature: the stated error is the largest the linear interpolant can
    be off while the field stays between the nodes' values, max(t, 1 - t) |f1 - f0| (the
    largest over the interpolation cell's corners), and it covers the analytic builder's
    (monotone) truth."""
    t = T.build_table(spec(grid={"tip_speed_m_per_s": [6.0, 14.0], "filling": [0.5, 0.7, 0.9]}),
                      analytic_builder, executor="serial", progress=False)
    lk = t.lookup({"tip_speed_m_per_s": 8.0, "filling": 0.7})
    f0 = t.lookup({"tip_speed_m_per_s": 6.0, "filling": 0.7}).values["collision_frequency_norm"]
    f1 = t.lookup({"tip_speed_m_per_s": 14.0, "filling": 0.7}).values["collision_frequency_norm"]
    err = lk.error["collision_frequency_norm"]
    # at least the step at the point's own filling (the cell's corners take the largest)
    assert np.all(err >= 0.75 * np.abs(f1 - f0) - 1e-12)
    truth = analytic_builder({}, {"tip_speed_m_per_s": 8.0, "filling": 0.7})
    actual = np.abs(lk.values["collision_frequency_norm"] - truth["collision_frequency_norm"])
    assert np.all(np.isfinite(err)) and np.all(actual <= err)


def test_outside_grid_refused_with_bounds(table):
    with pytest.raises(T.OutsideGridError) as e:
        table.lookup({"tip_speed_m_per_s": 15.5, "filling": 0.7})
    msg = str(e.value)
    assert "tip_speed_m_per_s = 15.5 m/s" in msg and "allowed 6.0 to 14.0 m/s" in msg
    with pytest.raises(T.OutsideGridError, match=r"filling = 0.45 is outside.*allowed 0.5 to 0.9"):
        table.lookup({"tip_speed_m_per_s": 10.0, "filling": 0.45})
    with pytest.raises(T.TableError, match="axis filling missing"):
        table.lookup({"tip_speed_m_per_s": 10.0})


def _op(v, phi, d=D_GB_M, rho=RHO_KG_PER_M3):
    return OperatingPoint(tip_speed_m_per_s=v, filling=phi, porosity=POROSITY,
                          r_stirrer_m=R_DISC_M, d_gb_m=d, rho_gb_kg_per_m3=rho,
                          y_gb_Pa=63e9, y_p_Pa=70e9, rho_p_kg_per_m3=2710.0,
                          rho_l_kg_per_m3=998.0, eta_susp_Pa_s=1e-3, solids_mass_fraction=0.2)


def test_table_stress_source(table):
    src: StressEnergySource = T.TableStressSource(table)
    op = _op(10.0, 0.7)
    zones = src.zones(op)
    want = analytic_builder({}, {"tip_speed_m_per_s": 10.0, "filling": 0.7})
    assert [z.name for z in zones] == ["A", "B"]
    assert math.isclose(sum(z.volume_fraction for z in zones), 1.0)
    for k, z in enumerate(zones):
        assert math.isclose(z.collision_rate_per_m3_s, want["collision_frequency_norm"][k]
                            * op.omega_rad_per_s * op.n_gb_per_m3, rel_tol=1e-12)
        # at the grid point the table's own reference energy is the op's SE
        assert math.isclose(op.se_beads_J, want["e_ref_J"], rel_tol=1e-12)
        # the table's energies (1/2 m* v^2, reduced mass) counted as seed 001 eq. 1 counts a
        # collision's: 1/2 m_GM v^2 with the bead's mass, m_GM / m* = 2 for equal beads
        np.testing.assert_allclose(z.energy_edges_J, 2.0 * op.se_beads_J * 10 ** T.norm_log10_edges())
        assert math.isclose(z.energy_weights.sum(), 1.0, rel_tol=1e-12)
        # the median of the weights sits where the builder put it
        cdf = np.cumsum(z.energy_weights)
        med = z.energy_J[np.searchsorted(cdf, 0.5)]
        q50 = 2.0 * want["se_quantiles_norm"][0, k, 1] * op.se_beads_J  # by the bead mass: twice the recorded
        assert abs(math.log10(med / q50)) < 0.2  # within one bin (0.2 decade)
    # energies scale with the op's own E_ref: twice the bead density, twice the energies
    z2 = src.zones(_op(10.0, 0.7, rho=2 * RHO_KG_PER_M3))
    np.testing.assert_allclose(z2[0].energy_edges_J, 2 * zones[0].energy_edges_J)
    with pytest.raises(T.OutsideGridError, match="tip_speed_m_per_s = 5.0"):
        src.zones(_op(5.0, 0.7))
    rest = src.zones(_op(0.0, 0.7))
    assert all(z.collision_rate_per_m3_s == 0.0 for z in rest)


def test_fixed_axis_needs_match_or_similarity():
    t = T.build_table(spec(grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.7],
                                 "bead_diameter_m": [0.8e-3]}),
                      analytic_builder, executor="serial", progress=False)
    p = {"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 1.0e-3}
    with pytest.raises(T.OutsideGridError, match="bead_diameter_m = 0.001 m.*holds only 0.0008"):
        t.lookup(p)
    lk = t.lookup(p, similar_axes=("bead_diameter_m",))
    assert "similarity assumed" in lk.notes[0]
    with pytest.raises(T.OutsideGridError, match="filling = 0.8"):
        t.lookup({**p, "filling": 0.8}, similar_axes=("bead_diameter_m",))


def test_tip_speed_similarity_holds_the_edge_outside_the_grid():
    t = T.build_table(spec(grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7]}),
                      analytic_builder, executor="serial", progress=False)
    for v, edge in ((2.0, 6.0), (20.0, 14.0)):
        lk = t.lookup({"tip_speed_m_per_s": v, "filling": 0.6}, similar_axes=("tip_speed_m_per_s",))
        at = t.lookup({"tip_speed_m_per_s": edge, "filling": 0.6})
        for k in T.FIELDS:
            np.testing.assert_array_equal(lk.values[k], at.values[k])
        assert f"tip_speed_m_per_s = {v!r} outside the grid [6.0, 14.0]" in lk.notes[0]
    # round-off beyond an edge is the edge
    lk = t.lookup({"tip_speed_m_per_s": 14.0 * (1 + 4e-16), "filling": 0.7 * (1 + 4e-16)})
    np.testing.assert_array_equal(lk.values["se_density"], t.data["se_density"][2, 1])
    with pytest.raises(T.OutsideGridError, match="tip_speed_m_per_s = 14.001"):
        t.lookup({"tip_speed_m_per_s": 14.001, "filling": 0.7})
    # filling never extrapolates, and without the option tip speed does not either
    with pytest.raises(T.OutsideGridError, match="filling = 0.9"):
        t.lookup({"tip_speed_m_per_s": 8.0, "filling": 0.9}, similar_axes=("tip_speed_m_per_s",))
    with pytest.raises(T.TableError, match="similar_axes: 'filling' not allowed"):
        T.TableStressSource(t, similar_axes=["filling"])
    src = T.TableStressSource(t, similar_axes=["tip_speed_m_per_s"])
    z3, z6 = src.zones(_op(3.0, 0.6)), src.zones(_op(6.0, 0.6))
    # same dimensionless fields, scaled with the op's own E_ref and omega n_gb
    for a, b in zip(z3, z6):
        np.testing.assert_allclose(a.energy_edges_J, b.energy_edges_J * (3.0 / 6.0) ** 2)
        assert math.isclose(a.collision_rate_per_m3_s, 0.5 * b.collision_rate_per_m3_s,
                            rel_tol=1e-12)
        np.testing.assert_array_equal(a.energy_weights, b.energy_weights)


def test_source_checks_axes_the_table_does_not_vary(tmp_path):
    s = T.TableSpec(scene={"name": "analytic", "beads": {"diameter_m": D_GB_M,
                                                         "density_kg_per_m3": RHO_KG_PER_M3}},
                    grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7, 0.9]},
                    kernel_version="k", builder_id=T.builder_id_of(analytic_builder))
    t = T.get_table(s, analytic_builder, cache_dir=tmp_path, executor="serial", progress=False)
    assert t.fixed_axis_values() == {"bead_diameter_m": D_GB_M,
                                     "bead_density_kg_per_m3": RHO_KG_PER_M3}
    with pytest.raises(T.OutsideGridError, match="bead_density_kg_per_m3 = 5020.0 kg/m3.*"
                       "holds only 2510.0"):
        T.TableStressSource(t).zones(_op(10.0, 0.7, rho=2 * RHO_KG_PER_M3))
    with pytest.raises(T.TableError, match="similar_axes: 'bead_size' not allowed"):
        T.TableStressSource(t, similar_axes=["bead_size"])
    src = T.TableStressSource(t, similar_axes=["bead_density_kg_per_m3"])
    src.zones(_op(10.0, 0.7, rho=2 * RHO_KG_PER_M3))
    assert "similarity assumed" in src.last_notes[0]


def test_source_builds_on_demand_outside_the_grid(tmp_path):
    from functools import partial

    cf = str(tmp_path / "builds")
    s = spec(grid={"tip_speed_m_per_s": [6.0, 10.0], "filling": [0.5, 0.7]}, count_file=cf)
    t = T.get_table(s, analytic_builder, cache_dir=tmp_path, executor="serial", progress=False)
    rebuild = partial(T.rebuild_including, builder=analytic_builder, cache_dir=tmp_path,
                      executor="serial", progress=False)
    src = T.TableStressSource(t, on_outside="build", rebuild=rebuild)
    zones = src.zones(_op(12.0, 0.75))
    assert list(src.table.axes["tip_speed_m_per_s"]) == [6.0, 10.0, 12.0]
    assert list(src.table.axes["filling"]) == [0.5, 0.7, 0.75]
    want = analytic_builder({}, {"tip_speed_m_per_s": 12.0, "filling": 0.75})
    op = _op(12.0, 0.75)
    assert math.isclose(zones[1].collision_rate_per_m3_s, want["collision_frequency_norm"][1]
                        * op.omega_rad_per_s * op.n_gb_per_m3, rel_tol=1e-12)
    assert (tmp_path / src.table.spec().key()).is_dir()  # cached


def test_slice_for_a_scene_gives_the_same_values(tmp_path):
    s = spec(grid=GRID)
    full = T.get_table(s, analytic_builder, cache_dir=tmp_path, executor="serial",
                       progress=False)
    sub = full.subset({"tip_speed_m_per_s": (8.5, 9.5), "filling": (0.8, 0.8)})
    assert list(sub.axes["tip_speed_m_per_s"]) == [8.0, 10.0]
    assert list(sub.axes["filling"]) == [0.8]
    npz, man = sub.export(tmp_path / "fmu" / "table")
    back = T.read_table(npz=npz, manifest_path=man)
    assert back.manifest["slice_of"] == s.key()
    assert npz.stat().st_size < (full.data["se_density"].nbytes // 4)
    p = {"tip_speed_m_per_s": 9.2, "filling": 0.8}
    for k in T.FIELDS:
        np.testing.assert_array_equal(back.lookup(p).values[k], full.lookup(p).values[k])
    with pytest.raises(T.OutsideGridError, match="tip_speed_m_per_s = 15.0"):
        full.subset({"tip_speed_m_per_s": (8.0, 15.0)})


def test_sampling_sigma_from_collision_counts(table):
    p = {"tip_speed_m_per_s": 10.0, "filling": 0.7}
    lk = table.lookup(p)
    want = analytic_builder({}, p)
    np.testing.assert_allclose(lk.sigma["collision_frequency_norm"],
                               want["collision_frequency_norm"]
                               / np.sqrt(want["collision_count"]), rtol=1e-12)
    # the median of a log-normal in log10 with sd s: sigma = q ln10 sqrt(pi/2) s / sqrt(N)
    q50 = want["se_quantiles_norm"][0, :, 1]
    approx = q50 * math.log(10) * math.sqrt(math.pi / 2) * 0.6 / np.sqrt(want["collision_count"])
    np.testing.assert_allclose(lk.sigma["se_quantiles_norm"][0, :, 1], approx, rtol=0.15)
    mid = table.lookup({"tip_speed_m_per_s": 9.0, "filling": 0.7})
    assert np.all(mid.bound("se_quantiles_norm") > mid.error["se_quantiles_norm"])


def test_collision_energy_by_the_beads_mass_or_the_pairs_reduced_mass(table):
    """seed 001 eq. 1 (SE_tn = 1/2 m_GM v_rel,n^2) against the recorded 1/2 m* v_rel,n^2: the
    ratio is m_GM / m*, with m* = m_i m_j / (m_i + m_j) = m_GM / 2 for two equal beads."""
    from millfmu.stress_tables.stress_source import COLLISION_ENERGY

    m = 1.3e-6  # any bead mass [kg]
    assert COLLISION_ENERGY["bead_mass"] == m / (m * m / (m + m)) and COLLISION_ENERGY["reduced_mass"] == 1.0
    op = _op(10.0, 0.7)
    by_mass = T.TableStressSource(table).zones(op)
    reduced = T.TableStressSource(table, collision_energy="reduced_mass").zones(op)
    for a, b in zip(by_mass, reduced):
        np.testing.assert_array_equal(a.energy_edges_J, 2.0 * b.energy_edges_J)
        np.testing.assert_array_equal(a.energy_weights, b.energy_weights)
        assert a.collision_rate_per_m3_s == b.collision_rate_per_m3_s
    with pytest.raises(T.TableError, match="collision_energy = 'x': allowed 'bead_mass', 'reduced_mass'"):
        T.TableStressSource(table, collision_energy="x")


class _Prepared:
    """The analytic builder with a ``before_points`` hook that counts its calls."""

    builder_id = T.builder_id_of(analytic_builder)

    def __init__(self):
        self.before = []

    def before_points(self, spec):
        self.before.append(spec.key())

    def __call__(self, scene, point):
        return analytic_builder(scene, point)


def test_a_build_prepares_its_builder_once_where_points_are_left_to_run(tmp_path):
    """build_table calls ``builder.before_points`` (the DEM's: compile its kernels in
    several processes once, not in every worker) once before the points run, and not where
    every point is stored already."""
    s = spec()
    b = _Prepared()
    T.get_table(s, b, cache_dir=tmp_path, executor="serial", progress=False)
    assert b.before == [s.key()]
    import shutil

    shutil.rmtree(T.entry_dir(s, tmp_path))  # the table gone, its points still stored
    again = _Prepared()
    T.get_table(s, again, cache_dir=tmp_path, executor="serial", progress=False)
    assert again.before == []
