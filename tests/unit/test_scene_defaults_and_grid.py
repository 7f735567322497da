"""One set of scene defaults, size distributions outside the grid, [initial] in a batch
scene, and the mass that leaves the grid (issue 11, cases 3, 4, 5 and 7)."""

import subprocess
import sys

import numpy as np
import pytest

from millfmu.mill import OUTSIDE_GRID_MAX, MillModel
from millfmu.runner import simulate
from millfmu.scene import SceneError, iter_keys, load_scene, scene_from_dict, scene_to_dict
from tests.conftest import make_scene


def test_an_empty_scene_is_the_embedded_default_scene(tmp_path):
    empty = tmp_path / "empty.toml"
    empty.write_text("")
    assert load_scene(empty) == load_scene(None) == scene_from_dict({})
    assert scene_from_dict({}).kinetics.model == "simple" and scene_from_dict({}).feed.x50_m == 10e-6


def test_a_key_left_out_is_the_default_scenes_value():
    s = scene_from_dict({"mill": {"tip_speed_m_per_s": 8.0}})
    d = load_scene()
    assert s.mill.tip_speed_m_per_s == 8.0 and s.mill.bead_filling == d.mill.bead_filling
    assert s.kinetics == d.kinetics and s.feed == d.feed


def test_a_distribution_of_another_kind_replaces_the_default_one_whole():
    s = scene_from_dict({"feed": {"kind": "rrsb", "x63_m": 20e-6, "n": 1.5}})
    assert s.feed.kind == "rrsb" and s.feed.x50_m is None and s.feed.sigma_ln is None
    assert "x50_m" not in scene_to_dict(s)["feed"]


def test_listed_defaults_are_the_default_scenes():
    d = scene_to_dict(load_scene())
    for key, _unit, default, _allowed, _doc in iter_keys():
        sec = d
        for part in key.split(".")[:-1]:
            sec = sec.get(part, {})
        if key.split(".")[-1] in sec:
            assert default == sec[key.split(".")[-1]], key


@pytest.mark.parametrize("feed, key",
                         [({"x50_m": 1e-3}, "feed.x50_m"), ({"kind": "monodisperse", "x_m": 1e-8}, "feed.x_m"),
                                       ({"kind": "rrsb", "x63_m": 300e-6, "n": 2.0}, "feed.x63_m")])
def test_feed_outside_the_grid_is_refused_naming_key_value_and_edges(scene_dict, feed, key):
    with pytest.raises(SceneError) as e:
        MillModel(make_scene(scene_dict, feed=feed))
    msg = str(e.value)
    assert e.value.key == key and repr(e.value.value) in msg
    assert "outside" in msg and "grid" in msg and f"{OUTSIDE_GRID_MAX:.0%}" in msg


def test_cli_refuses_a_feed_outside_the_grid_with_exit_2(tmp_path):
    scene = tmp_path / "coarse.toml"
    scene.write_text("[feed]\nx50_m = 1e-3\n")
    r = subprocess.run([sys.executable, "-m", "millfmu.cli", "run", str(scene), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "feed.x50_m = 0.001" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def test_initial_in_a_batch_scene_is_refused(scene_dict):
    with pytest.raises(SceneError) as e:
        make_scene(scene_dict, initial={"kind": "lognormal", "x50_m": 5e-6, "sigma_ln": 0.5})
    assert e.value.key == "initial" and "continuous" in str(e.value) and "[feed]" in str(e.value)
    s = make_scene(scene_dict, initial={"kind": "lognormal", "x50_m": 5e-6, "sigma_ln": 0.5},
                   operation={"mode": "continuous", "feed_mass_flow_kg_per_s": 1e-3})
    assert MillModel(s).outputs()["x50_m"] == pytest.approx(5e-6, rel=0.05)


def test_mass_below_the_grid_is_its_own_output_and_conserved(scene_dict):
    """The default scene on a grid from 0.1 um (its grid reaches down to 20 nm) grinds mass
    below the grid: it is named, not hidden in the finest class."""
    s = make_scene(scene_dict, run={"t_end_s": 1800.0, "dt_s": 10.0, "output_interval_s": 600.0},
                   grid={"x_min_m": 0.1e-6})
    model, recs, psds = simulate(s, progress=False)
    below = [r["below_grid_fraction"] for r in recs]
    assert below[0] < 1e-12 and np.all(np.diff(below) > 0.0) and below[-1] > 0.01
    o = model.outputs()
    # psd's finest class holds the below-grid part; Q3 at the lowest edge is that part.
    assert psds[-1][0] == pytest.approx(below[-1], rel=1e-12) and o["psd"][0] >= below[-1]
    assert o["x10_m"] >= model.grid.edges_m[0]
    assert abs(model.total_mass_kg() - model.m0_kg) <= 1e-13 * model.m0_kg
    assert any("below the size grid" in w for w in model.output_warnings(o))
