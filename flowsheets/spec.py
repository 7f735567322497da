"""Flowsheet files (TOML) -> validated flowsheet: units, parameters, connections. SI units.

A flowsheet file::

    connections = [
        "tank.outflow_mass_flow -> mill.feed_mass_flow",
        "tank.psd[*] -> mill.psd_in[*]",      # a whole size distribution, class by class
    ]
    products = ["mill.product_mass_flow"]     # mass flows leaving the flowsheet

    [flowsheet]
    name = "..."
    t_end_s = 1800.0
    step_s = 5.0                     # communication step
    algorithm = "jacobi"             # or "gauss-seidel"
    order = ["tank", "mill"]         # Gauss-Seidel order (default: the order of [units])
    max_halvings = 0                 # retries of a discarded step, each with half the step
    output_interval_s = 30.0         # default: every step

    [units.mill]                     # unit names: letters, digits, '_'
    type = "mill"                    # mill, feed, tank, classifier, pi
    [units.mill.scene]               # mill: overrides of the default scene (millfmu scene keys)
    operation = { mode = "continuous", n_tanks = 3 }
    [units.mill.start]               # start values of FMI variables (inputs, parameters)
    tip_speed = 10.0

All units share the size grid of the mills' scene (mills must agree on it). Unit keys carry
their units in their names as in scene files. A missing, mistyped, unknown or out-of-range
value raises :class:`FlowsheetError` naming the key, the value and what is allowed.
"""

from __future__ import annotations

import copy
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np

from millfmu.kinetics.grid import SizeGrid
from millfmu.mill import psd_fractions
from millfmu.scene import SceneError, default_scene_text, did_you_mean, scene_from_dict
from millfmu.text_files import NotUtf8, utf8_text

ALGORITHMS = ("jacobi", "gauss-seidel")
UNIT_TYPES = ("mill", "feed", "tank", "classifier", "pi")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_CONN = re.compile(
    r"^\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)(\[(\*|\d+)\])?\s*->\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)(\[(\*|\d+)\])?\s*$")


class FlowsheetError(ValueError):
    """A flowsheet value is missing, mistyped or out of range. ``key`` is the dotted key."""

    def __init__(self, key: str, value, allowed: str, source: str = "flowsheet"):
        self.key, self.value, self.allowed, self.source = key, value, allowed, source
        shown = "(missing)" if value is _MISSING else repr(value)
        super().__init__(f"{source}: {key} = {shown}: {allowed}")


_MISSING = object()

#: Per unit type: key -> (default or _MISSING, check, description). Checks return an error
#: text or None.


def _take(given: dict, spec: dict, prefix: str, source: str) -> dict:
    """Each key of ``spec`` (key -> (default, check, ...)) from ``given``, else its default:
    a required key (default _MISSING) that is missing, or a value its check refuses (the
    check returns the reason), is a FlowsheetError naming ``prefix.key``."""
    out = {}
    for k, (default, check, *_doc) in spec.items():
        v = given.get(k, default)
        if v is _MISSING:
            raise FlowsheetError(f"{prefix}.{k}", _MISSING, "required", source)
        if v is not None and (err := check(v)):
            unit = _unit_of(k)
            if unit and err.startswith("must be ") and err[-1].isdigit():
                err += f" {unit}"  # the bounds in the key's unit
            raise FlowsheetError(f"{prefix}.{k}", v, err, source)
        out[k] = v
    return out


#: a key's unit by its name's suffix (longest first), for the bounds a refusal names
_SUFFIX_UNITS = (("_kg_per_s", "kg/s"), ("_m_per_s", "m/s"), ("_kg_per_m3", "kg/m3"), ("_Pa_s", "Pa s"),
                 ("_kg", "kg"), ("_s", "s"), ("_m", "m"))


def _unit_of(key: str) -> str:
    return next((u for suf, u in _SUFFIX_UNITS if key.endswith(suf)), "")


def _num(lo=None, hi=None, lo_open=False, hi_open=False):
    def check(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return "must be a finite number"
        if lo is not None and (v < lo or (lo_open and v == lo)):
            return f"must be {'>' if lo_open else '>='} {lo:g}" + (f" and {'<' if hi_open else '<='} {hi:g}"
                                                                   if hi is not None else "")
        if hi is not None and (v > hi or (hi_open and v == hi)):
            return f"must be {'<' if hi_open else '<='} {hi:g}" + (f" and {'>' if lo_open else '>='} {lo:g}"
                                                                   if lo is not None else "")
        return None
    return check


def _str(choices):
    def check(v):
        return None if v in choices else "allowed: " + ", ".join(repr(c) for c in choices)
    return check


def _any(v):
    return None


UNIT_KEYS = {
    "mill": {
        "scene": ({}, lambda v: None if isinstance(v, dict) else "must be a table of scene overrides",
                  "overrides of the default scene"),
    },
    "feed": {
        "mass_flow_kg_per_s": (_MISSING, _any,
                               "solids mass flow: a number, or [[t_s, kg/s], ...] (piecewise linear; two points at one "
                               "time make a step)"),
        "psd": (None, _any, "size distribution (a scene size distribution table, default the mill's feed), or a list "
                            "of them each with t_s"),
        "solids_mass_fraction": (0.2, _num(0.0, 1.0, True, True), "solids mass fraction of the fed suspension"),
        "event_tolerance_s": (0.0, _num(0.0), "refuse a step holding a jump more than this before its end (0: never)"),
    },
    "tank": {
        "pump_mass_flow_kg_per_s": (0.0, _num(0.0, 1e3),
                                    "suspension mass flow of the outlet pump (without level control)"),
        "level_setpoint_kg": (0.0, _num(0.0, 1e7), "suspension mass held by level control of the pump (0: off)"),
        "level_time_constant_s": (60.0, _num(0.0, 1e6, True), "time constant of the level control"),
        "pump_start_s": (0.0, _num(0.0), "time from which the pump runs"),
        "initial_holdup_kg": (0.0, _num(0.0, 1e6), "solids in the tank at the start"),
        "initial_solids_mass_fraction": (0.2, _num(0.0, 1.0, True, True), "solids mass fraction at the start"),
        "initial_psd": (None, _any,
                        "size distribution at the start (a scene size distribution table; default the mill's feed)"),
    },
    "classifier": {
        "cut_size_m": (_MISSING, _num(0.0, 1.0, True), "cut size"),
        "sharpness": (3.0, _num(0.0, 100.0, True), "sharpness kappa of the Tromp curve"),
        "bypass": (0.0, _num(0.0, 1.0, False, True), "fraction of the feed reaching the coarse stream unclassified"),
        "liquid_to_coarse": (0.3, _num(0.0, 1.0), "fraction of the liquid going to the coarse stream"),
    },
    "pi": {
        "setpoint": (_MISSING, _num(), "setpoint of the measurement [measurement_unit]"),
        "kp": (_MISSING, _num(0.0), "proportional gain [output_unit/measurement_unit]"),
        "ki": (_MISSING, _num(0.0), "integral gain [output_unit/(measurement_unit s)]"),
        "u_min": (_MISSING, _num(), "lower output limit [output_unit]"),
        "u_max": (_MISSING, _num(), "upper output limit [output_unit]"),
        "bias": (_MISSING, _num(), "output at zero error and integral [output_unit]"),
        "direction": (-1.0, lambda v: None if v in (1, -1) else "must be +1 or -1", "+1 direct, -1 reverse acting"),
        "measurement_unit": ("m", _str(("m", "m/s", "kg/s", "kg", "1")), "unit of the measurement"),
        "output_unit": ("m/s", _str(("m", "m/s", "kg/s", "kg", "1")), "unit of the output"),
    },
}
COMMON_KEYS = {"type", "start"}


@dataclass
class Unit:
    name: str
    type: str
    params: dict
    start: dict = field(default_factory=dict)


@dataclass
class Connection:
    src: str
    src_var: str
    dst: str
    dst_var: str

    def __str__(self):
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class Flowsheet:
    name: str
    description: str
    t_end_s: float
    step_s: float
    algorithm: str
    order: list
    max_halvings: int
    output_interval_s: float
    units: dict  # name -> Unit (file order)
    connections: list  # of (line, Connection pattern strings); expanded by the master
    products: list  # of (unit, var)
    mill_scene: dict  # the scene dict all mills share (default scene with overrides)
    base_dir: Path
    source: str

    def with_(self, **changes) -> Flowsheet:
        f = copy.copy(self)
        for k, v in changes.items():
            setattr(f, k, v)
        return f


def parse_connection(line: str, key: str, source: str) -> tuple:
    """'a.x[*] -> b.y[*]' -> (src, var, src_index, dst, var, dst_index); index None, '*' or int."""
    if not isinstance(line, str):
        raise FlowsheetError(key, line, "must be a string 'unit.variable -> unit.variable'", source)
    m = _CONN.match(line)
    if not m:
        raise FlowsheetError(key, line,
                             "must read 'unit.variable -> unit.variable', with [*] on both sides for a whole size "
                             "distribution", source)
    su, sv, _, si, du, dv, _, di = m.groups()
    if (si == "*") != (di == "*"):
        raise FlowsheetError(key, line, "[*] (class by class) must be on both sides or neither", source)
    return su, sv, (None if si is None else si if si == "*" else int(si)), du, dv, (None if di is None else di
                                                                                    if di == "*" else int(di))


def _check_psd_table(v, key, source):
    if not isinstance(v, dict):
        raise FlowsheetError(key, v,
                             "must be a size distribution table (kind = 'lognormal', 'rrsb', 'monodisperse' or "
                             "'table', with its keys)", source)
    try:
        scene_from_dict({"feed": {k: x for k, x in v.items() if k != "t_s"}})
    except SceneError as e:
        raise FlowsheetError(key + e.key[len("feed"):], e.value, e.allowed, source) from None


def load_flowsheet(path) -> Flowsheet:
    """Read and validate a flowsheet file; raises FlowsheetError."""
    path = Path(path)
    source = str(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise FlowsheetError("file", str(path), f"cannot be read ({e.strerror})", source) from None
    try:
        text = utf8_text(raw)
    except NotUtf8 as e:
        raise FlowsheetError("file", str(path), f"is not UTF-8 text (byte {e.start}, line {e.line}); save it as UTF-8 "
                             "(TOML)", source) from None
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise FlowsheetError("file", str(path), f"is not valid TOML ({e})", source) from None
    return flowsheet_from_dict(d, source, path.parent)


def flowsheet_from_dict(d: dict, source: str = "flowsheet", base_dir: Path | None = None) -> Flowsheet:
    vals = _flowsheet_section(d, source)
    units_d = d.get("units")
    if not isinstance(units_d, dict) or not units_d:
        raise FlowsheetError("units", units_d if units_d is not None else _MISSING,
                             "must be a table with at least one unit ([units.NAME] with type = ...)", source)
    units = {}
    mill_scene = None
    for name, u in units_d.items():
        units[name], sd = _unit(name, u, mill_scene, source)
        mill_scene = sd if mill_scene is None else mill_scene
    if mill_scene is None:
        mill_scene = tomllib.loads(default_scene_text())

    order = vals["order"] or list(units)
    if sorted(order) != sorted(units):
        raise FlowsheetError("flowsheet.order", order, "must name every unit once: " + ", ".join(units), source)
    parsed, products = _links(d, units, source)
    return Flowsheet(vals["name"], vals["description"], float(vals["t_end_s"]), float(vals["step_s"]),
                     vals["algorithm"], order,
                     vals["max_halvings"], float(vals["output_interval_s"]), units, parsed, products, mill_scene,
                     base_dir or Path("."), source)


def _flowsheet_section(d: dict, source: str) -> dict:
    """The file's top-level keys checked, and its [flowsheet] values (with their defaults)."""
    allowed_top = {"connections", "products", "flowsheet", "units"}
    for k in d:
        if k not in allowed_top:
            raise FlowsheetError(k, d[k], "unknown key" + did_you_mean(k, allowed_top) + "; allowed: "
                                 + ", ".join(sorted(allowed_top)), source)
    fs = d.get("flowsheet", {})
    fs_keys = {"name": ("unnamed", lambda v: None if isinstance(v, str) else "must be a string"),
               "description": ("", lambda v: None if isinstance(v, str) else "must be a string"),
               "t_end_s": (_MISSING, _num(0.0, 1e7, True)),
               "step_s": (_MISSING, _num(0.0, 1e5, True)),
               "algorithm": ("jacobi", _str(ALGORITHMS)),
               "order": (None, lambda v: None if isinstance(v, list) and all(isinstance(x, str) for x in v)
                         else "must be a list of unit names"),
               "max_halvings": (0, lambda v: None if isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 30
                                else "must be an integer in [0, 30]"),
               "output_interval_s": (None, _num(0.0, None, True))}
    for k in fs:
        if k not in fs_keys:
            raise FlowsheetError(f"flowsheet.{k}", fs[k], "unknown key" + did_you_mean(k, fs_keys) + "; allowed: "
                                 + ", ".join(fs_keys), source)
    vals = _take(fs, fs_keys, "flowsheet", source)
    n_steps = vals["t_end_s"] / vals["step_s"]
    if abs(n_steps - round(n_steps)) > 1e-9 * n_steps:
        raise FlowsheetError("flowsheet.step_s", vals["step_s"],
                             f"must divide t_end_s = {vals['t_end_s']!r} s into whole steps", source)
    if vals["output_interval_s"] is None:
        vals["output_interval_s"] = vals["step_s"]
    return vals


def _unit(name: str, u, mill_scene: dict | None, source: str) -> tuple[Unit, dict | None]:
    """[units.NAME] checked: the Unit, and for a mill its scene as a dict (None otherwise);
    ``mill_scene``: the first mill's scene so far, whose grid every mill shares."""
    key = f"units.{name}"
    if not _NAME.match(name):
        raise FlowsheetError(key, name, "unit names are letters, digits and '_', not starting with a digit", source)
    if not isinstance(u, dict):
        raise FlowsheetError(key, u, "must be a table", source)
    t = u.get("type", _MISSING)
    if t not in UNIT_TYPES:
        raise FlowsheetError(f"{key}.type", t, "allowed: " + ", ".join(UNIT_TYPES) + did_you_mean(t, UNIT_TYPES),
                             source)
    spec = UNIT_KEYS[t]
    for k in u:
        if k not in spec and k not in COMMON_KEYS:
            raise FlowsheetError(f"{key}.{k}", u[k], f"unknown key for a {t}"
                                 + did_you_mean(k, list(spec) + sorted(COMMON_KEYS)) + "; allowed: "
                                 + ", ".join(list(spec) + sorted(COMMON_KEYS)), source)
    params = _take(u, spec, key, source)
    start = u.get("start", {})
    if not isinstance(start, dict) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                              for x in start.values()):
        raise FlowsheetError(f"{key}.start", start, "must be a table of variable = number", source)
    sd = None
    if t == "mill":
        sd = params["scene_dict"] = _mill_scene(params["scene"], key, mill_scene, source)
    if t == "feed":
        _feed(params, key, source)
    if t == "tank" and params["initial_psd"] is not None:
        _check_psd_table(params["initial_psd"], f"{key}.initial_psd", source)
    if t == "pi" and not params["u_min"] < params["u_max"]:
        raise FlowsheetError(f"{key}.u_min", params["u_min"], f"must be below u_max = {params['u_max']!r}", source)
    return Unit(name, t, params, dict(start)), sd


def _mill_scene(scene_d: dict, key: str, mill_scene: dict | None, source: str) -> dict:
    """A mill's scene: the default scene with the unit's sections over it, continuous and on
    the grid of the other mills (``mill_scene``)."""
    sd = tomllib.loads(default_scene_text())
    for sec, vals_ in scene_d.items():
        if isinstance(vals_, dict) and isinstance(sd.get(sec), dict):
            sd[sec].update(vals_)
        else:
            sd[sec] = vals_
    try:
        scene = scene_from_dict(sd, f"{source}: {key}.scene")
    except SceneError as e:
        raise FlowsheetError(f"{key}.scene.{e.key}", e.value, e.allowed, source) from None
    if scene.operation.mode != "continuous":
        raise FlowsheetError(f"{key}.scene.operation.mode", scene.operation.mode,
                             "must be 'continuous' in a flowsheet (a batch mill has no feed)", source)
    if mill_scene is not None and sd["grid"] != mill_scene["grid"]:
        raise FlowsheetError(f"{key}.scene.grid", sd["grid"],
                             f"must equal the other mills' grid {mill_scene['grid']!r}: all units share one size grid",
                             source)
    return sd


def _feed(params: dict, key: str, source: str):
    """A feed's mass flow [kg/s] as ``params["profile"]`` ([t_s, kg/s] points) and its size
    distributions checked."""
    mf = params["mass_flow_kg_per_s"]
    if isinstance(mf, (int, float)) and not isinstance(mf, bool):
        if not (math.isfinite(mf) and 0.0 <= mf <= 1e3):
            raise FlowsheetError(f"{key}.mass_flow_kg_per_s", mf, "must lie in [0, 1000] kg/s", source)
        params["profile"] = [[0.0, float(mf)]]
    else:
        ok = isinstance(mf, list) and mf and all(isinstance(p, list) and len(p) == 2
                                                 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         for x in p)
                                                 for p in mf)
        if not ok:
            raise FlowsheetError(f"{key}.mass_flow_kg_per_s", mf, "must be a number or a list of [t_s, kg/s] pairs",
                                 source)
        ts = [float(p[0]) for p in mf]
        if any(b < a for a, b in zip(ts, ts[1:])) or ts[0] < 0:
            raise FlowsheetError(f"{key}.mass_flow_kg_per_s", mf, "times must be >= 0 and non-decreasing", source)
        if any(not (0.0 <= p[1] <= 1e3) for p in mf):
            raise FlowsheetError(f"{key}.mass_flow_kg_per_s", mf, "flows must lie in [0, 1000] kg/s", source)
        if any(a == b == c for a, b, c in zip(ts, ts[1:], ts[2:])):
            raise FlowsheetError(f"{key}.mass_flow_kg_per_s", mf, "at most two points may share a time (a step)",
                                 source)
        params["profile"] = [[float(a), float(b)] for a, b in mf]
    psd = params["psd"]
    segs = psd if isinstance(psd, list) else [psd]
    for i, s in enumerate(segs):
        if s is not None:
            _check_psd_table(s, f"{key}.psd" + (f"[{i}]" if isinstance(psd, list) else ""), source)
    if isinstance(psd, list):
        ts = [s.get("t_s", 0.0) for s in segs]
        if not psd or ts[0] != 0.0 or any(b <= a for a, b in zip(ts, ts[1:])):
            raise FlowsheetError(f"{key}.psd", [s.get("t_s") for s in segs],
                                 "a list of size distributions needs t_s increasing from 0", source)


def _links(d: dict, units: dict, source: str) -> tuple[list, list]:
    """The connections, as (line, parsed), and the products, as (unit, variable)."""
    conns = d.get("connections", [])
    if not isinstance(conns, list):
        raise FlowsheetError("connections", conns, "must be a list of 'unit.variable -> unit.variable' strings", source)
    parsed = []
    for i, line in enumerate(conns):
        p = parse_connection(line, f"connections[{i}]", source)
        for u in (p[0], p[3]):
            if u not in units:
                raise FlowsheetError(f"connections[{i}]", line, f"unit {u!r} is not in [units] ({', '.join(units)})",
                                     source)
        parsed.append((line, p))
    prods = d.get("products", [])
    if not isinstance(prods, list):
        raise FlowsheetError("products", prods, "must be a list of 'unit.variable' strings", source)
    products = []
    for i, p in enumerate(prods):
        m = re.match(r"^([A-Za-z_]\w*)\.([A-Za-z_]\w*)$", p) if isinstance(p, str) else None
        if not m or m.group(1) not in units:
            raise FlowsheetError(f"products[{i}]", p, "must be 'unit.variable' with a unit of [units]", source)
        products.append((m.group(1), m.group(2)))
    return parsed, products


def shared_grid(fs: Flowsheet):
    g = fs.mill_scene["grid"]
    return SizeGrid.geometric(g["x_min_m"], g["x_max_m"], g["classes_per_octave"])


def psd_from_table(grid, table: dict | None, mill_scene: dict) -> np.ndarray:
    """Class mass fractions on ``grid`` of a scene size distribution table (None: the mill's feed)."""
    t = mill_scene["feed"] if table is None else {k: v for k, v in table.items() if k != "t_s"}
    return psd_fractions(grid, scene_from_dict({"feed": t}).feed)


def unit_configs(fs: Flowsheet) -> dict:
    """name -> ("mill", scene dict) or (kind, unit.json content) for every unit."""
    grid = shared_grid(fs)
    edges = grid.edges_m.tolist()
    out = {}
    for name, u in fs.units.items():
        p = u.params
        if u.type == "mill":
            out[name] = ("mill", p["scene_dict"])
        elif u.type == "feed":
            segs = p["psd"] if isinstance(p["psd"], list) else [p["psd"]]
            psd_segments = [[float((s or {}).get("t_s", 0.0)), psd_from_table(grid, s, fs.mill_scene).tolist()]
                            for s in segs]
            out[name] = ("feed", {"kind": "feed", "edges_m": edges, "profile": p["profile"],
                                  "psd_segments": psd_segments, "solids_mass_fraction": p["solids_mass_fraction"],
                                  "params": {"event_tolerance": p["event_tolerance_s"]}})
        elif u.type == "tank":
            out[name] = ("tank", {"kind": "tank", "edges_m": edges,
                                  "initial_psd": psd_from_table(grid, p["initial_psd"], fs.mill_scene).tolist(),
                                  "params": {"pump_mass_flow": p["pump_mass_flow_kg_per_s"],
                                             "pump_start_time": p["pump_start_s"],
                                             "level_setpoint": p["level_setpoint_kg"],
                                             "level_time_constant": p["level_time_constant_s"],
                                             "initial_holdup": p["initial_holdup_kg"],
                                             "initial_solids_mass_fraction": p["initial_solids_mass_fraction"]}})
        elif u.type == "classifier":
            out[name] = ("classifier", {"kind": "classifier", "edges_m": edges,
                                        "params": {"cut_size": p["cut_size_m"], "sharpness": p["sharpness"],
                                                   "bypass": p["bypass"],
                                                   "liquid_to_coarse": p["liquid_to_coarse"]}})
        else:
            out[name] = ("pi", {"kind": "pi", "edges_m": edges, "measurement_unit": p["measurement_unit"],
                                "output_unit": p["output_unit"],
                                "params": {k: float(p[k])
                                           for k in ("setpoint", "kp", "ki", "u_min", "u_max", "bias", "direction")}})
    return out
