"""FMI 2.0 co-simulation adapters (pythonfmu) of the units in :mod:`units`. No process logic.

A unit FMU built by :mod:`flowsheets.build` carries this module, :mod:`units` and millfmu's
size-grid module (renamed, like the mill FMU's code) and its configuration
``resources/unit.json``: the kind, the size grid's edges [m] (the mill's grid) and the
unit's parameters, so the FMU runs in any master without parameter settings. Parameters are
also FMI parameters (start = the configured value); tunable ones may change between steps.

Conventions as in the mill FMU (millfmu.fmu): every Real has a unit (UnitDefinitions); a
mass-flow output [kg/s] is the mean over the last step; outputs depend on no input within a
step (no direct feedthrough); bad input or a refused step answers fmi2Discard with a logged
message naming the variable, the value and what is allowed, and leaves the state as it was;
no Python exception reaches the host.
"""

from __future__ import annotations

import json
import math
import os
import traceback
from xml.etree.ElementTree import Element

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

try:  # carried into a unit FMU, the module sits next to this one
    from .fmi_xml import complete_model_description, get_reals
except ImportError:
    from millfmu.fmi_xml import complete_model_description, get_reals
from .units import Classifier, Feed, PIController, StepDiscarded, Tank, UnitInputError

#: Name of the configuration file in the FMU's resources folder.
CONFIG_FILE = "unit.json"

#: SI base-unit exponents of the units used (FMI 2.0 BaseUnit).
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


class UnitSlave(Fmi2Slave):
    """Base adapter: values in one list indexed by value reference; subclasses declare
    variables in ``_declare`` and connect them to their core in ``_make_core``/``_step``."""

    author = "millfmu"
    kind = ""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        with open(os.path.join(self.resources, CONFIG_FILE)) as f:
            self.cfg = json.load(f)
        self.edges_m = np.asarray(self.cfg["edges_m"], float)
        self.n = len(self.edges_m) - 1
        self._v: list = []
        self._units: dict = {}
        self._vr: dict = {}
        self._params: dict = {}  # name -> (vr, tunable)
        self._config_error = None
        self._initialized = False
        self._declare()
        self._n_vars = len(self._v)
        self.core = self._make_core(self._param_values())
        self._publish()

    # ---- declaration helpers -----------------------------------------------------------
    def _add(self, name, unit, desc, start, causality, variability, initial=None, settable=False):
        vr = len(self._v)
        self._v.append(float(start))
        self.register_variable(Real(name, causality=causality, variability=variability, initial=initial, description=desc,
                                    getter=lambda vr=vr: self._v[vr], setter=(lambda x, vr=vr: self._set(vr, x)) if settable else None))
        self._units[name] = unit
        self._vr[name] = vr
        return vr

    def param(self, name, unit, desc, tunable=False):
        vr = self._add(name, unit, desc, self.cfg["params"][name], Fmi2Causality.parameter,
                       Fmi2Variability.tunable if tunable else Fmi2Variability.fixed, Fmi2Initial.exact, settable=True)
        self._params[name] = (vr, tunable)

    def input(self, name, unit, desc, start):
        self._add(name, unit, desc, start, Fmi2Causality.input, Fmi2Variability.continuous, settable=True)

    def output(self, name, unit, desc):
        self._add(name, unit, desc, 0.0, Fmi2Causality.output, Fmi2Variability.continuous)

    def psd_vars(self, prefix, causality, what):
        for i in range(1, self.n + 1):
            desc = f"{what}: mass fraction in size class {i} ({self.edges_m[i - 1]:.4g} to {self.edges_m[i]:.4g} m)"
            if causality == "input":
                self.input(f"{prefix}[{i}]", "1", desc, 1.0 / self.n)
            else:
                self.output(f"{prefix}[{i}]", "1", desc)

    def vec(self, prefix) -> np.ndarray:
        a = self._vr[f"{prefix}[1]"]
        return np.array(self._v[a : a + self.n])

    def _param_values(self) -> dict:
        return {name: self._v[vr] for name, (vr, _) in self._params.items()}

    # ---- values --------------------------------------------------------------------------
    def log(self, msg: str, status=Fmi2Status.ok, category=None, debug=None):
        # The host's logger reads the message as a printf format: escape '%'.
        super().log(msg.replace("%", "%%"), status, category, debug)

    def _set(self, vr, x):
        self._v[vr] = float(x)

    def set_real(self, vrs, values):
        for vr, x in zip(vrs, values):
            var = self.vars.get(vr)
            if var is None or var.causality not in (Fmi2Causality.input, Fmi2Causality.parameter):
                name = var.name if var is not None else f"(value reference {vr})"
                self.log(f"fmi2SetReal: {name} = {x!r} ignored: only parameters and inputs can be set", Fmi2Status.error)
                continue
            if var.causality == Fmi2Causality.parameter and self._initialized and var.variability != Fmi2Variability.tunable:
                self.log(f"fmi2SetReal: parameter {var.name} = {x!r} ignored: fixed parameters can only be set before initialization ends", Fmi2Status.error)
                continue
            self._v[vr] = float(x)

    def get_real(self, vrs):
        return get_reals(self._v, vrs, lambda msg: self.log(msg, Fmi2Status.error))

    def _publish(self):
        for name, val in self.core.outputs().items():
            if isinstance(val, np.ndarray):
                a = self._vr[f"{name}[1]"]
                self._v[a : a + self.n] = val.tolist()
            else:
                self._v[self._vr[name]] = float(val)

    # ---- life cycle ----------------------------------------------------------------------
    def exit_initialization_mode(self):
        try:
            self.core = self._make_core(self._param_values())
            self._config_error = None
            self._publish()
        except UnitInputError as e:
            self._config_error = str(e)
            self.log(f"initialization: parameter {self._config_error}; every step will be refused", Fmi2Status.error)
        except Exception:
            self._config_error = "internal error while initializing: " + traceback.format_exc(limit=3)
            self.log(self._config_error, Fmi2Status.error)
        self._initialized = True

    def do_step(self, current_time, step_size):
        try:
            if self._config_error is not None:
                self.log(f"doStep at t = {current_time!r} s refused: {self._config_error}", Fmi2Status.discard)
                return False
            if not (math.isfinite(step_size) and step_size > 0.0):
                self.log(f"doStep at t = {current_time!r} s refused: communicationStepSize = {step_size!r}: must be finite and > 0 s", Fmi2Status.discard)
                return False
            self._step(float(step_size))
        except UnitInputError as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: input {e}", Fmi2Status.discard)
            return False
        except StepDiscarded as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: {e}", Fmi2Status.discard)
            return False
        except Exception:
            self.log(f"doStep at t = {current_time!r} s failed: " + traceback.format_exc(limit=4), Fmi2Status.error)
            return False
        self._publish()
        return True

    # ---- FMU state -----------------------------------------------------------------------
    def _get_fmu_state(self):
        return {"values": list(self._v), "core": self.core.get_state(), "config_error": self._config_error,
                "initialized": self._initialized, "params": self._param_values()}

    def _set_fmu_state(self, state):
        try:
            self.core = self._make_core(state["params"])
            self.core.set_state(state["core"])
            self._v = list(state["values"])
            self._config_error, self._initialized = state["config_error"], state["initialized"]
        except Exception:
            self.log("fmi2SetFMUstate: state not applied: " + traceback.format_exc(limit=3), Fmi2Status.error)

    # ---- model description ---------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:
        """pythonfmu's description plus units, exact start values, output dependencies (none:
        no direct feedthrough) and InitialUnknowns."""
        return complete_model_description(super().to_xml(model_options), self, self._units, unit_exponents, f"{self.description}; {self.n} size classes")


# ---------------------------------------------------------------------------------------
class FeedSlave(UnitSlave):
    kind = "feed"
    description = "Feed source: solids mass flow with steps and ramps, size distribution with steps"

    def _declare(self):
        self.param("event_tolerance", "s", "a step holding a jump of the feed more than this before its end is refused (0: never)")
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


class TankSlave(UnitSlave):
    kind = "tank"
    description = "Stirred holding tank, perfectly mixed, two inlets and a pumped outlet"

    def _declare(self):
        self.param("pump_mass_flow", "kg/s", "suspension mass flow of the outlet pump (while the tank holds suspension)", tunable=True)
        self.param("pump_start_time", "s", "time from which the pump runs")
        self.param("level_setpoint", "kg", "suspension mass the pump holds by level control (0: off, fixed pump flow)")
        self.param("level_time_constant", "s", "time constant of the level control")
        self.param("initial_holdup", "kg", "solids in the tank at the start")
        self.param("initial_solids_mass_fraction", "1", "solids mass fraction of the suspension at the start")
        for k in (1, 2):
            self.input(f"inlet{k}_mass_flow", "kg/s", f"solids mass flow into inlet {k}", 0.0)
            self.input(f"inlet{k}_solids_mass_fraction", "1", f"solids mass fraction of the suspension at inlet {k}, in (0, 1)",
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
            raise UnitInputError("initial_solids_mass_fraction", p["initial_solids_mass_fraction"], "must lie in (0, 1)")
        if not p["initial_holdup"] >= 0.0:
            raise UnitInputError("initial_holdup", p["initial_holdup"], "must be >= 0 kg")
        if not (p["level_setpoint"] >= 0.0 and p["level_time_constant"] > 0.0):
            raise UnitInputError("level_setpoint, level_time_constant", (p["level_setpoint"], p["level_time_constant"]), "must be >= 0 kg and > 0 s")
        return Tank(self.edges_m, p["initial_holdup"], p["initial_solids_mass_fraction"], self.cfg["initial_psd"],
                    p["pump_mass_flow"], p["pump_start_time"], p["level_setpoint"], p["level_time_constant"])

    def _step(self, h):
        v, vr = self._v, self._vr
        pump = v[vr["pump_mass_flow"]]
        if not (math.isfinite(pump) and pump >= 0.0):
            raise UnitInputError("pump_mass_flow", pump, "must be >= 0 kg/s")
        self.core.pump = pump
        inflow = [(v[vr[f"inlet{k}_mass_flow"]], v[vr[f"inlet{k}_solids_mass_fraction"]], self.vec(f"inlet{k}_psd")) for k in (1, 2)]
        self.core.step(h, inflow)


class ClassifierSlave(UnitSlave):
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

    def _step(self, h):
        v, vr = self._v, self._vr
        cut = v[vr["cut_size"]]
        if cut != self.core.cut_size_m:
            if not (cut > 0.0 and math.isfinite(cut)):
                raise UnitInputError("cut_size", cut, "must be > 0 m")
            self.core.set_parameters(cut, self.core.sharpness, self.core.bypass)
        self.core.step(h, v[vr["feed_mass_flow"]], v[vr["feed_solids_mass_fraction"]], self.vec("feed_psd"))


class PIControllerSlave(UnitSlave):
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
        self.core.setpoint = self._v[self._vr["setpoint"]]
        self.core.step(h, self._v[self._vr["measurement"]])


SLAVES = {"feed": FeedSlave, "tank": TankSlave, "classifier": ClassifierSlave, "pi": PIControllerSlave}
