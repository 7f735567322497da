"""FMI 2.0 co-simulation base of millfmu's FMUs (pythonfmu): Real variables with units, every
value in one list indexed by value reference.

Shared by the mill FMU (:mod:`millfmu.fmi.mill2`) and the flowsheets' unit FMUs
(``flowsheets.unit_fmu``); numpy-free and free of millfmu imports, so that any of them can
carry it. Statuses, as FMI 2.0 intends them:

- fmi2Discard from ``fmi2DoStep``: an input value the FMU refuses (named with its value and
  what is allowed) or a step it cannot take; the state is unchanged and the master may retry;
- fmi2Error where a call cannot be honoured but the instance survives: a parameter value
  refused at ``fmi2ExitInitializationMode`` (every later step is refused too), a
  currentCommunicationPoint that is not the FMU's time, a serialized state that is damaged
  or from another FMU, a state that cannot be applied. An :class:`FMUCallError` is raised,
  which millfmu's rebuilt pythonfmu wrapper returns as fmi2Error with the instance intact,
  logging its message as it is (see ``fmu_build.wrapper``). Under pythonfmu's own
  wrapper an exception would be fmi2Fatal and wreck the instance, so there the same cases
  are logged errors only (steps then refused with fmi2Discard, a state not applied);
- setting an output, or a fixed parameter after initialization: an error logged, the value
  ignored; reading an unknown value reference: NaN and an error logged.

Serialized states (fmi2SerializeFMUstate) carry a format version, the FMU's identity (its
class, named by the model identifier, which hashes the code and the configuration) and a
sha256 of the state; a state whose any of the three does not match is refused.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import traceback
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

#: Written by the build into the resources: "fixed" when the FMU carries millfmu's rebuilt
#: pythonfmu wrapper (exceptions -> fmi2Error), "stock" for pythonfmu's own.
WRAPPER_FILE = "wrapper.txt"
#: Format of serialized FMU states; a state of another format is refused.
STATE_FORMAT = "millfmu-fmu-state/1"
#: Largest difference between currentCommunicationPoint and the FMU's time that is taken
#: as the masters' round-off of accumulated time [s]: relative to the time and the step.
TIME_RTOL = 1e-9


class FMUCallError(RuntimeError):
    """An FMI call refused with fmi2Error (under the fixed wrapper); the instance is intact."""


class _Refused(Exception):
    """A parameter value refused at fmi2ExitInitializationMode (:meth:`Fmi2Base.refuse_configuration`)."""


class Fmi2Base(Fmi2Slave):
    """Values in one list indexed by value reference. Subclasses declare their variables
    with :meth:`declare` and provide:

    - ``_configure()``: apply the parameters (and the operating point) set before
      fmi2ExitInitializationMode; :meth:`refuse_configuration` for a value it refuses;
    - ``_take_step(h)``: advance by h [s] and publish the outputs; an exception of a type in
      ``REFUSED`` leaves the state unchanged and is answered fmi2Discard with
      ``_refusal(e)`` as the message;
    - ``_state()`` / ``_restore(state)``: the rest of the FMU state as JSON-able data;
    - ``_time()`` (optional): the FMU's time [s], where it keeps one, which a doStep's
      currentCommunicationPoint must match.
    """

    author = "millfmu"
    #: Exceptions of a step that refuse it (fmi2Discard); any other is fmi2Error.
    REFUSED: tuple = ()
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
        self._v: list = []
        self._units: dict = {}  # variable name -> unit name
        self._settable: dict = {}  # value reference -> "input", "tunable" or "fixed"
        self._config_error: str | None = None
        self._initialized = False

    # ---- declaration -------------------------------------------------------------------
    def declare(self, name: str, unit: str, causality: str, variability: str, description: str, start: float) -> int:
        """A Real of ``unit`` (a causality and a variability as FMI names them: "parameter",
        "tunable", ...); returns its value reference, which is its place in the value list."""
        vr = len(self._v)
        self._v.append(float(start))
        settable = causality in ("parameter", "input")
        # Every value lives in one list indexed by value reference: get_real is then one list
        # lookup per value, which keeps the per-step cost near pythonfmu's floor. The getter
        # and setter hold the list, not self: an instance is then no reference cycle, and its
        # model is freed when the host frees the instance instead of at the collector's next
        # full pass (which let the heap grow by about 20 kB per instance in the first few
        # hundred instances of a process).
        values = self._v
        self.register_variable(Real(name, causality=getattr(Fmi2Causality, causality),
                                    variability=getattr(Fmi2Variability, variability),
                                    initial=Fmi2Initial.exact if causality == "parameter" else None,
                                    description=description,
                                    getter=lambda vr=vr: values[vr],
                                    setter=(lambda x, vr=vr: values.__setitem__(vr, float(x))) if settable else None))
        self._units[name] = unit
        if settable:
            self._settable[vr] = "input" if causality == "input" else variability
        return vr

    def log(self, msg: str, status=Fmi2Status.ok, category=None, debug=None):
        # The host's logger takes the message as a printf format: a bare '%' (in a
        # traceback, a value or a name) must not be read as a conversion.
        super().log(msg.replace("%", "%%"), status, category, debug)

    def _refuse(self, msg: str, fallback=Fmi2Status.error):
        """Raise FMUCallError (-> fmi2Error, the wrapper logging ``msg`` as it is) under the
        fixed wrapper, else log ``msg`` only, with ``fallback`` as the logged status."""
        if self._raise_errors:
            raise FMUCallError(msg)
        self.log(msg, fallback)

    # ---- values ------------------------------------------------------------------------
    def get_real(self, vrs):
        """fmi2GetReal: a reference that names no Real variable reads NaN, and one error is logged."""
        values = self._v
        try:
            return [values[vr] for vr in vrs]
        except (IndexError, TypeError):
            n = len(values)
            bad = [vr for vr in vrs if not (isinstance(vr, int) and 0 <= vr < n)]
            self.log(f"fmi2GetReal: no Real variable with value reference {bad[0]}; got NaN", Fmi2Status.error)
            return [values[vr] if isinstance(vr, int) and 0 <= vr < n else math.nan for vr in vrs]

    def set_real(self, vrs, values):
        for vr, x in zip(vrs, values):
            kind = self._settable.get(vr)
            if kind is None:
                name = self.vars[vr].name if vr in self.vars else f"(value reference {vr})"
                self.log(f"fmi2SetReal: {name} = {x!r} ignored: only parameters and inputs can be set",
                         Fmi2Status.error)
                continue
            if kind == "fixed" and self._initialized:
                self.log(f"fmi2SetReal: parameter {self.vars[vr].name} = {x!r} ignored: fixed parameters can only be "
                         "set before initialization ends", Fmi2Status.error)
                continue
            self._v[vr] = float(x)

    # ---- life cycle --------------------------------------------------------------------
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        """The FMU's time starts at ``start_time`` [s]."""
        self._start_time = float(start_time)

    def refuse_configuration(self, text: str):
        """A parameter value is refused (``text`` names it, the value and what is allowed):
        fmi2Error from fmi2ExitInitializationMode, and every later step is refused."""
        raise _Refused(text)

    def exit_initialization_mode(self):
        """Values set so far are the FMU's configuration (``_configure``). Values it refuses:
        fmi2Error (logged), and every step is refused."""
        try:
            self._configure()
            self._config_error = None
        except _Refused as e:
            self._config_error = str(e)
        except Exception:  # any other exception would be fmi2Fatal under the stock wrapper
            self._config_error = "internal error while initializing: " + traceback.format_exc(limit=3)
        self._initialized = True
        if self._config_error is not None:
            self._refuse(f"fmi2ExitInitializationMode: {self._config_error}; every step will be refused")

    def _time(self) -> float | None:
        """The FMU's time [s] (where a step must start), or None where it keeps none."""
        return None

    def do_step(self, current_time: float, step_size: float) -> bool:
        t = self._time()
        if t is not None and not (math.isfinite(current_time)
                                  and abs(current_time - t) <= TIME_RTOL * max(abs(t), abs(step_size), 1.0)):
            self._refuse(f"doStep refused, state unchanged: currentCommunicationPoint = {current_time!r} s is not the "
                         f"FMU's time {t!r} s (the previous communication point plus its step, or the time of the "
                         "state set last)",
                         Fmi2Status.discard)
            return False
        try:
            if self._config_error is not None:
                self.log(f"doStep at t = {current_time!r} s refused: {self._config_error}", Fmi2Status.discard)
                return False
            self._take_step(step_size)
        except self.REFUSED as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: {self._refusal(e)}",
                     Fmi2Status.discard)
            return False
        except Exception:
            self.log(f"doStep at t = {current_time!r} s failed, state unchanged: " + traceback.format_exc(limit=4),
                     Fmi2Status.error)
            return False
        return True

    def _refusal(self, e: Exception) -> str:
        return str(e)

    # ---- FMU state ---------------------------------------------------------------------
    def _get_fmu_state(self):
        """The whole state as plain JSON-able data (copies; pythonfmu keeps the object),
        with the format and this FMU's identity."""
        return {"format": STATE_FORMAT, "fmu": type(self).__name__, "config_error": self._config_error,
                "initialized": self._initialized, "start_time": self._start_time, "values": list(self._v),
                **self._state()}

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
            keep = self._get_fmu_state()
            try:
                self._apply_state(state)
            except Exception as e:  # a malformed state: refused, nothing applied
                self._apply_state(keep)
                why = f"malformed ({type(e).__name__}: {e})"
        if why is not None:
            self._refuse(f"fmi2SetFMUstate: state refused, nothing applied: {why}")

    def _apply_state(self, state):
        values = [float(x) for x in state["values"]]
        if len(values) != len(self._v):
            raise ValueError(f"{len(values)} values, this FMU has {len(self._v)}")
        start, config_error, initialized = float(state["start_time"]), state["config_error"], bool(state["initialized"])
        self._restore(state)
        self._v[:] = values  # in place: the variables' getters hold this list
        self._config_error, self._initialized, self._start_time = config_error, initialized, start

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
            why = (None if blob.get("sha256") == cls._digest(state)
                   else "its sha256 does not match its content: damaged or edited")
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
            why, state = f"not a serialized state of this FMU ({type(e).__name__})", None
        why = why or cls._state_problem(state)
        if why is None:
            return state
        if cls._raise_errors:
            raise FMUCallError(f"fmi2DeSerializeFMUstate: {why}")
        return {"invalid": f"fmi2DeSerializeFMUstate gave no state: {why}"}

    # ---- model description -------------------------------------------------------------
    def complete_xml(self, root: Element, exponents, description: str) -> Element:
        """What pythonfmu 0.7's model description ``root`` (from ``Fmi2Slave.to_xml``) lacks
        for FMI 2.0 validity, added in place: the description text, units in
        UnitDefinitions (``exponents(unit name)`` -> {base unit: exponent}) and on every
        Real, exact start values, output dependencies (none: outputs change only in doStep,
        no direct feedthrough) and InitialUnknowns."""
        root.set("description", description)
        used = []
        by_name = {v.name: v for v in self.vars.values()}
        for sv in root.iter("ScalarVariable"):
            name = sv.get("name")
            real = sv.find("Real")
            u = self._units[name]
            real.set("unit", u)
            if u not in used:
                used.append(u)
            if real.get("start") is not None:
                # pythonfmu prints start values with limited digits; write them exactly.
                real.set("start", repr(float(self._v[by_name[name].value_reference])))
        defs = Element("UnitDefinitions")
        for u in used:
            unit = SubElement(defs, "Unit", {"name": u})
            SubElement(unit, "BaseUnit", {k: str(e) for k, e in exponents(u).items()})
        root.insert(list(root).index(root.find("CoSimulation")) + 1, defs)
        root.remove(root.find("ModelStructure"))
        ms = SubElement(root, "ModelStructure")
        outs = SubElement(ms, "Outputs")
        init = SubElement(ms, "InitialUnknowns")
        for i, v in enumerate(self.vars.values(), 1):
            if v.causality == Fmi2Causality.output:
                SubElement(outs, "Unknown", {"index": str(i), "dependencies": ""})
                # Initial outputs follow from parameters and input start values: no dependency
                # list, i.e. "depends on all".
                SubElement(init, "Unknown", {"index": str(i)})
        return root
