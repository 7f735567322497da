"""The mill FMU's variables, described once for every FMI version. No FMI library, no physics.

:func:`variables` lists them for a model in value-reference order. The FMI 2.0 adapter
(:mod:`millfmu.fmi.mill2`) writes a size-distribution variable as n Reals ``psd[1]`` ...
``psd[n]``; the FMI 3.0 adapter (:mod:`millfmu.fmi.mill3`) as one Float64 array whose length is
the structural parameter ``n_classes``. Units are SI; every variable has one.
"""

from __future__ import annotations

import copy
import os
import sys
from typing import NamedTuple

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np

from ..mill import PSD_SUM_TOL, MillModel
from ..scene import scene_from_dict


class HeldArray:
    """The array input a host sets value by value (psd_in): the same array object while
    its values do not change, built anew only when they do (a host passes every input at
    every step; comparing two lists costs a fraction of building an array, and the model
    remembers its check of a content). The model never writes into an input array."""

    def __init__(self):
        self._values: list | None = None
        self._array = None

    def array(self, values: list):
        """An array of ``values`` (a list of floats), the held one where they are equal."""
        if values != self._values:
            self._array = np.array(values, dtype=float)
            self._values = values
        return self._array


#: Name of the scene file in an FMU's resources folder.
SCENE_FILE = "scene.toml"
#: Prefix of the DEM table slice in the resources folder (detailed model with a table).
TABLE_PREFIX = "table"
#: The prediction band of the scene's own run (millfmu.runner.prediction_band), computed when
#: the FMU is built and stated in its description; absent where the scene has none.
BAND_FILE = "band.json"

#: Units used by the variables: name -> SI base-unit exponents (BaseUnit in FMI 2.0 and 3.0).
UNITS = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "kg": {"kg": 1},
    "kg/s": {"kg": 1, "s": -1},
    "m/s": {"m": 1, "s": -1},
    "kg/m3": {"kg": 1, "m": -3},
    "J": {"kg": 1, "m": 2, "s": -2},
    "1/s": {"s": -1},
    "W": {"kg": 1, "m": 2, "s": -3},
    "J/kg": {"m": 2, "s": -2},
    "Pa.s": {"kg": 1, "m": -1, "s": -1},
}

#: Parameters: FMI name, scene (section, key), unit, variability, description.
PARAMETERS = (
    ("bead_filling", ("mill", "bead_filling"), "1", "tunable",
     "bead filling: bulk bead volume at rest over chamber volume, in (0, 1)"),
    ("bead_diameter", ("beads", "diameter_m"), "m", "fixed", "grinding bead diameter"),
    ("bead_density", ("beads", "density_kg_per_m3"), "kg/m3", "fixed", "grinding bead density"),
    ("stress_frequency_factor", ("mill", "stress_frequency_factor"), "1", "fixed",
     "Kwade's stress-frequency constant k_c (calibration)"),
)

#: Scalar inputs: FMI name, scene (section, key), MillModel input name, unit, description, continuous only.
INPUTS = (
    ("tip_speed", ("mill", "tip_speed_m_per_s"), "tip_speed_m_per_s", "m/s", "stirrer tip speed, in [0, 40] m/s",
     False),
    ("solids_mass_fraction", ("suspension", "solids_mass_fraction"), "solids_mass_fraction", "1",
     "solids mass concentration of the suspension (mass fraction), in (0, 0.8)", False),
    ("feed_mass_flow", ("operation", "feed_mass_flow_kg_per_s"), "feed_mass_flow_kg_per_s", "kg/s",
     "solids feed mass flow, >= 0", True),
)

#: Scalar outputs: FMI name, MillModel output key, unit, description.
OUTPUTS = (
    ("x10", "x10_m", "m", "size with 10 % of the product mass below it"),
    ("x50", "x50_m", "m", "median size of the product (by mass)"),
    ("x90", "x90_m", "m", "size with 90 % of the product mass below it"),
    ("holdup", "holdup_kg", "kg", "solids mass in the mill"),
    ("product_mass_flow", "product_mass_flow_kg_per_s", "kg/s",
     "solids product mass flow, mean over the last step (0 in batch)"),
    ("se_beads", "se_beads_J", "J", "stress energy of the beads SE = pi/12 d^3 rho v_t^2"),
    ("se_product", "se_product_J", "J", "stress energy reaching the product SE_P"),
    ("sf", "sf_per_s", "1/s", "stress frequency at x50"),
    ("stress_number", "stress_number", "1", "stress number: SF integrated over time"),
    ("power", "power_W", "W", "stirrer power"),
    ("specific_energy", "specific_energy_J_per_kg", "J/kg", "stirrer energy per mass of solids treated"),
    ("eta_eff", "eta_eff_Pa_s", "Pa.s", "effective viscosity of the bead-suspension bulk (Krieger-Dougherty)"),
    ("reynolds", "reynolds", "1", "mill Reynolds number"),
    ("below_grid", "below_grid_fraction", "1",
     "product mass fraction below the size grid's lowest edge (part of the finest class's)"),
)
DISRUPTED = ("disrupted_fraction", "disrupted_fraction", "1", "mass fraction of disrupted cells (debris) in the mill")

#: Size distributions, one value per size class: FMI name, unit, description ("{i}": the class).
PSD_IN = ("psd_in", "1", f"feed mass fraction in size class {{i}} (all sum to 1 within {PSD_SUM_TOL:g})")
PSD = ("psd", "1", "product mass fraction in size class {i} (batch: mill content; continuous: outlet)")

#: FMI 3.0's structural parameter: the length of the size-distribution arrays.
CLASS_COUNT = ("n_classes", "number of size classes: the length of psd and psd_in (fixed by the scene's size grid)")


class Variable(NamedTuple):
    """One FMI variable of the mill FMU."""

    name: str  # FMI name (an array's base name: "psd")
    unit: str  # a key of UNITS
    causality: str  # "parameter", "input" or "output"
    variability: str  # "fixed", "tunable" or "continuous"
    description: str  # an array's has "{i}" where the class number goes
    start: object  # float, or a list of floats for an array
    size: int  # 0 for a scalar, else the number of size classes
    settable: tuple | None  # ("param", scene key) or ("input", MillModel input name); None for outputs
    scene_key: tuple | None  # (section, key) when the value is a scene value
    output_key: str | None  # MillModel output key of an output


def variables(model) -> list:
    """The variables of the FMU of ``model`` (a MillModel at its scene's operating point), in
    value-reference order: parameters, scalar inputs, psd_in (continuous scenes), psd, scalar
    outputs. A batch mill has no feed, so its FMU has no feed inputs that would do nothing."""
    scene, inputs, n = model.scene, model.inputs, model.grid.n
    out = [Variable(name, unit, "parameter", var, desc, float(getattr(getattr(scene, sec), key)), 0, ("param", key),
                    (sec, key), None)
           for name, (sec, key), unit, var, desc in PARAMETERS]
    out += [Variable(name, unit, "input", "continuous", desc, float(inputs[mkey]), 0, ("input", mkey), (sec, key), None)
            for name, (sec, key), mkey, unit, desc, cont_only in INPUTS if model.continuous or not cont_only]
    if model.continuous:
        out.append(Variable(*PSD_IN[:2], "input", "continuous", PSD_IN[2], [float(x) for x in inputs["psd_in"]], n,
                            ("input", "psd_in"), None, None))
    out.append(Variable(*PSD[:2], "output", "continuous", PSD[2], [0.0] * n, n, None, None, "psd"))
    outs = OUTPUTS + ((DISRUPTED,) if "disrupted_fraction" in model.outputs() else ())
    out += [Variable(name, unit, "output", "continuous", desc, 0.0, 0, None, None, key)
            for name, key, unit, desc in outs]
    return out


def read_scene_dict(resources: str) -> dict:
    """An FMU's scene (``<resources>/scene.toml``) as a dict; a DEM table it reads is the
    slice the build put into the resources (``<resources>/table.npz`` and ``.json``)."""
    with open(os.path.join(resources, SCENE_FILE), "rb") as f:
        d = tomllib.load(f)
    sd = d.get("kinetics", {}).get("stress_distribution", {})
    if sd.get("source") == "table":
        sd["table"] = os.path.join(resources, TABLE_PREFIX)
    return d


def model_with(scene_dict: dict, over: dict) -> MillModel:
    """The model of the scene ``scene_dict`` with ``over`` {(section, key): value} applied;
    SceneError naming the scene key when the scene (or its DEM table) refuses a value. The
    model runs without the DEM (``no_dem``): a point outside the carried table is refused,
    never built."""
    d = copy.deepcopy(scene_dict)
    for (sec, key), x in over.items():
        d.setdefault(sec, {})[key] = x
    return MillModel(scene_from_dict(d, SCENE_FILE), no_dem=True)


def plain(x):
    """JSON-able deep copy: arrays to lists of Python floats (repr round-trips exactly)."""
    if hasattr(x, "tolist"):
        return x.tolist()
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    return x


def read_band(resources: str) -> dict | None:
    """The prediction band the build wrote into the FMU's resources (None where absent)."""
    import json

    try:
        with open(os.path.join(resources, BAND_FILE), encoding="utf-8") as f:
            return json.load(f)
    except OSError:
        return None


def band_text(band: dict) -> str:
    """The band of the scene's own run in words (x50 [m], or the disrupted fraction), whole
    and per part."""
    key, unit = ("disrupted_fraction", "") if "disrupted_fraction" in band["outputs"] else ("x50_m", " m")

    def rng(outputs):
        lo, hi = outputs[key]
        return f"[{lo:.4g}, {hi:.4g}]{unit}"

    parts = ", ".join(f"{name} {rng(p['outputs'])}" for name, p in band["parts"].items())
    sources = {"table": "the table's stated error", "calibration": "the fitted constants' 95 % intervals"}
    whence = " and ".join(sources.get(name, name) for name in band["parts"])
    return (f"; prediction band of the scene's own run at t = {band['t_s']:g} s: {key} in {rng(band['outputs'])} "
            f"({parts}; from {whence})")


def model_description_text(base: str, scene, n_classes: int, table=None, band: dict | None = None) -> str:
    """The FMU's description: what it is, the scene, the stress-energy table it carries
    (``table``: the model's, identified by its manifest), what the scene's constants were
    fitted to (``scene.calibration``) and the prediction band of the scene's own run
    (``band``, :func:`read_band`). Shared by FMI 2 and 3."""
    text = (f"{base}; scene {scene.scene.name!r}, {scene.operation.mode}, {scene.kinetics.model} model, {n_classes} "
            "size classes")
    if table is not None:
        m = table.manifest
        dem = m.get("scene") or {}
        fluid = (dem.get("fluid") or {}).get("mode", "?")
        text += (f"; stress energies from the DEM table {str(m.get('key', '?'))[:12]} ({dem.get('name', '?')}, fluid "
                 f"{fluid}, component {scene.kinetics.stress_distribution.component})")
    if scene.scene.calibration:
        text += f"; calibration: {scene.scene.calibration}"
    if band is not None:
        text += band_text(band)
    return text
