"""The DEM cell of a table point (millfmu.dem.tables.cells.dem_scene_at_point): beads that
do not fit the scene's sector at their filling run in a wider one; every point that fits keeps
its scene, so its key in the point store and its result."""

from __future__ import annotations

import json

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from millfmu.dem import tables as T
from millfmu.dem.mills.geometry import SECTORS_DEG, place_beads
from millfmu.dem.scene import scene_from_dict
from millfmu.stress_tables.files import canonical_json, sha256_bytes


@pytest.fixture(scope="module")
def coupled():
    return T.read_table_ref("coupled")


def _point(d_m, filling):
    return {"tip_speed_m_per_s": 10.0, "filling": filling, "bead_diameter_m": d_m, "bead_density_kg_per_m3": 2510.0}


@pytest.mark.parametrize("name", ["coupled", "prescribed", "accelerator"])
def test_every_point_of_the_shipped_tables_keeps_its_scene(name):
    """The shipped tables' points that fit their scene's sector run the scene at the point as
    it is, so their keys in the point store do not depend on the cell rule; those that do
    not (the coupled table's 1.2 mm beads at 90 %, 15 degrees) are the ones its manifest
    names in ``cells``."""
    t = T.read_table_ref(name)
    spec = t.spec()
    wide = []
    for p in spec.points():
        if T.dem_scene_at_point(spec.scene, p) != T.scene_at_point(spec.scene, p):
            wide.append(p)
        else:
            assert T.point_scene(spec, p) == T.scene_at_point(spec.scene, p), p
    named = (t.manifest.get("cells") or {}).get("points", [])
    assert sorted(json.dumps(p, sort_keys=True) for p in wide) == \
        sorted(json.dumps(c["point"], sort_keys=True) for c in named)
    assert (T.wider_cells(spec) is None) == (not wide)
    if name == "coupled":
        assert [(p["bead_diameter_m"], p["filling"]) for p in wide] == [(1.2e-3, 0.9)] * 3
    else:
        assert not wide
    assert spec.key() == t.manifest["key"]


def test_the_point_store_key_of_the_coupled_tables_anchor_is_pinned(coupled):
    """The key under which the coupled table's anchor (10 m/s, 80 %, 0.8 mm glass) is stored: the
    table's points are found in a point store only while it stays as it is; the earlier
    format's key (names in the earlier spelling) is the one that format stored it under."""
    spec = coupled.spec()
    store = T.PointStore("unused")
    key = store.key(spec, spec.anchor() | {"bead_diameter_m": 0.8e-3, "bead_density_kg_per_m3": 2510.0})
    assert key == store.key(spec, spec.anchor())
    assert key == "ee5e5d04398c6441d4375bb4ab67d6ba98949f46a3df499bd538b27221b37609"
    earlier = sha256_bytes(canonical_json(store.earlier_key_content(spec, spec.anchor())).encode())
    assert earlier == "ce319bb895a6d3d1e8267c1bb3d0756bdb927794d56b98eb39b32750010ca02a"


@pytest.mark.parametrize("d_m, filling, sector", [(1.4e-3, 0.8, 12.0), (1.4e-3, 0.9, 24.0),
                                                   (2.0e-3, 0.8, 20.0), (2.0e-3, 0.9, 72.0)])
def test_large_beads_at_high_filling_are_buildable_in_a_wider_sector(coupled, d_m, filling, sector):
    """1.4 and 2.0 mm beads at 80 and 90 % do not fit the coupled table's 10-degree cell; they run
    in the narrowest whole-degree divisor of 360 that holds them, where they are placed without
    overlap, and the builder no longer refuses them."""
    scene = coupled.spec().scene
    p = _point(d_m, filling)
    own = T.scene_at_point(scene, p)
    cell, widest = T.dem_cells(scene, p)
    assert cell is widest and cell.fits
    assert T.dem_scene_at_point(scene, p) == cell.scene
    assert cell.scene["mill"]["sector_deg"] == sector
    # only the sector changes
    assert {k: v for k, v in cell.scene["mill"].items() if k != "sector_deg"} == \
        {k: v for k, v in own["mill"].items() if k != "sector_deg"}
    assert {k: v for k, v in cell.scene.items() if k != "mill"} == {k: v for k, v in own.items() if k != "mill"}
    # no narrower sector holds them, the scene's own 10 degrees among them: each is widened as well
    for deg in (s for s in SECTORS_DEG if 10.0 <= s < sector):
        narrower = dict(own, mill=dict(own["mill"], sector_deg=deg))
        assert T.dem_scene_at_point(narrower, {})["mill"]["sector_deg"] == sector, deg
    assert T.DemBuilder().unbuildable(scene, p) is None
    s = scene_from_dict(cell.scene)
    r = 0.5 * d_m
    x = place_beads(s.geometry, cell.need, r, seed=s.seed)
    assert x.shape == (cell.need, 3)
    assert np.all(s.geometry.inside(x, r))
    # no two beads overlap (the 2 % lattice gap), images across the axial period included
    h = s.geometry.height_m
    z = np.mod(x[:, 2], h)
    tree = cKDTree(np.column_stack([x[:, :2] + 1.0, z]), boxsize=[1e3, 1e3, h])
    assert not tree.query_pairs(2.0 * r * 1.0199)
    # the key names the sector the point runs in
    spec = T.TableSpec(scene=scene, grid={"filling": [filling], "bead_diameter_m": [d_m]}, kernel_version="k")
    assert T.PointStore("unused").key_content(spec, spec.points()[0])["scene"] == cell.scene


def test_a_wider_cell_costs_its_beads_and_is_named_in_the_manifest(coupled):
    """The cost estimate counts the wider cell's beads (the sector's ratio) besides the coupled
    liquid's share, which does not grow with them; a table whose points ran in a wider sector
    lists them in its manifest ('cells')."""
    from millfmu.dem.tables.dem_builder import COUPLED_FIXED_SHARE

    scene = coupled.spec().scene
    b = T.DemBuilder()
    liquid = COUPLED_FIXED_SHARE * 0.8 / 0.8e-3 ** 3  # the scene's own 0.8 mm beads at 80 %
    at_10 = b.relative_cost(scene, _point(1.4e-3, 0.5))  # fits the 10-degree cell
    beads_10 = 0.5 / 1.4e-3 ** 3
    assert b.relative_cost(scene, _point(1.4e-3, 0.8)) == pytest.approx(
        at_10 * (beads_10 * 0.8 / 0.5 * 12.0 / 10.0 + liquid) / (beads_10 + liquid))
    # the two cold points the share was fitted to: 1.4 mm at 80 % 121 s, steel 0.8 mm 403 s
    # on one thread
    steel = b.relative_cost(scene, {**_point(0.8e-3, 0.8), "bead_density_kg_per_m3": 7800.0})
    assert b.relative_cost(scene, _point(1.4e-3, 0.8)) / steel == pytest.approx(121.0 / 403.0, rel=0.03)
    spec = T.TableSpec(scene=scene, grid=dict(coupled.spec().grid), kernel_version="k",
                       one_at_a_time={"bead_diameter_m": [0.8e-3, 1.4e-3]})
    cells = T.wider_cells(spec)
    assert cells["points"] == [{"point": spec.point_along("bead_diameter_m", 1.4e-3), "sector_deg": 12.0}]
    assert "10-degree sector" in cells["note"]


def test_beads_no_sector_holds_are_refused_naming_the_widest():
    """4 mm beads at 80 %: 471 needed in 90 degrees, which hold 352; the scene's own cell is
    kept (the run would refuse it) and the refusal names the widest sector tried."""
    scene = T.read_table_ref("coupled").spec().scene
    p = _point(4e-3, 0.8)
    cell, widest = T.dem_cells(scene, p)
    assert not cell.fits and cell.scene == T.scene_at_point(scene, p)
    assert widest.scene["mill"]["sector_deg"] == 90.0 and (widest.need, widest.capacity) == (471, 352)
    why = T.DemBuilder().unbuildable(scene, p)
    assert "holds at most 352 beads of 4 mm placed without overlap in a sector of 90 degrees" in why
    assert "a filling of 0.8 needs 471" in why


def test_sectors_are_the_whole_degree_divisors_of_360_up_to_a_right_angle():
    assert SECTORS_DEG[0] == 4.0 and SECTORS_DEG[-1] == 90.0
    assert all(360.0 % s == 0.0 and s == math.floor(s) for s in SECTORS_DEG)
    assert list(SECTORS_DEG) == sorted(set(SECTORS_DEG))


def test_scenes_that_are_not_dem_scenes_are_left_as_they_are():
    """An analytic builder's scene (or the DEM builder id on a scene that is no DEM scene, as the
    tests' stand-in builders have) gets the scene at the point unchanged."""
    scene = {"name": "analytic"}
    at = {"tip_speed_m_per_s": 6.0}
    assert T.dem_scene_at_point(scene, at) == T.scene_at_point(scene, at)
    spec = T.TableSpec(scene=scene, grid={"tip_speed_m_per_s": [6.0]}, kernel_version="k", builder_id="analytic")
    assert T.point_scene(spec, {"tip_speed_m_per_s": 6.0}) == {"name": "analytic", "mill": {"tip_speed_m_per_s": 6.0}}


@pytest.mark.slow
def test_a_wider_sector_gives_the_same_statistics_per_volume_within_the_stated_error(coupled):
    """The coupled table's 1.2 mm node (10 m/s, 80 %, glass) run with the table's settings in the
    table's 10-degree cell and in 20 degrees (twice the beads, 1,937 and 3,873): per zone, the
    collision frequency per volume (over omega n_gb) and the median SE_tn / E_ref of the two runs
    agree within the table's stated error at the point, max(a/b, b/a) - 1 <= b. Measured on one
    thread (146 s and 265 s): 20 against 10 degrees, V1-V4, collision frequency -0.8/-5.6/+6.3/-8.9 %
    against a stated 23/23/19/26 %, median SE_tn +6.7/+57/+4.9/-8.1 % against 35/99/69/29 %."""
    pytest.importorskip("numba")
    from millfmu.stress_tables.stress_source import TableStressSource

    scene = coupled.spec().scene
    point = _point(1.2e-3, 0.8)
    wide = T.scene_at_point(scene, {})
    wide["mill"]["sector_deg"] = 20.0
    assert T.dem_scene_at_point(wide, point)["mill"]["sector_deg"] == 20.0  # it holds them: kept
    b = T.DemBuilder(threads=1)
    runs = [b(scene, point), b(wide, point)]
    assert runs[1]["collision_count"].sum() > 1.5 * runs[0]["collision_count"].sum()  # twice the volume
    stated = TableStressSource(coupled).relative_error(coupled.lookup(point))
    for key, value in (("collision_frequency", lambda r: np.asarray(r["collision_frequency_norm"], float)),
                       ("se_median", lambda r: np.asarray(r["se_quantiles_norm"], float)[0, :, 1])):
        a, c = (value(r) for r in runs)
        measured = np.maximum(a / c, c / a) - 1.0
        assert np.all(measured <= stated[key]), (key, measured, stated[key])
