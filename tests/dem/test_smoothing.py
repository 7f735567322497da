"""The beads' fields smoothed by split implicit diffusion (coupling.split_implicit_smoothing)
against closed forms: the variance each step adds, conservation, positivity, the exact
transpose, constants kept; chosen by name in a scene."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from millfmu.dem.coupling import projection as PJ  # noqa: E402
from millfmu.dem.coupling.split_implicit_smoothing import SplitImplicitSmoother  # noqa: E402
from millfmu.dem.fluid.grid import mill_grid  # noqa: E402
from millfmu.dem.mills.geometry import MillGeometry  # noqa: E402
from millfmu.dem.scene import DemSceneError, load_scene  # noqa: E402


def _line(axis, n, var, steps):
    """A uniform line of n unit cells along ``axis`` (0 r: walls at both ends; 1 theta,
    2 z: periodic), unit face coefficients, a unit total in the middle cell smoothed."""
    shape = [1, 1, 1]
    shape[axis] = n
    a = [np.zeros(shape) for _ in range(3)]
    a[axis][:] = 1.0
    if axis == 0:
        a[0][-1] = 0.0  # the wall
    sm = SplitImplicitSmoother(tuple(shape), np.ones(shape[0]), *a, var, steps)
    q = np.zeros((1, n))
    q[0, n // 2] = 1.0
    sm.smooth(q, True, 1)
    return q[0]


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("steps", [1, 4])
def test_each_direction_reaches_the_variance_exactly(axis, steps):
    """A backward-Euler step of the discrete diffusion adds 2 kappa dtau to the variance
    (the symbol 1 / (1 + 2 a (1 - cos k h)) has -d2/dk2 = 2 a h^2 at k = 0), so a unit
    total spreads to the per-axis variance 2 L^2 in any number of steps; 400 cells keep the
    tails (exp(-200 h / L)) off the ends."""
    var = 2.0 * 3.0 ** 2  # L = 3 cells
    q = _line(axis, 400, var, steps)
    x = np.arange(400) - 200.0
    assert q.sum() == pytest.approx(1.0, abs=1e-14)
    assert q.min() >= 0.0
    assert (q * x).sum() == pytest.approx(0.0, abs=1e-12)
    assert (q * x * x).sum() == pytest.approx(var, rel=1e-11)


def test_kernel_peak_against_a_gaussian_of_the_same_variance():
    """One step: the discrete Helmholtz kernel, whose continuum form exp(-|x|/b) / (2 b)
    peaks sqrt(pi) = 1.772 times the Gaussian of the same variance; four steps 1.11 (as the
    module says), so more steps approach the explicit sweeps' Gaussian."""
    var = 2.0 * 20.0 ** 2  # L = 20 cells: close to the continuum
    g = 1.0 / math.sqrt(2.0 * math.pi * var)
    assert _line(2, 2000, var, 1).max() / g == pytest.approx(math.sqrt(math.pi), rel=0.01)
    assert _line(2, 2000, var, 4).max() / g == pytest.approx(1.108, abs=0.005)


def _mill():
    geo = MillGeometry(0.015, 0.045, 0.028, disc_radius_m=0.036, disc_thickness_m=0.008,
                       sector_deg=60.0)
    return mill_grid(geo, 1e-3, n_theta=8)


@pytest.mark.parametrize("steps", [1, 3])
def test_on_a_mill_grid_conserves_keeps_signs_and_is_the_exact_transpose(steps):
    """On a disc mill's grid (solid disc, walls, 8 theta cells, periodic theta and z):
    totals conserved to round-off and never negative, solids untouched, constants kept by
    the values' smoothing, and <S_t a, b> = <a, S_v b> to round-off."""
    grid = _mill()
    proj = PJ.Projector(grid, 2e-3, method="split_implicit", steps=steps)
    solid = grid.solid.ravel() != 0
    rng = np.random.default_rng(3)
    a = rng.random((4, solid.size))
    a[:, solid] = 0.0
    a[1] = 0.0
    a[1, np.flatnonzero(~solid)[::97]] = 1.0  # isolated spikes
    t = a.copy()
    proj.smooth_totals(t)
    assert np.allclose(t.sum(axis=1), a.sum(axis=1), rtol=1e-13, atol=0)
    assert t.min() >= 0.0 and np.all(t[:, solid] == 0.0)
    # the spikes spread: the smoothing did something
    assert t[1].max() < 0.2
    b = rng.normal(size=(4, solid.size))
    b[:, solid] = 0.0
    v = b.copy()
    proj.smooth_values(v)
    lhs, rhs = float((t * b).sum()), float((a * v).sum())
    assert abs(lhs - rhs) <= 1e-12 * (abs(lhs) + abs(rhs))
    one = np.ones((2, solid.size))
    proj.smooth_values(one)
    assert np.allclose(one[:, ~solid], 1.0, rtol=0, atol=1e-13)
    # only the first ncols fields
    c = a.copy()
    proj.smooth_totals(c, ncols=2)
    assert np.array_equal(c[2:], a[2:]) and np.array_equal(c[:2], t[:2])


def test_split_implicit_and_explicit_spread_alike_on_the_mill_grid():
    """The same per-axis variance on the mill's (cylindrical, non-uniform) grid: a bead
    volume deposited in one cell spreads over about as many cells either way."""
    grid = _mill()
    cells = np.flatnonzero(grid.solid.ravel() == 0)
    q = np.zeros((1, grid.solid.size))
    q[0, cells[len(cells) // 2]] = 1.0
    spread = {}
    for m in ("explicit_diffusion", "split_implicit"):
        t = q.copy()
        PJ.Projector(grid, 2e-3, method=m, steps=4).smooth_totals(t)
        spread[m] = 1.0 / float((t[0] ** 2).sum())  # participation number [cells]
    assert spread["split_implicit"] == pytest.approx(spread["explicit_diffusion"], rel=0.3)
    assert spread["explicit_diffusion"] > 5.0


def test_smoothing_chosen_by_name_in_the_scene_and_its_refusals(tmp_path):
    sc = load_scene("accelerator_slice").with_overrides(smoothing="split_implicit")
    assert sc.coupling.smoothing == "split_implicit" and sc.coupling.smoothing_steps == 4
    assert "smoothing split_implicit in 4 step(s)" in sc.fluid_description
    assert "smoothing" not in load_scene("accelerator_slice").fluid_description
    with pytest.raises(DemSceneError, match="smoothing = 'gauss': allowed"):
        load_scene("accelerator_slice").with_overrides(smoothing="gauss")
    with pytest.raises(DemSceneError, match="the coupled liquid's; the fluid here is"):
        load_scene("accelerator_slice").with_overrides(fluid_mode="prescribed",
                                                       smoothing="split_implicit")
    from millfmu.dem.scene import _coupling_from_dict

    c = _coupling_from_dict({"smoothing": "split_implicit", "smoothing_steps": 2})
    assert c.smoothing_steps == 2
    with pytest.raises(DemSceneError, match="smoothing_steps = 0: allowed 1 to 64"):
        _coupling_from_dict({"smoothing": "split_implicit", "smoothing_steps": 0})
    with pytest.raises(DemSceneError, match="only smoothing = 'split_implicit' takes steps"):
        _coupling_from_dict({"smoothing_steps": 2})
    with pytest.raises(DemSceneError, match="fluid.coupled.smoothing = 'x': allowed"):
        _coupling_from_dict({"smoothing": "x"})


def test_a_coupled_run_with_split_implicit_smoothing(tmp_path):
    """A coupled accelerator sector with 4 theta cells runs with it and conserves the
    exchange as the explicit one does (the run's own budget checks)."""
    from millfmu.dem import run as R

    sc = load_scene("accelerator_slice").with_overrides(
        sector_deg=30.0, n_theta=4, smoothing="split_implicit", spin_up_s=5e-4,
        record_s=5e-4, sample_every_s=5e-4)
    st = R.run_scene(sc, tmp_path, progress=False, threads=1)
    assert "split_implicit" in st.fluid_model
    assert st.counts["contacts_recorded"] > 0


def _diffuse_cell_by_cell(q, vol, ar, at, az, sweeps, totals, ncols):
    """The explicit sweeps as a plain loop over the cells and their "+" faces (each flux
    added to both its cells at once, faces of coefficient 0 skipped): the order of
    additions of :func:`projection.diffuse`, which a faster form must keep to the bit (the
    coupled runs' results and the tables' version depend on it)."""
    nr, nt, nz = ar.shape
    for c in range(ncols):
        for _ in range(sweeps):
            tmp = np.empty((nr, nt, nz))
            for i in range(nr):
                tmp[i] = q[c, i] * (1.0 / vol[i] if totals else 1.0)
            for i in range(nr):
                ia = 1.0 if totals else 1.0 / vol[i]
                ib = 1.0 if totals or i + 1 >= nr else 1.0 / vol[i + 1]
                for j in range(nt):
                    jp = (j + 1) % nt
                    for k in range(nz):
                        kp = (k + 1) % nz
                        t0 = tmp[i, j, k]
                        for al, dst, s in ((az[i, j, k], (i, j, kp), ia),
                                           (ar[i, j, k], (i + 1, j, k), ib),
                                           (at[i, j, k] if nt > 1 else 0.0, (i, jp, k), ia)):
                            if al != 0.0:
                                f = al * (t0 - tmp[dst])
                                q[c, i, j, k] -= f * ia
                                q[(c,) + dst] += f * s


@pytest.mark.parametrize("shape", [(1, 1, 1), (3, 1, 2), (4, 1, 7), (3, 2, 5), (4, 3, 6),
                                   (2, 3, 1)])
@pytest.mark.parametrize("totals", [True, False])
def test_explicit_sweeps_add_in_the_cell_by_cell_order_to_the_bit(shape, totals):
    """The kernel and the plain loop give the same bytes, zeros' signs included, with walls
    and solids (coefficients 0) anywhere, on grids with and without theta cells."""
    rng = np.random.default_rng(sum(shape) + totals)
    a = []
    for axis in range(3):
        x = 0.1 * rng.random(shape) * (rng.random(shape) > 0.3)
        if axis == 0:
            x[-1] = 0.0  # the chamber wall
        if axis == 1 and shape[1] == 1:
            x[:] = 0.0
        a.append(x)
    vol = 1.0 + rng.random(shape[0])
    q = rng.standard_normal((2,) + shape)
    q[q > 1.2] = -0.0
    ref = q.copy()
    _diffuse_cell_by_cell(ref, vol, *a, 4, totals, 2)
    PJ.diffuse(q, vol, *a, 4, totals, np.zeros_like(q), 2)
    assert q.tobytes() == ref.tobytes()


def test_the_smoothing_length_as_an_override_and_its_refusals():
    """smoothing_diameters as a run-time override: the same check as the scene file's key."""
    sc = load_scene("disc_slice")
    assert sc.with_overrides(smoothing_diameters=0.5).coupling.smoothing_diameters == 0.5
    assert sc.with_overrides(smoothing_diameters=0).coupling.cell_m == sc.coupling.cell_m
    for bad in (-1, float("nan"), float("inf"), True, "1"):
        with pytest.raises(DemSceneError, match="smoothing_diameters = .*: must be a number >= 0"):
            sc.with_overrides(smoothing_diameters=bad)
    with pytest.raises(DemSceneError, match="the coupled liquid's; the fluid here is 'prescribed'"):
        sc.with_overrides(fluid_mode="prescribed", smoothing_diameters=0.5)
