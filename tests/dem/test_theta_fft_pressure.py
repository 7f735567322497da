"""The pressure equation by FFT in theta (fluid.theta_fft_pressure) against the direct
sparse LU of the whole operator: the same solution to round-off on grids whose solids do
not vary with theta; other grids refused by name."""

import numpy as np
import pytest

from millfmu.dem.fluid.grid import FLUID, GridError, mill_grid
from millfmu.dem.fluid.pressure import PressureSolver
from millfmu.dem.mills.geometry import MillGeometry


@pytest.mark.parametrize("sector_deg, n_theta", [(360.0, 16), (60.0, 7), (30.0, 2)])
def test_theta_fft_matches_the_direct_solver(sector_deg, n_theta):
    geo = MillGeometry(0.015, 0.045, 0.028, disc_radius_m=0.036, disc_thickness_m=0.008,
                       sector_deg=sector_deg)
    grid = mill_grid(geo, 1.5e-3, n_theta=n_theta)
    direct = PressureSolver(grid)
    fft = PressureSolver(grid, "theta_fft")
    rng = np.random.default_rng(n_theta)
    b = rng.normal(size=grid.shape) * (grid.solid == FLUID)
    xd = direct.solve(b, check=True)
    xf = fft.solve(b, check=True)
    scale = np.abs(xd).max()
    assert np.abs(xf - xd).max() <= 1e-11 * scale
    # both solve the equation (volume-weighted mean of b removed) to round-off, with the
    # first fluid cell at 0
    assert direct.last_residual < 1e-11 and fft.last_residual < 1e-11
    assert xf[grid.solid == FLUID][0] == 0.0
    # a checkpoint pickles it without the factors and factorises again on loading
    import pickle

    back = pickle.loads(pickle.dumps(fft))
    assert np.array_equal(back.solve(b), xf)


def test_theta_fft_refuses_grids_it_cannot_solve():
    geo = MillGeometry(0.015, 0.045, 0.028, disc_radius_m=0.036, disc_thickness_m=0.008,
                       sector_deg=60.0)
    with pytest.raises(GridError, match="needs theta cells"):
        PressureSolver(mill_grid(geo, 1.5e-3, n_theta=1), "theta_fft")
    grid = mill_grid(geo, 1.5e-3, n_theta=6)
    grid.solid[3, 2, 4] = 1  # a solid in one theta column only (a vane, a baffle)
    with pytest.raises(GridError, match="same solids in every theta column"):
        PressureSolver(grid, "theta_fft")
    with pytest.raises(ValueError, match="pressure_solver = 'cg': allowed"):
        PressureSolver(grid, "cg")


def test_chosen_by_name_and_a_coupled_disc_run_with_it(tmp_path):
    """A coupled disc sector with theta cells runs with theta_fft and gives the direct
    solver's run: the same pressure to round-off, so the same beads over a few intervals."""
    pytest.importorskip("numba")
    from millfmu.dem import run as R
    from millfmu.dem.scene import DemSceneError, load_scene

    sc = load_scene("disc_slice").with_overrides(
        sector_deg=30.0, n_theta=4, gravity_m_per_s2=(0.0, 0.0, 0.0), spin_up_s=2.5e-4,
        record_s=2.5e-4, sample_every_s=2.5e-4)
    fft = sc.with_overrides(pressure_solver="theta_fft")
    assert fft.coupling.pressure_solver == "theta_fft"
    assert "pressure by theta_fft" in fft.fluid_description
    with pytest.raises(DemSceneError, match="pressure_solver = 'x': allowed"):
        sc.with_overrides(pressure_solver="x")
    a = R.run_scene(sc, tmp_path / "direct", progress=False, threads=1)
    b = R.run_scene(fft, tmp_path / "fft", progress=False, threads=1)
    ea, eb = a.kinetic_energy["mean_j"], b.kinetic_energy["mean_j"]
    assert eb == pytest.approx(ea, rel=1e-9) and ea > 0
    fa, fb = (np.load(tmp_path / d / "fluid_fields.npz") for d in ("direct", "fft"))
    for k in fa.files:
        scale = np.nanmax(np.abs(fa[k])) if np.isfinite(fa[k]).any() else 0.0
        assert np.allclose(fb[k], fa[k], rtol=1e-7, atol=1e-9 * scale, equal_nan=True), k
    # stationary baffles are solid cells in some theta columns: refused by name before the
    # run's folder is made (the accelerator's vanes are driven nodes, not solids: allowed)
    from validation.seed002 import BAFFLES

    acc = load_scene("accelerator_slice").with_overrides(
        sector_deg=60.0, n_theta=12, baffles=BAFFLES, pressure_solver="theta_fft")
    with pytest.raises(R.DemRunError, match="same solids in every theta column"):
        R.run_scene(acc, tmp_path / "acc", progress=False, threads=1)
    assert not (tmp_path / "acc").exists()


def test_dem_run_advises_on_full_slices():
    from millfmu.dem.scene import load_scene, scene_advice

    full = load_scene("disc_slice")  # the full circle with gravity, one theta cell
    assert full.geometry.sector_deg == 360.0 and full.coupling.n_theta == 1
    assert any("cannot carry gravity's asymmetry" in a for a in scene_advice(full))
    t32 = full.with_overrides(n_theta=32)
    assert [a for a in scene_advice(t32) if "theta_fft" in a]
    assert scene_advice(t32.with_overrides(pressure_solver="theta_fft")) == []
    sector = full.with_overrides(sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0))
    assert scene_advice(sector) == []
    assert scene_advice(full.with_overrides(fluid_mode="prescribed")) == []
