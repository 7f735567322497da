"""Materials and stress models: yeast disruption, the detailed model through its stress-energy interface."""

import numpy as np
import pytest
from scipy.special import ndtr

from millfmu.kinetics import rates
from millfmu.kinetics.stress_distribution import LogNormalStressSource
from millfmu.kinetics.vogel_peukert2003 import breakage_probability
from millfmu.mill import MillModel
from tests.conftest import make_scene

YEAST = {"model": "yeast", "density_kg_per_m3": 1100.0, "youngs_modulus_Pa": 1e8, "burst_energy_median_J": 2e-5,
         "burst_energy_sigma_ln": 1.0,
         "breakage": {"phi": 1.0, "gamma": 1.0, "beta": 1.0}}
CELLS = {"kind": "lognormal", "x50_m": 5e-6, "sigma_ln": 0.15}


def test_vogel_peukert_hand_calculation():
    x, w = 10e-6, 1e5
    assert breakage_probability(x, w, 0.9, 0.5) == pytest.approx(1 - np.exp(-0.9 * x * (w - 0.5 / x)))
    assert breakage_probability(x, 0.5 / x * 0.99, 0.9, 0.5) == 0.0


def test_yeast_simple_rate_is_sf_times_burst_probability(scene_dict):
    m = MillModel(make_scene(scene_dict, material=YEAST, feed=CELLS, kinetics={"model": "simple"}))
    op = m.operating_point(m.inputs)
    x = m.operator.nodes_m
    s = m.selection_nodes(op)
    p = ndtr(np.log(op.se_product_J / 2e-5) / 1.0)
    assert np.allclose(s, op.stress_frequency_per_s(x) * p, rtol=1e-13)


def test_yeast_disruption_first_order_and_tip_speed(scene_dict):
    """Monodisperse-ish cells: disrupted fraction follows 1 - exp(-k t); faster at higher tip speed."""
    out = {}
    for v in (6.0, 10.0):
        m = MillModel(make_scene(scene_dict, material=YEAST, feed={"kind": "monodisperse", "x_m": 5e-6},
                                 mill={"tip_speed_m_per_s": v}))
        k = m.class_rates_per_s()[np.argmax(m.tank_masses_kg()[0][: m.grid.n])]
        o = m.step(100.0)
        assert o["disrupted_fraction"] == pytest.approx(-np.expm1(-k * 100.0), rel=1e-10)
        assert abs(m.total_mass_kg() - m.m0_kg) <= 1e-13 * m.m0_kg
        out[v] = o["disrupted_fraction"]
    assert out[10.0] > out[6.0] > 0.0


def test_detailed_with_narrow_distribution_equals_simple(scene_dict):
    """A collision-energy distribution concentrated at SE, with Kwade's collision rate and the whole
    collision energy reaching the particle, reduces to the simple model."""
    k_c = 2.5
    s_simple = make_scene(scene_dict, mill={"stress_frequency_factor": k_c}, kinetics={"model": "simple"})
    s_det = make_scene(scene_dict, kinetics={"model": "detailed", "energy_transfer": 1.0, "stress_distribution": {
        "source": "lognormal", "median_fraction": 1.0, "sigma_ln": 1e-6, "collision_factor": k_c}})
    a, b = MillModel(s_simple), MillModel(s_det)
    ra, rb = a.class_rates_per_s(), b.class_rates_per_s()
    assert ra.max() > 10.0 * ra[ra > 0.0].min()  # rates that differ between classes
    assert np.allclose(rb, ra, rtol=1e-4, atol=1e-14)


#: The breakage energies the default scene had before its calibration on the coupled table
#: (f_Mat = 1 kg/(J m), x W_m,min = 0.2 J m/kg; assumed): below saturation on these
#: log-normal energies, so that the rates respond to the energies. The calibrated default
#: (x W_m,min = 0, f_Mat = 179.5) breaks with probability near 1 at SE-scale energies.
ASSUMED_LIMESTONE = {"f_mat_kg_per_J_m": 1.0, "x_w_min_J_m_per_kg": 0.2}


def test_energy_transfer_scales_the_collision_energies(scene_dict):
    """eta_E multiplies every collision energy: eta_E = 0.3 on a distribution gives the rates of
    eta_E = 1 on the same distribution at 0.3 times the energies."""
    sd = {"source": "lognormal", "sigma_ln": 1.2, "collision_factor": 1.0}
    mat = ASSUMED_LIMESTONE
    a = MillModel(make_scene(scene_dict, material=mat,
                             kinetics={"model": "detailed", "energy_transfer": 0.3,
                                       "stress_distribution": {**sd, "median_fraction": 0.1}}))
    b = MillModel(make_scene(scene_dict, material=mat,
                             kinetics={"model": "detailed", "energy_transfer": 1.0,
                                       "stress_distribution": {**sd, "median_fraction": 0.03}}))
    c = MillModel(make_scene(scene_dict, material=mat,
                             kinetics={"model": "detailed", "energy_transfer": 1.0,
                                       "stress_distribution": {**sd, "median_fraction": 0.1}}))
    ra, rb, rc = a.class_rates_per_s(), b.class_rates_per_s(), c.class_rates_per_s()
    assert np.allclose(ra, rb, rtol=1e-12, atol=0.0)
    assert np.all(ra <= rc) and np.any(ra < 0.5 * rc)


def test_detailed_distribution_lowers_rates_of_coarse_particles(scene_dict):
    s_det = make_scene(scene_dict, material=ASSUMED_LIMESTONE,
                       kinetics={"model": "detailed", "stress_distribution": {"source": "lognormal"}})
    a, b = MillModel(make_scene(scene_dict, material=ASSUMED_LIMESTONE, kinetics={"model": "simple"})), MillModel(s_det)
    ra, rb = a.class_rates_per_s(), b.class_rates_per_s()
    assert np.all(rb <= ra * (1 + 1e-12))
    assert rb[-10] < 0.5 * ra[-10]


def test_lognormal_source_weights():
    class Op:
        se_beads_J = 1e-5
        omega_rad_per_s = 100.0
        n_gb_per_m3 = 1e9
    (z,) = LogNormalStressSource(0.01, 1.5, 2.0).zones(Op())
    assert z.energy_weights.sum() == pytest.approx(1.0, abs=1e-15)
    med = np.exp(np.interp(0.5, np.cumsum(z.energy_weights) - z.energy_weights / 2, np.log(z.energy_J)))
    assert med == pytest.approx(1e-7, rel=0.02)
    assert z.collision_rate_per_m3_s == pytest.approx(2.0 * 100.0 * 1e9)


def test_capture_from_psd_uses_adaptive_and_conserves(scene_dict):
    m = MillModel(make_scene(scene_dict, kinetics={"capture": "psd"}))
    x50 = m.outputs()["x50_m"]
    for _ in range(3):
        o = m.step(60.0)
    assert o["x50_m"] < x50
    assert abs(m.total_mass_kg() - m.m0_kg) <= 1e-13 * m.m0_kg and m.y.min() >= 0.0


def test_rates_none_model_requires_austin():
    with pytest.raises(ValueError, match="unknown stress model"):
        rates.selection_per_s("bogus", None, None, np.ones(3))
