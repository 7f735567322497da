"""FMI 2.0 co-simulation adapter (pythonfmu): FMI variables <-> :class:`MillModel`. No physics.

The FMU built by ``millfmu build-fmu`` carries this package (renamed, see ``fmu_build``) and
its scene (``resources/scene.toml``). Variables (all Real, SI units):

- parameters: ``bead_filling`` [1] (tunable, held over each step), ``bead_diameter`` [m],
  ``bead_density`` [kg/m3], ``stress_frequency_factor`` [1] (fixed);
- inputs: ``tip_speed`` [m/s], ``solids_mass_fraction`` [1]; continuous scenes also
  ``feed_mass_flow`` [kg/s] and ``psd_in[1..n]`` [1] (a batch mill has no feed, so a batch
  FMU has no feed inputs that would silently do nothing);
- outputs: ``psd[1..n]`` [1], ``x10``/``x50``/``x90`` [m], ``holdup`` [kg],
  ``product_mass_flow`` [kg/s], ``se_beads``/``se_product`` [J], ``sf`` [1/s],
  ``stress_number`` [1], ``power`` [W], ``specific_energy`` [J/kg], ``eta_eff`` [Pa.s],
  ``reynolds`` [1], ``below_grid`` [1] and, for yeast, ``disrupted_fraction`` [1].

Values set before ``fmi2ExitInitializationMode`` are the scene's operating point (the initial
holdup depends on filling and solids fraction); values set later are inputs held over the
next step. Outputs are the model's values at the end of the last step; an input acts only
through the next step (no direct feedthrough).

Bad input or a failed step refuses ``fmi2DoStep`` with fmi2Discard, logs a message naming
the variable and the value, and leaves the state as it was. Parameters the model refuses
at fmi2ExitInitializationMode, a currentCommunicationPoint that is not the FMU's time (the
start time plus the model's time) and a damaged or foreign state are fmi2Error; values,
statuses, states and the model description's completion are those of the FMI 2.0 base
that the flowsheets' unit FMUs share (:mod:`millfmu.fmi.base2`).
"""

from __future__ import annotations

from xml.etree.ElementTree import Element

from pythonfmu import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from .base2 import Fmi2Base
from .mill_adapter import MillAdapter
from .variables import UNITS, HeldArray, model_description_text, read_band, variables

#: The slave class of each FMU script by model identifier (see fmu_build.build.SCRIPT): the
#: script runs at every fmi2Instantiate, and this keeps it to one class per process.
SCRIPT_CLASSES: dict = {}


class MillSlave(MillAdapter, Fmi2Base):
    """The mill as a pythonfmu slave; the scene is ``<resources>/scene.toml``."""

    WARNING = Fmi2Status.warning

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        scene = self._start_model()
        n = self.model.grid.n
        self.n_classes = n
        # type(self): pythonfmu's __init__ set the instance's description to None.
        self._model_description = model_description_text(type(self).description, scene, n,
                                                         getattr(self.model.source, "table", None),
                                                         read_band(self.resources))
        run = scene.run
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=run.t_end_s, step_size=run.dt_s)

        # One description of the variables (millfmu.fmi.variables) serves FMI 2.0 and 3.0;
        # here an array is n Reals name[1] ... name[n].
        self._scene_key: dict = {}  # vr -> (section, key) for values that are scene values
        self._vr_param, self._vr_in, self._psd_in_vr0 = {}, {}, None
        self._psd_in = HeldArray()
        described = variables(self.model)
        for var in described:
            if var.size:
                first = len(self._v)
                for i, x in enumerate(var.start, 1):
                    self.declare(f"{var.name}[{i}]", var.unit, var.causality, var.variability,
                                 var.description.format(i=i), x)
                if var.name == "psd_in":
                    self._psd_in_vr0 = first
                else:
                    self._out_vr0 = first
                continue
            vr = self.declare(var.name, var.unit, var.causality, var.variability, var.description, var.start)
            if var.scene_key:
                self._scene_key[vr] = var.scene_key
            if var.causality == "parameter":
                self._vr_param[var.name] = vr
            elif var.causality == "input":
                self._vr_in[var.settable[1]] = vr
        self._out_keys = [var.output_key for var in described if var.causality == "output" and not var.size]
        self._n_vars = len(self._v)
        self._publish(self.model.outputs())
        for w in self.model.warnings:
            self.log(f"scene {scene.scene.name!r}: {w}", Fmi2Status.warning)

    # ---- values ----------------------------------------------------------------------------
    def _publish(self, outs: dict):
        """Copy the model's outputs into the value list."""
        a = self._out_vr0
        n = self.n_classes
        self._v[a : a + n] = outs["psd"].tolist()
        self._v[a + n : self._n_vars] = [float(outs[k]) for k in self._out_keys]

    def _inputs(self) -> dict:
        v = self._v
        inp = {mkey: v[vr] for mkey, vr in self._vr_in.items()}
        inp["bead_filling"] = v[self._vr_param["bead_filling"]]
        if self._psd_in_vr0 is not None:
            a = self._psd_in_vr0
            inp["psd_in"] = self._psd_in.array(v[a : a + self.n_classes])
        return inp

    def _input_name(self, model_name: str) -> str:
        if model_name == "bead_filling":
            return "bead_filling"
        if model_name in self._vr_in:
            return self.vars[self._vr_in[model_name]].name
        if model_name == "psd_in":
            return f"psd_in[1..{self.n_classes}]"
        return model_name

    def _scene_value_name(self, key: str) -> str:
        return next((self.vars[vr].name for vr, sk in self._scene_key.items() if f"{sk[0]}.{sk[1]}" == key), key)

    def _time(self) -> float:
        return self._start_time + self.model.t_s

    # ---- model description -----------------------------------------------------------------
    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description completed with units, exact start values, output
        dependencies and InitialUnknowns (see :meth:`Fmi2Base.complete_xml`)."""
        return self.complete_xml(super().to_xml({} if model_options is None else model_options), UNITS.__getitem__,
                                 self._model_description)
