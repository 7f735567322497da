"""Contact physics of the bead DEM against closed-form results.

Two beads (or a few) float in the middle of an idle annulus, far from the walls, with no
gravity and no fluid, so that only the contact law acts.
"""

import math

import numpy as np
import pytest

from millfmu.dem.engine.params import BeadMaterial, bead_mass_kg, hertz_contact_time_s
from millfmu.dem.mills.geometry import MillGeometry

pytest.importorskip("numba")

R = 0.4e-3  # bead radius [m]
GEOM = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.004)


def _pair(material, v_rel, dt, normal=(1.0, 0.0, 0.0), gap=0.05e-3):
    """Two beads approaching along `normal` with relative velocity v_rel (3,) [m/s]."""
    from millfmu.dem.engine.sim import DemSimulation

    n = np.asarray(normal, float)
    n /= np.linalg.norm(n)
    c = np.array([0.030, 0.0, 0.002])
    x = np.array([c - (R + gap / 2) * n, c + (R + gap / 2) * n])
    v = np.array([0.5 * np.asarray(v_rel), -0.5 * np.asarray(v_rel)])
    return DemSimulation(GEOM, material, x, R, 0.0, dt, velocities_m_per_s=v)


def _overlap(sim):
    d = sim.x[1] - sim.x[0]
    return 2 * R - math.sqrt(d @ d)


@pytest.mark.parametrize("e", [0.99, 0.9, 0.7])
def test_head_on_restitution_and_hertz_time(e):
    mat = BeadMaterial(restitution=e, friction=0.3, rolling_friction=0.0)
    v0 = 2.0  # relative approach speed [m/s]
    dt = 2e-8
    sim = _pair(mat, (v0, 0, 0), dt, gap=2e-9)
    t_contact = 0.0
    seen = False
    for _ in range(20000):
        sim.run(10)
        if _overlap(sim) > 0:
            seen = True
            t_contact += 10 * dt
        elif seen:
            break
    v_after = sim.v[1, 0] - sim.v[0, 0]
    assert v_after == pytest.approx(e * v0, rel=0.01)
    m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
    t_hertz = hertz_contact_time_s(m / 2, R / 2, mat.effective_youngs_pa, v0)
    if e >= 0.99:
        # the closed form is for elastic impact; it holds to 2 % at the mill's restitution
        assert t_contact == pytest.approx(t_hertz, rel=0.02)


def test_recorded_energy_is_half_mstar_vn2_of_approach():
    mat = BeadMaterial(restitution=0.99, friction=0.3, rolling_friction=0.1)
    v_rel = np.array([0.7, 0.2, -0.1])
    normal = np.array([1.0, 0.3, 0.2])
    sim = _pair(mat, v_rel, 5e-7, normal=normal, gap=0.02e-3)
    st = sim.run(400, record=True)
    from millfmu.dem.engine import kernels as K

    bb = st.events[st.events[:, K.EV_TYPE] == 0]
    assert bb.shape[0] == 1  # counted once, at its first overlap
    n0 = normal / np.linalg.norm(normal)
    m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
    mstar = m / 2
    # straight-line approach: d(t) = d0 - v_rel t touches at |d| = 2R; the contact normal
    # there, not the initial line of centres, splits v_rel into normal and shear parts
    d0 = (2 * R + 0.02e-3) * n0
    a, b, c = v_rel @ v_rel, -2 * (d0 @ v_rel), d0 @ d0 - (2 * R) ** 2
    t_touch = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
    n = (d0 - v_rel * t_touch) / (2 * R)
    vn = float(v_rel @ n)
    assert bb[0, K.EV_SETN] == pytest.approx(0.5 * mstar * vn ** 2, rel=1e-3)
    vt2 = float(v_rel @ v_rel) - vn ** 2
    assert bb[0, K.EV_SETS] == pytest.approx(0.5 * mstar * vt2, rel=1e-3)
    assert bb[0, K.EV_SEROT] == 0.0


def test_oblique_impact_gross_sliding_matches_coulomb_impulse():
    """Tangential impulse = mu x normal impulse while sliding (Maw et al. 1976 regime
    v_t0 > 7/2 mu (1 + e) v_n0 for equal spheres); spin from the same impulse."""
    mu = 0.3
    # e = 0.99 (seed 001): with stronger damping the normal force turns slightly tensile
    # at the end of the contact (LIGGGHTS does not clamp it), and the Coulomb cap
    # mu |F_n| then adds impulse that the closed form, which assumes F_n >= 0, lacks
    e = 0.99
    mat = BeadMaterial(restitution=e, friction=mu, rolling_friction=0.0)
    # a slow approach keeps the sliding distance small against the bead size
    vn0 = 0.002
    for ratio in (1.5, 4.0):
        vt0 = ratio * 3.5 * mu * (1 + e) * vn0
        dt = 2e-7
        sim = _pair(mat, (vn0, vt0, 0.0), dt, gap=1e-10)
        m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
        w_start = sim.v[0].copy()
        # impulses on bead 0 in the frame of the contact, which turns slightly while the
        # beads slide past each other: sum of F.n dt and |F_t| dt over the steps
        jn = jt = 0.0
        for _ in range(4000):
            sim.run(1)
            d = sim.x[0] - sim.x[1]
            n = d / np.linalg.norm(d)
            fn = float(sim.f[0] @ n)
            jn += fn * dt
            jt += float(np.linalg.norm(sim.f[0] - fn * n)) * dt
        assert _overlap(sim) < 0
        assert jn > 0 and jt > 0
        assert jt == pytest.approx(mu * jn, rel=0.01)
        assert m * np.linalg.norm(sim.v[0] - w_start) == pytest.approx(math.hypot(jn, jt),
                                                                       rel=1e-3)
        inertia = 0.4 * m * R ** 2
        # the tangential force turns bead 0 about -z: |w_z| = R J_t / I
        assert sim.w[0, 2] == pytest.approx(-R * jt / inertia, rel=0.01)


def _stick_reference(vn0, vt0, mat, mstar, rstar):
    """No-slip Hertz-Mindlin impact of two equal spheres without damping, integrated with
    scipy (dense output): m* d'' = -4/3 Y* sqrt(R*) d^(3/2); tangential spring force
    F_t = -8 G* sqrt(R* d) xi, xi the integral of the contact-point slip velocity u; for
    equal spheres du/dt = F_t (2/m + 2 R^2/I) = 3.5 F_t / m* (centres plus spins)."""
    from scipy.integrate import solve_ivp

    ys = mat.effective_youngs_pa
    gs = mat.effective_shear_pa

    def rhs(t, y):
        d, dd, xi, u = y
        dpos = max(d, 0.0)
        fn = 4.0 / 3.0 * ys * math.sqrt(rstar) * dpos ** 1.5
        ft = -8.0 * gs * math.sqrt(rstar * dpos) * xi
        return [dd, -fn / mstar, u, ft * 3.5 / mstar]

    def leave(t, y):
        return y[0] if t > 1e-6 else 1.0
    leave.terminal = True
    leave.direction = -1
    sol = solve_ivp(rhs, [0, 1e-2], [0.0, vn0, 0.0, vt0], events=leave, rtol=1e-10,
                    atol=[1e-13, 1e-10, 1e-13, 1e-10], max_step=1e-6, dense_output=True)
    assert sol.status == 1 and sol.t[-1] > 1e-5  # ended by the beads separating
    return sol


@pytest.mark.parametrize("nu", [0.25, 0.45])
def test_oblique_impact_sticking_matches_no_slip_solution(nu):
    """With a friction coefficient too high to slide, the contact-point slip velocity
    follows the Hertz-Mindlin no-slip solution: it reverses during the contact (the
    tangential spring) and ends where the stiffness ratio, set by nu, puts it."""
    mat = BeadMaterial(restitution=1.0, friction=100.0, rolling_friction=0.0,
                       poisson_ratio=nu)
    vn0, vt0 = 0.01, 0.002
    dt, gap = 5e-8, 1e-10
    m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
    sim = _pair(mat, (vn0, vt0, 0.0), dt, gap=gap)
    ref = _stick_reference(vn0, vt0, mat, m / 2, R / 2)
    t0 = gap / vn0  # first touch
    errs = []
    u_all = []
    for k in range(1, 15):
        sim.run(500)
        d = sim.x[0] - sim.x[1]
        n = d / np.linalg.norm(d)
        vrel = sim.v[0] - sim.v[1]
        ws = R * (sim.w[0] + sim.w[1])
        u = vrel - (vrel @ n) * n - np.cross(ws, n)
        t = k * 500 * dt - t0
        u_ref = ref.sol(min(t, ref.t[-1]))[3]
        errs.append(abs(u[1] - u_ref))
        u_all.append(u[1])
    assert _overlap(sim) < 0
    assert max(errs) < 0.03 * vt0
    assert min(u_all) < -0.5 * vt0  # the slip did reverse: a genuine stick impact


def test_elastic_frictionless_energy_conserved():
    from millfmu.dem.engine.sim import DemSimulation

    mat = BeadMaterial(restitution=1.0, friction=0.0, rolling_friction=0.0)
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    rng = np.random.default_rng(3)
    from millfmu.dem.mills.geometry import place_beads

    x = place_beads(geom, 60, R, seed=2)
    v = rng.normal(0.0, 0.15, size=(60, 3))
    sim = DemSimulation(geom, mat, x, R, 0.0, 1e-6, velocities_m_per_s=v)

    def energy():
        et, er = sim.kinetic_energy_j()
        return et + er + sim.hertz_energy_j()

    e0 = energy()
    st = sim.run(100_000, record=True)
    e1 = energy()
    assert st.events.shape[0] > 100  # the beads did collide, many times
    assert abs(e1 - e0) / e0 < 1e-4


def test_collision_across_the_sector_boundary_matches_interior_collision():
    """Rotational periodicity: a head-on collision through the boundary ray of a 45 degree
    sector gives the rebound of the same collision inside the cell, and is recorded once."""
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation

    mat = BeadMaterial(restitution=0.9, friction=0.3, rolling_friction=0.0)
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.004,
                        sector_deg=45.0)
    rc = 0.030
    # bead a just inside theta = 0, bead b just inside theta = 45 deg; b's image (rotated
    # by -45 deg) sits across the ray theta = 0, so the two meet through the boundary
    half = (R + 0.01e-3) / rc
    a = np.array([rc * math.cos(half), rc * math.sin(half), 0.002])
    th_b = math.radians(45.0) - half
    b = np.array([rc * math.cos(th_b), rc * math.sin(th_b), 0.002])
    t_a = np.array([-math.sin(half), math.cos(half), 0.0])  # azimuthal directions
    t_b = np.array([-math.sin(th_b), math.cos(th_b), 0.0])
    v0 = 0.5
    sim = DemSimulation(geom, mat, np.array([a, b]), R, 0.0, 2e-7,
                        velocities_m_per_s=np.array([-v0 * t_a, v0 * t_b]))
    st = sim.run(3000, record=True)
    bb = st.events[st.events[:, K.EV_TYPE] == 0]
    assert bb.shape[0] == 1
    m = bead_mass_kg(2 * R, mat.density_kg_per_m3)
    assert bb[0, K.EV_SETN] == pytest.approx(0.5 * (m / 2) * (2 * v0) ** 2, rel=1e-3)
    # after the rebound each bead moves back along its own azimuthal direction
    th = np.arctan2(sim.x[:, 1], sim.x[:, 0])
    speeds = [float(sim.v[k] @ np.array([-math.sin(th[k]), math.cos(th[k]), 0.0]))
              for k in range(2)]
    ref = _pair(mat, (2 * v0, 0, 0), 2e-7, gap=0.02e-3)
    ref.run(3000)
    e_ref = (ref.v[1, 0] - ref.v[0, 0]) / (2 * v0)
    assert sorted(speeds) == pytest.approx([-e_ref * v0, e_ref * v0], rel=2e-3)
    assert np.all((th >= 0) & (th < math.radians(45.0)))  # wrapped back into the sector


def test_neighbour_list_overflow_is_handled_without_changing_results():
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import place_beads

    mat = BeadMaterial()
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 700, R, seed=5)
    rng = np.random.default_rng(7)
    v = rng.normal(0.0, 0.3, size=x.shape)
    out = []
    for maxnb in (1, 40):
        sim = DemSimulation(geom, mat, x, R, 300.0, 5e-6, velocities_m_per_s=v,
                            max_neighbours=maxnb)
        st = sim.run(400, record=True)
        out.append((sim.x.copy(), sim.v.copy(), st.events.shape[0], sim.pair_capacity))
    assert out[0][3] > 700  # the lists did grow past their initial room (1 pair per bead)
    assert out[0][2] == out[1][2]
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=0, atol=1e-12)


def test_lists_overflowing_within_a_run_change_no_result():
    """A neighbour build inside run() that finds the spare lists too small stops the
    stepping loop, enlarges them and closes the step: same trajectory and contacts as a run
    with room to spare."""
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import place_beads

    mat = BeadMaterial()
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 700, R, seed=5)
    v = np.random.default_rng(7).normal(0.0, 0.3, size=x.shape)
    out = []
    for tight in (True, False):
        sim = DemSimulation(geom, mat, x, R, 300.0, 5e-6, velocities_m_per_s=v)
        rebuilt = []
        build = sim._build
        sim._build = lambda **kw: (rebuilt.append(kw), build(**kw))
        if tight:
            sim._alloc_spare(8)  # the first build within the run overflows
        st = sim.run(400, record=True)
        out.append((sim.x.copy(), sim.v.copy(), st.events.shape[0], len(rebuilt)))
    assert (out[0][3], out[1][3]) == (1, 0)  # the overflowing build was done again, once
    assert out[0][2] == out[1][2]
    # that step is closed with two half kicks instead of one fused kick: round-off apart
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=1e-9, atol=1e-10)


def test_bead_reordering_keeps_the_dynamics():
    """Sorting beads along the cell grid (memory locality) only renames them: the same
    run with and without reordering agrees bead by bead (up to summation order)."""
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import place_beads

    mat = BeadMaterial()
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 700, R, seed=5)
    rng = np.random.default_rng(7)
    v = rng.normal(0.0, 0.3, size=x.shape)
    res = []
    for every in (0, 50):
        sim = DemSimulation(geom, mat, x, R, 300.0, 5e-6, velocities_m_per_s=v,
                            sort_every_steps=every)
        n_ev = 0
        for _ in range(4):
            n_ev += sim.run(60, record=True).events.shape[0]
        xs = np.empty_like(sim.x)
        xs[sim.ids] = sim.x
        res.append((xs, n_ev, sim.ids.copy()))
    assert not np.array_equal(res[1][2], np.arange(700))  # it did reorder
    assert res[0][1] == res[1][1]
    np.testing.assert_allclose(res[0][0], res[1][0], rtol=0, atol=1e-10)


def _forces_once(sim):
    """One call of the force kernel on a copy of the contact state: (F [N], T [N m]) on
    every bead."""
    from millfmu.dem.engine import kernels as K

    psh, pfl, shw, flw = sim.psh.copy(), sim.pfl.copy(), sim.shw.copy(), sim.flw.copy()
    K.compute_forces(sim.x, sim.v, sim.w, sim.fb, sim.tb, sim.rad, sim.mass, sim.inertia,
                     sim.pst, sim.nnb, sim.pj, sim.pim, psh, pfl, shw, flw, sim.prm, sim.cb,
                     sim.maxj, False, 0, sim.evc, sim.evn, sim.torq, sim.fext, sim.claims(),
                     False, 0.0, sim.inv_m, sim.inv_i, sim.xref, sim.dmax)
    K.reduce_kick(sim.fb, sim.tb, sim.cb, sim.maxj, sim.f, sim.t, sim.v.copy(), sim.w.copy(),
                  sim.x.copy(), sim.inv_m, sim.inv_i, 0.0, 0.0, False, sim.xref, sim.dmax,
                  sim.claims(), False)
    return sim.f.copy(), sim.t.copy()


def test_equal_beads_shortcut_gives_the_general_forces_bit_for_bit():
    """With one radius and mass for all beads the force loop takes R* and m* computed once;
    making one bead with no neighbour a little larger sends every pair through the
    general formulas, and the other beads' forces and torques are the same bit for bit."""
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import place_beads

    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 700, R, seed=5)
    v = np.random.default_rng(7).normal(0.0, 0.3, size=x.shape)
    sim = DemSimulation(geom, BeadMaterial(), x, R, 300.0, 5e-6, velocities_m_per_s=v,
                        sort_every_steps=0)
    sim.run(100)
    listed = np.zeros(sim.n, bool)  # beads with a neighbour within the cutoff
    for i in range(sim.n):
        for k in range(sim.pst[i], sim.pst[i] + sim.nnb[i]):
            listed[[i, sim.pj[k]]] = True
    lone = int(np.nonzero(~listed)[0][0])
    assert sim.pfl.sum() > 30  # pairs in contact are exercised
    f_eq, t_eq = _forces_once(sim)
    sim.rad[lone] *= 1.01
    sim.mass[lone] *= 1.01 ** 3
    f_gen, t_gen = _forces_once(sim)
    others = np.arange(sim.n) != lone
    assert np.abs(f_eq[others]).max() > 0.0
    assert np.array_equal(f_eq[others], f_gen[others])
    assert np.array_equal(t_eq[others], t_gen[others])


def test_history_frame_from_the_separation_equals_the_one_from_the_normal():
    """The pair loop projects the tangential history with |s - (s.n) n|^2 = |s|^2 -
    (s.d)^2 / |d|^2 (no root); against the direct projection on the unit normal, for a
    history lying in a previous tangent plane turned by up to 0.1 rad: agreement to
    round-off."""
    from millfmu.dem.engine import kernels as K

    rng = np.random.default_rng(11)
    for _ in range(200):
        d = rng.normal(size=3) * 0.8e-3
        n = d / np.linalg.norm(d)
        t = np.cross(n, rng.normal(size=3))
        s_old = t / np.linalg.norm(t) * 10.0 ** rng.uniform(-9, -5)  # [m]
        tilt = rng.uniform(0, 0.1)
        s = s_old * math.cos(tilt) + n * np.linalg.norm(s_old) * math.sin(tilt)
        r2 = float(d @ d)
        want = K.history_frame(*s, *n)
        got = K.history_frame_pair(*s, *d, 1.0 / r2, 1.0 / math.sqrt(r2))
        assert got[0] == pytest.approx(want[0], rel=1e-12, abs=1e-12 * np.linalg.norm(s))
        assert got[1] == want[1]
        assert got[2] == pytest.approx(want[2], rel=1e-12)
    # a new contact: no history, nothing to rescale
    assert K.history_frame_pair(0.0, 0.0, 0.0, *d, 1.0 / r2, 1.0) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("contact", ["pair", "wall"])
def test_tangential_history_rescaled_or_projected_when_the_contact_plane_turns(contact):
    """A resting contact (no damping, no sliding) whose tangential spring s0 lies in the
    tangent plane of the previous step, evaluated after its normal turned by phi in one
    step: the default "rescaled" history keeps its length s0, the "projected" one (LAMMPS'
    gran/hertz/history, LIGGGHTS) keeps s0 cos(phi); either way it lies in the new
    tangent plane and the tangential force is S_t |s| with S_t = 8 G* sqrt(R* delta)
    (closed form). Pair: bead 1 below bead 0, then swung about bead 0 in the x-z plane;
    wall: a bead pressed into the chamber wall, then moved round the axis by phi."""
    from millfmu.dem.engine.sim import DemSimulation

    mat = BeadMaterial(restitution=1.0, friction=0.3, rolling_friction=0.0)
    delta, s0, phi = 5e-6, 5e-7, 0.3
    got = {}
    for mode in ("rescaled", "projected"):
        if contact == "pair":
            d = 2 * R - delta
            c = np.array([0.030, 0.0, 0.002])
            x = np.array([c, c - d * np.array([0.0, 0.0, 1.0])])
            sim = DemSimulation(GEOM, mat, x, R, 0.0, 1e-7, tangential_history=mode)
            k = sim.pst[0]
            assert sim.nnb[0] == 1 and np.all(sim.psh[k] == 0.0)
            sim.psh[k] = (s0, 0.0, 0.0)  # in the plane normal to n = e_z
            n = np.array([math.sin(phi), 0.0, math.cos(phi)])  # from bead 1 to bead 0
            sim.x[1] = c - d * n
            rstar = R / 2
        else:
            rc = GEOM.chamber_radius_m - R + delta
            x = np.array([[rc, 0.0, 0.002]])
            sim = DemSimulation(GEOM, mat, x, R, 0.0, 1e-7, tangential_history=mode)
            assert sim.flw[0, 1] == 1 and np.all(sim.shw[0, 1] == 0.0)
            sim.shw[0, 1] = (0.0, s0, 0.0)  # in the plane normal to n = -e_x
            sim.x[0] = (rc * math.cos(phi), rc * math.sin(phi), 0.002)
            n = np.array([-math.cos(phi), -math.sin(phi), 0.0])  # from the wall to the bead
            rstar = R
        sim._finish(record=False, kick=0.0)  # forces (and history) at the new positions
        s = sim.psh[k].copy() if contact == "pair" else sim.shw[0, 1].copy()
        f = sim.f[0]
        ft = f - (f @ n) * n
        st = 8.0 * mat.effective_shear_pa * math.sqrt(rstar * delta)
        assert s @ n == pytest.approx(0.0, abs=1e-12 * s0)
        assert np.linalg.norm(ft) == pytest.approx(st * np.linalg.norm(s), rel=1e-9)
        assert f @ n == pytest.approx(4.0 / 3.0 * mat.effective_youngs_pa
                                      * math.sqrt(rstar * delta) * delta, rel=1e-9)
        got[mode] = np.linalg.norm(s)
    assert got["rescaled"] == pytest.approx(s0, rel=1e-12)
    assert got["projected"] == pytest.approx(s0 * math.cos(phi), rel=1e-12)


def test_tangential_history_rejects_unknown_names():
    from millfmu.dem.engine.sim import DemSimulation

    x = np.array([[0.030, 0.0, 0.002]])
    with pytest.raises(ValueError, match="tangential_history"):
        DemSimulation(GEOM, BeadMaterial(), x, R, 0.0, 1e-7, tangential_history="lammps")


def test_history_at_start_advanced_or_zero():
    """Two beads built in contact (overlap delta along x) that slide past each other at u
    along y: the default "advanced" start evaluates the initial forces with the spring
    already at u dt (tangential force S_t u dt), "zero" (LAMMPS, LIGGGHTS) with none; the
    first step adds u dt to either (closed form, no damping, far below the Coulomb
    limit)."""
    from millfmu.dem.engine.sim import DemSimulation

    mat = BeadMaterial(restitution=1.0, friction=0.3, rolling_friction=0.0)
    delta, u, dt = 5e-6, 0.01, 1e-7
    c = np.array([0.030, 0.0, 0.002])
    x = np.array([c + [(R - delta / 2), 0, 0], c - [(R - delta / 2), 0, 0]])
    v = np.array([[0.0, u / 2, 0.0], [0.0, -u / 2, 0.0]])
    st = 8.0 * mat.effective_shear_pa * math.sqrt(R / 2 * delta)
    springs = {}
    for start, n0 in (("advanced", 1), ("zero", 0)):
        sim = DemSimulation(GEOM, mat, x, R, 0.0, dt, velocities_m_per_s=v,
                            history_at_start=start)
        k = sim.pst[0]
        assert sim.psh[k] == pytest.approx([0.0, n0 * u * dt, 0.0], abs=1e-9 * u * dt)
        assert sim.f[0, 1] == pytest.approx(-st * n0 * u * dt, abs=1e-9 * st * u * dt)
        sim.run(1)
        springs[start] = sim.psh[k, 1]
        assert springs[start] == pytest.approx((n0 + 1) * u * dt, rel=1e-4)
    assert springs["advanced"] - springs["zero"] == pytest.approx(u * dt, rel=1e-4)
    with pytest.raises(ValueError, match="history_at_start"):
        DemSimulation(GEOM, mat, x, R, 0.0, dt, history_at_start="none")


def test_wall_contacts_are_recorded_at_the_bead_and_counted_in_its_zone():
    """A bead that hits the chamber wall, and one that hits the disc's outer edge from the
    gap beyond the rim (zone V2): each contact is recorded once, at the bead's centre at
    its first overlap (the contact point lies inside the wall, and at the edge would not
    tell the bead's side), so that it lands in the bead's zone."""
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.zones import Zones

    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.028,
                        disc_radius_m=0.036, disc_thickness_m=0.008)
    hb = 0.004
    d = 0.3e-3  # start outside the edge by this much in r and z [m]
    x = np.array([[0.045 - R - 0.05e-3, 0.0, 0.010],   # just off the chamber wall
                  [0.0, 0.036 + d, hb + d]])            # beyond the disc's edge
    u = 0.5 / math.sqrt(2.0)
    v = np.array([[0.5, 0.0, 0.0], [0.0, -u, -u]])     # towards the wall and the edge
    sim = DemSimulation(geom, BeadMaterial(restitution=0.9), x, R, 0.0, 2e-7,
                        velocities_m_per_s=v)
    st = sim.run(4000, record=True)
    ev = st.events
    assert sorted(ev[:, K.EV_TYPE].tolist()) == [2.0, 3.0]  # chamber (1 + 1), disc (1 + 2)
    p = ev[:, [K.EV_X, K.EV_Y, K.EV_Z]]
    ch, dc = p[ev[:, K.EV_TYPE] == 2.0][0], p[ev[:, K.EV_TYPE] == 3.0][0]
    # first overlap: the centre within one step's travel of touching
    step = 0.5 * 2e-7
    assert 0.045 - R - math.hypot(ch[0], ch[1]) == pytest.approx(0.0, abs=step)
    corner = math.hypot(math.hypot(dc[0], dc[1]) - 0.036, dc[2] - hb)
    assert corner == pytest.approx(R, abs=step)
    zones = Zones(geom)
    assert list(zones.classify(p[np.argsort(ev[:, K.EV_TYPE])])) == [2, 1]  # V3, V2


@pytest.mark.parametrize("every", [0, 50])
@pytest.mark.parametrize("height", [0.004, 0.0067])
def test_half_lists_hold_every_pair_within_the_cutoff_once(every, height):
    """The half neighbour lists against all pairs: every pair of beads (and of a bead with
    the rotated image of another across a 30 degree sector's rays) closer than the
    cutoff is listed exactly once, under its lower index, with its image code; with the
    beads sorted along the cells (the build skips cells of lower beads only) and without;
    with three axial cells (the stencil's columns searched as one run of cells) and with
    six (runs split where the stencil wraps axially)."""
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import place_beads

    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.024, height_m=height,
                        sector_deg=30.0)
    x = place_beads(geom, int(500 * height / 0.004), R, seed=3)
    v = np.random.default_rng(4).normal(0.0, 0.5, size=x.shape)
    sim = DemSimulation(geom, BeadMaterial(), x, R, 300.0, 5e-6, velocities_m_per_s=v,
                        sort_every_steps=every)
    sim.run(120)
    K.rebuild(sim.x, sim.v, sim.w, sim.shw, sim.xref, sim.prm, sim.wrapk, sim.cutoff_m, True,
              sim.pst, sim.nnb, sim.pj, sim.pim, sim.psh, sim.pfl, sim.pst_o, sim.nnb_o,
              sim.pj_o, sim.pim_o, sim.psh_o, sim.pfl_o, sim.cb, sim.need, sim.maxj,
              sim.claims())
    listed = []
    for i in range(sim.n):
        for k in range(sim.pst_o[i], sim.pst_o[i] + sim.nnb_o[i]):
            listed.append((i, int(sim.pj_o[k]), int(sim.pim_o[k])))
        # the pairs in contact come first in each row (the force loop's branch on
        # overlap then changes once per row)
        fl = sim.pfl_o[sim.pst_o[i]:sim.pst_o[i] + sim.nnb_o[i]]
        assert np.all(fl[1:] <= fl[:-1])
    assert sim.pfl_o.sum() > 5
    assert len(listed) == len(set(listed))
    sec = math.radians(30.0)
    lz = geom.height_m
    want = set()
    for s in (-1, 0, 1):
        c, sn = math.cos(s * sec), math.sin(s * sec)
        img = sim.x @ np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])
        d = sim.x[:, None, :] - img[None, :, :]
        d[..., 2] -= lz * np.round(d[..., 2] / lz)
        close = (d ** 2).sum(-1) < sim.cutoff_m ** 2
        for i, j in zip(*np.nonzero(close)):
            if j > i:
                want.add((int(i), int(j), s))
    assert any(s != 0 for _, _, s in want)  # the sector's images are exercised
    assert int(geom.height_m / sim.cutoff_m) == (3 if height < 0.005 else 6)
    assert set(listed) == want


@pytest.mark.parametrize("eps", [0.999, 0.6, 0.45])
def test_koch_hill_drag_on_a_resting_bead(eps):
    """Force on a bead at rest in the prescribed Couette swirl: V_p beta U_f with beta from
    the REFERENCE's Koch-Hill formulas (and Stokes' 3 pi mu d U in the dilute limit)."""
    from millfmu.dem.engine import kernels as K
    from millfmu.dem.engine.sim import DemSimulation, FluidSettings

    mu, rho = 1.002e-3, 998.2
    fl = FluidSettings(density_kg_per_m3=rho, viscosity_Pa_s=mu, lubrication=False,
                       void_fraction=eps)
    omega = 8.0 / 0.015
    r = 0.025
    sim = DemSimulation(GEOM, BeadMaterial(), np.array([[r, 0.0, 0.002]]), R, omega, 5e-6,
                        fluid=fl)
    # Couette flow between the shaft (omega r_sh) and the fixed wall: u = A r + B / r
    a = -omega * 0.015 ** 2 / (0.045 ** 2 - 0.015 ** 2)
    b = omega * 0.015 ** 2 * 0.045 ** 2 / (0.045 ** 2 - 0.015 ** 2)
    u = a * r + b / r
    ux, uy, _ = K.swirl_velocity(r, 0.0, 0.002, sim.prm)
    assert (ux, uy) == pytest.approx((0.0, u), rel=1e-12, abs=1e-15)
    d = 2 * R
    phi = 1 - eps
    if phi < 0.4:
        f0 = (1 + 3 * math.sqrt(phi / 2) + 135 / 64 * phi * math.log(phi) + 16.14 * phi) / (
            1 + 0.681 * phi - 8.48 * phi ** 2 + 8.16 * phi ** 3)
    else:
        f0 = 10 * phi / eps ** 3
    f3 = 0.0673 + 0.212 * phi + 0.0232 / eps ** 5
    re = d * eps * u * rho / mu
    beta = 18 * mu * eps * eps * (f0 + 0.5 * f3 * re) / d ** 2
    vp = math.pi / 6 * d ** 3
    assert sim.f[0, 1] == pytest.approx(vp * beta * u, rel=1e-10)  # no gravity here
    if eps > 0.99:
        # dilute limit: Stokes drag with the Koch-Hill inertial correction
        assert sim.f[0, 1] == pytest.approx(3 * math.pi * mu * d * u * (1 + 0.5 * f3 * re),
                                            rel=0.05)


def wrapping_contact_pair(theta0_rad):
    """Two beads in a sheared, slowly closing contact, drifting azimuthally (about -z)
    in a 45 degree sector; the leading bead starts 0.05 mm past the ray theta0 (for
    theta0 = 0 it crosses theta = 0 during the contact and is wrapped to the far side).
    Returns (geometry, positions, velocities) [m, m/s]."""
    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.004,
                        sector_deg=45.0)
    rc = 0.030
    th_a = theta0_rad + 0.05e-3 / rc
    th_b = th_a + 2 * R / rc
    pos = np.array([[rc * math.cos(t), rc * math.sin(t), 0.002] for t in (th_a, th_b)])
    e_t = np.array([[-math.sin(t), math.cos(t), 0.0] for t in (th_a, th_b)])
    vel = -2.0 * e_t  # a neighbour build (and wrap) after about 37 steps of 2 us
    vel[0] += 0.02 * e_t[0] + np.array([0.0, 0.0, 0.02])  # closing and shearing
    return geom, pos, vel


def test_contact_carried_across_a_sector_wrap_equals_one_away_from_the_boundary():
    """Rotational periodicity with history: the leading bead is wrapped across the
    boundary ray in the middle of a sticking-sliding contact; its spring must be carried
    to the image pair (rotated with the bead), so that the contact evolves exactly as the
    same contact placed 20 degrees into the sector."""
    from millfmu.dem.engine.sim import DemSimulation

    mat = BeadMaterial(restitution=0.9, friction=0.5, rolling_friction=0.0)
    out = []
    for th0 in (0.0, math.radians(20.0)):
        geom, pos, vel = wrapping_contact_pair(th0)
        sim = DemSimulation(geom, mat, pos, R, 0.0, 2e-6, velocities_m_per_s=vel)
        wrapped = False
        for _ in range(12):
            sim.run(5)
            wrapped |= bool(np.arctan2(sim.x[0, 1], sim.x[0, 0]) > math.radians(30.0))
        gaps = []
        for k in (-1, 0, 1):  # through the periodic images of bead 0
            c, s = math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)
            xa = np.array([c * sim.x[0, 0] - s * sim.x[0, 1], s * sim.x[0, 0] + c * sim.x[0, 1],
                           sim.x[0, 2]])
            gaps.append(np.linalg.norm(sim.x[1] - xa) - 2 * R)
        assert min(gaps) < 0  # still in contact
        # relative motion in the frame of the pair: rotate both beads back by their angle
        th = np.arctan2(sim.x[:, 1], sim.x[:, 0])
        rel = []
        for k in range(2):
            c, s = math.cos(-th[k]), math.sin(-th[k])
            rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            rel.append((rot @ sim.v[k], rot @ sim.w[k]))
        out.append((wrapped, rel))
    assert out[0][0] and not out[1][0]  # only the first run crossed the boundary
    for (va, wa), (vb, wb) in zip(out[0][1], out[1][1]):
        np.testing.assert_allclose(va, vb, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(wa, wb, rtol=1e-6, atol=1e-6)
