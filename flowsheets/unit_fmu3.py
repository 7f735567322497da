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

from xml.etree.ElementTree import Element

try:  # carried into a unit FMU, the module sits next to this one
    from .base3 import Fmi3Base
except ImportError:
    from millfmu.fmi.base3 import Fmi3Base
from .unit_vars import (ClassifierUnit, FeedUnit, PIControllerUnit, TankUnit, UnitAdapter, psd_description,
                         unit_exponents)


class UnitSlave3(UnitAdapter, Fmi3Base):
    """Base adapter: a size distribution is one Float64 array of ``n_classes`` values."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._set_up()
        self.register_used_units(unit_exponents)

    def _add(self, name, unit, desc, start, causality, variability, array=False):
        s = self._slices[self.declare(name, unit, causality, variability, desc, start, array)]
        self._at[name] = s if array else s.start
        return s.start

    def psd_vars(self, prefix, causality, what):
        if self._vr_n is None:  # the structural parameter, before the first array (the PI controller has none)
            self.declare_class_count(self.n,
                                     "number of size classes: the length of the size-distribution arrays (the mill's "
                                     "grid)")
        start = [1.0 / self.n] * self.n if causality == "input" else [0.0] * self.n
        self._add(prefix, "1", psd_description(what, self.edges_m), start, causality, "continuous", array=True)

    def to_xml(self, model_options=None) -> Element:
        return self.complete_xml(super().to_xml({} if model_options is None else model_options),
                                 f"{self.description}; {self.n} size classes")


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
