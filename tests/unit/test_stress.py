"""Stress model and suspension formulas against hand calculations, seed 001's numbers, scaling laws."""

import math

import numpy as np
import pytest

from millfmu.kinetics import stress
from millfmu.kinetics.rates import OperatingPoint


def test_stress_energy_hand_calculation():
    # pi/12 * (0.8e-3)^3 * 2510 * 10^2 = 3.3644e-5 J
    assert stress.stress_energy_beads_J(0.8e-3, 2510.0, 10.0) == pytest.approx(math.pi / 12 * 5.12e-10 * 2510 * 100,
                                                                               rel=1e-14)
    assert stress.stress_energy_beads_J(0.8e-3, 2510.0, 10.0) == pytest.approx(3.36444e-5, rel=1e-5)


def test_stress_energy_at_product_elasticity_factor():
    assert stress.stress_energy_product_J(2.0, 1.0, 1.0) == pytest.approx(1.0)
    assert stress.stress_energy_product_J(2.0, 0.0, 1.0) == pytest.approx(2.0)
    assert stress.stress_energy_product_J(3.0, 2.0, 1.0) == pytest.approx(1.0)


def test_bead_number_and_collision_rate():
    n_gb = stress.bead_number_concentration_per_m3(0.8, 0.4, 0.8e-3)
    assert n_gb == pytest.approx(0.48 / (math.pi / 6 * 0.8e-3**3), rel=1e-14)
    om = stress.angular_velocity_rad_per_s(10.0, 0.036)
    assert om == pytest.approx(277.777777, rel=1e-6)
    assert stress.collision_rate_per_m3_s(om, n_gb, 2.0) == pytest.approx(2 * om * n_gb)


def test_capture_probability_and_stress_frequency_hand_calculation():
    x, d = 10e-6, 0.8e-3
    v_act = stress.active_volume_m3(x, d)
    assert v_act == pytest.approx(math.pi / 4 * 1e-10 * 8e-4)
    assert stress.capture_probability(1e12, v_act) == pytest.approx(1e12 * v_act)
    assert stress.capture_probability(1e20, v_act) == 1.0
    sf = stress.stress_frequency_per_s(1e11, 1e12, 0.5, 0.8, 0.4)
    assert sf == pytest.approx(1e11 * 0.5 / (1e12 * 0.52))


def test_seed001_effective_density_viscosity_and_reynolds():
    """Seed 001: 80 % filling, eps 0.4, glass in water: rho_eff 1724, eta_eff 0.225, Re 263 ... 614."""
    rho = stress.effective_density_kg_per_m3(0.8, 0.4, 2510.0, 998.2)
    assert round(rho) == 1724
    eta = stress.krieger_dougherty_viscosity_Pa_s(1.002e-3, stress.bead_volume_fraction(0.8, 0.4))
    assert round(eta, 3) == 0.225
    re = [stress.mill_reynolds_number(rho, eta, v, 0.036) for v in (6, 8, 10, 12, 14)]
    assert [round(r) for r in re] == [263, 351, 438, 526, 614]


def test_krieger_dougherty_limits():
    assert stress.krieger_dougherty_viscosity_Pa_s(1e-3, 0.0) == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="c_v"):
        stress.krieger_dougherty_viscosity_Pa_s(1e-3, 0.64)


def test_power_zero_at_rest_and_positive_otherwise():
    assert stress.stirrer_power_W(1700, 0.2, 0.0, 0.036, 5, 100, 0.1) == 0.0
    p = stress.stirrer_power_W(1700, 0.2, 10.0, 0.036, 5, 100, 0.1)
    n = 10 / (2 * math.pi * 0.036)
    re = stress.mill_reynolds_number(1700, 0.2, 10.0, 0.036)
    assert p == pytest.approx(5 * (100 / re + 0.1) * 1700 * n**3 * 0.072**5)


def _op(**kw):
    base = dict(tip_speed_m_per_s=10.0, filling=0.8, porosity=0.4, r_stirrer_m=0.036, d_gb_m=0.8e-3,
                rho_gb_kg_per_m3=2510.0,
                y_gb_Pa=63e9, y_p_Pa=70e9, rho_p_kg_per_m3=2710.0, rho_l_kg_per_m3=998.2, eta_susp_Pa_s=1e-3,
                solids_mass_fraction=0.2, k_c=1.0)
    base.update(kw)
    return OperatingPoint(**base)


@pytest.mark.parametrize("seed", range(5))
def test_scaling_stress_energy(seed):
    rng = np.random.default_rng(seed)
    v, d, rho = rng.uniform(1, 20), rng.uniform(1e-4, 3e-3), rng.uniform(1000, 7000)
    f = rng.uniform(1.1, 3.0)
    se = stress.stress_energy_beads_J(d, rho, v)
    assert stress.stress_energy_beads_J(d, rho, f * v) == pytest.approx(f**2 * se, rel=1e-12)
    assert stress.stress_energy_beads_J(f * d, rho, v) == pytest.approx(f**3 * se, rel=1e-12)
    assert stress.stress_energy_beads_J(d, f * rho, v) == pytest.approx(f * se, rel=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_scaling_stress_number(seed):
    """SN ~ n t / d^2 while P_cap < 1 (Kwade 1999), and ~ n t / d^3 when every contact captures one particle."""
    rng = np.random.default_rng(seed)
    f, g = rng.uniform(1.1, 3.0), rng.uniform(1.1, 2.0)
    x = 300e-6  # coarse: n_p V_act < 1
    op = _op(solids_mass_fraction=0.05)
    sn = float(op.stress_frequency_per_s(x)) * 10.0
    assert float(stress.capture_probability(op.class_number_concentration_per_m3(x),
                                            stress.active_volume_m3(x, op.d_gb_m))) < 1.0
    sn_v = float(_op(solids_mass_fraction=0.05, tip_speed_m_per_s=10.0 * f).stress_frequency_per_s(x)) * 10.0
    sn_t = float(op.stress_frequency_per_s(x)) * 10.0 * f
    sn_d = float(_op(solids_mass_fraction=0.05, d_gb_m=0.8e-3 * g).stress_frequency_per_s(x)) * 10.0
    assert sn_v == pytest.approx(f * sn, rel=1e-12)
    assert sn_t == pytest.approx(f * sn, rel=1e-12)
    assert sn_d == pytest.approx(sn / g**2, rel=1e-12)
    x = 5e-6  # fine: P_cap = 1
    sn = float(op.stress_frequency_per_s(x))
    sn_d = float(_op(solids_mass_fraction=0.05, d_gb_m=0.8e-3 * g).stress_frequency_per_s(x))
    assert sn_d == pytest.approx(sn / g**3, rel=1e-12)
