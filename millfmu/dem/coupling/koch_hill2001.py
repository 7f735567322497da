"""Koch & Hill (2001) drag in the CFDEM form (project REFERENCE, "Koch-Hill drag"): the
interphase momentum coefficient beta of a bead in a suspension of local void fraction eps.

phi = 1 - eps; Re_p = d eps |u - v| rho / mu;
F0 = (1 + 3 sqrt(phi/2) + 135/64 phi ln phi + 16.14 phi) /
     (1 + 0.681 phi - 8.48 phi^2 + 8.16 phi^3)  for phi < 0.4, else 10 phi / eps^3;
F3 = 0.0673 + 0.212 phi + 0.0232 / eps^5;  F = eps (F0 + 0.5 F3 Re_p);
beta = 18 mu eps F / d^2 [kg/(m3 s)]; drag on the bead V_p beta (u - v) ("model A").
Koch, D. L. & Hill, R. J. (2001), Annu. Rev. Fluid Mech. 33, 619-647.

The same law with a constant void fraction drives the prescribed swirl
(:func:`millfmu.dem.engine.kernels.koch_hill_beta` with F0, F3 from
:func:`millfmu.dem.engine.params.koch_hill_f0_f3`); here eps varies per bead.
"""

import math

from millfmu.dem.engine._jit import inlined, serial


@inlined
def f0_f3(eps):
    """The void-fraction terms F0, F3 [-] at void fraction eps."""
    phi = 1.0 - eps
    if phi < 0.4:
        lg = phi * math.log(phi) if phi > 0.0 else 0.0
        f0 = (1.0 + 3.0 * math.sqrt(phi / 2.0) + 135.0 / 64.0 * lg + 16.14 * phi) / (
            1.0 + 0.681 * phi - 8.48 * phi * phi + 8.16 * phi * phi * phi)
    else:
        f0 = 10.0 * phi / (eps * eps * eps)
    e2 = eps * eps
    f3 = 0.0673 + 0.212 * phi + 0.0232 / (e2 * e2 * eps)
    return f0, f3


@inlined
def beta(d, eps, mu, rho, urel):
    """beta [kg/(m3 s)] of a bead of diameter d [m] at void fraction eps [-] and relative
    speed urel [m/s] in a liquid of viscosity mu [Pa s] and density rho [kg/m3]."""
    f0, f3 = f0_f3(eps)
    re = d * eps * urel * rho / mu
    return 18.0 * mu * eps * eps * (f0 + 0.5 * f3 * re) / (d * d)


#: Beyond this interval / relaxation-time ratio a bead's held drag would overshoot: the
#: coefficient is then the exact one of drag-only relaxation over the interval.
STIFF_RATIO = 0.5


@serial
def bead_coefficients(rad, mass, eps_b, urel, mu, rho, interval, model_b, out):
    """Drag coefficient c_i = V_i beta_i [kg/s] per bead for a coupling interval of
    ``interval`` [s]: beta at the bead's local void fraction eps_b and relative speed urel
    [m/s], divided by eps in model B. The force c_i (u - v_i) is held over the interval;
    where the bead's relaxation time m_i / c_i is shorter than interval / STIFF_RATIO (a
    viscous suspension; never water with sub-millimetre beads at 5e-5 s) a held force
    would overshoot, and c_i is replaced by m_i (1 - exp(-x)) / interval, x = interval c_i
    / m_i, the exact mean drag of a bead relaxing under drag alone. Returns the largest x
    (a stiffness diagnostic)."""
    xmax = 0.0
    for i in range(rad.size):
        d = 2.0 * rad[i]
        vol = math.pi / 6.0 * d * d * d
        b = beta(d, eps_b[i], mu, rho, urel[i])
        if model_b:
            b /= eps_b[i]
        c = vol * b
        x = interval * c / mass[i]
        if x > xmax:
            xmax = x
        if x > STIFF_RATIO:
            c = mass[i] * (1.0 - math.exp(-x)) / interval
        out[i] = c
    return xmax
