"""Schiller & Naumann (1933) drag of a single sphere: the drag law of a dilute discrete
phase model, where a particle sees no neighbours (no void fraction).

Re_p = rho d |u - v| / mu; C_D = 24 / Re_p (1 + 0.15 Re_p^0.687) for Re_p < 1000, 0.44
above; drag F = c (u - v) with c = 3 pi mu d (1 + 0.15 Re_p^0.687) [kg/s] (Re_p < 1000).
Schiller, L. & Naumann, A. (1933), Z. Ver. Dtsch. Ing. 77, 318-320; the form Fluent's
discrete phase model and most CFD-DEM codes use for an isolated sphere.

Check: a sphere settling in still liquid reaches the speed u_t at which the drag equals
its buoyant weight, (rho_p - rho_f) V g = c(u_t) u_t (:func:`terminal_speed_m_per_s`), after
the relaxation time m / c (Stokes: rho_p d^2 / (18 mu)).
"""

import math

from millfmu.dem.engine._jit import device

#: particle Reynolds number above which C_D = 0.44 (Newton's regime)
RE_NEWTON = 1000.0


@device
def drag_coefficient(d, mu, rho, urel):
    """c [kg/s] of a sphere of diameter d [m] at relative speed urel [m/s] in a liquid of
    viscosity mu [Pa s] and density rho [kg/m3]: drag c (u - v)."""
    re = rho * d * urel / mu
    if re < RE_NEWTON:
        return 3.0 * math.pi * mu * d * (1.0 + 0.15 * re ** 0.687)
    # C_D = 0.44: F = C_D pi/8 rho d^2 urel^2 = c urel
    return 0.44 * math.pi / 8.0 * rho * d * d * urel


def drag_coefficient_py(d: float, mu: float, rho: float, urel: float) -> float:
    """:func:`drag_coefficient` without numba [kg/s]."""
    re = rho * d * urel / mu
    if re < RE_NEWTON:
        return 3.0 * math.pi * mu * d * (1.0 + 0.15 * re ** 0.687)
    return 0.44 * math.pi / 8.0 * rho * d * d * urel


def terminal_speed_m_per_s(d: float, rho_p: float, rho_f: float, mu: float,
                       g: float = 9.81) -> float:
    """Settling speed [m/s] of a sphere (diameter d [m], density rho_p [kg/m3]) in still
    liquid (rho_f [kg/m3], mu [Pa s]): drag c(u) u = (rho_p - rho_f) pi/6 d^3 g, solved by
    bisection (the drag grows monotonically with u)."""
    weight = (rho_p - rho_f) * math.pi / 6.0 * d ** 3 * g
    lo, hi = 0.0, 1.0
    while drag_coefficient_py(d, mu, rho_f, hi) * hi < weight:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if drag_coefficient_py(d, mu, rho_f, mid) * mid < weight:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
