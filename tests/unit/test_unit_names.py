"""One unit-suffix convention (millfmu.unit_names): the current names, and the earlier
release's spellings still read from scene files, tables, stored points, run folders and
checkpoints, the same content under either name."""

from __future__ import annotations

import copy
import json
import re
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

from millfmu.unit_names import earlier_name, modern_name, modernize, to_earlier

ROOT = Path(__file__).resolve().parents[2]
PAIRS = [("tip_speed_m_s", "tip_speed_m_per_s"), ("bead_density_kg_m3", "bead_density_kg_per_m3"),
         ("viscosity_pa_s", "viscosity_Pa_s"), ("omega_rad_s", "omega_rad_per_s"),
         ("gravity_m_s2", "gravity_m_per_s2"), ("nu_m2_s", "nu_m2_per_s"),
         ("rotor_throughflow_m3_s", "rotor_throughflow_m3_per_s"),
         ("one_at_a_time__bead_density_kg_m3__axis_bead_density_kg_m3",
          "one_at_a_time__bead_density_kg_per_m3__axis_bead_density_kg_per_m3")]
UNCHANGED = ["collision_rate_per_m3_s", "f_mat_kg_per_J_m", "diameter_m", "e_ref_J", "filling",
             "stirrer_power_w", "tip_speed_m_per_s"]


@pytest.mark.parametrize("old,new", PAIRS)
def test_earlier_names_map_to_the_current_ones_and_back(old, new):
    assert modern_name(old) == new
    assert modern_name(new) == new
    assert earlier_name(new) == old


@pytest.mark.parametrize("name", UNCHANGED)
def test_names_without_an_earlier_spelling_stay(name):
    assert modern_name(name) == name


def test_the_sources_use_the_current_spelling_only():
    """No tracked source, scene, data or doc file (the changelog and this module's own
    tables and the scene docs' section on the earlier spelling aside) names a quantity the earlier way."""
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    if not files:
        pytest.skip("not a git checkout")
    old = re.compile(r"(?<=[A-Za-z0-9])(_m_s|_m_s2|_m2_s|(?<!per)_m3_s|_kg_m3|_pa_s|_rad_s|_M_S|_KG_M3|_RAD_S)\b")
    skip = {"CHANGELOG.md", "millfmu/unit_names.py", "tests/unit/test_unit_names.py"}
    bad = []
    for f in files:
        p = ROOT / f
        if f in skip or p.suffix not in {".py", ".toml", ".md", ".json", ".csv", ".txt", ".cfg"} or not p.is_file():
            continue
        section = ""
        for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
            section = line if line.startswith("## ") else section
            if old.search(line) and not (f == "docs/scenes.md" and section == "## Names and units"):
                bad.append(f"{f}:{i}: {line.strip()[:100]}")
    assert not bad, "\n".join(bad[:20])


def test_modernize_refuses_a_key_given_in_both_spellings(tmp_path):
    with pytest.raises(ValueError, match=r"mill.tip_speed_m_s: given twice, also as 'tip_speed_m_per_s'"):
        modernize({"mill": {"tip_speed_m_s": 8.0, "tip_speed_m_per_s": 10.0}})
    # a scene names both values, not a placeholder
    from millfmu.scene import SceneError, load_scene

    f = tmp_path / "both.toml"
    f.write_text("[mill]\ntip_speed_m_s = 8.0\ntip_speed_m_per_s = 10.0\n")
    with pytest.raises(SceneError) as e:
        load_scene(f)
    assert str(e.value).endswith("mill.tip_speed_m_s = 8.0: given twice, also as tip_speed_m_per_s = 10.0 (its "
                                 "current spelling); give one")


def _old_dem_scene():
    from millfmu.dem.scene import load_scene_dict

    return to_earlier(load_scene_dict("disc_slice"))


def test_a_dem_scene_of_the_earlier_spelling_is_the_same_scene_with_a_note():
    from millfmu.dem.scene import DemSceneError, load_scene_dict, scene_from_dict

    old = _old_dem_scene()
    assert "tip_speed_m_s" in old["mill"] and "viscosity_pa_s" in old["fluid"]
    with pytest.warns(FutureWarning, match=r"mill.tip_speed_m_s -> tip_speed_m_per_s.*fluid.viscosity_pa_s -> "
                                           r"viscosity_Pa_s.*this release only"):
        s_old = scene_from_dict(copy.deepcopy(old))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s_new = scene_from_dict(load_scene_dict("disc_slice"))
    assert s_old == s_new
    both = copy.deepcopy(old)
    both["mill"]["tip_speed_m_per_s"] = 12.0
    with pytest.raises(DemSceneError, match="given twice"):
        scene_from_dict(both)


def test_a_dem_scene_file_of_the_earlier_spelling_reads_as_the_current_names(tmp_path):
    from millfmu.dem.scene import load_scene_dict

    old = _old_dem_scene()
    text = "\n".join(f"{k} = {json.dumps(v)}" for k, v in old.items() if not isinstance(v, dict))
    for sec, body in old.items():
        if isinstance(body, dict):
            flat = {k: v for k, v in body.items() if not isinstance(v, dict)}
            text += f"\n[{sec}]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in flat.items())
            for sub, sv in body.items():
                if isinstance(sv, dict):
                    text += f"\n[{sec}.{sub}]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in sv.items()
                                                          if v is not None)
    f = tmp_path / "old.toml"
    f.write_text(text + "\n")
    with pytest.warns(FutureWarning, match="old.toml"):
        d = load_scene_dict(str(f))
    assert d["mill"]["tip_speed_m_per_s"] == 10.0 and "tip_speed_m_s" not in d["mill"]


def test_a_mill_scene_naming_an_axis_the_earlier_way_reads_as_the_current_name():
    from millfmu.scene import load_scene, scene_from_dict, scene_to_dict

    d = scene_to_dict(load_scene())
    d["kinetics"]["stress_distribution"]["similar_axes"] = ["tip_speed_m_s", "bead_density_kg_m3"]
    with pytest.warns(FutureWarning, match=r"similar_axes\[0\] = 'tip_speed_m_s' -> tip_speed_m_per_s"):
        s = scene_from_dict(d, "old.toml")
    assert s.kinetics.stress_distribution.similar_axes == ["tip_speed_m_per_s", "bead_density_kg_per_m3"]


def _earlier_format_copy(table, folder: Path) -> Path:
    """``table`` written as the earlier format wrote it: names in the earlier spelling,
    format 1, its key the earlier one, into a cache entry folder ``folder``."""
    from millfmu.stress_tables.files import (MANIFEST_FILE, MANIFEST_SUM_FILE, MANIFEST_SUM_KEY, TABLE_FILE,
                                             manifest_digest, sha256_bytes, sha256_file)
    from millfmu.stress_tables.spec import EARLIER_FORMAT

    folder.mkdir(parents=True)
    arrs = {earlier_name(k): v for k, v in table.arrays().items()}
    np.savez_compressed(folder / TABLE_FILE, **arrs)
    m = to_earlier({k: v for k, v in table.manifest.items() if k != MANIFEST_SUM_KEY})
    m.update(format=EARLIER_FORMAT, key=table.spec().earlier_key(),
             files={TABLE_FILE: {"bytes": (folder / TABLE_FILE).stat().st_size,
                                 "sha256": sha256_file(folder / TABLE_FILE)}})
    m[MANIFEST_SUM_KEY] = manifest_digest(m)
    text = json.dumps(m, indent=1, sort_keys=True).encode()
    (folder / MANIFEST_FILE).write_bytes(text)
    (folder / MANIFEST_SUM_FILE).write_text(sha256_bytes(text) + "\n")
    return folder


def test_a_cached_table_of_the_earlier_format_is_found_and_read_with_the_current_names(tmp_path):
    from millfmu.dem.tables import cache
    from millfmu.stress_tables.table import read_table_ref

    t = read_table_ref("coupled")
    spec = t.spec()
    assert spec.earlier_key() != spec.key()
    _earlier_format_copy(t, tmp_path / spec.earlier_key())
    got = cache.load_cached(spec, tmp_path)
    assert got is not None
    assert list(got.axes) == list(t.axes) and set(got.refs) == set(t.refs)
    for k, v in t.arrays().items():
        np.testing.assert_array_equal(got.arrays()[k], v)
    assert got.manifest["key"] == spec.key() and got.manifest["format"] == 2
    listed = cache.cache_entries(tmp_path, kernel_version=spec.kernel_version)
    assert [e["state"] for e in listed] == ["ok"]
    # an edited entry of the earlier format fails its own key
    man = tmp_path / spec.earlier_key() / "manifest.json"
    man.write_text(man.read_text().replace('"tip_speed_m_s"', '"tip_speed_m_per_s"', 1))
    (tmp_path / spec.earlier_key() / "manifest.json.sha256").unlink()
    assert cache.load_cached(spec, tmp_path) is None


def test_a_stored_point_of_the_earlier_format_is_reused(tmp_path):
    from millfmu.dem.tables.build import PointStore
    from millfmu.stress_tables.files import canonical_json, sha256_bytes
    from millfmu.stress_tables.table import read_table_ref

    spec = read_table_ref("coupled").spec()
    point = spec.points()[0]
    result = {"e_ref_J": 1e-4, "omega_rad_per_s": 277.8, "n_gb_per_m3": 1e9}
    store = PointStore(tmp_path)
    kc = store.earlier_key_content(spec, point)
    assert "tip_speed_m_s" in kc["scene"]["mill"] and kc["format"] == 1
    key = sha256_bytes(canonical_json(kc).encode())
    (tmp_path / f"{key}.json").write_text(json.dumps({"key_content": kc, "result": to_earlier(result)}))
    assert store.get(spec, point) == result


def test_a_checkpoint_of_the_earlier_spelling_gets_the_current_attribute_names():
    from millfmu.dem import run as R

    class Holder:
        pass

    Holder.__module__ = "millfmu.dem.engine.sim"
    h = Holder()
    h.omega_rad_s, h.n = 2.0, 3
    state = {"format": 2, "sim": h, "loop": {"tip_speed_m_s": [1.0]}, "same": h}
    R._current_attribute_names(state, set())
    assert h.omega_rad_per_s == 2.0 and not hasattr(h, "omega_rad_s") and h.n == 3
    assert state["loop"] == {"tip_speed_m_per_s": [1.0]}
