"""Wet restitution per contact (Legendre et al. 2006, ``[fluid] wet_collisions =
"legendre2006"``): the law's levels and damping ratios, two beads and a bead on a wall through
the engine against the published curve, the scene's choice and its refusals, and checkpoints
of a shorter parameter vector."""

from __future__ import annotations

import io
import math
import pickle

import numpy as np
import pytest

from millfmu.dem.engine import legendre2006 as L
from millfmu.dem.engine.params import BeadMaterial


def test_levels_and_damping_ratios():
    assert L.restitution_ratio(35.0) == pytest.approx(math.exp(-1.0))
    assert L.restitution_ratio(0.0) == 0.0
    tab = L.beta_table(0.99)
    assert tab.shape == (256,)
    assert tab[1] == -1.0  # e = 0: critically damped
    assert tab[255] == pytest.approx(BeadMaterial(restitution=0.99).damping_beta, rel=1e-14)
    assert np.all(np.diff(tab[1:]) > 0)  # more restitution, less damping
    # the level of a contact: 1 + round(254 e / e_dry), St = m* v / (6 pi eta R*^2)
    m, r, eta = 3.4e-7, 2e-4, 1e-3
    for st in (1e-3, 5.0, 35.0, 200.0, 1e6):
        v = st * 6 * math.pi * eta * r * r / m
        assert L.contact_level(v, m, r, eta, L.ST_SCALE) == 1 + int(round(254 * math.exp(-35.0 / st)))
    assert L.contact_level(0.0, m, r, eta, L.ST_SCALE) == 1


@pytest.mark.parametrize("st", [8.0, 16.0, 50.0, 200.0, 1000.0])
def test_collisions_through_the_engine_follow_the_published_curve(st):
    """Two beads head-on and a bead on a disc's face, each at Stokes number St: e within
    0.01 of e_dry exp(-35 / St) (levels of 1/254 of e_dry and the Hertz contact's damping
    by the linear spring's ratio)."""
    from validation import wet_collisions as W

    want = W.published(st, W.MATERIAL["restitution"])
    assert W.run_collision(W.speed_at(st), False, "legendre2006") == pytest.approx(want, abs=0.01)
    assert W.run_wall_collision(W.wall_speed_at(st), "legendre2006") == pytest.approx(want, abs=0.01)
    # the table's law leaves a wall contact dry
    assert W.run_wall_collision(W.wall_speed_at(st), "lubrication") == pytest.approx(0.99, abs=1e-3)


def test_the_scene_names_the_law_and_refuses_what_contradicts_it():
    from millfmu.dem.scene import DemSceneError, load_scene_dict, scene_from_dict

    d = load_scene_dict("disc_slice")
    assert scene_from_dict(d).fluid.wet_collisions == "lubrication"
    assert scene_from_dict(d).fluid.lubrication
    d["fluid"]["wet_collisions"] = "legendre2006"
    with pytest.raises(DemSceneError, match="fluid.lubrication = true with fluid.wet_collisions"):
        scene_from_dict(d)  # disc_slice.toml sets lubrication = true
    del d["fluid"]["lubrication"]
    fl = scene_from_dict(d).fluid
    assert fl.wet_collisions == "legendre2006" and not fl.lubrication
    d["fluid"]["wet_collisions"] = "stokes"
    with pytest.raises(DemSceneError, match=r"fluid.wet_collisions = 'stokes': allowed \['lubrication', "):
        scene_from_dict(d)


def _sim(**fluid_kw):
    from millfmu.dem.engine.sim import DemSimulation, FluidSettings
    from millfmu.dem.mills.geometry import MillGeometry

    d = 8e-4
    geo = MillGeometry(shaft_radius_m=5 * d, chamber_radius_m=80 * d, height_m=10 * d,
                       disc_radius_m=70 * d, disc_thickness_m=d, disc_z_m=0.0)
    return DemSimulation(geo, BeadMaterial(), [[40 * d, 0.0, 5 * d]], 0.5 * d, 0.0, 1e-6,
                         fluid=FluidSettings(drag=False, **fluid_kw), threads=1)


def test_the_simulation_refuses_the_law_with_lubrication_on_and_on_the_gpu():
    with pytest.raises(ValueError, match="with lubrication on"):
        _sim(lubrication=True, wet_collisions="legendre2006")
    with pytest.raises(ValueError, match="one of"):
        _sim(wet_collisions="legendre")
    from millfmu.dem.engine.sim import DemSimulation, FluidSettings

    s = _sim(lubrication=False, wet_collisions="legendre2006")
    with pytest.raises(ValueError, match="GPU stepper has no wet restitution"):
        DemSimulation(s.geometry, s.material, s.x, s.rad, 0.0, 1e-6,
                      fluid=FluidSettings(drag=False, lubrication=False, wet_collisions="legendre2006"),
                      threads=1, device="gpu")


def test_a_checkpoint_of_the_shorter_parameter_vector_goes_on_with_the_lubrication_law():
    s = _sim()
    state = dict(s.__dict__)
    state["prm"] = s.prm[:40].copy()
    del state["wet_restitution"]
    back = object.__new__(type(s))
    back.__setstate__(state)
    assert back.prm.shape == s.prm.shape and np.array_equal(back.prm, s.prm)
    assert back.wet_restitution is False
    # and through the checkpoint's pickling
    from millfmu.dem import run as R

    buf = io.BytesIO()
    R._Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(back)
    assert np.array_equal(pickle.loads(buf.getvalue()).prm, s.prm)
