"""The shipped default table verifies, states its resolution and rebuild command, and the
detailed model runs on it through the one stress-energy interface."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.dem.tables_cli import REBUILD_DEFAULT


@pytest.fixture(scope="module")
def table():
    return T.read_default_table()


def test_default_table_verifies(table, tmp_path):
    npz, man = T.default_table_paths()
    assert npz.stat().st_size + man.stat().st_size < 5e6
    m = table.manifest
    assert m["builder"] == T.DemBuilder.builder_id
    assert m["scene"]["name"] == "disc_slice" and m["scene"]["kind"] == "disc_slice"
    assert m["resolution"]["shape"] == list(table.shape)
    assert m["rebuild_command"] == REBUILD_DEFAULT
    assert table.zone_names == ("V1", "V2", "V3", "V4")
    assert np.all(table.data["collision_count"].sum(axis=-1) > 1000)
    # a copy with one flipped byte is detected
    data = bytearray(npz.read_bytes())
    data[len(data) // 3] ^= 0x10
    (tmp_path / "t.npz").write_bytes(bytes(data))
    with pytest.raises(T.TableError, match="corrupted"):
        T.read_table(npz=tmp_path / "t.npz", manifest_path=man)


def test_detailed_model_runs_on_the_default_table(table):
    from millfmu.mill import MillModel
    from millfmu.scene import load_scene

    scene = load_scene(resources.files("millfmu.data").joinpath("examples",
                                                                 "limestone_detailed.toml"))
    model = MillModel(scene)
    src = T.TableStressSource(table)
    model.source = src  # what [kinetics.stress_distribution] source = "table" will do
    op = model.operating_point(model.inputs)
    zones = src.zones(op)
    assert [z.name for z in zones] == ["V1", "V2", "V3", "V4"]
    assert all(z.collision_rate_per_m3_s > 0 for z in zones)
    x0 = model.outputs()["x50_m"]
    model.step(120.0)
    assert model.outputs()["x50_m"] < x0
