"""Counting contacts present at frames (seed 002's post-processing) against hand cases."""

import math

import numpy as np
import pytest

from millfmu.dem.analysis.snapshots import Frame, contacts_present, every_kth
from millfmu.dem.mills import accelerator as A
from millfmu.dem.mills import zones_for
from millfmu.dem.scene import load_scene

R = 0.4e-3  # bead radius [m]


def _turn(a, ang):
    c, s = math.cos(ang), math.sin(ang)
    return np.array([c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]])


def test_contacts_present_hand_case():
    """Four pairs: one plain contact, one too far apart, one across the sector's periodic
    boundary (j's image turned by -sector) and one across the axial period."""
    sector = math.radians(60.0)
    period = 0.013
    r0 = 0.02
    x = np.array([
        [r0, 0.0, 0.005], [r0 + 0.7e-3, 0.0, 0.005],             # 0-1: overlap 0.1 mm
        [r0, 0.0, 0.008], [r0 + 1.0e-3, 0.0, 0.008],             # 2-3: 0.2 mm apart
        _turn([r0, 0.2e-3, 0.011], 0.0),                          # 4: just above 0 deg
        _turn([r0, -0.4e-3, 0.011], sector),                      # 5: just below 60 deg
        [0.025, 0.0, 0.0001], [0.025, 0.0, period - 0.0002],     # 6-7: axial image
    ])
    v = np.zeros_like(x)
    w = np.zeros_like(x)
    v[0] = [1.0, 0.0, 0.0]
    w[0] = [0.0, 0.0, 100.0]
    v[4] = [0.0, 0.5, 0.0]
    v[5] = _turn([0.0, -0.5, 0.0], sector)  # its image moves at -0.5 m/s in y
    w[5] = _turn([30.0, 0.0, 0.0], sector)
    v[6] = [0.0, 0.0, 1.0]
    v[7] = [0.0, 0.0, -1.0]
    pairs = (np.array([0, 2, 4, 6]), np.array([1, 3, 5, 7]), np.array([0, 0, -1, 0]))
    f = contacts_present(x, v, w, R, pairs, sector, period)
    assert f.count == 3
    # pair 0-1: n along x, v_n = 1 m/s, relative spin 100 rad/s, point mid-overlap
    assert f.vn2_m2_s2[0] == pytest.approx(1.0)
    assert f.wrel2_rad2_s2[0] == pytest.approx(1e4)
    assert f.point_m[0] == pytest.approx([r0 + 0.35e-3, 0.0, 0.005])
    # pair 4-5: image 0.6 mm below in y, n along +y, relative normal speed 1 m/s, spin 30
    assert f.vn2_m2_s2[1] == pytest.approx(1.0)
    assert f.wrel2_rad2_s2[1] == pytest.approx(900.0)
    assert f.point_m[1] == pytest.approx([r0, -0.1e-3, 0.011], abs=1e-12)
    # pair 6-7: 0.3 mm apart through the period, approaching at 2 m/s
    assert f.vn2_m2_s2[2] == pytest.approx(4.0)
    assert f.wrel2_rad2_s2[2] == 0.0
    # none without pairs
    assert contacts_present(x, v, w, R, (np.zeros(0), np.zeros(0), np.zeros(0)), sector,
                            period).count == 0


def test_snapshot_quantities_and_the_papers_frame_rate():
    """Two frames with 3 and 1 contacts in SEV_1: SN_g counts what is present summed over
    the frames per volume and (frames x interval); energies with the bead's m_g and I_g."""
    s = load_scene("accelerator_slice")
    z = zones_for(s)
    d, rho = 0.8e-3, 6040.0
    m = math.pi / 6 * d ** 3 * rho
    inertia = m * d * d / 10
    p = np.array([[0.029, 0.0, 0.0]])
    f1 = Frame(np.repeat(p, 3, 0), np.array([1.0, 1.0, 4.0]), np.array([0.0, 0.0, 100.0]))
    f2 = Frame(p.copy(), np.array([9.0]), np.array([0.0]))
    dt = 0.01
    q = A.snapshot_stress_quantities([f1, f2], dt, z, d, rho, 100, s.tip_speed_m_per_s,
                                     s.omega_rad_per_s)
    z1 = q["zones"]["SEV_1"]
    v1 = z.volumes_m3()[0]
    assert z1["contacts"] == 4
    assert z1["SN_g_per_m3_s"] == pytest.approx(4 / (v1 * 2 * dt))
    tn = 0.5 * m * (1 + 1 + 4 + 9)
    ts = 0.5 * inertia * 100.0
    assert z1["SI_j"] == pytest.approx((tn + ts) / 4)
    assert q["frames"] == 2 and "2 frames" in q["counting"]
    # frames every 0.01 s give the paper's 0.05 s from every fifth; 0.03 s does not
    frames = list(range(12))
    sub, every = every_kth(frames, 0.01, 0.05)
    assert sub == [4, 9] and every == pytest.approx(0.05)
    assert every_kth(frames, 0.03, 0.05) is None
    assert every_kth(frames, 0.05, 0.05) is None
    assert every_kth(frames[:3], 0.01, 0.05) is None
