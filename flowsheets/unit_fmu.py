"""FMI 2.0 co-simulation adapters (pythonfmu) of the units in :mod:`units`, declared in
:mod:`unit_vars` (shared with the FMI 3.0 adapters, :mod:`unit_fmu3`). No process logic.

A unit FMU built by :mod:`flowsheets.build` carries this module, :mod:`unit_vars`, :mod:`units` and millfmu's
size-grid module (renamed, like the mill FMU's code) and its configuration
``resources/unit.json``: the kind, the size grid's edges [m] (the mill's grid) and the
unit's parameters, so the FMU runs in any master without parameter settings. Parameters are
also FMI parameters (start = the configured value); tunable ones may change between steps.

Conventions as in the mill FMU (millfmu.fmi.mill2): every Real has a unit (UnitDefinitions); a
mass-flow output [kg/s] is the mean over the last step; outputs depend on no input within a
step (no direct feedthrough); bad input or a refused step answers fmi2Discard with a logged
message naming the variable, the value and what is allowed, and leaves the state as it was;
no Python exception reaches the host.
"""

from __future__ import annotations

import math
import traceback
from xml.etree.ElementTree import Element

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

try:  # carried into a unit FMU, the module sits next to this one
    from .base2 import complete_model_description, get_reals
except ImportError:
    from millfmu.fmi.base2 import complete_model_description, get_reals
from .unit_vars import ClassifierUnit, FeedUnit, PIControllerUnit, TankUnit, psd_description, read_config, unit_exponents
from .units import StepDiscarded, UnitInputError


class UnitSlave(Fmi2Slave):
    """Base adapter: values in one list indexed by value reference; subclasses declare
    variables in ``_declare`` and connect them to their core in ``_make_core``/``_step``."""

    author = "millfmu"
    kind = ""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.cfg = read_config(self.resources)
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
            desc = psd_description(what, self.edges_m, i)
            if causality == "input":
                self.input(f"{prefix}[{i}]", "1", desc, 1.0 / self.n)
            else:
                self.output(f"{prefix}[{i}]", "1", desc)

    def value(self, name) -> float:
        return self._v[self._vr[name]]

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
    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus units, exact start values, output dependencies (none:
        no direct feedthrough) and InitialUnknowns."""
        return complete_model_description(super().to_xml({} if model_options is None else model_options), self, self._units, unit_exponents, f"{type(self).description}; {self.n} size classes")


# ---------------------------------------------------------------------------------------
class FeedSlave(FeedUnit, UnitSlave):
    pass


class TankSlave(TankUnit, UnitSlave):
    pass


class ClassifierSlave(ClassifierUnit, UnitSlave):
    pass


class PIControllerSlave(PIControllerUnit, UnitSlave):
    pass


SLAVES = {"feed": FeedSlave, "tank": TankSlave, "classifier": ClassifierSlave, "pi": PIControllerSlave}
