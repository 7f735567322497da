"""Koch & Hill (2001) drag in the CFDEM form (project REFERENCE, "Koch-Hill drag"): the
interphase momentum coefficient beta of a bead in a suspension of void fraction eps. The
DEM's one definition of the law; the coupled exchange (:mod:`millfmu.dem.coupling`) and
the prescribed swirl (:func:`millfmu.dem.engine.kernels.body_force`) both take it from here.

phi = 1 - eps; Re_p = d eps |u - v| rho / mu;
F0 = (1 + 3 sqrt(phi/2) + 135/64 phi ln phi + 16.14 phi) /
     (1 + 0.681 phi - 8.48 phi^2 + 8.16 phi^3)  for phi < 0.4, else 10 phi / eps^3;
F3 = 0.0673 + 0.212 phi + 0.0232 / eps^5;  F = eps (F0 + 0.5 F3 Re_p);
beta = 18 mu eps F / d^2 [kg/(m3 s)]; drag on the bead V_p beta (u - v) ("model A").
Koch, D. L. & Hill, R. J. (2001), Annu. Rev. Fluid Mech. 33, 619-647.

Two evaluations of the law, one per user:
- per bead at its local void fraction (the coupled exchange): :func:`f0_f3` and
  :func:`beta`, compiled into the exchange's kernels;
- at the one void fraction of a prescribed swirl: :func:`f0_f3_python` once per run, in
  Python, and :func:`beta_of_terms` per bead in the force loop.
They round differently: the powers of phi and eps are products in the kernels and the C
library's pow in Python's ``**``, and beta's factors are grouped ((18 mu eps) eps) (F0 +
0.5 F3 Re_p) per bead but (18 mu eps) (eps (F0 + 0.5 F3 Re_p)) in the swirl. The DEM is
chaotic, so a force changed in its last bit is another trajectory, and each path's
results are fixed to the bit by the tables' kernel version
(:data:`millfmu.dem.tables.cache.SAME_DEM_AS`): neither evaluation is rewritten as the
other without a new version.
"""

import math

from millfmu.dem.engine._jit import device, inlined


@inlined
def f0_f3(eps):
    """The void-fraction terms F0, F3 [-] at void fraction eps [-] (0 < eps <= 1)."""
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


def f0_f3_python(void_fraction: float) -> tuple[float, float]:
    """F0, F3 [-] at ``void_fraction`` [-] in plain Python (no numba): the prescribed
    swirl's terms, set once per run in the parameter vector (``P_KH_F0``, ``P_KH_F3``) and
    completed per bead by :func:`beta_of_terms`."""
    eps = void_fraction
    phi = 1.0 - eps
    if phi < 0.4:
        lg = phi * math.log(phi) if phi > 0 else 0.0
        f0 = (1.0 + 3.0 * math.sqrt(phi / 2.0) + 135.0 / 64.0 * lg + 16.14 * phi) / (
            1.0 + 0.681 * phi - 8.48 * phi ** 2 + 8.16 * phi ** 3)
    else:
        f0 = 10.0 * phi / eps ** 3
    f3 = 0.0673 + 0.212 * phi + 0.0232 / eps ** 5
    return f0, f3


@device
def beta_of_terms(d, eps, mu_f, rho_f, urel, f0, f3):
    """beta [kg/(m3 s)] from the void-fraction terms f0, f3 [-] of
    :func:`f0_f3_python`: d the bead diameter [m], eps the void fraction [-], mu_f [Pa s],
    rho_f [kg/m3], urel = |U_f - U_p| [m/s]. A CUDA twin of it serves the GPU's force
    kernel (:mod:`millfmu.dem.engine.gpu`)."""
    re = d * eps * urel * rho_f / mu_f
    ff = eps * (f0 + 0.5 * f3 * re)
    return 18.0 * mu_f * eps * ff / (d * d)
