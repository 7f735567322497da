"""FMI 3.0 co-simulation adapter (pythonfmu3): FMI variables <-> :class:`MillModel`. No physics.

The FMU built by ``millfmu build-fmu --fmi-version 3`` carries this package (renamed, see
``fmu_build``), its scene (``resources/scene.toml``) and pythonfmu3's wrapper with millfmu's
fixes. The variables are those of the FMI 2.0 FMU (one description:
:mod:`millfmu.fmi.variables`), all Float64 with SI units, plus FMI 3.0's independent
variable ``time`` [s] and the structural parameter ``n_classes``: the size distributions
``psd_in`` (continuous scenes) and ``psd`` are arrays of ``n_classes`` values.

Values set before ``fmi3ExitInitializationMode`` are the scene's operating point; later ones
are inputs held over the next step; outputs are the model's at the end of the last step (no
direct feedthrough). Statuses, as FMI 3.0 intends them:

- fmi3Discard from ``fmi3DoStep``: an input value the model refuses (named with its value and
  what is allowed) or a step it cannot take; the state is unchanged and the master may retry;
- fmi3Error: an illegal call (see :mod:`millfmu.fmi.base3`); a parameter value the scene
  refuses, from ``fmi3ExitInitializationMode`` (and from every step after it); a state from
  another FMU given to ``fmi3SetFMUState``; the instance stays usable.
"""

from __future__ import annotations

from xml.etree.ElementTree import Element

from pythonfmu3 import DefaultExperiment, Fmi3Status

from .base3 import Fmi3Base
from .mill_adapter import MillAdapter
from .variables import CLASS_COUNT, UNITS, HeldArray, model_description_text, read_band, variables


class MillSlave3(MillAdapter, Fmi3Base):
    """The mill as a pythonfmu3 slave; the scene is ``<resources>/scene.toml``."""

    WARNING = Fmi3Status.warning

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        scene = self._start_model()
        n = self.model.grid.n
        self._model_description = model_description_text(self.description, scene, n,
                                                         getattr(self.model.source, "table", None),
                                                         read_band(self.resources))
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=scene.run.t_end_s,
                                                    step_size=scene.run.dt_s)

        # One description of the variables (millfmu.fmi.variables) serves FMI 2.0 and 3.0;
        # here an array is one Float64 of n_classes values.
        self.declare_class_count(n, CLASS_COUNT[1], CLASS_COUNT[0])
        described = variables(self.model)
        self._scene_key = {}  # position in the value list -> (section, key)
        self._in = {}  # MillModel input name -> position (a slice for psd_in) in the value list
        self._psd_in = HeldArray()
        for var in described:
            desc = var.description.format(i=f"i = 1..{n}") if var.size else var.description
            s = self._slices[self.declare(var.name, var.unit, var.causality, var.variability, desc, var.start,
                                          array=bool(var.size))]
            if var.scene_key:
                self._scene_key[s.start] = var.scene_key
            if var.settable and var.settable[0] == "input":
                self._in[var.settable[1]] = s if var.size else s.start
            if var.name == "bead_filling":  # a tunable parameter, held over each step like an input
                self._in["bead_filling"] = s.start
            if var.output_key == "psd":
                self._out = slice(s.start, None)  # psd, then the scalar outputs to the end of the list
        self._names = {var.settable[1]: var.name for var in described if var.settable}  # MillModel name -> FMI name
        self._scene_names = {".".join(var.scene_key): var.name for var in described
                             if var.scene_key}  # "section.key" -> FMI name
        self._out_keys = [var.output_key for var in described if var.causality == "output" and not var.size]
        self.register_used_units(UNITS.__getitem__)
        self._publish(self.model.outputs())

    # ---- values ------------------------------------------------------------------------
    def _publish(self, outs: dict):
        """Copy the model's outputs into the value list."""
        self._v[self._out] = outs["psd"].tolist() + [float(outs[k]) for k in self._out_keys]

    def _inputs(self) -> dict:
        v = self._v
        return {k: (self._psd_in.array(v[at]) if isinstance(at, slice) else v[at]) for k, at in self._in.items()}

    def _input_name(self, model_name: str) -> str:
        return self._names.get(model_name, model_name)

    def _scene_value_name(self, key: str) -> str:
        return self._scene_names.get(key, key)

    # ---- model description -------------------------------------------------------------
    def to_xml(self, model_options=None) -> Element:
        return self.complete_xml(super().to_xml({} if model_options is None else model_options),
                                 self._model_description)
