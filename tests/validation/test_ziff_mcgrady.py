"""Closed-form solutions of the continuous breakage equation (Ziff & McGrady 1985), reached through scenes.

Binary breakage with fragments uniform in volume, b(v|u) = 2/u, has the cumulative mass
breakage function B = (v/u)^2 = (x/y)^6: Austin's form with phi = 1, gamma = 6. A rate
proportional to particle volume, S = k v, is Austin's selection with alpha = 3; to its
square, alpha = 6. With v in units of v_ref = x_ref^3 and an exponential initial number
density c0(v) = exp(-v), the number densities at tau = k t are
    S = k v:   c(v, tau) = (1 + tau)^2 exp(-v (1 + tau)),
    S = k v^2: c(v, tau) = exp(-v - tau v^2) (1 + 2 tau (1 + v)),
and the mass in a class is the integral of v c over it.

For S = k v^2 the discrete operator is exact in the class masses: the mass moved from a
parent of volume u into class i is S(u) u c(u) (v_{i+1}^2 - v_i^2)/u^2 = k (v_{i+1}^2 - v_i^2)
times the parent's mass density, and the loss from class j is k v_j^2 times its mass,
neither depending on how the mass is distributed inside the class. The numerical solution
must then equal the closed form to round-off at every resolution.
"""


import numpy as np
import pytest
from scipy.integrate import quad

from millfmu.kinetics.grid import SizeGrid
from millfmu.mill import MillModel
from tests.conftest import make_scene

X_REF = 10e-6  # m
K = 0.01  # 1/s
V_MIN, V_MAX = 1e-5, 40.0


def mass_density(v, tau, p):
    if p == 1:
        return v * (1 + tau) ** 2 * np.exp(-v * (1 + tau))
    return v * np.exp(-v - tau * v * v) * (1 + 2 * tau * (1 + v))


def class_masses(edges_v, tau, p):
    m = np.array([quad(mass_density, a, b, args=(tau, p), epsabs=0, epsrel=1e-13, limit=200)[0]
                  for a, b in zip(edges_v[:-1], edges_v[1:])])
    m[0] += quad(mass_density, 0.0, edges_v[0], args=(tau, p), epsabs=0, epsrel=1e-13)[0]
    return m


def scene_for(scene_dict, p, classes_per_octave):
    x_min = X_REF * V_MIN ** (1 / 3)
    x_max = X_REF * V_MAX ** (1 / 3)
    grid = SizeGrid.geometric(x_min, x_max, classes_per_octave)
    ev = (grid.edges_m / X_REF) ** 3
    q3 = np.array([quad(mass_density, 0.0, v, args=(0.0, p), epsabs=0, epsrel=1e-13)[0] for v in ev])
    q3 = np.minimum(q3 / q3[-1], 1.0)
    s = make_scene(
        scene_dict,
        material={"model": "austin", "breakage": {"phi": 1.0, "gamma": 6.0, "beta": 6.0},
                  "selection": {"a_per_s": K, "x0_m": X_REF, "alpha": 3.0 * p, "Lambda": 0.0}},
        kinetics={"model": "none"},
        grid={"x_min_m": x_min, "x_max_m": x_max, "classes_per_octave": float(classes_per_octave)},
        feed={"kind": "table", "sizes_m": grid.edges_m.tolist(), "Q3": q3.tolist()},
    )
    return s, grid


def error_at(scene_dict, p, cpo, tau):
    s, grid = scene_for(scene_dict, p, cpo)
    m = MillModel(s, grid=grid)
    m.step(tau / K)
    num = m.tank_masses_kg()[0] / m.y.sum()
    # class_masses puts what lies below the grid into the finest class: so does the psd.
    num = np.r_[num[0] + num[-1], num[1:-1]]
    ev = (grid.edges_m / X_REF) ** 3
    exact = class_masses(ev, tau, p)
    # Tail beyond v_max: the same share at t = 0 was folded into the top class.
    exact /= exact.sum()
    return np.abs(num - exact).sum(), m


def test_convergence_to_closed_form_rate_proportional_to_volume(scene_dict, record_property):
    p, tau = 1, 2.0
    cpos = [2, 4, 8, 16]
    errs = [error_at(scene_dict, p, c, tau)[0] for c in cpos]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    record_property("errors", errs)
    record_property("orders", orders.tolist())
    print(f"S ~ v^{p}: L1 mass error at tau={tau} for {cpos} classes/octave: {errs}; orders {orders}")
    assert errs[-1] < 2e-3
    assert np.all(orders > 1.8), orders


def test_exact_for_rate_proportional_to_volume_squared(scene_dict):
    errs = [error_at(scene_dict, 2, c, tau)[0] for c in (2, 4, 8, 16) for tau in (0.5, 2.0, 10.0)]
    print(f"S ~ v^2: L1 mass errors {errs}")
    assert max(errs) < 1e-13


@pytest.mark.parametrize("p", [1, 2])
def test_closed_form_mass_conserved(scene_dict, p):
    _, m = error_at(scene_dict, p, 4, 5.0)
    assert m.y.min() >= 0.0
    assert abs(m.total_mass_kg() - m.m0_kg) <= 1e-13 * m.m0_kg
