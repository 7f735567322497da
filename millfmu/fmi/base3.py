"""FMI 3.0 co-simulation base of millfmu's FMUs (pythonfmu3): Float64 variables, scalars or
arrays whose length is one structural parameter, every value in one flat list.

FMI 3.0 statuses: a call the standard calls illegal (setting an output, or a fixed
parameter after initialization; an unknown value reference; a wrong number of values;
another array length; a doStep whose currentCommunicationPoint is not the FMU's time)
raises :class:`FmiCallError`, which the FMU's wrapper (pythonfmu3's, with millfmu's
fixes: fmu_build.fmi3_wrapper) answers with fmi3Error and this message; the
instance is left as it was. Input values are checked by the step, which refuses bad ones
with fmi3Discard (the master may retry). No other exception may leave a call.

Shared by the mill FMU and the flowsheet unit FMUs; numpy-free so that any of them can
carry it.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import math
import traceback
from xml.etree.ElementTree import Element

from pythonfmu3 import (Dimension, Fmi3Causality, Fmi3Initial, Fmi3Slave, Fmi3Status, Fmi3StepResult, Fmi3Variability,
                       Float64, UInt64, Unit)

#: Format of the FMU states (fmi3GetFMUState, fmi3SerializeFMUState).
STATE_FORMAT = "millfmu-fmi3-state-1"
#: Largest difference between currentCommunicationPoint and the FMU's time that is taken
#: as the masters' round-off of accumulated time [s]: relative to the time and the step.
#: The FMI 2.0 base's (millfmu.fmi.base2.TIME_RTOL), which this module cannot import (an FMI 3.0
#: FMU carries no pythonfmu).
TIME_RTOL = 1e-9




def _fixed_class_count(value):
    """Setter of the class count: never called (set_uint64 checks the value and refuses a
    change); given so that pythonfmu3 makes none that holds the instance (a reference
    cycle that kept every freed instance until the collector's next full pass)."""
    raise FmiCallError(f"the class count is fixed when the FMU is built (got {value})")

class FmiCallError(Exception):
    """An illegal call: the FMU answers fmi3Error with this message and changes nothing."""


class Fmi3Base(Fmi3Slave):
    """Values in one list: a scalar takes one entry, an array ``n_classes`` entries; value
    reference -> slice of that list. Subclasses declare their variables with
    :meth:`declare` (after :meth:`declare_class_count` when they have arrays) and provide:

    - ``_configure()``: apply the parameters (and the operating point) set before
      fmi3ExitInitializationMode; :meth:`refuse_configuration` for a value it refuses;
    - ``_take_step(h)``: advance by h [s] and publish the outputs; an exception of a type in
      ``REFUSED`` leaves the state unchanged and is answered fmi3Discard with
      ``_refusal(e)`` as the message;
    - ``_state()`` / ``_restore(state)``: the rest of the FMU state as JSON-able data.
    """

    author = "millfmu"
    #: Exceptions of a step that refuse it (fmi3Discard); any other is fmi3Error.
    REFUSED: tuple = ()

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # pythonfmu3's __init__ sets these instance attributes to None over the class's.
        self.author, self.description = type(self).author, type(self).description
        self._v: list = []
        self._slices: dict = {}  # value reference -> slice of _v
        self._settable: dict = {}  # value reference -> "input", "tunable" or "fixed"
        self._unit_of: dict = {}  # variable name -> unit name
        self._initialized = False
        self._config_error: str | None = None
        self.n_classes = 0
        self._vr_n = None
        # FMI 3.0 wants exactly one independent variable: the time of the last communication
        # point, value 0 of the list.
        self.vr_time = self.declare("time", "s", "independent", "continuous",
                                    "simulation time at the last communication point", 0.0)

    # ---- declaration -------------------------------------------------------------------
    def declare_class_count(self, n: int, description: str, name: str = "n_classes") -> int:
        """The structural parameter giving the arrays' length (fixed: the FMU's size grid)."""
        self.n_classes = int(n)
        self._vr_n = len(self.vars)
        self.register_variable(UInt64(name, causality=Fmi3Causality.structuralParameter,
                                      variability=Fmi3Variability.fixed,
                                      initial=Fmi3Initial.exact, start=self.n_classes, description=description,
                                      getter=lambda n=self.n_classes: n, setter=_fixed_class_count))
        return self._vr_n

    def declare(self, name: str, unit: str, causality: str, variability: str, description: str, start,
                array: bool = False) -> int:
        """A Float64 (an array of n_classes values when ``array``); returns its value reference."""
        vr = len(self.vars)
        values = [float(x) for x in start] if array else [float(start)]
        if array and len(values) != self.n_classes:
            raise ValueError(f"{name}: {len(values)} start values for {self.n_classes} classes")
        a = len(self._v)
        self._v.extend(values)
        s = self._slices[vr] = slice(a, a + len(values))
        if causality in ("input", "parameter"):
            self._settable[vr] = "input" if causality == "input" else variability
        initial = {"parameter": Fmi3Initial.exact, "output": Fmi3Initial.calculated}.get(causality)
        # the getter holds the value list, not self (no reference cycle: see millfmu.fmi.base2)
        v = self._v
        self.register_variable(Float64(
            name, causality=getattr(Fmi3Causality, causality), variability=getattr(Fmi3Variability, variability),
                                       initial=initial,
            description=description, unit=unit, dimensions=[Dimension(valueReference=str(self._vr_n))] if array else [],
            getter=(lambda: v[s]) if array else (lambda: v[s.start])))
        self._unit_of[name] = unit
        return vr

    # ---- values ------------------------------------------------------------------------
    def get_float64(self, vrs):
        v, slices = self._v, self._slices
        out = []
        try:
            for vr in vrs:
                out += v[slices[vr]]
        except KeyError:
            raise FmiCallError(f"fmi3GetFloat64: no Float64 variable has value reference {vr}") from None
        return out

    def set_float64(self, vrs, values):
        # Check the whole call first: a refused call changes nothing.
        plan, pos = [], 0
        for vr in vrs:
            s = self._slices.get(vr)
            if s is None:
                raise FmiCallError(f"fmi3SetFloat64: no Float64 variable has value reference {vr}")
            kind = self._settable.get(vr)
            name = self.vars[vr].name
            shown = repr(values[pos]) if s.stop - s.start == 1 and pos < len(values) else f"({s.stop - s.start} values)"
            if kind is None:
                raise FmiCallError(f"fmi3SetFloat64: {name} = {shown} refused: {name} has causality "
                                   f"{self.vars[vr].causality.name}; only parameters and inputs can be set")
            if kind == "fixed" and self._initialized:
                raise FmiCallError(f"fmi3SetFloat64: parameter {name} = {shown} refused: a fixed parameter can be set "
                                   "only before fmi3ExitInitializationMode")
            plan.append((s, values[pos : pos + s.stop - s.start]))
            pos += s.stop - s.start
        if pos != len(values):
            raise FmiCallError(f"fmi3SetFloat64: nValues = {len(values)}, but the value references name {pos} values")
        for s, xs in plan:
            self._v[s] = [float(x) for x in xs]

    def get_uint64(self, vrs):
        for vr in vrs:
            if vr != self._vr_n or self._vr_n is None:
                raise FmiCallError(f"fmi3GetUInt64: no UInt64 variable has value reference {vr}")
        return [ctypes.c_uint64(self.n_classes) for _ in vrs]

    def set_uint64(self, vrs, values):
        if len(vrs) != len(values):
            raise FmiCallError(f"fmi3SetUInt64: nValues = {len(values)}, but the value references name {len(vrs)} "
                               "values")
        for vr, x in zip(vrs, values):
            if vr != self._vr_n or self._vr_n is None:
                raise FmiCallError(f"fmi3SetUInt64: no UInt64 variable has value reference {vr}")
            if x != self.n_classes:
                name = self.vars[vr].name
                raise FmiCallError(f"fmi3SetUInt64: {name} = {x} refused: this FMU's size grid has {self.n_classes} "
                                   "classes (fixed when the FMU was built)")

    # ---- life cycle ----------------------------------------------------------------------
    def refuse_configuration(self, text: str):
        """A parameter value is refused: fmi3Error now, and every later step too."""
        self._config_error = text
        raise FmiCallError(f"fmi3ExitInitializationMode: {text}; every step will be refused")

    def exit_initialization_mode(self):
        self._initialized = True
        try:
            self._configure()
        except FmiCallError:
            raise
        except Exception:  # a fault of the code, not of the call: report it whole
            self.refuse_configuration("internal error while initializing: " + traceback.format_exc(limit=3))

    def setup_experiment(self, start_time: float):
        """The FMU's time starts at fmi3EnterInitializationMode's startTime (millfmu's
        wrapper passes it on; pythonfmu3's own drops it)."""
        self._v[0] = float(start_time)

    def do_step(self, current_time: float, step_size: float):
        t = self._v[0]
        scale = max(abs(t), abs(step_size) if math.isfinite(step_size) else 0.0, 1.0)
        if not (math.isfinite(current_time) and abs(current_time - t) <= TIME_RTOL * scale):
            raise FmiCallError(f"fmi3DoStep refused, state unchanged: currentCommunicationPoint = {current_time!r} s "
                               f"is not the FMU's time {t!r} s (the previous communication point plus its step, or the "
                               f"time of the state set last; allowed within a relative {TIME_RTOL:g})")
        if self._config_error is not None:
            self.log(f"doStep at t = {current_time!r} s refused: {self._config_error}", Fmi3Status.error)
            return Fmi3StepResult(status=Fmi3Status.error)
        try:
            self._take_step(step_size)
        except self.REFUSED as e:
            self.log(f"doStep at t = {current_time!r} s refused, state unchanged: {self._refusal(e)}",
                     Fmi3Status.discard)
            return Fmi3StepResult(status=Fmi3Status.discard)
        except Exception:
            self.log(f"doStep at t = {current_time!r} s failed, state unchanged: " + traceback.format_exc(limit=4),
                     Fmi3Status.error)
            return Fmi3StepResult(status=Fmi3Status.error)
        self._v[0] = current_time + step_size  # time: the first value (declared first)
        return True

    def _refusal(self, e: Exception) -> str:
        return str(e)

    # ---- FMU state ---------------------------------------------------------------------
    def _get_fmu_state(self):
        """The whole state as plain JSON-able data (copies: the wrapper keeps the object)."""
        return {"format": STATE_FORMAT, "fmu": type(self).__name__, "values": list(self._v),
                "config_error": self._config_error,
                "initialized": self._initialized, **self._state()}

    def _set_fmu_state(self, state):
        if (not isinstance(state, dict) or state.get("format") != STATE_FORMAT
                or state.get("fmu") != type(self).__name__):
            got = (f"{state.get('format')!r} of {state.get('fmu')!r}" if isinstance(state, dict)
                   else type(state).__name__)
            raise FmiCallError(f"fmi3SetFMUState: the state ({got}) is not a state of this FMU ({STATE_FORMAT!r} of "
                               f"{type(self).__name__!r}); nothing changed")
        keep = self._get_fmu_state()
        try:
            self._apply_state(state)
        except Exception as e:
            self._apply_state(keep)
            raise FmiCallError(
                f"fmi3SetFMUState: state not applied, nothing changed: {type(e).__name__}: {e}") from None

    def _apply_state(self, state):
        if len(state["values"]) != len(self._v):
            raise ValueError(f"{len(state['values'])} values, this FMU has {len(self._v)}")
        self._restore(state)
        self._v[:] = [float(x) for x in state["values"]]  # in place: the getters hold it
        self._config_error = state["config_error"]
        self._initialized = bool(state["initialized"])

    @staticmethod
    def _digest(state) -> str:
        return hashlib.sha256(json.dumps(state, sort_keys=True, separators=(",", ":")).encode()).hexdigest()

    @classmethod
    def _fmu_state_to_bytes(cls, state) -> bytes:
        """JSON of the state with its sha256 (see :meth:`_fmu_state_from_bytes`)."""
        return json.dumps({"sha256": cls._digest(state), "state": state}, separators=(",", ":")).encode("utf-8")

    @classmethod
    def _fmu_state_from_bytes(cls, state: bytes):
        """The state in ``state``; refused (fmi3Error, the instance unchanged) when it is not
        JSON or its sha256 does not match its content (one changed digit is still JSON)."""
        try:
            blob = json.loads(bytes(state).decode("utf-8"))
            inner = blob["state"]
            digest = blob["sha256"]
        except (ValueError, KeyError, TypeError) as e:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
            raise FmiCallError(f"fmi3DeserializeFMUState: {len(state)} bytes that are not a serialized state of this "
                               f"FMU ({type(e).__name__}: {e})") from None
        if digest != cls._digest(inner):
            raise FmiCallError(f"fmi3DeserializeFMUState: {len(state)} bytes refused: the state's sha256 does not "
                               "match its content (damaged or edited); nothing changed")
        return inner

    # ---- model description -------------------------------------------------------------
    def register_used_units(self, exponents):
        """UnitDefinitions for the units the variables use; ``exponents(name)`` -> {base unit: exponent}."""
        used = list(dict.fromkeys(self._unit_of.values()))
        self.register_units([Unit(u, **exponents(u)) for u in used])

    def complete_xml(self, root: Element, description: str) -> Element:
        """pythonfmu3's description with exact start values (it prints 16 digits, and cuts an
        array's longer than 1000 characters to the first character) and outputs declared free
        of direct feedthrough (they change only in a step)."""
        root.set("description", description)
        by_name = {v.name: vr for vr, v in self.vars.items()}
        for el in root.find("ModelVariables"):
            if el.tag == "Float64" and el.get("start") is not None:
                el.set("start", " ".join(repr(x) for x in self._v[self._slices[by_name[el.get("name")]]]))
        for out in root.find("ModelStructure").iter("Output"):
            out.set("dependencies", "")
        return root
