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
  ``reynolds`` [1] and, for yeast, ``disrupted_fraction`` [1].

Values set before ``fmi2ExitInitializationMode`` are the scene's operating point (the initial
holdup depends on filling and solids fraction); values set later are inputs held over the
next step. Outputs are the model's values at the end of the last step; an input acts only
through the next step (no direct feedthrough).

Bad input or a failed step refuses ``fmi2DoStep`` with fmi2Discard, logs a message naming
the variable and the value, and leaves the state as it was. No Python exception leaves
``do_step``/``get_real``/``set_real`` (pythonfmu turns one into fmi2Fatal).
"""

from __future__ import annotations

import copy
import traceback
from xml.etree.ElementTree import Element

import numpy as np
from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

from .fmi_xml import complete_model_description, get_reals
# The variable tables live in fmu_variables (shared with the FMI 3.0 adapter); re-exported here.
from .fmu_variables import (DISRUPTED, INPUTS, OUTPUTS, PARAMETERS, SCENE_FILE, TABLE_PREFIX, UNITS,  # noqa: F401
                            model_with, plain as _plain, read_scene_dict, variables)
from .mill import InputError, MillModel, StepError
from .scene import SceneError, scene_from_dict


class MillSlave(Fmi2Slave):
    """The mill as a pythonfmu slave; the scene is ``<resources>/scene.toml``."""

    author = "millfmu"
    description = "Wet stirred media mill (bead mill): population balance with Kwade's stress model"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._scene_dict = read_scene_dict(self.resources)
        scene = scene_from_dict(self._scene_dict, SCENE_FILE)
        self.model = MillModel(scene)
        self._overrides: dict = {}
        self._config_error: str | None = None
        self._initialized = False
        n = self.model.grid.n
        self.n_classes = n
        self._base_scene = scene
        # type(self): pythonfmu's __init__ set the instance's description to None.
        self._model_description = f"{type(self).description}; scene {scene.scene.name!r}, {scene.operation.mode}, {scene.kinetics.model} model, {n} size classes"
        run = scene.run
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=run.t_end_s, step_size=run.dt_s)

        # Every value lives in one list indexed by value reference: get_real is then one
        # list lookup per value, which keeps the per-step cost near pythonfmu's floor.
        self._v: list = []
        self._units: dict = {}
        self._settable: dict = {}  # vr -> (kind, key)
        self._scene_key: dict = {}  # vr -> (section, key) for values that are scene values

        def add(name, unit, desc, start, causality, variability, initial=None, settable=None, scene_key=None):
            vr = len(self._v)
            self._v.append(float(start))
            self.register_variable(Real(name, causality=causality, variability=variability, initial=initial, description=desc,
                                        getter=lambda vr=vr: self._v[vr], setter=(lambda x, vr=vr: self._set(vr, x)) if settable else None))
            self._units[name] = unit
            if settable:
                self._settable[vr] = settable
            if scene_key:
                self._scene_key[vr] = scene_key
            return vr

        # One description of the variables (millfmu.fmu_variables) serves FMI 2.0 and 3.0;
        # here an array is n Reals name[1] ... name[n].
        self._vr_param, self._vr_in, self._psd_in_vr0 = {}, {}, None
        described = variables(self.model)
        for var in described:
            causality, variability = getattr(Fmi2Causality, var.causality), getattr(Fmi2Variability, var.variability)
            initial = Fmi2Initial.exact if var.causality == "parameter" else None
            if var.size:
                if var.name == "psd_in":
                    self._psd_in_vr0 = len(self._v)
                else:
                    self._out_vr0 = len(self._v)
                for i, x in enumerate(var.start, 1):
                    add(f"{var.name}[{i}]", var.unit, var.description.format(i=i), x, causality, variability, initial, settable=var.settable)
                continue
            vr = add(var.name, var.unit, var.description, var.start, causality, variability, initial, settable=var.settable, scene_key=var.scene_key)
            if var.causality == "parameter":
                self._vr_param[var.name] = vr
            elif var.causality == "input":
                self._vr_in[var.settable[1]] = vr
        self._out_keys = [var.output_key for var in described if var.causality == "output" and not var.size]
        self._n_vars = len(self._v)
        self._publish(self.model.outputs())

    def log(self, msg: str, status=Fmi2Status.ok, category=None, debug=None):
        # The host's logger takes the message as a printf format: a bare '%' (in a
        # traceback, a value or a scene name) must not be read as a conversion.
        super().log(msg.replace("%", "%%"), status, category, debug)

    # ---- values ----------------------------------------------------------------------------
    def _publish(self, outs: dict):
        """Copy the model's outputs into the value list."""
        a = self._out_vr0
        n = self.n_classes
        self._v[a : a + n] = outs["psd"].tolist()
        self._v[a + n : self._n_vars] = [float(outs[k]) for k in self._out_keys]

    def _set(self, vr: int, x):
        self._v[vr] = float(x)

    def get_real(self, vrs):
        return get_reals(self._v, vrs, lambda msg: self.log(msg, Fmi2Status.error))

    def set_real(self, vrs, values):
        for vr, x in zip(vrs, values):
            what = self._settable.get(vr)
            if what is None:
                name = self.vars[vr].name if vr in self.vars else f"(value reference {vr})"
                self.log(f"fmi2SetReal: {name} = {x!r} ignored: only parameters and inputs can be set", Fmi2Status.error)
                continue
            if what[0] == "param" and self._initialized and self.vars[vr].variability != Fmi2Variability.tunable:
                self.log(f"fmi2SetReal: parameter {self.vars[vr].name} = {x!r} ignored: fixed parameters can only be set before initialization ends", Fmi2Status.error)
                continue
            self._v[vr] = float(x)

    # ---- life cycle ------------------------------------------------------------------------
    def exit_initialization_mode(self):
        """Values set so far are the scene's operating point: rebuild the model if they differ."""
        try:
            over = {}
            for vr, (sec, key) in self._scene_key.items():
                x = self._v[vr]
                if x != getattr(getattr(self._base_scene, sec), key):
                    over[(sec, key)] = x
            self._configure(over)
        except Exception:  # never let an exception reach the host: it would be fmi2Fatal
            self._config_error = "internal error while initializing: " + traceback.format_exc(limit=3)
            self.log(self._config_error, Fmi2Status.error)
        self._initialized = True

    def _configure(self, over: dict):
        """Build the model for the scene with ``over`` {(section, key): value} applied."""
        if over == self._overrides:
            return
        try:
            model = model_with(self._scene_dict, over)  # a DEM table may refuse the scene's operating point
        except SceneError as e:
            name = next((self.vars[vr].name for vr, sk in self._scene_key.items() if f"{sk[0]}.{sk[1]}" == e.key), e.key)
            self._config_error = f"{name} = {e.value!r}: {e.allowed}"
            self.log(f"initialization: {self._config_error}; every step will be refused", Fmi2Status.error)
            return
        if model.grid.n != self.n_classes:  # pragma: no cover - no parameter changes the grid
            raise RuntimeError("size grid changed")
        self.model = model
        self._overrides = dict(over)
        self._config_error = None
        self._publish(model.outputs())

    def _inputs(self) -> dict:
        v = self._v
        inp = {mkey: v[vr] for mkey, vr in self._vr_in.items()}
        inp["bead_filling"] = v[self._vr_param["bead_filling"]]
        if self._psd_in_vr0 is not None:
            a = self._psd_in_vr0
            inp["psd_in"] = np.array(v[a : a + self.n_classes])
        return inp

    def _fmi_name(self, model_name: str) -> str:
        if model_name == "bead_filling":
            return "bead_filling"
        if model_name in self._vr_in:
            return self.vars[self._vr_in[model_name]].name
        if model_name == "psd_in":
            return f"psd_in[1..{self.n_classes}]"
        if model_name == "dt_s":
            return "communicationStepSize"
        return model_name

    def do_step(self, current_time: float, step_size: float) -> bool:
        try:
            if self._config_error is not None:
                self.log(f"doStep at t = {current_time!r} s refused: {self._config_error}", Fmi2Status.discard)
                return False
            outs = self.model.step(step_size, **self._inputs())
        except InputError as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: input {self._fmi_name(e.name)} = {e.value!r}: {e.allowed}",
                     Fmi2Status.discard)
            return False
        except StepError as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: {e}", Fmi2Status.discard)
            return False
        except Exception:
            self.log(f"doStep at t = {current_time!r} s failed, state unchanged: " + traceback.format_exc(limit=4), Fmi2Status.error)
            return False
        self._publish(outs)
        return True

    # ---- FMU state -------------------------------------------------------------------------
    def _get_fmu_state(self):
        """The whole state as plain JSON-able data (copies; pythonfmu keeps the object)."""
        return {
            "overrides": [[sec, key, x] for (sec, key), x in self._overrides.items()],
            "config_error": self._config_error,
            "initialized": self._initialized,
            "values": list(self._v),
            "model": _plain(self.model.get_state()),
        }

    def _set_fmu_state(self, state):
        try:
            self._configure({(sec, key): x for sec, key, x in state["overrides"]})
            self.model.set_state(copy.deepcopy(state["model"]))
            self._v = list(state["values"])
            self._config_error = state["config_error"]
            self._initialized = state["initialized"]
        except Exception:
            self.log("fmi2SetFMUstate: state not applied: " + traceback.format_exc(limit=3), Fmi2Status.error)

    # ---- model description -----------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:
        """pythonfmu's description completed with units, exact start values, output
        dependencies and InitialUnknowns (see :mod:`millfmu.fmi_xml`)."""
        return complete_model_description(super().to_xml(model_options), self, self._units, UNITS.__getitem__, self._model_description)
