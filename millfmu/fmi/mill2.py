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
the variable and the value, and leaves the state as it was. Where FMI 2.0 wants fmi2Error
(a call the instance cannot honour but survives: parameters the model refuses at
fmi2ExitInitializationMode, a currentCommunicationPoint that is not the FMU's time, a
serialized state that is damaged or from another FMU), the reason is logged and an
:class:`FMUCallError` raised, which millfmu's rebuilt pythonfmu wrapper returns as
fmi2Error with the instance intact (see ``fmu_build.wrapper``). Under pythonfmu's own
wrapper an exception would be fmi2Fatal and wreck the instance, so there the same cases
are logged errors only (steps then refused with fmi2Discard, a state not applied).

Serialized states (fmi2SerializeFMUstate) carry a format version, the FMU's identity (its
model identifier, which hashes the code and the scene) and a sha256 of the state; a state
whose any of the three does not match is refused.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import traceback
from xml.etree.ElementTree import Element

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

from .base2 import complete_model_description, get_reals
# The variable tables live in millfmu.fmi.variables (shared with the FMI 3.0 adapter); re-exported here.
from .variables import (DISRUPTED, HeldArray, INPUTS, OUTPUTS, PARAMETERS, SCENE_FILE, TABLE_PREFIX, UNITS,  # noqa: F401
                            model_description_text, model_with, plain as _plain, read_band, read_scene_dict, variables)
from ..mill import InputError, MillModel, StepError
from ..scene import SceneError, scene_from_dict

#: Written by the build into the resources: "fixed" when the FMU carries millfmu's rebuilt
#: pythonfmu wrapper (exceptions -> fmi2Error), "stock" for pythonfmu's own.
WRAPPER_FILE = "wrapper.txt"
#: Format of serialized FMU states; a state of another format is refused.
STATE_FORMAT = "millfmu-fmu-state/1"
#: Largest difference between currentCommunicationPoint and the FMU's time that is taken
#: as the masters' round-off of accumulated time [s]: relative to the time and the step.
TIME_RTOL = 1e-9


#: The slave class of each FMU script by model identifier (see fmu_build.build.SCRIPT): the
#: script runs at every fmi2Instantiate, and this keeps it to one class per process.
SCRIPT_CLASSES: dict = {}


class FMUCallError(RuntimeError):
    """An FMI call refused with fmi2Error (under the fixed wrapper); the instance is intact."""


class MillSlave(Fmi2Slave):
    """The mill as a pythonfmu slave; the scene is ``<resources>/scene.toml``."""

    author = "millfmu"
    description = "Wet stirred media mill (bead mill): population balance with Kwade's stress model"

    #: Raise FMUCallError where FMI wants fmi2Error: only under the fixed wrapper (set per
    #: FMU class from its resources; the class serves the static state (de)serialization).
    _raise_errors = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        try:
            with open(os.path.join(self.resources, WRAPPER_FILE)) as f:
                type(self)._raise_errors = f.read().strip() == "fixed"
        except OSError:
            type(self)._raise_errors = False
        self._start_time = 0.0
        self._warned: set = set()  # what the log said once (MillModel.new_warnings)
        self._scene_dict = read_scene_dict(self.resources)
        scene = scene_from_dict(self._scene_dict, SCENE_FILE)
        self.model = MillModel(scene, no_dem=True)  # an FMU carries no DEM: it never builds a table
        self._overrides: dict = {}
        self._config_error: str | None = None
        self._initialized = False
        n = self.model.grid.n
        self.n_classes = n
        self._base_scene = scene
        # type(self): pythonfmu's __init__ set the instance's description to None.
        self._model_description = model_description_text(type(self).description, scene, n, getattr(self.model.source, "table", None),
                                                         read_band(self.resources))
        run = scene.run
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=run.t_end_s, step_size=run.dt_s)

        # Every value lives in one list indexed by value reference: get_real is then one
        # list lookup per value, which keeps the per-step cost near pythonfmu's floor.
        self._v: list = []
        self._units: dict = {}
        self._settable: dict = {}  # vr -> (kind, key)
        self._scene_key: dict = {}  # vr -> (section, key) for values that are scene values

        # The getters and setters hold the value list, not self: an instance is then no
        # reference cycle, and its model is freed when the host frees the instance instead of
        # at the collector's next full pass (which let the heap grow by about 20 kB per
        # instance in the first few hundred instances of a process).
        values = self._v

        def add(name, unit, desc, start, causality, variability, initial=None, settable=None, scene_key=None):
            vr = len(values)
            values.append(float(start))
            self.register_variable(Real(name, causality=causality, variability=variability, initial=initial, description=desc,
                                        getter=lambda vr=vr: values[vr],
                                        setter=(lambda x, vr=vr: values.__setitem__(vr, float(x))) if settable else None))
            self._units[name] = unit
            if settable:
                self._settable[vr] = settable
            if scene_key:
                self._scene_key[vr] = scene_key
            return vr

        # One description of the variables (millfmu.fmi.variables) serves FMI 2.0 and 3.0;
        # here an array is n Reals name[1] ... name[n].
        self._vr_param, self._vr_in, self._psd_in_vr0 = {}, {}, None
        self._psd_in = HeldArray()
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
        for w in self.model.warnings:
            self.log(f"scene {scene.scene.name!r}: {w}", Fmi2Status.warning)

    def _refuse(self, msg: str, fallback=Fmi2Status.error):
        """Log ``msg``; raise FMUCallError (-> fmi2Error) under the fixed wrapper, else log
        only, with ``fallback`` as the logged status."""
        if self._raise_errors:
            self.log(msg, Fmi2Status.error)
            raise FMUCallError(msg)
        self.log(msg, fallback)

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
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        """The FMU's time starts at ``start_time`` [s]."""
        self._start_time = float(start_time)

    def exit_initialization_mode(self):
        """Values set so far are the scene's operating point: rebuild the model if they differ.
        Values the model refuses: fmi2Error (logged), and every step is refused."""
        try:
            over = {}
            for vr, (sec, key) in self._scene_key.items():
                x = self._v[vr]
                if x != getattr(getattr(self._base_scene, sec), key):
                    over[(sec, key)] = x
            self._config_error = None
            model, error = self._model_for(over)
            if error is None:
                self._use(model, over)
            else:
                self._config_error = error
        except Exception:  # any other exception would be fmi2Fatal under the stock wrapper
            self._config_error = "internal error while initializing: " + traceback.format_exc(limit=3)
        self._initialized = True
        if self._config_error is not None:
            self._refuse(f"fmi2ExitInitializationMode: {self._config_error}; every step will be refused")

    def _model_for(self, over: dict):
        """(model, None) for the scene with ``over`` {(section, key): value} applied, or
        (None, message naming the FMI variable) when the model refuses it."""
        if over == self._overrides:
            return self.model, None
        try:
            model = model_with(self._scene_dict, over)  # a DEM table may refuse the scene's operating point
        except SceneError as e:
            name = next((self.vars[vr].name for vr, sk in self._scene_key.items() if f"{sk[0]}.{sk[1]}" == e.key), e.key)
            return None, f"{name} = {e.value!r}: {e.allowed}"
        if model.grid.n != self.n_classes:  # pragma: no cover - no parameter changes the grid
            raise RuntimeError("size grid changed")
        return model, None

    def _use(self, model, over: dict):
        self.model = model
        self._overrides = dict(over)
        self._publish(model.outputs())

    def _inputs(self) -> dict:
        v = self._v
        inp = {mkey: v[vr] for mkey, vr in self._vr_in.items()}
        inp["bead_filling"] = v[self._vr_param["bead_filling"]]
        if self._psd_in_vr0 is not None:
            a = self._psd_in_vr0
            inp["psd_in"] = self._psd_in.array(v[a : a + self.n_classes])
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
        t = self._start_time + self.model.t_s
        if not (math.isfinite(current_time) and abs(current_time - t) <= TIME_RTOL * max(abs(t), abs(step_size), 1.0)):
            self._refuse(f"doStep refused, state unchanged: currentCommunicationPoint = {current_time!r} s is not the FMU's time "
                         f"{t!r} s (the previous communication point plus its step, or the time of the state set last)",
                         Fmi2Status.discard)
            return False
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
        for w in self.model.new_warnings(outs, self._warned):
            self.log(w, Fmi2Status.warning)
        return True

    # ---- FMU state -------------------------------------------------------------------------
    def _get_fmu_state(self):
        """The whole state as plain JSON-able data (copies; pythonfmu keeps the object),
        with the format and this FMU's identity."""
        return {
            "format": STATE_FORMAT,
            "fmu": type(self).__name__,
            "overrides": [[sec, key, x] for (sec, key), x in self._overrides.items()],
            "config_error": self._config_error,
            "initialized": self._initialized,
            "start_time": self._start_time,
            "values": list(self._v),
            "model": _plain(self.model.get_state()),
        }

    @classmethod
    def _state_problem(cls, state) -> str | None:
        """Why ``state`` is not a state of this FMU (None if it is)."""
        if not isinstance(state, dict):
            return f"not a state of this FMU (a {type(state).__name__})"
        if "invalid" in state:
            return state["invalid"]
        if state.get("format") != STATE_FORMAT:
            return f"format {state.get('format')!r}, this FMU reads {STATE_FORMAT!r}"
        if state.get("fmu") != cls.__name__:
            return f"a state of FMU {state.get('fmu')!r}, this is {cls.__name__!r}"
        return None

    def _set_fmu_state(self, state):
        """Restore a state from :meth:`_get_fmu_state`: all or nothing."""
        why = self._state_problem(state)
        if why is None:
            model = backup = None
            try:
                over = {(sec, key): x for sec, key, x in state["overrides"]}
                values = [float(x) for x in state["values"]]
                if len(values) != self._n_vars:
                    raise ValueError(f"{len(values)} values, this FMU has {self._n_vars}")
                model, error = self._model_for(over)
                if error is not None:
                    raise ValueError(error)
                backup = model.get_state()
                model.set_state(copy.deepcopy(state["model"]))
                start = float(state["start_time"])
            except Exception as e:  # a malformed state: refused, nothing applied
                if backup is not None:
                    model.set_state(backup)
                why = f"malformed ({type(e).__name__}: {e})"
        if why is not None:
            self._refuse(f"fmi2SetFMUstate: state refused, nothing applied: {why}")
            return
        self.model, self._overrides = model, over
        self._v[:] = values  # in place: the variables' getters hold this list
        self._config_error = state["config_error"]
        self._initialized = bool(state["initialized"])
        self._start_time = start

    @staticmethod
    def _digest(state) -> str:
        return hashlib.sha256(json.dumps(state, sort_keys=True, separators=(",", ":")).encode()).hexdigest()

    @classmethod
    def _fmu_state_to_bytes(cls, state) -> bytes:
        """JSON of the state with its sha256 (see :meth:`_fmu_state_from_bytes`)."""
        return json.dumps({"sha256": cls._digest(state), "state": state}, separators=(",", ":")).encode()

    @classmethod
    def _fmu_state_from_bytes(cls, data: bytes):
        """The state in ``data``; refused (FMUCallError -> fmi2Error) when it is not JSON,
        its checksum does not match, or its format or FMU differ. Under the stock wrapper a
        marker that fmi2SetFMUstate refuses instead (an exception would be fmi2Fatal)."""
        try:
            blob = json.loads(bytes(data).decode())
            state = blob["state"]
            why = None if blob.get("sha256") == cls._digest(state) else "its sha256 does not match its content: damaged or edited"
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
            why, state = f"not a serialized state of this FMU ({type(e).__name__})", None
        why = why or cls._state_problem(state)
        if why is None:
            return state
        if cls._raise_errors:
            raise FMUCallError(f"fmi2DeSerializeFMUstate: {why}")
        return {"invalid": f"fmi2DeSerializeFMUstate gave no state: {why}"}

    # ---- model description -----------------------------------------------------------------
    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description completed with units, exact start values, output
        dependencies and InitialUnknowns (see :mod:`millfmu.fmi.base2`)."""
        return complete_model_description(super().to_xml({} if model_options is None else model_options), self, self._units, UNITS.__getitem__, self._model_description)
