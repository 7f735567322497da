"""Collision statistics must not depend on the time step (seed 001 Table 1: dt = 5e-6 s)."""

import pytest

pytest.importorskip("numba")


@pytest.mark.slow
def test_collision_frequency_and_median_se_converged_in_dt(tmp_path):
    from millfmu.dem.run import run_scene
    from millfmu.dem.scene import scene_from_dict

    base = {"kind": "annulus", "name": "dt_check",
            "mill": {"shaft_radius_m": 0.015, "chamber_radius_m": 0.021, "height_m": 0.004,
                     "tip_speed_m_per_s": 6.0},
            "beads": {"filling": 0.8},
            "fluid": {"enabled": True},
            "run": {"spin_up_s": 0.02, "record_s": 0.04, "sample_every_s": 0.005}}
    res = []
    for dt in (5e-6, 2.5e-6):
        d = dict(base, run=dict(base["run"], dt_s=dt))
        s = run_scene(scene_from_dict(d), tmp_path / f"dt{dt}", progress=False)
        z = s.zones[0]
        res.append((z.collision_frequency_per_m3_s, z.se["tn"].quantiles_j["q50"]))
    (f1, m1), (f2, m2) = res
    assert z.collision_count > 20000
    assert abs(f2 / f1 - 1) < 0.05
    assert abs(m2 / m1 - 1) < 0.05
