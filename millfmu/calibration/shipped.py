"""Seed 000's one-datum calibration and the shipped calibrated pairs.

The one-datum case (one value, one constant: the exact solution, no interval) is seed 000's
calibration of the two stress models at one reference point: the simple model's k_c
(``mill.stress_frequency_factor``) and the detailed model's eta_E
(``kinetics.energy_transfer``); :func:`fit` and :data:`SHIPPED` keep that interface. The
detailed model's material constant of each pair is fitted to a stand-in curve with
:func:`millfmu.calibration.calibrate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from importlib import resources

from ..scene import Scene, load_scene, number_key
from .fitting import Predictor, calibrate
from .measured import Data, read_data

#: The package whose ``examples`` folder holds the shipped scenes and data.
_DATA = __package__.rpartition(".")[0] + ".data"

#: Quantities a datum may name: output key -> (whether it rises with the rates, unit).
QUANTITIES = {"disrupted_fraction": (True, "1"), "x50_m": (False, "m")}
#: The constant each model keeps free: model -> (scene section, key).
CONSTANTS = {"simple": ("mill", "stress_frequency_factor"), "detailed": ("kinetics", "energy_transfer")}


@dataclass(frozen=True)
class Datum:
    """One batch result at the reference point: ``quantity`` (a key of :data:`QUANTITIES`)
    has ``value`` [its unit] after ``t_s`` [s]; ``source`` says where the number comes from."""

    quantity: str
    value: float
    t_s: float
    source: str

    def data(self) -> Data:
        return Data("disrupted" if self.quantity == "disrupted_fraction" else "sizes",
                    ((float(self.t_s), self.quantity, None, float(self.value)),), self.source)


@dataclass(frozen=True)
class Pair:
    """A shipped calibration: the simple and the detailed scene of one material at one
    reference point (example file names; None is the embedded default scene), the datum the
    simple model's k_c was fitted to, and the stand-in curve (``data``, a file in
    millfmu/data/examples; the datum is one of its points) the detailed model's material
    constant ``detailed_key`` was fitted to with eta_E at its bound 1."""

    material: str
    simple: str | None
    detailed: str | None
    datum: Datum
    data: str
    detailed_key: str

    def scenes(self) -> tuple[Scene, Scene]:
        return example_scene(self.simple), example_scene(self.detailed)

    def data_path(self):
        return resources.files(_DATA).joinpath("examples", self.data)


#: The shipped pairs. Neither datum nor curve is a measurement of this mill: the sources hold
#: no breakage rate measured in it (seed 000's measured rates are in the part of the paper
#: the project does not have). Each stands in for the experiment a user fits to.
SHIPPED = (
    Pair("yeast", "yeast_disruption.toml", "yeast_disruption_detailed.toml",
         Datum("disrupted_fraction", 0.80, 600.0,
               "stand-in datum: 80 % of the cells disrupted after 10 min, the result the shipped simple "
               "example gave before its burst energies were put on a physical footing"),
         "yeast_standin_batch.csv", "material.burst_energy_median_J"),
    # The default scene is the simple model of the limestone pair; its detailed model is the
    # example at the same reference point.
    Pair("limestone", None, "limestone_detailed.toml",
         Datum("x50_m", 2.88e-6, 1800.0,
               "stand-in datum: x50 = 2.88 um after 30 min from the 10 um feed, the shipped simple model's "
               "result with k_c = 1 and the earlier assumed breakage energies, which the flowsheets were tuned with"),
         "limestone_standin_batch.csv", "material.f_mat_kg_per_J_m"),
)


def example_scene(name: str | None) -> Scene:
    """A shipped example scene by file name (None: the embedded default scene)."""
    if name is None:
        return load_scene(None)
    return load_scene(resources.files(_DATA).joinpath("examples", name))


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
    """``quantity`` after ``t_s`` seconds of batch operation at the scene's operating point
    (one exact step with the rates frozen there, equal to any number of smaller steps to
    round-off)."""
    if quantity not in QUANTITIES:
        raise ValueError(f"datum quantity {quantity!r}: allowed {', '.join(QUANTITIES)}")
    d = Datum(quantity, math.nan, t_s, "")
    return float(Predictor(scene, d.data(), check_sizes=False).values(scene)[0])


def fit(scene: Scene, model: str, datum: Datum, key: str | None = None) -> float:
    """The constant (default: the model's, k_c or eta_E) for which the scene run with
    ``model`` reproduces the datum: :func:`calibrate` with one value and one constant.
    Raises :class:`CalibrationError` (a ValueError) naming what the model reaches when the
    datum is out of reach."""
    base = with_model(scene, model)
    key = key or ".".join(CONSTANTS[model])
    return calibrate(base, datum.data(), [key]).value(key)


def check(pair: Pair, refit: bool = True) -> dict:
    """The pair's calibration, for the record and the tests: both models' results at the
    datum's time with the shipped constants; with ``refit`` the simple model's k_c fitted
    anew to the datum and the detailed model's material constant to the stand-in curve
    (value and 95 % interval)."""
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
        "detailed_key": pair.detailed_key,
        "detailed_constant": number_key(detailed, pair.detailed_key),
        "detailed_data": pair.data,
        "simple": batch_value(with_model(simple, "simple"), d.quantity, d.t_s),
        "detailed": batch_value(with_model(detailed, "detailed"), d.quantity, d.t_s),
    }
    if refit:
        out["k_c_fit"] = fit(simple, "simple", d)
        with resources.as_file(pair.data_path()) as path:
            c = calibrate(detailed, read_data(path), [pair.detailed_key])
        f = c.constants[pair.detailed_key]
        out["detailed_constant_fit"] = f.value
        out["detailed_constant_ci95"] = list(f.ci95) if f.ci95 else None
        out["detailed_rms_residual"] = c.rms_residual
    return out

