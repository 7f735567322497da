"""Wet restitution after Legendre, Zenit, Daniel & Guiraud (2006): the restitution of a
collision in a liquid falls with its Stokes number as

    e / e_dry = exp(-35 / St),   St = m* v / (6 pi eta R*^2),

their fit to the immersed sphere-wall collisions of Joseph, Zenit, Hunt & Rosenwinkel
(2001) and Gondret, Lance & Petit (2002) (St with the sphere's mass and radius), which
head-on collisions of two spheres follow too with the pair's reduced mass and radius
(Yang & Hunt 2006). v is the approach speed before the liquid film slows it; the curve
includes the film's damping, so the DEM applies it instead of the lubrication force
between close beads (``[fluid] wet_collisions = "legendre2006"``, lubrication off), not on
top of it.

Legendre, D., Zenit, R., Daniel, C. & Guiraud, P. (2006), Chem. Eng. Sci. 61, 3543-3549;
Joseph, G. G. et al. (2001), J. Fluid Mech. 433, 329-346; Gondret, P. et al. (2002), Phys.
Fluids 14, 643-652; Yang, F.-L. & Hunt, M. L. (2006), Phys. Fluids 18, 121506.

How the DEM applies it: at a contact's first overlap the normal approach speed gives St
(the pair's m* and R*; at a wall the bead's mass and radius) and e = e_dry exp(-35 / St);
the contact keeps that restitution until it opens, as a level 1..255 of e / e_dry in the
contact's flag (0 meaning "no contact"; :data:`LEVELS` steps of 1/254), whose damping
ratio beta = ln e / sqrt(ln^2 e + pi^2) the parameter vector holds (:func:`beta_table`).
Level 1 (e below 0.4 % of e_dry) is taken as e = 0, beta = -1, the critically damped
contact.
"""

import math

import numpy as np

from millfmu.dem.engine._jit import contact
from millfmu.dem.engine.params import damping_beta_of

#: the curve's Stokes number scale: e / e_dry = exp(-ST_SCALE / St) [-]
ST_SCALE = 35.0
#: steps of e / e_dry a contact's flag holds: level = 1 + round(LEVELS e / e_dry)
LEVELS = 254


def restitution_ratio(stokes: float) -> float:
    """e / e_dry [-] at Stokes number ``stokes`` [-] (0 at St <= 0)."""
    return math.exp(-ST_SCALE / stokes) if stokes > 0.0 else 0.0


def beta_table(e_dry: float) -> np.ndarray:
    """beta [-] of each contact level (index 1..255: e = e_dry (level - 1) / LEVELS; index 0,
    no contact, unused), 256 entries for the parameter vector."""
    out = np.zeros(LEVELS + 2)
    for lev in range(1, LEVELS + 2):
        out[lev] = damping_beta_of(e_dry * (lev - 1) / LEVELS)
    return out


@contact
def contact_level(vn_abs, mstar, rstar, eta, st_scale):
    """The level (1..255, :data:`LEVELS`) of e / e_dry = exp(-st_scale / St) of a contact
    that opens at normal approach speed vn_abs [m/s], reduced mass mstar [kg] and radius
    rstar [m], in a liquid of viscosity eta [Pa s]."""
    st = mstar * vn_abs / (6.0 * math.pi * eta * rstar * rstar)
    if st <= 0.0:
        return np.uint8(1)
    return np.uint8(1 + int(math.exp(-st_scale / st) * LEVELS + 0.5))
