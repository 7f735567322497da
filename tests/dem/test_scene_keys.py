"""A DEM scene file's misspelt or misplaced key is refused by name, with the keys allowed
there, in every table of every kind: a typo never falls back silently to a default."""

from __future__ import annotations

import pytest

from millfmu.dem.scene import KINDS, DemSceneError, load_scene_dict, mill_keys, scene_from_dict


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("table, key, allowed", [
    ("mill", "shaft_radus_m", "'shaft_radius_m'"),
    ("run", "spin_up", "'spin_up_s'"),
    ("output", "map_bins", "'map_bins_r'"),
    ("beads", "diameter", "'diameter_m'"),
    ("zones", "sev_z", None),
])
def test_an_unknown_key_is_refused_by_name(kind, table, key, allowed):
    d = load_scene_dict(kind)
    d.setdefault(table, {})[key] = 1.0
    with pytest.raises(DemSceneError, match=rf"^{table}\.{key}: unknown key") as e:
        scene_from_dict(d)
    if allowed:
        assert allowed in str(e.value)
    if table in ("mill", "zones"):
        assert f"for {kind}" in str(e.value)


def test_a_key_of_another_kind_of_mill_is_refused():
    d = load_scene_dict("accelerator_slice")
    d["mill"]["disc_radius_m"] = 0.03
    with pytest.raises(DemSceneError, match=r"mill.disc_radius_m: unknown key for accelerator_slice; "
                                            r"allowed: \[.*'rotor_radius_m'"):
        scene_from_dict(d)
    d = load_scene_dict("disc_slice")
    d["mill"]["rotor_speed_rpm"] = 1200.0
    with pytest.raises(DemSceneError, match=r"mill.rotor_speed_rpm: unknown key for disc_slice"):
        scene_from_dict(d)
    assert "rotor_speed_rpm" in mill_keys("accelerator_slice") and "height_m" in mill_keys("annulus")


def test_every_shipped_scene_uses_only_allowed_keys():
    for kind in KINDS:
        scene_from_dict(load_scene_dict(kind))
