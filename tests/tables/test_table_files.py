"""Damaged, edited and short-recording tables (issue 11, cases 2, 9 and 10)."""

import copy
import json
import shutil
import subprocess
import sys

import pytest

from millfmu.dem import tables as T
from millfmu.stress_tables import table as table_module  # where read_default_table finds its files
from millfmu.mill import MillModel
from millfmu.scene import SceneError
from tests.conftest import make_scene


@pytest.fixture
def exported(tmp_path):
    """A copy of the default table exported as tmp/copy.npz, .json (checksums inside)."""
    t = T.read_default_table()
    npz, man = t.export(tmp_path / "copy")
    return tmp_path / "copy", npz, man


def _scene_file(tmp_path, prefix):
    p = tmp_path / "scene.toml"
    p.write_text(f'[kinetics]\nmodel = "detailed"\n[kinetics.stress_distribution]\ntable = "{prefix}"\n[run]\n'
                 't_end_s = 10.0\ndt_s = 1.0\noutput_interval_s = 5.0\n')
    return p


def _flip(path, offset):
    b = bytearray(path.read_bytes())
    b[offset] ^= 0x01
    path.write_bytes(bytes(b))


@pytest.mark.parametrize("damage, words", [
    (lambda npz, man: _flip(npz, 1000), "does not match the manifest"),
    (lambda npz, man: npz.write_bytes(npz.read_bytes()[:5000]), "truncated"),
    (lambda npz, man: npz.unlink(), "missing"),
    (lambda npz, man: man.unlink(), "missing"),
])
def test_damaged_table_is_refused_by_run_and_build_fmu_naming_file_and_fix(tmp_path, exported, damage, words):
    prefix, npz, man = exported
    damage(npz, man)
    scene = _scene_file(tmp_path, prefix)
    for cmd in (["run", str(scene), "--out", str(tmp_path / "out")],
                ["build-fmu", str(scene), "-o", str(tmp_path / "m.fmu")]):
        r = subprocess.run([sys.executable, "-m", "millfmu.cli", *cmd], capture_output=True, text=True)
        assert r.returncode == 2, (cmd, r.stderr)
        assert "Traceback" not in r.stderr and "kinetics.stress_distribution.table" in r.stderr
        assert words in r.stderr and str(prefix) in r.stderr and "tables build" in r.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.fmu").exists()


def test_damaged_default_table_names_the_rebuild_command(monkeypatch, tmp_path, detailed_scene_dict):
    npz, man = T.default_table_paths()
    shutil.copy(npz, tmp_path / "coupled_table.npz")
    shutil.copy(man, tmp_path / "coupled_table.json")
    _flip(tmp_path / "coupled_table.npz", 2000)
    monkeypatch.setattr(table_module, "default_table_paths",
                        lambda: (tmp_path / "coupled_table.npz", tmp_path / "coupled_table.json"))
    with pytest.raises(SceneError) as e:
        MillModel(make_scene(detailed_scene_dict, kinetics={"stress_distribution": {"table": "default"}}))
    assert "coupled_table.npz" in str(e.value) and "corrupted" in str(e.value)
    assert "--export millfmu/data/coupled_table" in str(e.value)


def test_edited_export_manifest_fails_verify(tmp_path, exported):
    prefix, npz, man = exported
    ok = subprocess.run([sys.executable, "-m", "millfmu.cli", "tables", "verify", str(prefix)], capture_output=True,
                        text=True)
    assert ok.returncode == 0 and f"{prefix}: ok" in ok.stdout
    m = json.loads(man.read_text())
    m["build_wall_time_s"] = 1.0  # a harmless-looking edit, outside the key's content
    man.write_text(json.dumps(m, indent=1, sort_keys=True))
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "tables", "verify", str(prefix)], capture_output=True,
                       text=True)
    assert r.returncode == 1 and "BAD" in r.stdout and "manifest_sha256" in r.stdout


def test_manifest_without_any_checksum_is_refused(tmp_path, exported):
    prefix, npz, man = exported
    m = json.loads(man.read_text())
    del m[T.MANIFEST_SUM_KEY]
    man.write_text(json.dumps(m))
    with pytest.raises(T.TableError, match="no checksum"):
        T.read_table(npz=npz, manifest_path=man)


def test_table_from_a_short_recording_warns(tmp_path, detailed_scene_dict):
    t = T.read_default_table()
    spec = t.spec()
    scene = copy.deepcopy(spec.scene)
    scene["run"]["record_s"] = 0.004
    short = T.TableSpec(scene=scene, grid=spec.grid, kernel_version=spec.kernel_version, builder_id=spec.builder_id)
    t.manifest = T.manifest_for(short, t)
    t.export(tmp_path / "short")
    m = MillModel(make_scene(detailed_scene_dict, kinetics={"stress_distribution": {"table": str(tmp_path / "short")}}))
    assert any("0.004 s" in w and "stirrer revolution" in w for w in m.warnings), m.warnings
    # 0.1 s recordings: no warning about them (the detailed example's one warning is its regime)
    assert not [w for w in MillModel(make_scene(detailed_scene_dict)).warnings if "stirrer revolution" in w]
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", "-q",
                        str(_scene_file(tmp_path, tmp_path / "short")),
                        "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert r.returncode == 0 and "warning: stress-energy table" in r.stderr and "0.004 s" in r.stderr
    res = json.loads((tmp_path / "out" / "result.json").read_text())
    assert any("0.004 s" in w for w in res["warnings"])


# ---- issue 27: table contents are validated on read ----------------------------------------
def _edit(t, field, value, where=(0, 0, 0)):
    import numpy as np

    a = np.array(t.data[field], float)
    a[where + (0,) * (a.ndim - len(where))] = value
    t.data[field] = a


def _integral_off(t):
    import numpy as np

    d = np.array(t.data["se_density"], float)
    d[0, 0, 0, 0, :] *= 1.5
    t.data["se_density"] = d


def _silent_point(t):
    """Every zone of the first grid point without collisions (frequencies and counts 0)."""
    import numpy as np

    for k in ("collision_frequency_norm", "collision_count"):
        a = np.array(t.data[k], float)
        a[0, 0, :] = 0.0
        t.data[k] = a


@pytest.mark.parametrize("edit, words", [
    (_silent_point, "collision_frequency_norm is 0 in every zone at point index (0, 0)"),
    (lambda t: _edit(t, "collision_frequency_norm", 0.0), "a zone has collisions in both or in neither"),
    (lambda t: _edit(t, "collision_frequency_norm", float("nan")), "collision_frequency_norm holds a non-finite value"),
    (lambda t: _edit(t, "collision_frequency_norm", float("inf")), "collision_frequency_norm holds a non-finite value"),
    (lambda t: _edit(t, "collision_frequency_norm", 1e300), "collision_frequency_norm holds a value beyond"),
    (lambda t: _edit(t, "collision_frequency_norm", -2.0), "collision_frequency_norm holds a value below 0"),
    (lambda t: _edit(t, "se_density", -0.5), "se_density holds a value below 0"),
    (lambda t: _edit(t, "se_quantiles_norm", float("inf")), "se_quantiles_norm holds an infinite value"),
    (lambda t: _edit(t, "volume_fraction", 1e300), "volume_fraction holds a value beyond"),
    (_integral_off, "integrates to"),
])
def test_a_rechecksummed_table_with_impossible_values_is_refused_by_name_with_the_rebuild_command(tmp_path, edit, words,
                                                                                                  monkeypatch):
    t = T.read_default_table()
    edit(t)
    prefix = tmp_path / "edited"
    with monkeypatch.context() as m:
        m.setattr(table_module, "_check_values", lambda t, where: None)  # export reads its files back
        t.export(prefix)  # checksums of the edited content: only the values can tell
    scene = _scene_file(tmp_path, prefix)
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", str(scene), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert (words in r.stderr and "kinetics.stress_distribution.table" in r.stderr
            and "tables build" in r.stderr), r.stderr
    assert not (tmp_path / "out").exists()


def test_the_shipped_tables_pass_the_value_checks():
    for ref in ("default", "coupled", "accelerator"):
        T.read_table_ref(ref).check_values(ref)
