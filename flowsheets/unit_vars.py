"""The flowsheet units' FMI variables and their connection to the unit cores, for every FMI
version. No FMI library, no process logic (that is :mod:`units`).

Each unit class declares its variables with the adapter's helpers (``param``, ``input``,
``output``, ``psd_vars``), builds its core from the parameters (``_make_core``) and steps it
with the current inputs (``_step``, reading values with ``value`` and ``vec``).
:class:`UnitAdapter` connects them to the FMI bases of millfmu (``millfmu.fmi.base2`` and
``base3``), whose values, statuses and states the unit FMUs share with the mill FMU. The
FMI 2.0 adapter (:mod:`unit_fmu`) writes a size distribution as n Reals ``psd[1]`` ...
``psd[n]``, the FMI 3.0 adapter (:mod:`unit_fmu3`) as one Float64 array of ``n_classes``
values.
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

from .units import Classifier, Feed, PIController, StepDiscarded, Tank, UnitInputError, checked_fractions

#: SI base-unit exponents of the units used (BaseUnit in FMI 2.0 and 3.0).
BASE_UNITS = {
    "1": {}, "m": {"m": 1}, "s": {"s": 1}, "kg": {"kg": 1}, "kg/s": {"kg": 1, "s": -1}, "m/s": {"m": 1, "s": -1},
}


def unit_exponents(name: str) -> dict:
    """Base-unit exponents of a unit name: a BASE_UNITS name, or '(A)/(B.C)' of such names."""
    if name in BASE_UNITS:
        return dict(BASE_UNITS[name])
    if not (name.startswith("(") and ")/(" in name and name.endswith(")")):
        raise KeyError(name)
    num, den = name[1:-1].split(")/(")
    out = unit_exponents(num)
    for part in den.split("."):
        for k, v in unit_exponents(part).items():
            out[k] = out.get(k, 0) - v
    return {k: v for k, v in out.items() if v}


def psd_description(what: str, edges_m, i: int | None = None) -> str:
    """Description of a size-distribution variable: of class ``i`` (1-based; FMI 2.0's
    scalars), or of the whole array (FMI 3.0)."""
    if i is None:
        return (f"{what}: mass fraction in size class i = 1..{len(edges_m) - 1} ({edges_m[0]:.4g} to "
                f"{edges_m[-1]:.4g} m, the mill's grid)")
    return f"{what}: mass fraction in size class {i} ({edges_m[i - 1]:.4g} to {edges_m[i]:.4g} m)"


#: Name of the configuration file in a unit FMU's resources folder.
CONFIG_FILE = "unit.json"


def read_config(resources: str) -> dict:
    """A unit FMU's configuration (``<resources>/unit.json``): kind, edges_m, params, ..."""
    with open(os.path.join(resources, CONFIG_FILE)) as f:
        return json.load(f)


# ---------------------------------------------------------------------------------------
class UnitAdapter:
    """What a unit's FMU does in every FMI version, on top of the version's base (which
    gives ``_v``, the value list, ``refuse_configuration`` and the statuses): the
    configuration, the unit's variables by name, its core built from the parameters and
    stepped with the inputs, and its part of the FMU state.

    The version's adapter provides ``_add(name, unit, description, start, causality,
    variability) -> position`` and ``psd_vars``, which put a size distribution's positions
    in ``_at`` as one slice of the value list.
    """

    kind = ""
    #: Exceptions of a step that refuse it (discard): the state is unchanged.
    REFUSED = (UnitInputError, StepDiscarded)

    def _set_up(self):
        """Read ``unit.json``, declare the variables and build the core at the configured parameters."""
        self.cfg = read_config(self.resources)
        self.edges_m = np.asarray(self.cfg["edges_m"], float)
        self.n = len(self.edges_m) - 1
        self._at: dict = {}  # variable name -> position (a slice for a size distribution) in the value list
        self._params: dict = {}  # parameter name -> position in the value list
        self._declare()
        self.core = self._make_core(self._param_values())
        self._publish()

    # ---- declaration helpers -----------------------------------------------------------
    def param(self, name, unit, desc, tunable=False):
        self._params[name] = self._add(name, unit, desc, self.cfg["params"][name], "parameter",
                                       "tunable" if tunable else "fixed")

    def input(self, name, unit, desc, start):
        self._add(name, unit, desc, start, "input", "continuous")

    def output(self, name, unit, desc):
        self._add(name, unit, desc, 0.0, "output", "continuous")

    # ---- values ------------------------------------------------------------------------
    def value(self, name) -> float:
        return self._v[self._at[name]]

    def vec(self, prefix) -> np.ndarray:
        return np.array(self._v[self._at[prefix]])

    def _param_values(self) -> dict:
        return {name: self._v[at] for name, at in self._params.items()}

    def _publish(self):
        for name, val in self.core.outputs().items():
            self._v[self._at[name]] = val.tolist() if isinstance(val, np.ndarray) else float(val)

    # ---- life cycle --------------------------------------------------------------------
    def _configure(self):
        """The core at the parameters set before initialization ended; a value the unit
        refuses is refused by name (the base's ``refuse_configuration``)."""
        try:
            core = self._make_core(self._param_values())
        except UnitInputError as e:
            self.refuse_configuration(f"parameter {e}")
        self.core = core
        self._config_error = None
        self._start_from_inputs()
        self._publish()

    def _start_from_inputs(self):
        """What a unit's start outputs take from the inputs set before initialization ended
        (the master sets a connected input from its sender's start output); nothing by default."""

    def _take_step(self, h):
        if not (math.isfinite(h) and h > 0.0):
            raise UnitInputError("communicationStepSize", h, "must be finite and > 0 s")
        self._step(float(h))
        self._publish()

    def _refusal(self, e: Exception) -> str:
        return f"input {e}" if isinstance(e, UnitInputError) else str(e)

    # ---- FMU state ---------------------------------------------------------------------
    def _state(self) -> dict:
        return {"core": self.core.get_state(), "params": self._param_values()}

    def _restore(self, state: dict):
        core = self._make_core(state["params"])
        core.set_state(state["core"])
        self.core = core


# ---------------------------------------------------------------------------------------
class FeedUnit:
    kind = "feed"
    description = "Feed source: solids mass flow with steps and ramps, size distribution with steps"

    def _declare(self):
        self.param("event_tolerance", "s",
                   "a step holding a jump of the feed more than this before its end is refused (0: never)")
        self.output("mass_flow", "kg/s", "solids mass flow, mean over the last step")
        self.output("solids_mass_fraction", "1", "solids mass fraction of the fed suspension")
        self.psd_vars("psd", "output", "feed over the last step")
        self.output("x50", "m", "median size of the feed over the last step")
        self.output("mass_total", "kg", "solids fed since the start")

    def _make_core(self, p):
        c = self.cfg
        return Feed(self.edges_m, c["profile"], c["psd_segments"], c["solids_mass_fraction"], p["event_tolerance"])

    def _step(self, h):
        self.core.step(h)


class TankUnit:
    kind = "tank"
    description = "Stirred holding tank, perfectly mixed, two inlets and a pumped outlet"

    def _declare(self):
        self.param("pump_mass_flow", "kg/s",
                   "suspension mass flow of the outlet pump (while the tank holds suspension)", tunable=True)
        self.param("pump_start_time", "s", "time from which the pump runs")
        self.param("level_setpoint", "kg", "suspension mass the pump holds by level control (0: off, fixed pump flow)")
        self.param("level_time_constant", "s", "time constant of the level control")
        self.param("initial_holdup", "kg", "solids in the tank at the start")
        self.param("initial_solids_mass_fraction", "1", "solids mass fraction of the suspension at the start")
        for k in (1, 2):
            self.input(f"inlet{k}_mass_flow", "kg/s", f"solids mass flow into inlet {k}", 0.0)
            self.input(f"inlet{k}_solids_mass_fraction", "1",
                       f"solids mass fraction of the suspension at inlet {k}, in (0, 1)",
                       self.cfg["params"]["initial_solids_mass_fraction"])
            self.psd_vars(f"inlet{k}_psd", "input", f"inlet {k}")
        self.output("outflow_mass_flow", "kg/s", "solids mass flow out of the outlet, mean over the last step")
        self.output("solids_mass_fraction", "1", "solids mass fraction of the tank's suspension")
        self.psd_vars("psd", "output", "outflow over the last step")
        self.output("holdup", "kg", "solids in the tank")
        self.output("suspension_mass", "kg", "suspension (solids and liquid) in the tank")
        self.output("x50", "m", "median size of the tank's content")

    def _make_core(self, p):
        if not (math.isfinite(p["pump_mass_flow"]) and p["pump_mass_flow"] >= 0.0):
            raise UnitInputError("pump_mass_flow", p["pump_mass_flow"], "must be >= 0 kg/s")
        if not 0.0 < p["initial_solids_mass_fraction"] < 1.0:
            raise UnitInputError("initial_solids_mass_fraction", p["initial_solids_mass_fraction"],
                                 "must lie in (0, 1)")
        if not p["initial_holdup"] >= 0.0:
            raise UnitInputError("initial_holdup", p["initial_holdup"], "must be >= 0 kg")
        if not (p["level_setpoint"] >= 0.0 and p["level_time_constant"] > 0.0):
            raise UnitInputError("level_setpoint, level_time_constant", (p["level_setpoint"], p["level_time_constant"]),
                                 "must be >= 0 kg and > 0 s")
        return Tank(self.edges_m, p["initial_holdup"], p["initial_solids_mass_fraction"], self.cfg["initial_psd"],
                    p["pump_mass_flow"], p["pump_start_time"], p["level_setpoint"], p["level_time_constant"])

    def _step(self, h):
        value = self.value
        pump = value("pump_mass_flow")
        if not (math.isfinite(pump) and pump >= 0.0):
            raise UnitInputError("pump_mass_flow", pump, "must be >= 0 kg/s")
        self.core.pump = pump
        inflow = [(value(f"inlet{k}_mass_flow"), value(f"inlet{k}_solids_mass_fraction"), self.vec(f"inlet{k}_psd"))
                  for k in (1, 2)]
        self.core.step(h, inflow)


class ClassifierUnit:
    kind = "classifier"
    description = "Classifier without holdup: Tromp curve with cut size, sharpness and bypass"

    def _declare(self):
        self.param("cut_size", "m", "cut size x_t: T(x_t) = bypass + (1 - bypass)/2", tunable=True)
        self.param("sharpness", "1", "sharpness kappa of T = bypass + (1 - bypass)/(1 + (x_t/x)^kappa)")
        self.param("bypass", "1", "fraction of the feed reaching the coarse stream unclassified, in [0, 1)")
        self.param("liquid_to_coarse", "1", "fraction of the feed's liquid leaving with the coarse stream, in [0, 1]")
        self.input("feed_mass_flow", "kg/s", "solids mass flow into the classifier", 0.0)
        self.input("feed_solids_mass_fraction", "1", "solids mass fraction of the feed suspension, in (0, 1)", 0.2)
        self.psd_vars("feed_psd", "input", "classifier feed")
        for s in ("coarse", "fine"):
            self.output(f"{s}_mass_flow", "kg/s", f"solids mass flow of the {s} stream, mean over the last step")
            self.output(f"{s}_solids_mass_fraction", "1", f"solids mass fraction of the {s} stream")
            self.psd_vars(f"{s}_psd", "output", f"{s} stream over the last step")
            self.output(f"{s}_x50", "m", f"median size of the {s} stream")

    def _make_core(self, p):
        if not (p["cut_size"] > 0.0 and math.isfinite(p["cut_size"])):
            raise UnitInputError("cut_size", p["cut_size"], "must be > 0 m")
        if not p["sharpness"] > 0.0:
            raise UnitInputError("sharpness", p["sharpness"], "must be > 0")
        if not 0.0 <= p["bypass"] < 1.0:
            raise UnitInputError("bypass", p["bypass"], "must lie in [0, 1)")
        if not 0.0 <= p["liquid_to_coarse"] <= 1.0:
            raise UnitInputError("liquid_to_coarse", p["liquid_to_coarse"], "must lie in [0, 1]")
        return Classifier(self.edges_m, p["cut_size"], p["sharpness"], p["bypass"], p["liquid_to_coarse"])

    def _start_from_inputs(self):
        try:
            psd = checked_fractions("feed_psd", self.vec("feed_psd"), self.n, UnitInputError)
        except UnitInputError:
            return  # the first step refuses it by name
        self.core.await_feed(psd)

    def _step(self, h):
        value = self.value
        cut = value("cut_size")
        if cut != self.core.cut_size_m:
            if not (cut > 0.0 and math.isfinite(cut)):
                raise UnitInputError("cut_size", cut, "must be > 0 m")
            self.core.set_parameters(cut, self.core.sharpness, self.core.bypass)
        self.core.step(h, value("feed_mass_flow"), value("feed_solids_mass_fraction"), self.vec("feed_psd"))


class PIControllerUnit:
    kind = "pi"
    description = "PI controller with output limits and anti-windup (conditional integration)"

    def _declare(self):
        mu, ou = self.cfg["measurement_unit"], self.cfg["output_unit"]
        self.param("setpoint", mu, "setpoint of the measurement", tunable=True)
        self.param("kp", f"({ou})/({mu})", "proportional gain")
        self.param("ki", f"({ou})/({mu}.s)", "integral gain")
        self.param("u_min", ou, "lower output limit")
        self.param("u_max", ou, "upper output limit")
        self.param("bias", ou, "output at zero error and zero integral (the initial output)")
        self.param("direction", "1", "+1: direct acting (e = setpoint - measurement); -1: reverse acting")
        self.input("measurement", mu, "measured value (held over the step)", self.cfg["params"]["setpoint"])
        self.output("output", ou, "controller output, clamped to [u_min, u_max]")
        self.output("error", mu, "control error e = direction (setpoint - measurement)")
        self.output("integral", ou, "integral part of the output")
        self.output("saturated", "1", "1 while the output is clamped, else 0")

    def _make_core(self, p):
        if p["direction"] not in (1.0, -1.0):
            raise UnitInputError("direction", p["direction"], "must be +1 or -1")
        return PIController(p["setpoint"], p["kp"], p["ki"], p["u_min"], p["u_max"], p["bias"], p["direction"])

    def _step(self, h):
        self.core.setpoint = self.value("setpoint")
        self.core.step(h, self.value("measurement"))
