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
import os
import sys
import traceback
from xml.etree.ElementTree import Element

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np
from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

from .fmi_xml import complete_model_description, get_reals

from .mill import PSD_SUM_TOL, InputError, MillModel, StepError
from .scene import SceneError, scene_from_dict

#: Name of the scene file in the FMU's resources folder.
SCENE_FILE = "scene.toml"
#: Prefix of the DEM table slice in the resources folder (detailed model with a table).
TABLE_PREFIX = "table"

#: Units used by the variables: name -> SI base-unit exponents (FMI 2.0 BaseUnit).
UNITS = {
    "1": {},
    "m": {"m": 1},
    "kg": {"kg": 1},
    "kg/s": {"kg": 1, "s": -1},
    "m/s": {"m": 1, "s": -1},
    "kg/m3": {"kg": 1, "m": -3},
    "J": {"kg": 1, "m": 2, "s": -2},
    "1/s": {"s": -1},
    "W": {"kg": 1, "m": 2, "s": -3},
    "J/kg": {"m": 2, "s": -2},
    "Pa.s": {"kg": 1, "m": -1, "s": -1},
}

#: Parameters: FMI name, scene (section, key), unit, variability, description.
PARAMETERS = (
    ("bead_filling", ("mill", "bead_filling"), "1", "tunable", "bead filling: bulk bead volume at rest over chamber volume, in (0, 1)"),
    ("bead_diameter", ("beads", "diameter_m"), "m", "fixed", "grinding bead diameter"),
    ("bead_density", ("beads", "density_kg_per_m3"), "kg/m3", "fixed", "grinding bead density"),
    ("stress_frequency_factor", ("mill", "stress_frequency_factor"), "1", "fixed", "Kwade's stress-frequency constant k_c (calibration)"),
)

#: Scalar inputs: FMI name, scene (section, key), MillModel input name, unit, description, continuous only.
INPUTS = (
    ("tip_speed", ("mill", "tip_speed_m_per_s"), "tip_speed_m_per_s", "m/s", "stirrer tip speed, in [0, 40] m/s", False),
    ("solids_mass_fraction", ("suspension", "solids_mass_fraction"), "solids_mass_fraction", "1", "solids mass concentration of the suspension (mass fraction), in (0, 0.8)", False),
    ("feed_mass_flow", ("operation", "feed_mass_flow_kg_per_s"), "feed_mass_flow_kg_per_s", "kg/s", "solids feed mass flow, >= 0", True),
)

#: Scalar outputs: FMI name, MillModel output key, unit, description.
OUTPUTS = (
    ("x10", "x10_m", "m", "size with 10 % of the product mass below it"),
    ("x50", "x50_m", "m", "median size of the product (by mass)"),
    ("x90", "x90_m", "m", "size with 90 % of the product mass below it"),
    ("holdup", "holdup_kg", "kg", "solids mass in the mill"),
    ("product_mass_flow", "product_mass_flow_kg_per_s", "kg/s", "solids product mass flow, mean over the last step (0 in batch)"),
    ("se_beads", "se_beads_J", "J", "stress energy of the beads SE = pi/12 d^3 rho v_t^2"),
    ("se_product", "se_product_J", "J", "stress energy reaching the product SE_P"),
    ("sf", "sf_per_s", "1/s", "stress frequency at x50"),
    ("stress_number", "stress_number", "1", "stress number: SF integrated over time"),
    ("power", "power_W", "W", "stirrer power"),
    ("specific_energy", "specific_energy_J_per_kg", "J/kg", "stirrer energy per mass of solids treated"),
    ("eta_eff", "eta_eff_Pa_s", "Pa.s", "effective viscosity of the bead-suspension bulk (Krieger-Dougherty)"),
    ("reynolds", "reynolds", "1", "mill Reynolds number"),
)
DISRUPTED = ("disrupted_fraction", "disrupted_fraction", "1", "mass fraction of disrupted cells (debris) in the mill")


def _plain(x):
    """JSON-able deep copy: arrays to lists of Python floats (repr round-trips exactly)."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


class MillSlave(Fmi2Slave):
    """The mill as a pythonfmu slave; the scene is ``<resources>/scene.toml``."""

    author = "millfmu"
    description = "Wet stirred media mill (bead mill): population balance with Kwade's stress model"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        with open(os.path.join(self.resources, SCENE_FILE), "rb") as f:
            self._scene_dict = tomllib.load(f)
        sd = self._scene_dict.get("kinetics", {}).get("stress_distribution", {})
        if sd.get("source") == "table":
            # The build put the table slice this scene needs into the resources.
            sd["table"] = os.path.join(self.resources, TABLE_PREFIX)
        scene = scene_from_dict(self._scene_dict, SCENE_FILE)
        self.model = MillModel(scene)
        self._overrides: dict = {}
        self._config_error: str | None = None
        self._initialized = False
        n = self.model.grid.n
        self.n_classes = n
        self._base_scene = scene
        self._model_description = f"{self.description}; scene {scene.scene.name!r}, {scene.operation.mode}, {scene.kinetics.model} model, {n} size classes"
        run = scene.run
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=run.t_end_s, step_size=run.dt_s)

        # Every value lives in one list indexed by value reference: get_real is then one
        # list lookup per value, which keeps the per-step cost near pythonfmu's floor.
        self._v: list = []
        self._units: dict = {}
        self._settable: dict = {}  # vr -> (kind, key)
        self._scene_key: dict = {}  # vr -> (section, key) for values that are scene values
        cont = self.model.continuous

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

        self._vr_param = {}
        for name, (sec, key), unit, var, desc in PARAMETERS:
            start = getattr(getattr(scene, sec), key)
            self._vr_param[name] = add(name, unit, desc, start, Fmi2Causality.parameter, getattr(Fmi2Variability, var), Fmi2Initial.exact,
                                       settable=("param", key), scene_key=(sec, key))
        self._vr_in = {}
        inputs = self.model.inputs
        for name, (sec, key), mkey, unit, desc, cont_only in INPUTS:
            if cont_only and not cont:
                continue
            self._vr_in[mkey] = add(name, unit, desc, inputs[mkey], Fmi2Causality.input, Fmi2Variability.continuous,
                                    settable=("input", mkey), scene_key=(sec, key))
        self._psd_in_vr0 = None
        if cont:
            self._psd_in_vr0 = len(self._v)
            for i, w in enumerate(inputs["psd_in"], 1):
                add(f"psd_in[{i}]", "1", f"feed mass fraction in size class {i} (all sum to 1 within {PSD_SUM_TOL:g})", w,
                    Fmi2Causality.input, Fmi2Variability.continuous, settable=("input", "psd_in"))
        self._out_vr0 = len(self._v)
        last = self.model.outputs()
        for i in range(1, n + 1):
            add(f"psd[{i}]", "1", f"product mass fraction in size class {i} (batch: mill content; continuous: outlet)", 0.0,
                Fmi2Causality.output, Fmi2Variability.continuous)
        outs = OUTPUTS + ((DISRUPTED,) if "disrupted_fraction" in last else ())
        self._out_keys = [key for _, key, _, _ in outs]
        for name, _key, unit, desc in outs:
            add(name, unit, desc, 0.0, Fmi2Causality.output, Fmi2Variability.continuous)
        self._n_vars = len(self._v)
        self._publish(last)

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
        d = copy.deepcopy(self._scene_dict)
        for (sec, key), x in over.items():
            d.setdefault(sec, {})[key] = x
        try:
            scene = scene_from_dict(d, SCENE_FILE)
            model = MillModel(scene)  # a DEM table may refuse the scene's operating point
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
