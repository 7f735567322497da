"""The beads' share of the resolved viscous stress (millfmu.dem.fluid.anderson_jackson1967):
the stress divergence against closed forms with its measured order, the scene key's
refusals, and a coupled run with the force closing its angular-momentum budget."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem.fluid import anderson_jackson1967 as AJ  # noqa: E402
from millfmu.dem.fluid.grid import annulus_grid  # noqa: E402
from millfmu.dem.fluid.solver import FluidError, FluidProperties, FluidSolver  # noqa: E402
from millfmu.dem.scene import DemSceneError, load_scene, load_scene_dict, scene_from_dict  # noqa: E402

R1, R2, MU, RHO, C = 0.015, 0.025, 0.4, 1000.0, 50.0


def _divergence(n_r, field, n_theta=1):
    """div tau of a laminar liquid on an annulus of n_r radial cells whose ``field``
    ('ut', 'uz' or 'ur') is set to its closed-form profile, the others zero; returns
    (r centres or faces, the component's interior values)."""
    sector = 2 * math.pi if n_theta == 1 else math.pi / 2
    g = annulus_grid(R1, R2, 0.004, n_r, 4, n_theta=n_theta, sector_rad=sector)
    # the shaft turns as u_theta = C r^2 has it at r1 (its edge is not among the nodes checked)
    s = FluidSolver(g, FluidProperties(RHO, MU), C * R1, turbulence="laminar")
    rc, rf = g.r_centres_m, g.r_faces_m
    s.ur[:] = 0.0
    s.ut[:] = 0.0
    s.uz[:] = 0.0
    if field == "ut":
        s.ut[:] = (C * rc ** 2)[:, None, None]
    elif field == "uz":
        s.uz[:] = (C * rc ** 2)[:, None, None]
    else:
        s.ur[1:-1] = (C / rf[1:-1])[:, None, None]
    dr_, dt_, dz_ = AJ.stress_divergence(s)
    if field == "ur":
        return rf[2:-2], dr_[2:-2]  # nodes whose edges and cells lie off the walls
    d = dt_ if field == "ut" else dz_
    return rc[1:-1], d[1:-1]


def test_the_swirls_stress_divergence_is_3_mu_c_to_second_order():
    """u_theta = c r^2: div tau_theta = mu (u'' + u'/r - u/r^2) = 3 mu c; the finite
    volumes' relative error is dr^2 / (12 r^2) (the annular cell's r^3 moment), so the
    error times r^2 falls with order 2; the same with theta cells."""
    errs = []
    for n in (8, 16, 32):
        r, d = _divergence(n, "ut")
        assert np.allclose(d, d[:, :1, :1])  # uniform in theta and z
        rel = d[:, 0, 0] / (3 * MU * C) - 1.0
        dr = (R2 - R1) / n
        np.testing.assert_allclose(rel, dr ** 2 / (12 * r ** 2), rtol=1e-6)
        errs.append(np.abs(rel * r ** 2).max())
    orders = [math.log2(a / b) for a, b in zip(errs[:-1], errs[1:])]
    print(f"u_theta = c r^2: errors x r^2 {errs} m2, orders {orders}")
    assert min(orders) > 1.99 and errs[-1] < 1e-7
    r, d4 = _divergence(16, "ut", n_theta=4)
    r, d1 = _divergence(16, "ut")
    np.testing.assert_allclose(d4, d1[:, :1, :] * np.ones_like(d4), rtol=1e-12)


def test_the_axial_stress_divergence_is_4_mu_c():
    """u_z = c r^2: div tau_z = mu (1/r) d(r u_z')/dr = 4 mu c, exact in the finite volumes
    (the face gradients of a quadratic are exact)."""
    r, d = _divergence(12, "uz")
    np.testing.assert_allclose(d, 4 * MU * C, rtol=1e-9)


def test_the_source_flows_stress_divergence_vanishes():
    """u_r = c / r (a line source, divergence-free): div tau_r = 0, in the finite volumes
    to round-off against the scale mu c / r^3 (their differences of r u_r and of u_r / r
    are exact for it)."""
    for n in (8, 16, 32):
        r, d = _divergence(n, "ur")
        err = np.abs(d * r[:, None, None] ** 3 / (MU * C)).max()
        print(f"u_r = c / r, {n} cells: |div tau_r| r^3 / (mu c) {err:.2e}")
        assert err < 1e-10


def test_the_force_is_the_momentum_rows_viscous_term():
    """The beads' div tau is the liquid's own viscous term: on a swirl u_theta(r) and an
    axial flow u_z(r), which nothing advects, the theta and z rows' explicit rates times
    rho are div tau to round-off (the kernel repeats the rows' finite volumes; this ties
    them together)."""
    from millfmu.dem.fluid import step_kernels as SK

    for field in ("ut", "uz"):
        g = annulus_grid(R1, R2, 0.004, 12, 4)
        s = FluidSolver(g, FluidProperties(RHO, MU), C * R1, turbulence="laminar")
        rc = g.r_centres_m
        s.ur[:] = 0.0
        s.ut[:] = (C * rc ** 2)[:, None, None] if field == "ut" else 0.0
        s.uz[:] = (C * rc ** 2)[:, None, None] if field == "uz" else 0.0
        _, d_t, d_z = AJ.stress_divergence(s)
        W, F = s._W, s._F
        s.VK.face_fluxes(s.ur, s.ut, s.uz, F[SK.EPSR], F[SK.EPST], F[SK.EPSZ], s.rf, s.dr,
                         s.vc, s.dth, s.dz, W[SK.FR], W[SK.FT], W[SK.FZ])
        s.VK.rates(s.ur, s.ut, s.uz, W[SK.FR], W[SK.FT], W[SK.FZ], s.kr, s.kt, s.kz,
                   W[SK.TRR], W[SK.TTT], W[SK.TZZ], W[SK.ERT], W[SK.ERZ], W[SK.ETZ],
                   F[SK.EPSR], s.rf, s.rc, s.dr, s.vc, s.dth, s.dz, s.rho, W[SK.RR],
                   W[SK.RT], W[SK.RZ])
        rate, div, kind = ((W[SK.RT], d_t, s.kt) if field == "ut" else (W[SK.RZ], d_z, s.kz))
        solved = kind == 0
        assert np.any(div[solved] != 0.0)
        np.testing.assert_allclose(rate[solved] * RHO, div[solved], rtol=1e-12, atol=0.0)


def _coupled(key):
    d = load_scene_dict("disc_slice")
    d["fluid"]["coupled"]["bead_stress_force"] = key
    return scene_from_dict(d)


def test_the_scene_key_and_its_refusals():
    sc = _coupled("anderson_jackson1967")
    assert sc.coupling.bead_stress_force == "anderson_jackson1967"
    assert "viscous-stress force (Anderson & Jackson 1967" in sc.fluid_description
    assert load_scene("disc_slice").coupling.bead_stress_force == "none"
    assert "viscous-stress" not in load_scene("disc_slice").fluid_description
    with pytest.raises(DemSceneError, match=r"bead_stress_force = 'viscForce': allowed "
                                            r"\['none', 'anderson_jackson1967'\]"):
        _coupled("viscForce")
    d = load_scene_dict("accelerator_slice")  # model B
    d["fluid"]["coupled"]["bead_stress_force"] = "anderson_jackson1967"
    with pytest.raises(DemSceneError, match="only model A"):
        scene_from_dict(d)
    g = annulus_grid(R1, R2, 0.004, 8, 4)
    with pytest.raises(FluidError, match="stress_force with fluid model = 'B'"):
        FluidSolver(g, model="B", stress_force=True)


def test_the_model_a_rule_is_one_check_for_files_and_overrides():
    """A scene file and an override refuse the force beside model B for the same reason,
    each naming its own item; a model and the force given together are judged after both
    are applied (model A with the force is fine, model B without it too)."""
    d = load_scene_dict("accelerator_slice")  # model B
    d["fluid"]["coupled"]["bead_stress_force"] = "anderson_jackson1967"
    with pytest.raises(DemSceneError) as from_file:
        scene_from_dict(d)
    base = load_scene("accelerator_slice")
    with pytest.raises(DemSceneError) as from_override:
        base.with_overrides(bead_stress_force="anderson_jackson1967")
    reason = "only model A (vans_model = 'A', scheme 'vans') gives the beads the generalized buoyancy"
    assert str(from_file.value).startswith(f"fluid.coupled.bead_stress_force = 'anderson_jackson1967': {reason}")
    assert str(from_override.value).startswith(f"bead_stress_force = 'anderson_jackson1967': {reason}")
    both = base.with_overrides(vans_model="A", bead_stress_force="anderson_jackson1967")
    assert (both.coupling.model, both.coupling.bead_stress_force) == ("A", "anderson_jackson1967")
    with_force = _coupled("anderson_jackson1967")
    with pytest.raises(DemSceneError, match=r"vans_model = 'B': this scene's beads take model A's "
                                            r"viscous-stress force \('anderson_jackson1967'\); only model A"):
        with_force.with_overrides(vans_model="B")
    assert with_force.with_overrides(vans_model="B", bead_stress_force="none").coupling.model == "B"


def test_a_coupled_run_with_the_stress_force_closes_its_budget(tmp_path):
    """The beads' stress force and its reaction on the liquid cancel: stirrer drive =
    change of fluid + bead angular momentum + chamber wall impulse, as without it, over
    a short coupled run of the disc sector from rest; the liquid's stresses carry no eps, so the
    disc's shear on the liquid is larger than without the force."""
    from millfmu.dem.run import run_scene

    out = {}
    for key in ("none", "anderson_jackson1967"):
        sc = _coupled(key).with_overrides(
            sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), spin_up_s=0.0005,
            record_s=0.002, sample_every_s=0.0005)
        st = run_scene(sc, tmp_path / key, progress=False)
        b = st.flow["angular_momentum_budget"]
        print(key, b)
        assert abs(b["closure_rel"]) < 0.01
        out[key] = st
    t0 = out["none"].flow["torque"]["stirrer_fluid_shear_nm"]
    t1 = out["anderson_jackson1967"].flow["torque"]["stirrer_fluid_shear_nm"]
    print(f"liquid's shear torque on the stirrer: {t0:.4g} N m without, {t1:.4g} N m with")
    assert t1 > t0
    assert "viscous-stress force" in out["anderson_jackson1967"].flow["fluid"]["model"]
    assert "viscous-stress force" not in out["none"].flow["fluid"]["model"]
