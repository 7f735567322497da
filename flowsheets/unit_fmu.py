"""FMI 2.0 co-simulation adapters (pythonfmu) of the units in :mod:`units`, declared in
:mod:`unit_vars` (shared with the FMI 3.0 adapters, :mod:`unit_fmu3`). No process logic.

A unit FMU built by :mod:`flowsheets.build` carries this module, :mod:`unit_vars`, :mod:`units`,
millfmu's size-grid module and millfmu's FMI 2.0 base (:mod:`millfmu.fmi.base2`) (renamed,
like the mill FMU's code) and its configuration ``resources/unit.json``: the kind, the size
grid's edges [m] (the mill's grid) and the unit's parameters, so the FMU runs in any master
without parameter settings. Parameters are also FMI parameters (start = the configured
value); tunable ones may change between steps.

Values, statuses and states are the mill FMU's (the base they share): every Real has a unit
(UnitDefinitions); a mass-flow output [kg/s] is the mean over the last step; outputs depend
on no input within a step (no direct feedthrough); bad input or a refused step answers
fmi2Discard with a logged message naming the variable, the value and what is allowed, and
leaves the state as it was; a parameter value the unit refuses is fmi2Error from
fmi2ExitInitializationMode (under millfmu's fixed wrapper; logged under pythonfmu's own),
and every later step is refused; no other Python exception reaches the host.
"""

from __future__ import annotations

from xml.etree.ElementTree import Element

try:  # carried into a unit FMU, the module sits next to this one
    from .base2 import Fmi2Base
except ImportError:
    from millfmu.fmi.base2 import Fmi2Base
from .unit_vars import (ClassifierUnit, FeedUnit, PIControllerUnit, TankUnit, UnitAdapter, psd_description,
                         unit_exponents)


class UnitSlave(UnitAdapter, Fmi2Base):
    """Base adapter: a size distribution is n Reals ``name[1]`` ... ``name[n]``."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._set_up()

    def _add(self, name, unit, desc, start, causality, variability):
        vr = self._at[name] = self.declare(name, unit, causality, variability, desc, start)
        return vr

    def psd_vars(self, prefix, causality, what):
        first = len(self._v)
        for i in range(1, self.n + 1):
            start = 1.0 / self.n if causality == "input" else 0.0
            self.declare(f"{prefix}[{i}]", "1", causality, "continuous", psd_description(what, self.edges_m, i), start)
        self._at[prefix] = slice(first, first + self.n)

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus units, exact start values, output dependencies (none:
        no direct feedthrough) and InitialUnknowns."""
        return self.complete_xml(super().to_xml({} if model_options is None else model_options), unit_exponents,
                                 f"{type(self).description}; {self.n} size classes")


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
