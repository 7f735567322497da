"""Calibration of the two stress models at one reference operating point (seed 000).

Seed 000 compares two models of the specific breakage rate, each with one free constant
fitted at a reference operating point; the variations of the operating parameters are then
predictions, without refitting:

- simple model (Kwade 1999): k_c, Kwade's stress-frequency constant
  (``mill.stress_frequency_factor``: n_c/t = k_c omega n_gb);
- detailed model: eta_E, the share of a collision's energy that reaches a captured particle
  (``kinetics.energy_transfer``; the particle then receives eta_E E (1 + Y_P/Y_GM)^-1 of a
  collision of energy E from the stress-energy distribution).

The material parameters (burst energies of cells, breakage energies of minerals) are the
same for both models; the constants absorb what each model leaves out.

The datum of a fit is one batch result at the scene's own operating point: the disrupted
fraction of cells (``disrupted_fraction``) or the median size (``x50_m``) after ``t_s``
seconds. :data:`SHIPPED` lists the shipped example pairs (simple and detailed scene of one
material, one reference point) with their data; their scene files state the fitted values
and the point they were fitted at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from importlib import resources

from scipy.optimize import brentq

from .mill import MillModel
from .scene import Scene, load_scene

#: Quantities a datum may name: output key -> (whether it rises with the rates, unit).
QUANTITIES = {"disrupted_fraction": (True, "1"), "x50_m": (False, "m")}
#: The constant each model keeps free: model -> (scene section, key).
CONSTANTS = {"simple": ("mill", "stress_frequency_factor"), "detailed": ("kinetics", "energy_transfer")}
#: Bracket of a fit [-]: k_c over 12 decades; eta_E is a share, at most 1.
BRACKETS = {"simple": (1e-6, 1e6), "detailed": (1e-9, 1.0)}


@dataclass(frozen=True)
class Datum:
    """One batch result at the reference point: ``quantity`` (a key of :data:`QUANTITIES`)
    has ``value`` [its unit] after ``t_s`` [s]; ``source`` says where the number comes from."""

    quantity: str
    value: float
    t_s: float
    source: str


@dataclass(frozen=True)
class Pair:
    """A shipped calibration: the simple and the detailed scene of one material at one
    reference point (example file names; None is the embedded default scene) and the
    datum both were fitted to."""

    material: str
    simple: str | None
    detailed: str | None
    datum: Datum

    def scenes(self) -> tuple[Scene, Scene]:
        return example_scene(self.simple), example_scene(self.detailed)


#: The shipped pairs. Neither datum is a measurement of this mill: the sources hold no
#: breakage rate measured in it (seed 000's measured rates are in the part of the paper the
#: project does not have). Each stands in for the one experiment a user fits to.
SHIPPED = (
    Pair("yeast", "yeast_disruption.toml", "yeast_disruption_detailed.toml",
         Datum("disrupted_fraction", 0.80, 600.0,
               "stand-in datum: 80 % of the cells disrupted after 10 min, the result the shipped simple "
               "example gave before its burst energies were put on a physical footing")),
    Pair("limestone", "limestone_simple.toml", None,
         Datum("x50_m", 2.88e-6, 1800.0,
               "stand-in datum: x50 = 2.88 um after 30 min from the 10 um feed, the shipped simple model's "
               "result with k_c = 1, which the flowsheets were tuned with")),
)


def example_scene(name: str | None) -> Scene:
    """A shipped example scene by file name (None: the embedded default scene)."""
    if name is None:
        return load_scene(None)
    return load_scene(resources.files(__name__.rpartition(".")[0] + ".data").joinpath("examples", name))


def with_model(scene: Scene, model: str) -> Scene:
    """The scene with ``kinetics.model`` set to ``model`` ('simple' or 'detailed')."""
    return replace(scene, kinetics=replace(scene.kinetics, model=model))


def constant(scene: Scene, model: str) -> float:
    """The model's fitted constant in the scene: k_c (simple) or eta_E (detailed)."""
    sec, key = CONSTANTS[model]
    return float(getattr(getattr(scene, sec), key))


def with_constant(scene: Scene, model: str, value: float) -> Scene:
    """The scene with the model's constant set to ``value``."""
    sec, key = CONSTANTS[model]
    return replace(scene, **{sec: replace(getattr(scene, sec), **{key: float(value)})})


def batch_value(scene: Scene, quantity: str, t_s: float) -> float:
    """``quantity`` after ``t_s`` seconds of batch operation at the scene's operating point.

    One exact step with the rates frozen at that point (equal to any number of smaller steps
    to round-off). The scene must be a batch scene with the class capture probability and no
    tip-speed profile: a datum belongs to one operating point.
    """
    if quantity not in QUANTITIES:
        raise ValueError(f"datum quantity {quantity!r}: allowed {', '.join(QUANTITIES)}")
    if scene.operation.mode != "batch" or scene.run.tip_speed_profile or scene.kinetics.capture != "class":
        raise ValueError(f"scene {scene.scene.name!r}: a calibration needs a batch scene at one operating point "
                         "(no tip-speed profile, kinetics.capture = 'class')")
    out = MillModel(scene).step(float(t_s))
    if quantity not in out:
        raise ValueError(f"scene {scene.scene.name!r} has no output {quantity!r} (material {scene.material.model!r})")
    return float(out[quantity])


def fit(scene: Scene, model: str, datum: Datum, rtol: float = 1e-10) -> float:
    """The model's constant for which the scene (run with ``model``) reproduces the datum.

    Both constants move the result monotonically (k_c scales every rate; a larger share of
    the collision energy breaks more): a bracketed root search in log space. Raises
    ValueError, naming what the model reaches, when the datum lies outside the bracket
    (e.g. the detailed model with the whole collision energy, eta_E = 1, breaks less than
    the datum asks: the DEM's collisions are too few or too weak for it).
    """
    rises, _ = QUANTITIES[datum.quantity]
    base = with_model(scene, model)

    def residual(log_c):
        v = batch_value(with_constant(base, model, math.exp(log_c)), datum.quantity, datum.t_s)
        return (v - datum.value) if rises else (datum.value - v)

    lo, hi = (math.log(b) for b in BRACKETS[model])
    r_lo, r_hi = residual(lo), residual(hi)
    if r_lo > 0.0 or r_hi < 0.0:
        name = CONSTANTS[model][1]
        ends = {c: batch_value(with_constant(base, model, c), datum.quantity, datum.t_s) for c in BRACKETS[model]}
        raise ValueError(f"{model} model of {scene.scene.name!r}: {datum.quantity} = {datum.value:g} after {datum.t_s:g} s "
                         f"is out of reach; {name} = {BRACKETS[model][0]:g} gives {ends[BRACKETS[model][0]]:.6g}, "
                         f"{BRACKETS[model][1]:g} gives {ends[BRACKETS[model][1]]:.6g}")
    return math.exp(brentq(residual, lo, hi, xtol=rtol, rtol=rtol))


def check(pair: Pair, refit: bool = True) -> dict:
    """The pair's calibration: both models' results at the datum's time with the shipped
    constants, and (``refit``) the constants fitted anew, for the record and the tests."""
    simple, detailed = pair.scenes()
    d = pair.datum
    out = {
        "material": pair.material,
        "quantity": d.quantity,
        "t_s": d.t_s,
        "datum": d.value,
        "source": d.source,
        "k_c": constant(simple, "simple"),
        "energy_transfer": constant(detailed, "detailed"),
        "simple": batch_value(with_model(simple, "simple"), d.quantity, d.t_s),
        "detailed": batch_value(with_model(detailed, "detailed"), d.quantity, d.t_s),
    }
    if refit:
        out["k_c_fit"] = fit(simple, "simple", d)
        out["energy_transfer_fit"] = fit(detailed, "detailed", d)
    return out
