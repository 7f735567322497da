"""Tables with one-at-a-time axes (bead diameter and density varied from the scene's point):
the points run, the lookup's separable scaling (exact for a separable builder), files,
slices, the stress source and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from millfmu.dem import tables as T
from tests.tables._builders import (D_GB_M, RHO_KG_PER_M3, count, separable_builder,
                                    separable_spec)


def _counting(cf):
    def b(scene, point):
        with open(cf, "a") as fh:
            fh.write("x\n")
        return separable_builder(scene, point)
    return b


def test_points_and_count(tmp_path):
    s = separable_spec()
    pts = s.points()
    # 9 grid points, the anchor (10 m/s, 0.7) is one of them; 2 + 1 points off the grid
    assert len(pts) == 12
    assert pts[9:] == [
        {"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 0.5e-3},
        {"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 1.2e-3},
        {"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_density_kg_per_m3": 6040.0}]
    # an anchor off the grid is run as well
    off = separable_spec(anchor_filling=0.8)
    assert len(off.points()) == 13 and off.points()[9] == {"tip_speed_m_per_s": 10.0,
                                                          "filling": 0.8}
    # keys: tables without the axes keep theirs; the axes are part of the key
    assert "one_at_a_time" in s.key_content()
    assert separable_spec(one_at_a_time={}).key() != s.key()
    assert "one_at_a_time" not in separable_spec(one_at_a_time={}).key_content()
    cf = str(tmp_path / "n")
    t = T.get_table(s, _counting(cf), cache_dir=tmp_path / "c", executor="serial",
                    progress=False)
    assert count(cf) == 12
    assert set(t.one_at_a_time) == {"bead_diameter_m", "bead_density_kg_per_m3"}
    assert t.anchor == {"tip_speed_m_per_s": 10.0, "filling": 0.7}
    # a table that shares the grid points runs only the new ones
    T.get_table(separable_spec(one_at_a_time={"bead_diameter_m": [D_GB_M, 1.6e-3]}),
                _counting(cf), cache_dir=tmp_path / "c", executor="serial", progress=False)
    assert count(cf) == 13


def test_spec_errors_name_the_axis():
    with pytest.raises(T.TableError, match=r"bead_diameter_m = \[0.0005, 0.0012\].*"
                                           r"must include the scene's value 0.0008"):
        separable_spec(one_at_a_time={"bead_diameter_m": [0.5e-3, 1.2e-3]})
    with pytest.raises(T.TableError, match="also a grid axis"):
        separable_spec(one_at_a_time={"filling": [0.5, 0.7]})
    with pytest.raises(T.TableError, match="one-at-a-time axis 'speed': unknown"):
        separable_spec(one_at_a_time={"speed": [1.0]})
    with pytest.raises(T.TableError, match=r"scene \[beads\] diameter_m: missing"):
        T.TableSpec(scene={"mill": {"tip_speed_m_per_s": 10.0}}, grid={"tip_speed_m_per_s": [10.0]},
                    kernel_version="k", one_at_a_time={"bead_diameter_m": [1e-3]})


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    return T.get_table(separable_spec(), separable_builder,
                       cache_dir=tmp_path_factory.mktemp("cache"), executor="serial",
                       progress=False)


@pytest.mark.parametrize("v, phi, d, rho", [(14.0, 0.9, 1.2e-3, 6040.0),
                                           (6.0, 0.5, 0.5e-3, RHO_KG_PER_M3),
                                           (10.0, 0.7, 1.2e-3, 6040.0)])
def test_separable_builder_is_reproduced_off_the_anchor(table, v, phi, d, rho):
    pt = {"tip_speed_m_per_s": v, "filling": phi, "bead_diameter_m": d, "bead_density_kg_per_m3": rho}
    lk = table.lookup(pt)
    want = separable_builder({}, pt)
    for k in ("filling_local", "speed_over_tip_speed", "collision_frequency_norm",
              "collision_power_norm", "se_quantiles_norm"):
        np.testing.assert_allclose(lk.values[k], want[k], rtol=1e-12, atol=1e-14, err_msg=k)
    np.testing.assert_array_equal(lk.values["volume_fraction"], want["volume_fraction"])
    assert any("one-at-a-time axis; separability assumed" in n for n in lk.notes)
    # the shifted density against the exactly binned log-normal of the shifted median:
    # the shift is linear within a bin, so it agrees to a small part of the peak, its total
    # is kept and its median is the builder's to 0.01 decade
    U = T.norm_log10_edges()
    got, exact = lk.values["se_density"], np.asarray(want["se_density"])
    assert np.max(np.abs(got - exact)) < 0.02 * np.max(exact)
    np.testing.assert_allclose((got * np.diff(U)).sum(-1), 1.0, rtol=1e-12)
    for c in range(3):
        for z in range(2):
            F = np.concatenate([[0.0], np.cumsum(got[c, z] * np.diff(U))])
            med = np.interp(0.5, F, U)
            assert abs(med - np.log10(want["se_quantiles_norm"][c, z, 1])) < 0.01


def test_between_nodes_and_at_the_reference(table):
    base = {"tip_speed_m_per_s": 12.0, "filling": 0.8}
    ref = table.lookup(dict(base, bead_diameter_m=D_GB_M, bead_density_kg_per_m3=RHO_KG_PER_M3))
    assert not ref.notes  # the scene's values: the grid's lookup unchanged
    grid_only = T.Table(axes=table.axes, zone_names=table.zone_names, data=table.data,
                        refs=table.refs).lookup(base)
    for k in T.FIELDS:
        np.testing.assert_array_equal(ref.values[k], grid_only.values[k])
    # between 0.8 and 1.2 mm: linear in d along the side axis (3 nodes: errors finite)
    lk = table.lookup(dict(base, bead_diameter_m=1.0e-3, bead_density_kg_per_m3=RHO_KG_PER_M3))
    f = lambda d: (d / D_GB_M) ** -0.4  # noqa: E731
    lin = f(D_GB_M) + (f(1.2e-3) - f(D_GB_M)) * 0.5
    np.testing.assert_allclose(lk.values["collision_frequency_norm"],
                               grid_only.values["collision_frequency_norm"] * lin, rtol=1e-12)
    assert np.all(np.isfinite(lk.error["collision_frequency_norm"]))
    assert np.all(lk.error["collision_frequency_norm"] > grid_only.error[
        "collision_frequency_norm"])
    assert np.all(lk.sigma["collision_frequency_norm"] > 0)
    # the shift's own uncertainty widens the density's error beyond the grid's
    assert np.nanmax(lk.error["se_density"] - grid_only.error["se_density"]) > 0
    # between the two densities: a 2-node axis, no curvature, its field taken as monotone
    # between the nodes: the error is finite and holds the builder's value
    lk = table.lookup(dict(base, bead_diameter_m=D_GB_M, bead_density_kg_per_m3=4000.0))
    g = lambda rho: (rho / RHO_KG_PER_M3) ** 0.2  # noqa: E731  the builder's factor on rates
    exact = grid_only.values["collision_frequency_norm"] * g(4000.0)
    assert np.all(np.isfinite(lk.error["collision_frequency_norm"]))
    assert np.all(np.abs(lk.values["collision_frequency_norm"] - exact) <= lk.error["collision_frequency_norm"])


def test_lookup_refuses_outside_and_missing(table):
    with pytest.raises(T.OutsideGridError, match=r"bead_diameter_m = 0.002 m is outside"):
        table.lookup({"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 2e-3,
                      "bead_density_kg_per_m3": RHO_KG_PER_M3})
    with pytest.raises(T.TableError, match="one-at-a-time axis bead_density_kg_per_m3 missing"):
        table.lookup({"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 1e-3})
    # similarity named: the edge's change is held
    lk = table.lookup({"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 2e-3,
                       "bead_density_kg_per_m3": RHO_KG_PER_M3}, similar_axes=("bead_diameter_m",))
    at_edge = table.lookup({"tip_speed_m_per_s": 10.0, "filling": 0.7, "bead_diameter_m": 1.2e-3,
                            "bead_density_kg_per_m3": RHO_KG_PER_M3})
    np.testing.assert_array_equal(lk.values["se_density"], at_edge.values["se_density"])


def test_files_slice_and_export(table, tmp_path):
    npz, man = table.export(tmp_path / "t")
    back = T.read_table(npz=npz, manifest_path=man)
    m = json.loads(man.read_text())
    assert m["one_at_a_time"]["bead_diameter_m"] == [0.5e-3, D_GB_M, 1.2e-3]
    assert m["resolution"]["one_at_a_time"]["points"] == 3
    pt = {"tip_speed_m_per_s": 8.0, "filling": 0.6, "bead_diameter_m": 0.6e-3,
          "bead_density_kg_per_m3": 5000.0}
    for k in T.FIELDS:
        np.testing.assert_array_equal(back.lookup(pt).values[k], table.lookup(pt).values[k])
    sub = table.subset({"filling": (0.5, 0.7)})
    np.testing.assert_allclose(sub.lookup(pt).values["se_density"],
                               table.lookup(pt).values["se_density"], rtol=1e-13, atol=1e-15)
    npz2, man2 = sub.export(tmp_path / "s")
    T.read_table(npz=npz2, manifest_path=man2)
    # a side table's axis that does not match the manifest is refused
    with np.load(npz) as f:
        arrs = {k: f[k] for k in f.files}
    arrs["oat__bead_diameter_m__axis_bead_diameter_m"] = np.array([0.5e-3, 0.9e-3, 1.2e-3])
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrs)
    mm = json.loads(man.read_text())
    mm["files"]["table.npz"] = {"bytes": bad.stat().st_size, "sha256": T.sha256_file(bad)}
    mm[T.MANIFEST_SUM_KEY] = T.manifest_digest(mm)
    (tmp_path / "bad.json").write_text(json.dumps(mm))
    with pytest.raises(T.TableError, match="one-at-a-time axis bead_diameter_m missing or "
                                           "differs"):
        T.read_table(npz=bad, manifest_path=tmp_path / "bad.json")


def test_shift_log_density_moves_by_whole_bins_and_keeps_the_total():
    U = T.norm_log10_edges()
    dens = np.zeros(U.size - 1)
    dens[40:45] = [1.0, 2.0, 3.0, 2.0, 1.0]
    moved = T.shift_log_density(dens, np.array(0.4))  # two bins of 0.2 decades
    np.testing.assert_allclose(moved[42:47], dens[40:45], rtol=1e-12)
    assert abs((moved * np.diff(U)).sum() - (dens * np.diff(U)).sum()) < 1e-12
    # a shift beyond the range piles up in the end bin, total kept
    far = T.shift_log_density(dens, np.array(-30.0))
    assert far[0] > 0 and math.isclose((far * np.diff(U)).sum(), (dens * np.diff(U)).sum())


def test_stress_source_reads_the_axes(table):
    src = T.TableStressSource(table)
    assert set(src.point_of(_op(0.8e-3))) == {"tip_speed_m_per_s", "filling", "bead_diameter_m",
                                              "bead_density_kg_per_m3"}
    with pytest.raises(T.OutsideGridError, match="bead_diameter_m"):
        src.check(_op(2e-3))


def _op(d):
    from types import SimpleNamespace
    return SimpleNamespace(tip_speed_m_per_s=10.0, filling=0.7, d_gb_m=d,
                           rho_gb_kg_per_m3=RHO_KG_PER_M3, eta_susp_Pa_s=1e-3)


def test_cli_one_at_a_time(tmp_path, capsys):
    from millfmu.cli import main

    cache = str(tmp_path / "cache")
    argv = ["tables", "build", "--scene", "disc_slice", "--tip-speed", "8,10,12",
            "--filling", "0.8", "--bead-diameter", "0.0005,0.0008", "--one-at-a-time",
            "bead-diameter", "--sector-deg", "10", "--no-gravity", "--cache-dir", cache,
            "--executor", "serial", "--no-progress",
            "--builder", "tests.tables._builders:separable_builder",
            "--export", str(tmp_path / "t")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "3 x 1 points + 2 bead_diameter_m values one at a time" in out
    m = json.loads((tmp_path / "t.json").read_text())
    assert "--bead-diameter 0.0005,0.0008 --one-at-a-time bead-diameter" in m["rebuild_command"]
    assert main(argv[:2] + ["--bead-diameter", "0.0005,0.0008", "--filling", "0.8",
                            "--one-at-a-time", "bead-density", "--cache-dir", cache]) == 2
    assert "--one-at-a-time bead_density_kg_per_m3: give its values with --bead-density" in \
        capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(argv[:2] + ["--one-at-a-time", "colour"])


def test_cli_check_point(tmp_path, capsys):
    """`millfmu tables check` runs the builder at a point and compares the lookup: exact for
    a separable builder at a grid node with a one-at-a-time axis off its reference, where
    the grid alone misses the axis's factor; --write records it in the manifest."""
    from millfmu.cli import main

    prefix = str(tmp_path / "t")
    b = "tests.tables._builders:separable_builder"
    assert main(["tables", "build", "--scene", "disc_slice", "--tip-speed", "8,10,12",
                 "--filling", "0.7,0.8,0.9", "--bead-density", "2510,6040",
                 "--one-at-a-time", "bead-density", "--sector-deg", "10", "--no-gravity",
                 "--cache-dir", str(tmp_path / "cache"), "--executor", "serial",
                 "--no-progress", "--builder", b, "--export", prefix]) == 0
    capsys.readouterr()
    check = ["tables", "check", prefix, "--builder", b]
    assert main(check + ["--tip-speed", "12", "--filling", "0.9", "--bead-density", "6040",
                         "--write"]) == 0
    out = capsys.readouterr().out
    assert "collision_frequency_norm" in out and "recorded in" in out
    t = T.read_table(npz=prefix + ".npz", manifest_path=prefix + ".json")
    (res,) = t.manifest["separability_check"]["points"]
    assert res["point"] == {"tip_speed_m_per_s": 12.0, "filling": 0.9,
                            "bead_density_kg_per_m3": 6040.0}
    f = (6040.0 / RHO_KG_PER_M3) ** 0.2  # the builder's factor on rates, speeds, fillings
    for k in ("speed_over_tip_speed", "filling_local", "collision_frequency_norm"):
        assert np.allclose(res[k]["lookup_rel_diff"], 0.0, atol=1e-9)
        assert np.allclose(res[k]["grid_only_rel_diff"], 1.0 / f - 1.0, rtol=1e-3)
    assert np.allclose(res["se_tn_q50_norm"]["lookup_rel_diff"], 0.0, atol=1e-9)
    assert np.allclose(res["se_tn_q50_norm"]["grid_only_rel_diff"],
                       (6040.0 / RHO_KG_PER_M3) ** -0.3 - 1.0, rtol=1e-3)
    # the same point again replaces its entry; a point on the axes' references between
    # grid nodes is an interpolation check
    assert main(check + ["--tip-speed", "12", "--filling", "0.9", "--bead-density", "6040",
                         "--write"]) == 0
    assert main(check + ["--tip-speed", "9", "--write"]) == 0
    m = json.loads((tmp_path / "t.json").read_text())
    assert len(m["separability_check"]["points"]) == 1
    (res,) = m["interpolation_check"]["points"]
    assert res["point"] == {"tip_speed_m_per_s": 9.0, "filling": 0.8,
                            "bead_density_kg_per_m3": RHO_KG_PER_M3}
    assert "grid_only_rel_diff" in res["filling_local"]
    capsys.readouterr()
    # axes the table does not have and points outside it are refused, before any run
    assert main(check + ["--viscosity", "0.002"]) == 2
    assert "axes ['viscosity_Pa_s'] are not the table's" in capsys.readouterr().err
    assert main(check + ["--tip-speed", "20"]) == 2
    assert "tip_speed_m_per_s" in capsys.readouterr().err


def test_cli_check_from_an_earlier_manifest(tmp_path, capsys):
    """`millfmu tables check NEW --from OLD.json` compares NEW's lookup with the runs that
    OLD's checks recorded, without running the builder: after a refinement that makes the
    interpolation check's point a node, that check is exact to the recorded 4 digits; the
    separability check stays exact; a manifest of other settings is refused."""
    from millfmu.cli import main

    b = "tests.tables._builders:separable_builder"
    common = ["--filling", "0.7,0.8,0.9", "--bead-density", "2510,6040", "--one-at-a-time",
              "bead-density", "--sector-deg", "10", "--no-gravity", "--cache-dir",
              str(tmp_path / "cache"), "--executor", "serial", "--no-progress", "--builder", b]
    old, new = str(tmp_path / "old"), str(tmp_path / "new")
    assert main(["tables", "build", "--tip-speed", "8,10,12"] + common + ["--export", old]) == 0
    check = ["tables", "check", old, "--builder", b, "--write"]
    assert main(check + ["--tip-speed", "12", "--filling", "0.9", "--bead-density", "6040"]) == 0
    assert main(check + ["--tip-speed", "9"]) == 0
    interp_old = json.loads((tmp_path / "old.json").read_text())["interpolation_check"]
    assert abs(interp_old["points"][0]["se_tn_q50_norm"]["lookup_rel_diff"][0]) > 1e-3
    assert main(["tables", "build", "--tip-speed", "8,9,10,12"] + common + ["--export", new]) == 0
    capsys.readouterr()
    assert main(["tables", "check", new, "--from", old + ".json", "--write"]) == 0
    out = capsys.readouterr().out
    assert "recorded by an earlier table's check" in out and "recorded 2 checks" in out
    m = json.loads((tmp_path / "new.json").read_text())
    (sep,) = m["separability_check"]["points"]
    (itp,) = m["interpolation_check"]["points"]
    assert itp["point"]["tip_speed_m_per_s"] == 9.0 and itp["run_from"]
    assert sep["run_kernel_version"] == \
        json.loads((tmp_path / "old.json").read_text())["kernel_version"]
    for res in (sep, itp):
        for k in T.CHECK_FIELDS:
            # the runs are recorded to 4 significant digits: 5e-4 relative at most
            assert np.allclose(res[k]["lookup_rel_diff"], 0.0, atol=5e-4), (k, res[k])
    # runs of other settings are no samples of this table; a point with --from is refused
    other = str(tmp_path / "other")
    assert main(["tables", "build", "--tip-speed", "8,10,12"] + common +
                ["--record", "0.2", "--export", other]) == 0
    capsys.readouterr()
    assert main(["tables", "check", other, "--from", old + ".json"]) == 2
    assert "are not the table's, so its runs are no samples of it" in capsys.readouterr().err
    assert main(["tables", "check", new, "--from", old + ".json", "--tip-speed", "9"]) == 2


def test_a_one_at_a_time_value_inside_its_range_assumes_no_similarity():
    """The shipped coupled table scales its grid by the bead-diameter side table at 0.6 and
    1.2 mm (inside 0.5-1.2 mm): no similarity is assumed there, so a run warns of none; the
    stress source still names an axis the table does not have (similarity assumed)."""
    from millfmu.mill import MillModel
    from millfmu.scene import example_path, load_scene, scene_from_dict, scene_to_dict
    from millfmu.stress_tables.table import read_table_ref

    t = read_table_ref("coupled")
    point = {"tip_speed_m_per_s": 10.0, "filling": 0.8, "bead_diameter_m": 1.2e-3, "bead_density_kg_per_m3": 2510.0}
    lk = t.lookup(point)
    assert lk.similar == set() and any("one-at-a-time axis" in n for n in lk.notes)
    for d in (0.6e-3, 1.2e-3):
        s = scene_to_dict(load_scene(example_path("yeast_disruption_detailed")))
        s["beads"]["diameter_m"] = d
        m = MillModel(scene_from_dict(s), no_dem=True)
        m.step(1.0)
        assert m.source.similarity_warnings() == {}, d
