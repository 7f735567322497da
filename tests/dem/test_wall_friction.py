"""Bead-wall friction apart from bead-bead friction (``[beads] wall_friction``,
``wall_rolling_friction``): a bead on a wall follows the closed forms with the wall's
coefficients, whatever the beads' own; a scene names them or takes the beads'; a checkpoint
made before they existed goes on with the beads' coefficients at its walls."""

from __future__ import annotations

import numpy as np
import pytest

from millfmu.dem.engine import kernels as K
from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.scene import DemSceneError, load_scene_dict, scene_from_dict
from validation import contact_law as C

pytest.importorskip("numba")


def _close(rows, rel):
    for q, row in rows.items():
        if row["closed_form"] is not None:
            assert abs(row["ours"] - row["closed_form"]) <= rel * abs(row["closed_form"]), q


def _ours(rows):
    return {q: r["ours"] for q, r in rows.items()}


def test_a_bead_sliding_on_a_wall_slows_at_the_walls_friction():
    """Case a of the contact-law study with the beads' friction 0.05 and the wall's 0.6: the
    same run to the bit as with 0.6 for both; it slides at mu_w g and rolls from t1 = 2 v0 /
    (7 mu_w g) at 5/7 v0."""
    mat = dict(C.SEED001, friction=0.05, wall_friction=0.6)
    rows = C.case_slide_roll(moving_wall=False, mur=0.0, workdir=None, mat=mat)["quantities"]
    both = C.case_slide_roll(moving_wall=False, mur=0.0, workdir=None,
                             mat=dict(C.SEED001, friction=0.6))["quantities"]
    assert _ours(rows) == _ours(both)
    v0 = C.SLIP_SPEED_M_PER_S
    assert rows["roll onset t1 [s]"]["closed_form"] == pytest.approx(2 * v0 / (7 * 0.6 * C.G_M_PER_S2))
    _close({q: r for q, r in rows.items() if q != "speed at 2 t1 [m/s]"}, 1e-3)
    _close(rows, 1e-2)


def test_a_bead_on_a_turning_disc_takes_the_walls_friction_and_rolling_friction():
    """Case c/d on the turning disc with rolling friction only at the wall (0.10; the beads'
    0) and the wall's friction 0.3 against the beads' 1.0: the same run to the bit as the
    study's case with 0.3 and 0.10 for both; dragged at mu_w g, rolling from V / ((7/2 mu_w
    - 5/2 mu_r,w) g), then speeding up at 5/7 mu_r,w g (within the study's 2 %)."""
    mat = dict(C.SEED001, friction=1.0, wall_friction=0.3, wall_rolling_friction=0.10)
    rows = C.case_slide_roll(moving_wall=True, mur=0.0, workdir=None, mat=mat)["quantities"]
    both = C.case_slide_roll(moving_wall=True, mur=0.10, workdir=None)["quantities"]
    assert _ours(rows) == _ours(both)
    v0 = C.SLIP_SPEED_M_PER_S
    assert rows["roll onset t1 [s]"]["closed_form"] == pytest.approx(
        v0 / ((3.5 * 0.3 - 2.5 * 0.1) * C.G_M_PER_S2))
    _close(rows, C.TOLERANCES["closed_form"])


def test_the_parameter_vector_holds_the_walls_coefficients_or_the_beads():
    from millfmu.dem.engine.sim import DemSimulation
    from validation.contact_law import _disc_geometry

    def prm(material):
        sim = DemSimulation(_disc_geometry(4e-4), material, [[0.01, 0.0, 5e-4]], 4e-4, 0.0, 1e-6,
                            fluid=None, threads=1)
        return sim

    same = prm(BeadMaterial(friction=0.4, rolling_friction=0.02)).prm
    assert (same[K.P_MUW], same[K.P_MURW]) == (0.4, 0.02) == (same[K.P_MU], same[K.P_MUR])
    sim = prm(BeadMaterial(friction=0.4, rolling_friction=0.02, wall_friction=0.9,
                           wall_rolling_friction=0.0))
    assert (sim.prm[K.P_MU], sim.prm[K.P_MUR], sim.prm[K.P_MUW], sim.prm[K.P_MURW]) == (0.4, 0.02, 0.9, 0.0)
    # a checkpoint of the vector before the walls' entries: its walls keep the beads' values
    state = dict(sim.__dict__)
    state["prm"] = sim.prm[:K.P_MUW].copy()
    back = object.__new__(type(sim))
    back.__setstate__(state)
    assert back.prm.shape == (K.N_PRM,)
    assert (back.prm[K.P_MUW], back.prm[K.P_MURW]) == (0.4, 0.02)
    assert np.array_equal(back.prm[:K.P_MUW], sim.prm[:K.P_MUW])


def test_a_scene_names_the_walls_friction_or_takes_the_beads():
    d = load_scene_dict("disc_slice")
    m = scene_from_dict(d).material
    assert (m.bead_wall_friction, m.bead_wall_rolling_friction) == (m.friction, m.rolling_friction)
    d["beads"].update(wall_friction=0.6, wall_rolling_friction=0)
    m = scene_from_dict(d).material
    assert (m.wall_friction, m.wall_rolling_friction) == (0.6, 0.0)
    assert (m.bead_wall_friction, m.bead_wall_rolling_friction, m.friction) == (0.6, 0.0, 0.3)
    for key, bad, msg in (("wall_friction", -0.1, "beads.wall_friction = -0.1: must be a finite number >= 0"),
                          ("wall_rolling_friction", float("nan"), "beads.wall_rolling_friction = nan"),
                          ("wall_friction", "high", "beads.wall_friction = 'high': must be a float")):
        d = load_scene_dict("disc_slice")
        d["beads"][key] = bad
        with pytest.raises(DemSceneError, match=msg):
            scene_from_dict(d)
    # the same checks where a run overrides the scene's value
    base = scene_from_dict(load_scene_dict("disc_slice"))
    assert base.with_overrides(wall_friction=0.6).material.bead_wall_friction == 0.6
    for bad, msg in ((-0.1, "beads.wall_friction = -0.1: must be a finite number >= 0"),
                     ("high", "beads.wall_friction = 'high': must be a float")):
        with pytest.raises(DemSceneError, match=msg):
            base.with_overrides(wall_friction=bad)
    d = load_scene_dict("disc_slice")
    d["beads"]["wall_fricton"] = 0.6
    with pytest.raises(DemSceneError, match=r"beads.wall_fricton: unknown key; allowed: \[.*'wall_friction'"):
        scene_from_dict(d)
