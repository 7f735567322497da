"""A one-at-a-time axis run across a sub-grid of the grid axes (``TableSpec.across``), where
its effect depends on them: the points run, the lookup's scaling interpolated over the
sub-grid (exact at its nodes), files, the separability error's distance and the CLI."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from millfmu.dem import tables as T
from tests.tables._builders import (D_GB_M, RHO_KG_PER_M3, _densities, q50_norm,
                                    separable_builder)

RHO_HI = 6040.0
SUB = {"tip_speed_m_per_s": [6.0, 14.0], "filling": [0.5, 0.7, 0.9]}


def density_effect(rho: float, v: float, phi: float) -> tuple:
    """What the bead density changes beyond the separable builder's: rates times
    (rho/2510)^(0.05 (v - 10)), energies shifted by log10 (rho/2510)^(0.5 (phi - 0.7)), so
    that its effect at 6 m/s and 50 % is not its effect at the anchor (10 m/s, 70 %)."""
    r = rho / RHO_KG_PER_M3
    return r ** (0.05 * (v - 10.0)), math.log10(r ** (0.5 * (phi - 0.7)))


def _with_effect(out: dict, f: float, shift: float) -> tuple:
    """A builder's result with rates and speeds times ``f`` and the SE quantiles shifted by
    ``shift`` decades, and the shift (for the densities the caller rebuilds)."""
    for k in ("filling_local", "speed_over_tip_speed", "collision_frequency_norm",
              "collision_power_norm"):
        out[k] = out[k] * f
    out["se_quantiles_norm"] = out["se_quantiles_norm"] * 10.0 ** shift
    return out, shift


def coupled_builder(scene: dict, point: dict) -> dict:
    beads = scene.get("beads", {})
    rho = float(point.get("bead_density_kg_per_m3", beads.get("density_kg_per_m3", RHO_KG_PER_M3)))
    d = float(point.get("bead_diameter_m", beads.get("diameter_m", D_GB_M)))
    v = float(point.get("tip_speed_m_per_s", 10.0))
    phi = float(point.get("filling", 0.8))
    out, shift = _with_effect(separable_builder(scene, point), *density_effect(rho, v, phi))
    base = math.log10((d / D_GB_M) ** 0.7 * (rho / RHO_KG_PER_M3) ** 0.3)
    out["se_density"] = np.array(_densities(np.log10(q50_norm(v, phi)) + base + shift))
    return out


def spec(across=None) -> T.TableSpec:
    scene = {"name": "coupled-effect", "mill": {"tip_speed_m_per_s": 10.0},
             "beads": {"filling": 0.7, "diameter_m": D_GB_M, "density_kg_per_m3": RHO_KG_PER_M3}}
    return T.TableSpec(scene=scene,
                       grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7, 0.9]},
                       kernel_version="test-kernel-1",
                       builder_id=T.builder_id_of(coupled_builder),
                       one_at_a_time={"bead_diameter_m": [0.5e-3, D_GB_M, 1.2e-3],
                                      "bead_density_kg_per_m3": [RHO_KG_PER_M3, RHO_HI]},
                       across={} if across is None else across)


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    d = tmp_path_factory.mktemp("across")
    kw = dict(cache_dir=d / "c", executor="serial", progress=False)
    return (T.get_table(spec({"bead_density_kg_per_m3": SUB}), coupled_builder, **kw),
            T.get_table(spec(), coupled_builder, **kw))


def _point(v, phi, rho=RHO_HI, d=D_GB_M):
    return {"tip_speed_m_per_s": v, "filling": phi, "bead_diameter_m": d,
            "bead_density_kg_per_m3": rho}


def test_points_key_and_side_table():
    s = spec({"bead_density_kg_per_m3": SUB})
    pts = s.points()
    # 9 grid points (the anchor among them), 2 diameters at the anchor, the density's other
    # value at the 2 x 3 sub-grid (at the scene's density the sub-grid's points are the grid's)
    assert len(pts) == 9 + 2 + 6
    assert {"tip_speed_m_per_s": 6.0, "filling": 0.5, "bead_density_kg_per_m3": RHO_HI} in pts
    assert list(s.side_axes("bead_density_kg_per_m3")) == [
        "bead_density_kg_per_m3", "tip_speed_m_per_s", "filling"]
    assert list(s.side_axes("bead_diameter_m")) == ["bead_diameter_m"]
    # a table without ``across`` keeps its key; with it, the sub-grid is part of the key
    assert "across" not in spec().key_content()
    assert s.key() != spec().key()
    assert s.key_content()["across"] == {"bead_density_kg_per_m3": SUB}


def test_spec_errors_name_the_item():
    with pytest.raises(T.TableError, match="'filling' is not a one-at-a-time axis"):
        spec({"filling": {"tip_speed_m_per_s": [6.0, 14.0]}})
    with pytest.raises(T.TableError, match="viscosity_Pa_s is not a grid axis"):
        spec({"bead_density_kg_per_m3": {"viscosity_Pa_s": [0.001, 0.002]}})
    with pytest.raises(T.TableError, match=r"filling = \[0.5\]: give at least 2 values"):
        spec({"bead_density_kg_per_m3": {"filling": [0.5]}})


@pytest.mark.parametrize("v,phi", [(6.0, 0.5), (14.0, 0.9), (6.0, 0.7), (14.0, 0.5)])
def test_exact_at_the_sub_grids_nodes_where_the_anchor_alone_misses(tables, v, phi):
    """At the sub-grid's nodes the lookup is the builder's run; a table that ran the density
    at the anchor alone misses by the effect's dependence on tip speed and filling."""
    across, alone = tables
    run = coupled_builder({"beads": {"diameter_m": D_GB_M}}, _point(v, phi))
    a, b = across.lookup(_point(v, phi)), alone.lookup(_point(v, phi))
    for k in ("collision_frequency_norm", "filling_local", "speed_over_tip_speed"):
        np.testing.assert_allclose(a.values[k], run[k], rtol=1e-12)
    np.testing.assert_allclose(a.values["se_quantiles_norm"][..., 1],
                               run["se_quantiles_norm"][..., 1], rtol=1e-12)
    f, shift = density_effect(RHO_HI, v, phi)
    f0, shift0 = density_effect(RHO_HI, 10.0, 0.7)
    miss = b.values["collision_frequency_norm"] / run["collision_frequency_norm"]
    np.testing.assert_allclose(miss, f0 / f, rtol=1e-12)
    assert not np.allclose(miss, 1.0, rtol=1e-3)
    assert any("sub-grid it was run across" in n for n in a.notes)


def test_between_nodes_nearer_than_the_anchor_alone(tables):
    across, alone = tables
    p = _point(8.0, 0.6)
    run = coupled_builder({"beads": {"diameter_m": D_GB_M}}, p)
    err = [abs(t.lookup(p).values["collision_frequency_norm"][0] / run["collision_frequency_norm"][0] - 1)
           for t in (across, alone)]
    assert err[0] < 0.5 * err[1]
    # the density at its reference: the grid alone, whatever the sub-grid
    ref = _point(8.0, 0.6, rho=RHO_KG_PER_M3)
    np.testing.assert_array_equal(across.lookup(ref).values["collision_frequency_norm"],
                                  alone.lookup(ref).values["collision_frequency_norm"])


def test_files_round_trip_and_slice(tables, tmp_path):
    across, _ = tables
    npz, man = across.export(tmp_path / "t")
    back = T.read_table(npz=npz, manifest_path=man)
    side = back.one_at_a_time["bead_density_kg_per_m3"]
    assert list(side.axes) == ["bead_density_kg_per_m3", "tip_speed_m_per_s", "filling"]
    assert side.shape == (2, 2, 3)
    p = _point(7.0, 0.55)
    np.testing.assert_array_equal(back.lookup(p).values["se_density"],
                                  across.lookup(p).values["se_density"])
    assert json.loads(man.read_text())["across"] == {"bead_density_kg_per_m3": SUB}
    part = across.subset({"tip_speed_m_per_s": (6.0, 9.0)})
    np.testing.assert_array_equal(part.lookup(p).values["collision_frequency_norm"],
                                  across.lookup(p).values["collision_frequency_norm"])
    # a side table whose sub-grid differs from the manifest's is refused
    m = json.loads(man.read_text())
    m["across"]["bead_density_kg_per_m3"]["filling"] = [0.5, 0.9]
    with pytest.raises(T.TableError):
        T.read_table(npz=npz, manifest_path=_rewrite(man, m))


def _rewrite(man, m):
    from millfmu.stress_tables.files import manifest_digest

    m = {k: v for k, v in m.items() if k != "manifest_sha256"}
    m["key"] = T.TableSpec(scene=m["scene"], grid=m["grid"], kernel_version=m["kernel_version"],
                           builder_id=m["builder"], one_at_a_time=m["one_at_a_time"],
                           across=m["across"]).key()
    m["manifest_sha256"] = manifest_digest(m)
    man.write_text(json.dumps(m))
    sums = man.with_name(man.name + ".sha256")
    if sums.exists():
        sums.unlink()
    return man


def test_separability_error_counts_the_distance_from_the_sub_grid(tables):
    """A check off the sub-grid's nodes states b = b_c (g / g_c) (h / h_c), g the distance
    from the nearest sub-grid value per grid axis; zero where the density was run."""
    across, _ = tables
    t = _with_check(across, {"tip_speed_m_per_s": 10.0, "filling": 0.6, "bead_diameter_m": D_GB_M,
                             "bead_density_kg_per_m3": RHO_HI}, 0.2)
    # the check's distance: tip speed on the sub-grid's 6/14 is 4/8, filling 0.1/0.4
    at = t.separability_error(_point(10.0, 0.6))
    assert at["collision_frequency"][0] == pytest.approx(0.2)
    for p in (_point(6.0, 0.5), _point(14.0, 0.7), _point(6.0, 0.6, rho=RHO_KG_PER_M3)):
        assert t.separability_error(p)["collision_frequency"][0] == 0.0
    # half the check's distance (tip speed 8: 2/8 from 6 m/s)
    assert t.separability_error(_point(8.0, 0.5))["collision_frequency"][0] == pytest.approx(0.1)
    # off the sub-grid with no check: not stated
    assert math.isnan(across.separability_error(_point(8.0, 0.5))["collision_frequency"][0])


def test_separability_error_of_an_axis_run_at_the_anchor_alone(tables):
    """The diameter run at the anchor alone (10 m/s, 70 %) at 0.5/0.8/1.2 mm: b = b_c (g /
    g_c) (h / h_c), g the largest distance from the anchor over tip speed and filling and
    along the diameter from the nearest value run, each in units of its range; h = |ln(d /
    0.8 mm)|."""
    _, alone = tables
    t = copy.copy(alone)
    c = {"point": _point(6.0, 0.5, rho=RHO_KG_PER_M3, d=D_LO),
         "collision_frequency_norm": {"lookup_rel_diff": [1.0, -0.5]},
         "se_tn_q50_norm": {"lookup_rel_diff": [0.25, None]}}
    t.manifest = dict(alone.manifest, separability_check={"measure": "test", "points": [c]})

    def cf(v, phi, d, rho=RHO_KG_PER_M3):
        return t.separability_error(_point(v, phi, rho=rho, d=d))["collision_frequency"]

    assert np.allclose(cf(6.0, 0.5, D_LO), [1.0, 1.0])  # g_c = 0.5 (4 of 8 m/s, 0.2 of 0.4)
    assert math.isnan(t.separability_error(_point(6.0, 0.5, rho=RHO_KG_PER_M3, d=D_LO))["se_median"][1])
    for p in ((10.0, 0.7, D_LO), (6.0, 0.5, D_GB_M)):  # the anchor's run; the reference
        assert np.all(cf(*p) == 0.0)
    assert np.allclose(cf(10.0, 0.6, D_LO), [0.5, 0.5])  # g = 0.25
    h = math.log(D_GB_M / 0.6e-3) / math.log(D_GB_M / D_LO)
    assert cf(6.0, 0.5, 0.6e-3)[0] == pytest.approx(h)  # g = g_c, nearer the reference
    # at the anchor, between 0.5 and 0.8 mm: g = 0.1 / 0.7 along the diameter
    assert cf(10.0, 0.7, 0.6e-3)[0] == pytest.approx((0.1 / 0.7) / 0.5 * h)
    # the density run at the anchor alone with no check: NaN off the anchor, 0 at its run
    assert np.all(np.isnan(cf(8.0, 0.6, D_GB_M, RHO_HI)))
    assert np.all(cf(10.0, 0.7, D_GB_M, RHO_HI) == 0.0)


def test_a_node_run_again_states_its_difference_near_that_node(tables):
    """A check at a node of the sub-grid (another realization of it) adds its b_c there,
    carried by the side table's interpolation weights: half of it halfway to the next tip
    speed, nothing at the other nodes or at the density's reference."""
    across, _ = tables
    node = _point(6.0, 0.5)
    t = _with_check(across, node, 0.5)
    assert t.separability_error(node)["collision_frequency"][0] == pytest.approx(0.5)
    assert t.separability_error(_point(6.0, 0.5, rho=RHO_KG_PER_M3))["se_median"][0] == 0.0
    assert t.separability_error(_point(14.0, 0.5))["collision_frequency"][0] == 0.0
    # halfway in tip speed and density (the side table's axes): weight 1/4; off the
    # sub-grid's nodes no distance check measured it (NaN)
    mid = _point(10.0, 0.5, rho=math.sqrt(RHO_KG_PER_M3 * RHO_HI))
    assert math.isnan(t.separability_error(mid)["collision_frequency"][0])
    w = dict(t._side_weights("bead_density_kg_per_m3", mid))[(0, 0, 0)]
    assert w == pytest.approx(0.5 * (RHO_HI - mid["bead_density_kg_per_m3"]) / (RHO_HI - RHO_KG_PER_M3))


def _with_check(table, point, b):
    import copy

    t = copy.copy(table)
    c = {"point": point, "collision_frequency_norm": {"lookup_rel_diff": [b, b]},
         "se_tn_q50_norm": {"lookup_rel_diff": [b, b]}}
    t.manifest = dict(table.manifest, separability_check={"measure": "test", "points": [c]})
    return t


def _build_argv(tmp_path, axis: str, values: str, across: str, builder: str) -> list:
    """``millfmu tables build`` of the disc slice on 8/10/12 m/s x 70/80 % with one
    one-at-a-time axis run across, by a stand-in builder of this module, exported to t."""
    return ["tables", "build", "--scene", "disc_slice", "--tip-speed", "8,10,12",
            "--filling", "0.7,0.8", f"--{axis}", values, "--one-at-a-time", axis, "--across", across,
            "--sector-deg", "10", "--no-gravity", "--cache-dir", str(tmp_path / "cache"), "--executor",
            "serial", "--no-progress", "--builder", f"tests.tables.test_across:{builder}",
            "--export", str(tmp_path / "t")]


def test_cli_across_builds_and_names_it_in_the_rebuild_command(tmp_path, capsys):
    from millfmu.cli import main

    argv = _build_argv(tmp_path, "bead-density", "2510,6040", "bead-density:tip-speed=8,12", "coupled_builder")
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "3 x 2 points + 2 bead_density_kg_per_m3 values one at a time across 2 grid points" in out
    m = json.loads((tmp_path / "t.json").read_text())
    assert "--one-at-a-time bead-density --across bead-density:tip-speed=8,12" in m["rebuild_command"]
    assert m["across"] == {"bead_density_kg_per_m3": {"tip_speed_m_per_s": [8.0, 12.0]}}
    assert main(argv[:-2] + ["--across", "bead-diameter:tip-speed=8,12"]) == 2
    assert "'bead_diameter_m' is not a one-at-a-time axis" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(argv[:2] + ["--across", "bead-density"])
    assert "expected AXIS[=V1,V2,..]:GRID-AXIS=V1,V2" in capsys.readouterr().err
    for bad, words in (("bead-density,filling:tip-speed=8,12", "expected one axis name"),
                       ("bead-density:tip-speed=8,12:tip-speed=8,10", "tip-speed given twice")):
        with pytest.raises(SystemExit):
            main(argv[:2] + ["--across", bad])
        assert words in capsys.readouterr().err
    assert main(argv[:-2] + ["--across", "bead-density:filling=0.7,0.8"]) == 2
    assert "--across bead_density_kg_per_m3: given more than once" in capsys.readouterr().err


# ---- an axis run partly across: some of its values across the sub-grid, the others at the anchor
D_LO, D_HI = 0.5e-3, 1.2e-3
PART = {"bead_diameter_m": [D_GB_M, D_HI], "tip_speed_m_per_s": [6.0, 14.0], "filling": [0.5, 0.7, 0.9]}


def diameter_effect(d: float, v: float, phi: float) -> tuple:
    """What the bead diameter changes beyond the separable builder's, depending on tip speed
    and filling: rates times (d/0.8 mm)^(0.1 (v - 10)), energies shifted by
    log10 (d/0.8 mm)^(phi - 0.7)."""
    r = d / D_GB_M
    return r ** (0.1 * (v - 10.0)), math.log10(r ** (phi - 0.7))


def diameter_builder(scene: dict, point: dict) -> dict:
    beads = scene.get("beads", {})
    d = float(point.get("bead_diameter_m", beads.get("diameter_m", D_GB_M)))
    v = float(point.get("tip_speed_m_per_s", 10.0))
    phi = float(point.get("filling", 0.8))
    out, shift = _with_effect(coupled_builder(scene, point), *diameter_effect(d, v, phi))
    rho = float(point.get("bead_density_kg_per_m3", beads.get("density_kg_per_m3", RHO_KG_PER_M3)))
    base = math.log10((d / D_GB_M) ** 0.7 * (rho / RHO_KG_PER_M3) ** 0.3)
    out["se_density"] = np.array(_densities(np.log10(q50_norm(v, phi)) + base + shift
                                            + density_effect(rho, v, phi)[1]))
    return out


def part_spec(across) -> T.TableSpec:
    return T.TableSpec(**{**spec().__dict__, "builder_id": T.builder_id_of(diameter_builder),
                          "across": across})


@pytest.fixture(scope="module")
def part_tables(tmp_path_factory):
    """(partly across, every diameter at the anchor alone, every diameter across)."""
    d = tmp_path_factory.mktemp("part")
    kw = dict(cache_dir=d / "c", executor="serial", progress=False)
    full = {k: v for k, v in PART.items() if k != "bead_diameter_m"}
    return tuple(T.get_table(part_spec(a), diameter_builder, **kw)
                 for a in ({"bead_diameter_m": PART}, {}, {"bead_diameter_m": full}))


def test_partly_across_points_and_key():
    s = part_spec({"bead_diameter_m": PART})
    assert s.partly_across("bead_diameter_m")
    assert s.side_axes("bead_diameter_m") == {"bead_diameter_m": (D_GB_M, D_HI),
                                              "tip_speed_m_per_s": (6.0, 14.0), "filling": (0.5, 0.7, 0.9)}
    assert s.anchor_side_axes("bead_diameter_m") == {"bead_diameter_m": (D_LO, D_GB_M, D_HI)}
    pts = s.points()
    # 9 grid points, 0.5 and 1.2 mm and the density's 6040 at the anchor, 1.2 mm at the 2 x 3
    # sub-grid; 0.5 mm at no sub-grid point
    assert len(pts) == 9 + 3 + 6
    assert {"tip_speed_m_per_s": 6.0, "filling": 0.5, "bead_diameter_m": D_HI} in pts
    assert not [p for p in pts if p.get("bead_diameter_m") == D_LO and p["tip_speed_m_per_s"] != 10.0]
    # all values named: the same specification as the axis across without the list
    every = dict(PART, bead_diameter_m=[D_LO, D_GB_M, D_HI])
    full = {k: v for k, v in PART.items() if k != "bead_diameter_m"}
    assert part_spec({"bead_diameter_m": every}).key() == part_spec({"bead_diameter_m": full}).key()
    assert s.key() != part_spec({"bead_diameter_m": full}).key()


@pytest.mark.parametrize("vals,words", [([D_LO, D_HI], "consecutive values"),
                                        ([D_HI], "consecutive values"),
                                        ([D_GB_M, 1.0e-3], "is not one of the axis's values"),
                                        ([D_LO, D_GB_M - 1e-9], "is not one of")])
def test_partly_across_errors_name_the_values(vals, words):
    with pytest.raises(T.TableError, match=words):
        part_spec({"bead_diameter_m": dict(PART, bead_diameter_m=vals)})
    with pytest.raises(T.TableError, match="besides its own"):
        part_spec({"bead_diameter_m": {"bead_diameter_m": [D_GB_M, D_HI]}})


@pytest.mark.parametrize("v,phi", [(6.0, 0.5), (14.0, 0.9), (6.0, 0.7)])
def test_partly_across_exact_at_the_nodes_and_the_anchor_beyond(part_tables, v, phi):
    """1.2 mm at the sub-grid's nodes: the builder's run; 0.5 mm (run at the anchor alone):
    the anchor-alone table's lookup to the bit; 1.0 mm (between the values run across):
    the every-value-across table's values."""
    part, alone, full = part_tables
    run = diameter_builder({"beads": {"diameter_m": D_GB_M}}, _point(v, phi, rho=RHO_KG_PER_M3, d=D_HI))
    got = part.lookup(_point(v, phi, rho=RHO_KG_PER_M3, d=D_HI))
    for k in ("collision_frequency_norm", "filling_local", "speed_over_tip_speed"):
        np.testing.assert_allclose(got.values[k], run[k], rtol=1e-12)
    np.testing.assert_allclose(got.values["se_quantiles_norm"][..., 1], run["se_quantiles_norm"][..., 1],
                               rtol=1e-12)
    lo = _point(v, phi, rho=RHO_KG_PER_M3, d=0.6e-3)
    a, b = part.lookup(lo), alone.lookup(lo)
    for k in a.values:
        np.testing.assert_array_equal(a.values[k], b.values[k])
    assert any("separability assumed" in n for n in a.notes)
    mid = _point(v, phi, rho=RHO_KG_PER_M3, d=1.0e-3)
    a, c = part.lookup(mid), full.lookup(mid)
    for k in ("collision_frequency_norm", "collision_power_norm", "se_density"):
        np.testing.assert_allclose(a.values[k], c.values[k], rtol=1e-12, atol=1e-300)


def test_partly_across_files_slice_and_range(part_tables, tmp_path):
    part, _, _ = part_tables
    npz, man = part.export(tmp_path / "p")
    back = T.read_table(npz=npz, manifest_path=man)
    assert list(back.one_at_a_time_anchor) == ["bead_diameter_m"]
    assert list(back.one_at_a_time_values("bead_diameter_m")) == [D_LO, D_GB_M, D_HI]
    for d in (0.6e-3, 1.1e-3):
        p = _point(7.0, 0.55, rho=RHO_KG_PER_M3, d=d)
        np.testing.assert_array_equal(back.lookup(p).values["se_density"], part.lookup(p).values["se_density"])
        sub = part.subset({"tip_speed_m_per_s": (6.0, 9.0)})
        np.testing.assert_array_equal(sub.lookup(p).values["collision_frequency_norm"],
                                      part.lookup(p).values["collision_frequency_norm"])
    with pytest.raises(T.OutsideGridError, match="bead_diameter_m"):
        part.lookup(_point(8.0, 0.6, rho=RHO_KG_PER_M3, d=0.4e-3))
    with pytest.raises(T.OutsideGridError, match="bead_diameter_m"):
        part.lookup(_point(8.0, 0.6, rho=RHO_KG_PER_M3, d=1.4e-3))
    # the side table at the anchor is missing from the file: refused, naming it
    from millfmu.stress_tables.files import sha256_file

    with np.load(npz) as f:
        arrs = {k: f[k] for k in f.files if not k.startswith("oat_anchor__")}
    bad = tmp_path / "q.npz"
    np.savez_compressed(bad, **arrs)
    m = json.loads(man.read_text())
    m["files"] = {"table.npz": {"bytes": bad.stat().st_size, "sha256": sha256_file(bad)}}
    with pytest.raises(T.TableError, match="bead_diameter_m at the anchor missing"):
        T.read_table(npz=bad, manifest_path=_rewrite(tmp_path / "q.json", m))


def test_partly_across_separability_reads_the_checks_of_its_side(part_tables):
    """A point beyond the values run across reads the checks at the anchor's side (distance
    from the anchor); one within them, the sub-grid's checks only."""
    part, _, _ = part_tables
    off = _point(8.0, 0.6, rho=RHO_KG_PER_M3, d=D_LO)  # a check of the side at the anchor
    t = _with_check(part, off, 0.3)
    assert t.separability_error(off)["collision_frequency"][0] == pytest.approx(0.3)
    # 1.0 mm between the sub-grid's nodes: that check is not its side's, so nothing measured it
    assert math.isnan(t.separability_error(_point(8.0, 0.6, rho=RHO_KG_PER_M3, d=1.0e-3))["collision_frequency"][0])
    # at the sub-grid's nodes nothing is added
    assert t.separability_error(_point(6.0, 0.5, rho=RHO_KG_PER_M3, d=D_HI))["collision_frequency"][0] == 0.0
    within = _point(8.0, 0.6, rho=RHO_KG_PER_M3, d=D_HI)
    t = _with_check(part, within, 0.2)
    assert t.separability_error(within)["collision_frequency"][0] == pytest.approx(0.2)
    assert math.isnan(t.separability_error(off)["collision_frequency"][0])


def test_cli_partly_across_parses_and_names_it_in_the_rebuild_command(tmp_path):
    from millfmu.cli import main
    from millfmu.dem.tables.cli import _across

    assert _across("bead-diameter=0.0008,0.0012:tip-speed=6,14") == (
        "bead_diameter_m", {"bead_diameter_m": [0.0008, 0.0012], "tip_speed_m_per_s": [6.0, 14.0]})
    argv = _build_argv(tmp_path, "bead-diameter", "0.0005,0.0008,0.0012",
                       "bead-diameter=0.0008,0.0012:tip-speed=8,12", "diameter_builder")
    assert main(argv) == 0
    m = json.loads((tmp_path / "t.json").read_text())
    assert "--across bead-diameter=0.0008,0.0012:tip-speed=8,12" in m["rebuild_command"]
    assert m["across"] == {"bead_diameter_m": {"bead_diameter_m": [0.0008, 0.0012],
                                               "tip_speed_m_per_s": [8.0, 12.0]}}
    t = T.read_table(npz=tmp_path / "t.npz", manifest_path=tmp_path / "t.json")
    assert t.one_at_a_time["bead_diameter_m"].shape == (2, 2)
    assert t.one_at_a_time_anchor["bead_diameter_m"].shape == (3,)


def test_a_value_added_beyond_the_values_run_across_runs_at_the_anchor(part_tables, tmp_path):
    """On demand, 1.4 mm beyond the diameters run across (0.8, 1.2 mm): one new point, at the
    anchor; the values run across and their sub-grid stay as they are."""
    from millfmu.dem.tables.dem_builder import rebuild_including

    part, _, _ = part_tables
    big = rebuild_including(part, {"bead_diameter_m": 1.4e-3}, builder=diameter_builder,
                            cache_dir=tmp_path, executor="serial", progress=False)
    assert big.manifest["points_run"] == 1
    assert list(big.one_at_a_time_values("bead_diameter_m")) == [D_LO, D_GB_M, D_HI, 1.4e-3]
    assert big.one_at_a_time["bead_diameter_m"].shape == part.one_at_a_time["bead_diameter_m"].shape
    p = _point(7.0, 0.55, rho=RHO_KG_PER_M3, d=1.3e-3)
    assert any("separability assumed" in n for n in big.lookup(p).notes)
