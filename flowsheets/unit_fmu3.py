"""FMI 3.0 co-simulation adapters (pythonfmu3) of the units in :mod:`units`, declared in
:mod:`unit_vars` (shared with the FMI 2.0 adapters, :mod:`unit_fmu`). No process logic.

A unit FMU built by ``flowsheets.build`` with FMI version 3 carries this module,
:mod:`unit_vars`, :mod:`units`, millfmu's size-grid module and millfmu's FMI 3.0 base
(:mod:`millfmu.fmi.base3`), its configuration ``resources/unit.json`` and pythonfmu3's
wrapper with millfmu's fixes. The variables are those of the FMI 2.0 unit FMU, all Float64
with units, plus ``time`` and the structural parameter ``n_classes``: every size
distribution is one array of ``n_classes`` values.

Statuses as in the FMI 3.0 mill FMU (millfmu.fmi.mill3): bad input or a refused step (the feed
holding a jump of its profile) is fmi3Discard from ``fmi3DoStep`` with the state unchanged;
a parameter value the unit refuses is fmi3Error from ``fmi3ExitInitializationMode`` (and
from every later step); illegal calls are fmi3Error (millfmu.fmi.base3).
"""

from __future__ import annotations

import math
from xml.etree.ElementTree import Element

import numpy as np

try:  # carried into a unit FMU, the module sits next to this one
    from .base3 import Fmi3Base
except ImportError:
    from millfmu.fmi.base3 import Fmi3Base
from .unit_vars import ClassifierUnit, FeedUnit, PIControllerUnit, TankUnit, psd_description, read_config, unit_exponents
from .units import StepDiscarded, UnitInputError


class UnitSlave3(Fmi3Base):
    """Base adapter: the unit classes of :mod:`unit_vars` declare the variables with
    param/input/output/psd_vars and read them with value/vec."""

    kind = ""
    REFUSED = (UnitInputError, StepDiscarded)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.cfg = read_config(self.resources)
        self.edges_m = np.asarray(self.cfg["edges_m"], float)
        self.n = len(self.edges_m) - 1
        self._at: dict = {}  # variable name -> position (a slice for an array) in the value list
        self._params: dict = {}  # name -> position in the value list
        self._declare()
        self.register_used_units(unit_exponents)
        self.core = self._make_core(self._param_values())
        self._publish()

    # ---- declaration helpers -----------------------------------------------------------
    def _add(self, name, unit, desc, start, causality, variability, array=False):
        s = self._slices[self.declare(name, unit, causality, variability, desc, start, array)]
        self._at[name] = s if array else s.start
        return s.start

    def param(self, name, unit, desc, tunable=False):
        self._params[name] = self._add(name, unit, desc, self.cfg["params"][name], "parameter", "tunable" if tunable else "fixed")

    def input(self, name, unit, desc, start):
        self._add(name, unit, desc, start, "input", "continuous")

    def output(self, name, unit, desc):
        self._add(name, unit, desc, 0.0, "output", "continuous")

    def psd_vars(self, prefix, causality, what):
        if self._vr_n is None:  # the structural parameter, before the first array (the PI controller has none)
            self.declare_class_count(self.n, "number of size classes: the length of the size-distribution arrays (the mill's grid)")
        start = [1.0 / self.n] * self.n if causality == "input" else [0.0] * self.n
        self._add(prefix, "1", psd_description(what, self.edges_m), start, causality, "continuous", array=True)

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
        try:
            self.core = self._make_core(self._param_values())
        except UnitInputError as e:
            self.refuse_configuration(f"parameter {e}")
        self._config_error = None
        self._publish()

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

    # ---- model description -------------------------------------------------------------
    def to_xml(self, model_options=None) -> Element:
        return self.complete_xml(super().to_xml({} if model_options is None else model_options), f"{self.description}; {self.n} size classes")


# ---------------------------------------------------------------------------------------
class FeedSlave3(FeedUnit, UnitSlave3):
    pass


class TankSlave3(TankUnit, UnitSlave3):
    pass


class ClassifierSlave3(ClassifierUnit, UnitSlave3):
    pass


class PIControllerSlave3(PIControllerUnit, UnitSlave3):
    pass


SLAVES = {"feed": FeedSlave3, "tank": TankSlave3, "classifier": ClassifierSlave3, "pi": PIControllerSlave3}
