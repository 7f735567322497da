"""Calibration: fit scene constants to a user's measured batch grinding data, with intervals.

A material's breakage energy (and the share of a collision's energy that reaches a
particle) is what a process engineer pins with his own grinding test. :func:`calibrate`
fits one or two scene constants (:data:`FITTABLE`) to measured batch data at the scene's
operating point:

- residuals: ln(x_model / x_data) for characteristic sizes (``x10_m``, ``x50_m``,
  ``x90_m``), Q3_model(x) - Q3_data for full size distributions (``x_m``, ``Q3``), and
  f_model - f_data for the disrupted fraction of cells;
- scipy.optimize.least_squares on the logarithm of each constant, inside its physical
  bounds (eta_E in (0, 1]; the others > 0) and a search range of :data:`SEARCH_DECADES`
  decades around the start;
- 95 % confidence intervals from the Jacobian at the optimum in log space, and the
  correlation of a pair. ``error_model="per_sample"`` (the default where a time has more than
  one value: x10/x50/x90 of one sample, or a Q3 curve) allows an error shared by all values
  of one sample (a laser-diffraction measurement shifts a sample's whole distribution): a
  cluster-robust (sandwich) covariance with one cluster per measurement time, the CR2
  small-sample correction (Bell & McCaffrey 2002; Pustejovsky & Tipton 2018) and Student's t
  with G - 1 degrees of freedom (G times). ``error_model="independent"`` (and data with one
  value per time) takes every value's error as independent: Gauss-Newton s^2 (J^T J)^-1,
  s^2 = sum r^2 / (n - p), Student's t with n - p degrees of freedom (Bates & Watts 1988,
  ch. 2). With shared errors the independent interval is too narrow (about 70 % coverage in
  the project's held-out study of x10/x50/x90 data);
- a lack-of-fit warning (:attr:`Calibration.lack_of_fit`) when the residuals are systematic:
  the per-time mean residual trends with time (Kendall's tau, exact, p < :data:`LACK_OF_FIT_P`)
  or, for x10/x50/x90, one size column lies off the others at every time (F test of column
  terms against the scatter left by each time's mean and the Jacobian, p < :data:`LACK_OF_FIT_P`).

A constant the data cannot pin is refused by name (:class:`CalibrationError`): its interval
spans more than :data:`MAX_INTERVAL_FACTOR`, a pair's |correlation| exceeds
:data:`MAX_CORRELATION`, it ends on a bound (which bound, and which constant to free
instead), the model does not respond to it, it lies on a plateau (the objective at the far
end of its search range is within the noise of the optimum: the data bound it on one side
only), or there are fewer values than constants.

The one-datum case (one value, one constant: the exact solution, no interval) is seed 000's
calibration of the two stress models at one reference point: the simple model's k_c
(``mill.stress_frequency_factor``) and the detailed model's eta_E
(``kinetics.energy_transfer``); :func:`fit` and :data:`SHIPPED` keep that interface.
"""

from __future__ import annotations

import csv
import datetime
import hashlib
import io
import json
import math
import os
import re
import shutil
import sys
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from .api import load_scene as load_any
from .mill import MillModel, StepError, q3_at_edges
from .scene import Scene, load_scene, number_key, scene_to_dict, toml_text, toml_value


class CalibrationError(ValueError):
    """Data or a fit that cannot give the constants asked for: says which item, why and what
    to do instead. Nothing is written."""


@dataclass(frozen=True)
class Constant:
    """A scene constant that :func:`calibrate` may fit: dotted scene key, unit, physical
    bounds (lower exclusive, upper inclusive) and the scenes it acts in."""

    key: str
    unit: str
    lo: float
    hi: float
    models: tuple  # kinetics models it acts in
    materials: tuple  # material models it acts in
    meaning: str


#: The constants a calibration may fit, by scene key.
FITTABLE = {c.key: c for c in (
    Constant("kinetics.energy_transfer", "1", 0.0, 1.0, ("detailed",), ("mineral", "yeast", "austin"),
             "share eta_E of a collision's energy that reaches a captured particle (at most all of it)"),
    Constant("material.x_w_min_J_m_per_kg", "J m/kg", 0.0, math.inf, ("simple", "detailed"), ("mineral",),
             "Vogel-Peukert mass-specific threshold energy times size, x W_m,min"),
    Constant("material.f_mat_kg_per_J_m", "kg/(J m)", 0.0, math.inf, ("simple", "detailed"), ("mineral",),
             "Vogel-Peukert material strength parameter f_Mat"),
    Constant("material.burst_energy_median_J", "J", 0.0, math.inf, ("simple", "detailed"), ("yeast",),
             "median burst energy of a cell"),
    Constant("mill.stress_frequency_factor", "1", 0.0, math.inf, ("simple",), ("mineral", "yeast", "austin"),
             "Kwade's stress-frequency constant k_c"),
)}

#: Refusal limits: a 95 % interval wider than this factor (upper / lower) does not pin the
#: constant; nor does a pair correlated beyond this.
MAX_INTERVAL_FACTOR = 10.0
MAX_CORRELATION = 0.99
#: Search range of a constant without a finite physical bound: this many decades either side
#: of its start. An optimum at its end means the data push the constant towards 0 or
#: infinity, where it stops acting: it is not pinned.
SEARCH_DECADES = 8.0
#: Forward-difference step of the Jacobian in ln(constant) [-]: the model is smooth in its
#: constants (exact exponential steps), so the truncation error (about h) stays far below the
#: data's noise while round-off (about 1e-16 / h) does too.
JAC_STEP = 1e-6
#: Error models of :func:`calibrate`: every value's error independent, or an error shared by
#: the values of one sample (one measurement time) on top of independent ones.
ERROR_MODELS = ("independent", "per_sample")
#: Small-sample correction of the cluster-robust covariance: "CR2" (bias-reduced, Bell &
#: McCaffrey 2002) or "CR1" (G/(G-1) (n-1)/(n-p)); intervals use t with G - 1 dof either way.
CLUSTER_CORRECTION = "CR2"
#: Significance level of the lack-of-fit tests (each); with independent or per-sample noise
#: each fires in at most this share of fits.
LACK_OF_FIT_P = 0.01
#: Smallest systematic residual reported as lack of fit [residual unit: 1 % of a size, 0.01 of
#: Q3 or of a fraction]: below it a pattern is the model's curvature in its constants (the
#: tests are exact only for a linear model), far inside what a size analysis reproduces.
LACK_OF_FIT_MIN = 0.01
#: Measured quantities, by column: residual kind and unit.
SIZE_COLUMNS = ("x10_m", "x50_m", "x90_m")


# ---- data ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Data:
    """Measured batch data: ``kind`` 'sizes' (columns among x10_m, x50_m, x90_m), 'q3'
    (x_m [m] and Q3 [-] per time) or 'disrupted' (disrupted_fraction [-]); ``rows`` are
    (t_s, column, x_m or None, value). ``source``: the file (or 'data') and ``sha256`` its
    bytes; ``feed_rows`` counts rows at t = 0, which describe the feed and are not fitted."""

    kind: str
    rows: tuple
    source: str = "data"
    sha256: str = ""
    feed_rows: int = 0
    #: What the data's reader noticed that does not stop a fit (duplicate measurements).
    notes: tuple = ()

    @property
    def times_s(self) -> list:
        return sorted({r[0] for r in self.rows})

    @property
    def n(self) -> int:
        return len(self.rows)


def _num(text, where: str, col: str) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: column {col} = {text!r}: not a number") from None
    if not math.isfinite(v):
        raise CalibrationError(f"{where}: column {col} = {text!r}: must be finite")
    return v


def parse_data(text: str, source: str = "data") -> Data:
    """Data from CSV text: a header row, then one row per time (per time and size for Q3).

    Columns: ``t_s`` [s] and either some of ``x10_m``/``x50_m``/``x90_m`` [m], or ``x_m`` [m]
    and ``Q3`` [-], or ``disrupted_fraction`` [-]. Lines starting with '#' are comments; an
    empty cell is a value not measured. Rows at t_s = 0 are the feed (the scene's) and are
    not fitted. Raises :class:`CalibrationError` naming the line and column."""
    text = text.removeprefix("\ufeff")  # a byte-order mark, as spreadsheet programs write UTF-8
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise CalibrationError(f"{source}: no header and no data rows")
    reader = list(csv.reader(io.StringIO("\n".join(ln for _, ln in lines))))
    header = [h.strip() for h in reader[0]]
    allowed = ("t_s",) + SIZE_COLUMNS + ("x_m", "Q3", "disrupted_fraction")
    unknown = [h for h in header if h not in allowed]
    if unknown or "t_s" not in header or len(set(header)) != len(header):
        raise CalibrationError(f"{source}: header {','.join(header)!r}: needs t_s and either some of x10_m, x50_m, x90_m, or "
                               f"x_m and Q3, or disrupted_fraction (each once)" + (f"; unknown column(s) {unknown}" if unknown else ""))
    cols = set(header) - {"t_s"}
    kinds = {"sizes": cols <= set(SIZE_COLUMNS) and bool(cols), "q3": cols == {"x_m", "Q3"},
             "disrupted": cols == {"disrupted_fraction"}}
    kind = next((k for k, ok in kinds.items() if ok), None)
    if kind is None:
        raise CalibrationError(f"{source}: columns {sorted(cols)}: give either some of x10_m, x50_m, x90_m, or x_m with Q3, "
                               f"or disrupted_fraction, not a mix")
    rows, feed = [], 0
    for (lineno, _), rec in zip(lines[1:], reader[1:]):
        where = f"{source} line {lineno}"
        if len(rec) != len(header):
            raise CalibrationError(f"{where}: {len(rec)} cells, the header has {len(header)}")
        cell = dict(zip(header, (c.strip() for c in rec)))
        t = _num(cell["t_s"], where, "t_s")
        if t < 0.0:
            raise CalibrationError(f"{where}: column t_s = {t:g}: must be >= 0 s")
        if t == 0.0:
            feed += 1
            continue
        if kind == "q3":
            x, q = _num(cell["x_m"], where, "x_m"), _num(cell["Q3"], where, "Q3")
            if x <= 0.0:
                raise CalibrationError(f"{where}: column x_m = {x:g}: must be > 0 m")
            _check_metres(x, where, "x_m")
            if not 0.0 <= q <= 1.0:
                raise CalibrationError(f"{where}: column Q3 = {q:g}: must lie in [0, 1]")
            rows.append((t, "Q3", x, q))
            continue
        for col in sorted(cols):
            if cell[col] == "":
                continue
            v = _num(cell[col], where, col)
            if kind == "disrupted" and not 0.0 <= v <= 1.0:
                raise CalibrationError(f"{where}: column {col} = {v:g}: must lie in [0, 1]")
            if kind == "sizes" and v <= 0.0:
                raise CalibrationError(f"{where}: column {col} = {v:g}: must be > 0 m")
            if kind == "sizes":
                _check_metres(v, where, col)
            rows.append((t, col, None, v))
        if kind == "sizes":
            given = [(c, float(cell[c])) for c in SIZE_COLUMNS if c in cell and cell[c] != ""]
            for (c1, v1), (c2, v2) in zip(given, given[1:]):
                if v1 > v2:
                    raise CalibrationError(f"{where}: {c1} = {v1:g} m is larger than {c2} = {v2:g} m: a size distribution's "
                                           f"x10 <= x50 <= x90; check the columns' order in the header")
    if not rows:
        raise CalibrationError(f"{source}: no measured values after t_s = 0")
    seen, dup = set(), []
    for t, col, x, _ in rows:
        key = (t, col, x)
        if key in seen and key not in dup:
            dup.append(key)
        seen.add(key)
    notes = tuple(f"{source}: {col}{'' if x is None else f' at x_m = {x:g}'} at t_s = {t:g} is given more than once; each is "
                  f"fitted as an independent measurement (average repeats first if they are one sample's)" for t, col, x in dup)
    return Data(kind, tuple(rows), source, hashlib.sha256(text.encode()).hexdigest(), feed, notes)


#: Largest particle size [m] a bead mill's data may give: beyond it a value is taken to be
#: in another unit (a size of 25 meant as micrometres), since mills grind feeds below 1 cm.
MAX_SIZE_M = 0.01


def _check_metres(x: float, where: str, col: str):
    if x > MAX_SIZE_M:
        raise CalibrationError(f"{where}: column {col} = {x:g} m: larger than {MAX_SIZE_M:g} m, which no bead mill grinds; "
                               f"the column is in metres (if {x:g} is in micrometres, write {x * 1e-6:g})")


def read_data(path) -> Data:
    """:func:`parse_data` of a CSV file (UTF-8); the error names the file."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise CalibrationError(f"--data {p}: cannot be read ({e.strerror or e})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise CalibrationError(f"--data {p}: not UTF-8 text (byte {e.start})") from None
    d = parse_data(text, str(p))
    return replace(d, sha256=hashlib.sha256(raw).hexdigest())


# ---- the model at the data ---------------------------------------------------------------------
def _check_scene(scene: Scene):
    if scene.operation.mode != "batch" or scene.run.tip_speed_profile or scene.kinetics.capture != "class":
        raise CalibrationError(f"scene {scene.scene.name!r}: a calibration needs a batch scene at one operating point "
                               "(operation.mode = 'batch', no run.tip_speed_profile, kinetics.capture = 'class')")


def with_values(scene: Scene, values: dict) -> Scene:
    """The scene with dotted keys set to ``values`` (validated as a scene file is)."""
    return load_any(scene, overrides={k: float(v) for k, v in values.items()})


class _Predictor:
    """The model's values at the data's times and sizes for given constants."""

    def __init__(self, scene: Scene, data: Data, check_sizes: bool = True):
        _check_scene(scene)
        self.scene, self.data = scene, data
        self.times = data.times_s
        model = MillModel(scene)
        lo, hi = model.grid.edges_m[0], model.grid.edges_m[-1]
        for t, col, x, v in data.rows:
            size = x if x is not None else (v if col in SIZE_COLUMNS else None)
            if check_sizes and size is not None and not lo <= size <= hi:
                raise CalibrationError(f"{data.source}: {('x_m' if x is not None else col)} = {size:g} m at t_s = {t:g}: outside the "
                                       f"scene's size grid [{lo:.4g}, {hi:.4g}] m; widen [grid] (x_min_m, x_max_m)")
        if data.kind == "disrupted" and scene.material.model != "yeast":
            raise CalibrationError(f"{data.source}: disrupted_fraction needs a cell scene (material.model = 'yeast'), "
                                   f"not {scene.material.model!r}")

    def values(self, scene: Scene) -> np.ndarray:
        """The model's value for each data row (same order) [unit of the row's column]."""
        model = MillModel(scene)
        at, t_prev = {}, 0.0
        for t in self.times:
            out = model.step(t - t_prev)
            t_prev = t
            at[t] = out
        e = np.log(model.grid.edges_m)
        res = []
        for t, col, x, _v in self.data.rows:
            out = at[t]
            if col == "Q3":
                res.append(float(np.interp(math.log(x), e, q3_at_edges(out))))
            else:
                if col not in out:
                    raise CalibrationError(f"{self.data.source}: scene {scene.scene.name!r} has no output {col}")
                res.append(float(out[col]))
        return np.asarray(res)

    def residuals(self, model_values: np.ndarray) -> np.ndarray:
        obs = np.array([r[3] for r in self.data.rows])
        if self.data.kind == "sizes":
            return np.log(model_values / obs)
        return model_values - obs


# ---- the fit -----------------------------------------------------------------------------------
@dataclass
class Fitted:
    """One fitted constant: ``value`` [its unit], ``ci95`` (lower, upper) or None when the data
    leave no degree of freedom, ``start``, ``sd_ln`` (standard error of ln value)."""

    key: str
    unit: str
    value: float
    start: float
    ci95: tuple | None
    sd_ln: float | None


@dataclass
class Calibration:
    """The result of :func:`calibrate`: fitted constants, their correlation, the residuals,
    the calibrated scene and where the data came from."""

    scene: Scene
    constants: dict
    correlation: list | None
    residuals: list
    rms_residual: float
    residual_unit: str
    dof: int
    data_source: str
    data_sha256: str
    evaluations: int
    date_utc: str
    notes: list = field(default_factory=list)
    #: "independent" or "per_sample" (see :func:`calibrate`) and how the intervals were made.
    error_model: str = "independent"
    interval_method: str = ""
    #: Degrees of freedom of the intervals' t quantile (n - p, or G - 1 for per-sample errors).
    interval_dof: int | None = None
    #: What in the residuals is systematic beyond the noise (empty: nothing found).
    lack_of_fit: list = field(default_factory=list)

    def value(self, key: str) -> float:
        return self.constants[key].value

    def to_dict(self) -> dict:
        return {
            "scene": self.scene.scene.name,
            "data": {"file": self.data_source, "sha256": self.data_sha256},
            "date_utc": self.date_utc,
            "method": "scipy.optimize.least_squares on ln(constant) within bounds; 95 % intervals from the Jacobian "
                      f"at the optimum: {self.interval_method}",
            "error_model": self.error_model,
            "interval_degrees_of_freedom": self.interval_dof,
            "lack_of_fit": self.lack_of_fit,
            "constants": {k: {"value": c.value, "unit": c.unit, "start": c.start,
                              "ci95": list(c.ci95) if c.ci95 else None, "sd_ln": c.sd_ln} for k, c in self.constants.items()},
            "correlation": self.correlation,
            "degrees_of_freedom": self.dof,
            "rms_residual": self.rms_residual,
            "residual_unit": self.residual_unit,
            "residuals": self.residuals,
            "model_evaluations": self.evaluations,
            "notes": self.notes,
        }

    def record(self) -> str:
        """One line for the scene's ``scene.calibration``: what was fitted to what."""
        parts = []
        for k, c in self.constants.items():
            ci = f" (95 % interval {c.ci95[0]:.4g} to {c.ci95[1]:.4g})" if c.ci95 else " (exact, no interval)"
            parts.append(f"{k} = {c.value:.6g} {c.unit}{ci}")
        return (f"{', '.join(parts)} fitted at this operating point to {Path(self.data_source).name} (sha256 "
                f"{self.data_sha256[:16]}...) by millfmu calibrate on {self.date_utc}, rms residual {self.rms_residual:.3g} "
                f"({self.residual_unit})")

    def summary(self) -> str:
        out = [f"calibration of {self.scene.scene.name!r} to {self.data_source} ({len(self.residuals)} values, "
               f"{self.dof} degrees of freedom)"]
        for k, c in self.constants.items():
            ci = f"95 % interval [{c.ci95[0]:.4g}, {c.ci95[1]:.4g}]" if c.ci95 else "no interval (no degree of freedom)"
            out.append(f"  {k} = {c.value:.5g} {c.unit}  ({ci}; start {c.start:.4g})")
        if self.correlation is not None and len(self.constants) == 2:
            out.append(f"  correlation of the pair: {self.correlation[0][1]:+.3f}")
        out.append(f"  rms residual {self.rms_residual:.3g} ({self.residual_unit})")
        if self.interval_method:
            out.append(f"  errors: {self.error_model.replace('_', '-')}; intervals: {self.interval_method}")
        out.extend(f"  warning: lack of fit: {w}" for w in self.lack_of_fit)
        out.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(out)


def _other_constants(scene: Scene, key: str) -> list:
    """The constants that could be freed instead of ``key`` in this scene (not those already
    at their finite upper bound, such as eta_E = 1)."""
    return [k for k, c in FITTABLE.items() if k != key and scene.kinetics.model in c.models and scene.material.model in c.materials
            and not number_key(scene, k) >= c.hi]


def _resolve_fit(scene: Scene, fit) -> list:
    keys = [k.strip() for k in (fit.split(",") if isinstance(fit, str) else fit) if k.strip()]
    if not 1 <= len(keys) <= 2 or len(set(keys)) != len(keys):
        raise CalibrationError(f"--fit {','.join(keys)!r}: give one or two different constants among {', '.join(FITTABLE)}")
    for k in keys:
        c = FITTABLE.get(k)
        if c is None:
            raise CalibrationError(f"--fit {k}: not a fittable constant; allowed {', '.join(FITTABLE)}")
        if scene.kinetics.model not in c.models or scene.material.model not in c.materials:
            raise CalibrationError(f"--fit {k}: has no effect in scene {scene.scene.name!r} (kinetics.model = "
                                   f"{scene.kinetics.model!r}, material.model = {scene.material.model!r}); free one of "
                                   f"{', '.join(_other_constants(scene, k)) or '(none)'}")
    return keys


def calibrate(scene, data, fit, start: dict | None = None, progress=None, error_model: str | None = None) -> Calibration:
    """Fit the constants ``fit`` (dotted keys of :data:`FITTABLE`, one or two) of ``scene`` to
    measured batch ``data`` (a :class:`Data`, a CSV path, or CSV text) at the scene's
    operating point. ``start``: start values by key (default: the scene's). ``progress``: a
    callable taking one line per model-evaluation batch (the Jacobian of an iteration).
    ``error_model``: "per_sample" (an error shared by the values of one time, cluster-robust
    intervals; the default where a time has more than one value) or "independent" (the
    default for one value per time).

    Returns a :class:`Calibration`; raises :class:`CalibrationError` when the data cannot pin
    the constants (see the module's docstring) or are malformed."""
    from scipy import stats
    from scipy.optimize import least_squares

    if not isinstance(scene, Scene):
        scene = load_any(scene)
    if not isinstance(data, Data):
        data = parse_data(data, "data") if isinstance(data, str) and "\n" in data else read_data(data)
    keys = _resolve_fit(scene, fit)
    if error_model is not None and error_model.replace("-", "_") not in ERROR_MODELS:
        raise CalibrationError(f"--errors {error_model}: allowed {', '.join(m.replace('_', '-') for m in ERROR_MODELS)}")
    pred = _Predictor(scene, data)
    n, p = data.n, len(keys)
    if n < p:
        raise CalibrationError(f"{data.source}: {n} measured value(s) cannot pin {p} constants ({', '.join(keys)}): "
                               f"fit one of them, or measure at more times")
    starts = [float((start or {}).get(k, number_key(scene, k))) for k in keys]
    for k, v in zip(keys, starts):
        if not v > 0.0:
            raise CalibrationError(f"--fit {k}: starts from {v:g} {FITTABLE[k].unit}, the scene's value; a fit in ln({k}) needs "
                                   f"a positive start: set one in the scene (or --start {k}=VALUE)")
    x0 = np.log(starts)
    lo, hi = [], []
    for k, s in zip(keys, x0):
        c = FITTABLE[k]
        hi.append(min(s + SEARCH_DECADES * math.log(10), math.log(c.hi)) if math.isfinite(c.hi) else s + SEARCH_DECADES * math.log(10))
        lo.append(s - SEARCH_DECADES * math.log(10))
    x0 = np.minimum(x0, hi)
    count = {"evals": 0, "iter": 0}

    def scene_at(x):
        return with_values(scene, {k: math.exp(v) for k, v in zip(keys, x)})

    def fun(x):
        count["evals"] += 1
        try:
            r = pred.residuals(pred.values(scene_at(x)))
        except StepError as e:
            raise CalibrationError(f"the model failed at {_fmt(keys, x)}: {e}") from None
        # A size the model grinds below the grid gives ln(0): make it a large, finite residual.
        return np.nan_to_num(r, nan=1e3, posinf=1e3, neginf=-1e3)

    def jac(x):
        f0 = fun(x)
        J = np.empty((n, p))
        for j in range(p):
            h = JAC_STEP if x[j] + JAC_STEP <= hi[j] else -JAC_STEP
            xj = x.copy()
            xj[j] += h
            J[:, j] = (fun(xj) - f0) / h
        count["iter"] += 1
        if progress is not None:
            progress(f"calibrate: iteration {count['iter']}, {count['evals']} model runs, rms residual "
                     f"{math.sqrt(np.mean(f0 ** 2)):.4g}, {_fmt(keys, x)}")
        return J

    res = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0, xtol=1e-10, ftol=1e-12, gtol=1e-12,
                        max_nfev=200)
    x, r = res.x, res.fun
    J = jac(x)
    _refuse_unpinned(scene, keys, x, lo, hi, J, pred, scene_at)
    dof = n - p
    notes = []
    if data.feed_rows:
        notes.append(f"{data.feed_rows} row(s) at t_s = 0 describe the feed (the scene's) and were not fitted")
    groups = np.array([data.times_s.index(row[0]) for row in data.rows])
    n_groups = len(data.times_s)
    # Some time has more than one quantity (x10/x50/x90, Q3 at several sizes): one sample's values, which may
    # share an error. Repeats of one quantity at one time are fitted as independent measurements (Data.notes).
    shared = len({(row[0], row[1], row[2]) for row in data.rows}) > n_groups
    model = "per_sample" if error_model is None and shared else (error_model or "independent").replace("-", "_")
    if model == "per_sample" and not shared:
        notes.append("per-sample errors asked for, but each time has one quantity: they are independent errors")
        model = "independent"
    if model == "per_sample" and n_groups <= p:
        notes.append(f"per-sample errors asked for, but {n_groups} time(s) cannot give an interval for {p} constant(s) "
                     f"with an error shared per time: intervals take every value's error as independent")
        model = "independent"
    sd = corr = tq = None
    method, t_dof = "", None
    if dof > 0:
        JtJinv = np.linalg.inv(J.T @ J)
        if model == "per_sample":
            cov = _cluster_cov(J, r, groups, JtJinv, CLUSTER_CORRECTION)
            t_dof = n_groups - 1
            method = (f"cluster-robust (sandwich) covariance, one cluster per measurement time ({n_groups}), "
                      f"{CLUSTER_CORRECTION} small-sample correction, Student's t with {t_dof} degrees of freedom")
        else:
            cov = float(r @ r) / dof * JtJinv
            t_dof = dof
            method = f"s^2 (J^T J)^-1 (independent errors), Student's t with {t_dof} degrees of freedom"
        sd = np.sqrt(np.diag(cov))
        corr = (cov / np.outer(sd, sd)).tolist()
        tq = float(stats.t.ppf(0.975, t_dof))
        for k, v, s in zip(keys, x, sd):
            if 2.0 * tq * s > math.log(MAX_INTERVAL_FACTOR):
                span = f"a factor {math.exp(2 * tq * s):.3g}" if 2 * tq * s < 700 else "more than 300 decades"
                raise CalibrationError(f"--fit {k}: not pinned by the data: its 95 % interval [{math.exp(max(v - tq * s, -700)):.3g}, "
                                       f"{math.exp(min(v + tq * s, 700)):.3g}] spans {span} (at most a factor "
                                       f"{MAX_INTERVAL_FACTOR:g} allowed); "
                                       + (f"fit {next(o for o in keys if o != k)} alone with {k} set in the scene, or measure "
                                          f"more" if p == 2 else f"fit {_others_text(scene, k, keys)} instead, or measure more"))
        # Whether the data tell a pair apart is the design's (J^T J)^-1 correlation: the cluster-robust
        # estimate of it scatters from sample to sample with few times.
        design = JtJinv[0, 1] / math.sqrt(JtJinv[0, 0] * JtJinv[1, 1]) if p == 2 else 0.0
        if p == 2 and abs(design) > MAX_CORRELATION:
            raise CalibrationError(f"--fit {','.join(keys)}: the data cannot tell the two apart (correlation "
                                   f"{design:+.4f}, at most {MAX_CORRELATION} allowed); fit one of them alone with the other "
                                   f"set in the scene")
        _refuse_plateau(scene, keys, x, lo, hi, fun, r, cov, JtJinv, tq)
    else:
        notes.append("as many values as constants: the exact solution, no interval (no residual degree of freedom)")
    fitted = {}
    for j, k in enumerate(keys):
        ci = None if sd is None else (math.exp(x[j] - tq * sd[j]), math.exp(x[j] + tq * sd[j]))
        fitted[k] = Fitted(k, FITTABLE[k].unit, math.exp(x[j]), math.exp(x0[j]), ci, None if sd is None else float(sd[j]))
    model_values = pred.values(scene_at(x))
    unit = "ln(x_model / x_data)" if data.kind == "sizes" else ("Q3_model - Q3_data" if data.kind == "q3" else
                                                                    "f_model - f_data")
    rows = [{"t_s": t, "quantity": col, **({"x_m": xx} if xx is not None else {}), "data": v, "model": float(m),
             "residual": float(rr)} for (t, col, xx, v), m, rr in zip(data.rows, model_values, r)]
    return Calibration(scene=scene_at(x), constants=fitted, correlation=corr, residuals=rows,
                       rms_residual=float(math.sqrt(np.mean(r ** 2))), residual_unit=unit, dof=dof,
                       data_source=data.source, data_sha256=data.sha256, evaluations=count["evals"],
                       date_utc=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"), notes=notes,
                       error_model=model, interval_method=method, interval_dof=t_dof,
                       lack_of_fit=_lack_of_fit(data, r, J) if dof > 0 else [])


def _cluster_cov(J, r, groups, JtJinv, correction="CR2"):
    """Cluster-robust covariance (JtJ)^-1 (sum_g J_g^T u_g u_g^T J_g) (JtJ)^-1 of the
    constants' logarithms, clusters ``groups`` (one per measurement time). CR2: u_g =
    (I - H_gg)^(-1/2) r_g with the hat matrix H = J (J^T J)^-1 J^T (unbiased when the errors
    are in fact independent and equal); CR1: u_g = r_g, the sum times G/(G-1) (n-1)/(n-p)."""
    n, p = J.shape
    labels = np.unique(groups)
    meat = np.zeros((p, p))
    for g in labels:
        idx = np.flatnonzero(groups == g)
        Jg, rg = J[idx], r[idx]
        if correction == "CR2":
            Hgg = Jg @ JtJinv @ Jg.T
            w, V = np.linalg.eigh(np.eye(len(idx)) - Hgg)
            rg = V @ ((V.T @ rg) / np.sqrt(np.clip(w, 1e-12, None)))
        s = Jg.T @ rg
        meat += np.outer(s, s)
    if correction == "CR1":
        G = len(labels)
        meat *= G / (G - 1) * (n - 1) / max(n - p, 1)
    return JtJinv @ meat @ JtJinv


def _refuse_plateau(scene, keys, x, lo, hi, fun, r, cov, JtJinv, tq):
    """CalibrationError for a constant on a plateau: at the far end of its search range (the
    other constant kept at its fit) the sum of squared residuals rises above the optimum's by
    less than it does at the edge of the 95 % interval (tq^2 var / (J^T J)^-1_jj), so the data
    do not exclude that end: a finite interval from the local slope would be false."""
    s_min = float(r @ r)
    for j, k in enumerate(keys):
        c = FITTABLE[k]
        allowed = tq ** 2 * float(cov[j, j]) / float(JtJinv[j, j])
        for end, side in ((hi[j], "upper"), (lo[j], "lower")):
            if side == "upper" and math.isfinite(c.hi) and end >= math.log(c.hi) - 1e-12:
                continue  # a physical bound (eta_E = 1), not a search end: the data may sit there
            if abs(end - x[j]) < 1e-6:
                continue
            xe = np.array(x, dtype=float)
            xe[j] = end
            try:
                re = fun(xe)
            except CalibrationError:
                continue
            rise = float(re @ re) - s_min
            if rise < allowed:
                bound = "below" if side == "upper" else "above"
                raise CalibrationError(
                    f"--fit {k}: lies on a plateau: at the {side} end of its search range ({math.exp(end):.3g} {c.unit}, "
                    f"{SEARCH_DECADES:g} decades from the start) the sum of squared residuals rises by only {rise:.3g} "
                    f"above the fit's at {math.exp(x[j]):.4g} {c.unit}, less than the noise allows at the edge of a 95 % "
                    f"interval ({allowed:.3g}): the data bound it from {bound} only (the model no longer responds to it "
                    f"there), so no two-sided interval holds; fit {_others_text(scene, k, keys)} instead, or measure where "
                    f"it acts (other times, sizes or operating point)")


def _lack_of_fit(data: Data, r, J) -> list:
    """What in the residuals ``r`` is systematic beyond the noise (independent or shared per
    time): a trend of the per-time mean residual with time (Kendall's tau, exact) and, for
    x10/x50/x90, a size column off the others at every time (F test of column terms in a
    regression of the residuals on each time's mean and the Jacobian ``J``, whose terms take up
    what the fitted constants' own error adds). Each test at level :data:`LACK_OF_FIT_P`."""
    from scipy import stats

    out = []
    times = data.times_s
    r = np.asarray(r, dtype=float)
    means = np.array([np.mean([ri for ri, row in zip(r, data.rows) if row[0] == t]) for t in times])
    if len(times) >= 5:
        tau, pv = stats.kendalltau(times, means, method="exact")
        if np.isfinite(pv) and pv < LACK_OF_FIT_P and np.ptp(means) > 2 * LACK_OF_FIT_MIN:
            text = (f"residuals {'rise' if tau > 0 else 'fall'} with time: mean per time {means[0]:+.3g} at {times[0]:g} s, "
                    f"{means[-1]:+.3g} at {times[-1]:g} s (Kendall's tau {tau:+.2f}, p = {pv:.2g})")
            if data.kind == "sizes":
                text += (f"; the model's sizes {'fall behind' if tau > 0 else 'run ahead of'} the data's as grinding "
                         f"goes on (its grinding kinetics has another shape)")
                signs = []
                for col in SIZE_COLUMNS:
                    sg = "".join("+" if ri > 0 else "-" for ri, row in zip(r, data.rows) if row[1] == col)
                    if sg:
                        signs.append(f"{col.split('_')[0]} {sg}")
                text += "; signs by time: " + ", ".join(signs)
            out.append(text)
    if data.kind == "sizes":
        cols = [c for c in SIZE_COLUMNS if any(row[1] == c for row in data.rows)]
        table = {(row[0], row[1]): ri for ri, row in zip(r, data.rows)}
        full = [t for t in times if all((t, c) in table for c in cols)]
        if len(cols) >= 2 and len(full) >= 3:
            R = np.array([[table[(t, c)] for c in cols] for t in full])
            G, C = R.shape
            dev = R - R.mean(axis=1, keepdims=True)
            col_eff = dev.mean(axis=0)
            # F test of the columns in r ~ time + J (+ column): the fitted constants' own error (r = e - J dtheta)
            # moves the columns apart as the model's sensitivities differ by column; J's terms absorb that.
            where = {(row[0], row[1]): i for i, row in enumerate(data.rows)}
            idx = [where[(t, c)] for t in full for c in cols]
            X0 = np.hstack([np.kron(np.eye(G), np.ones((C, 1))), np.asarray(J, dtype=float)[idx]])
            X1 = np.hstack([X0, np.kron(np.ones((G, 1)), np.eye(C)[:, 1:])])
            y = r[idx]

            def rss(X):
                beta = np.linalg.lstsq(X, y, rcond=None)[0]
                return float(np.sum((y - X @ beta) ** 2)), int(np.linalg.matrix_rank(X))

            (rss0, k0), (rss1, k1) = rss(X0), rss(X1)
            dfn, dfe = k1 - k0, len(y) - k1
            if dfn < 1 or dfe < 1:
                return out
            F = ((rss0 - rss1) / dfn) / (rss1 / dfe) if rss1 > 1e-30 else math.inf
            pv = float(stats.f.sf(F, dfn, dfe)) if math.isfinite(F) else 0.0
            if pv < LACK_OF_FIT_P and np.max(np.abs(col_eff)) > LACK_OF_FIT_MIN:
                spread = col_eff[-1] - col_eff[0]
                offs = ", ".join(f"{c.split('_')[0]} {e:+.3g}" for c, e in zip(cols, col_eff))
                out.append(f"size columns lie off each other at every time: mean residual less each time's mean {offs} "
                           f"(F = {F:.3g}, p = {pv:.2g}); the model's distribution is {'wider' if spread > 0 else 'narrower'} "
                           f"than the data's ({cols[-1].split('_')[0]}/{cols[0].split('_')[0]} off by a factor "
                           f"{math.exp(abs(spread)):.3g})")
    return out


def _fmt(keys, x) -> str:
    return ", ".join(f"{k.rpartition('.')[2]} = {math.exp(v):.5g}" for k, v in zip(keys, x))


def _others_text(scene, key, keys) -> str:
    return " or ".join(o for o in _other_constants(scene, key) if o not in keys) or "(none: measure more)"


def _refuse_unpinned(scene, keys, x, lo, hi, J, pred, scene_at):
    """CalibrationError for a constant on a bound or one the model does not respond to."""
    for j, k in enumerate(keys):
        c = FITTABLE[k]
        at_hi, at_lo = x[j] >= hi[j] - 1e-9, x[j] <= lo[j] + 1e-9
        if not (at_hi or at_lo) and np.any(J[:, j] != 0.0):
            continue
        others = _others_text(scene, k, keys)
        reach = pred.values(scene_at(x))
        got = ", ".join(f"{col} {v:.4g}" for (t, col, _x, _v), v in list(zip(pred.data.rows, reach))[-3:])
        if not (at_hi or at_lo):
            raise CalibrationError(f"--fit {k}: the model stops responding to it at {math.exp(x[j]):.4g} {c.unit} (its effect "
                                   f"has vanished or saturated there) and gives {got}: the data need what it cannot give; free "
                                   f"{others} instead, or start it elsewhere")
        if len(keys) == 2:
            other = next(o for o in keys if o != k)
            raise CalibrationError(f"--fit {','.join(keys)}: the data do not pin the pair: {k} ended on the "
                                   f"{'upper' if at_hi else 'lower'} end of its range ({math.exp(x[j]):.4g} {c.unit}); fit "
                                   f"{other} alone with {k} set in the scene")
        if at_hi and math.isfinite(c.hi) and abs(math.exp(x[j]) - c.hi) <= 1e-9 * c.hi:
            raise CalibrationError(f"--fit {k}: the data are out of reach; {k.rpartition('.')[2]} = {c.hi:g} (its upper bound: "
                                   f"{c.meaning}) gives {got}; free {others} instead")
        side = "upper" if at_hi else "lower"
        raise CalibrationError(f"--fit {k}: ran to the {side} end of its search range ({math.exp(x[j]):.3g} {c.unit}, "
                               f"{SEARCH_DECADES:g} decades from the start) where it stops acting: the data do not pin it "
                               f"(there the model gives {got}); fit {others} instead or start from another value")


# ---- files -------------------------------------------------------------------------------------
_LINE = re.compile(r"^(\s*)([A-Za-z0-9_]+)(\s*=\s*)([^#\n]*?)(\s*(#.*)?)$")
_HEADER = re.compile(r"^\s*\[([A-Za-z0-9_.]+)\]\s*(#.*)?$")


def set_toml_values(text: str, values: dict) -> str:
    """``text`` (a scene file) with dotted keys set to ``values`` (numbers, strings), comments kept; a
    key not in the file is added to its section (the section appended if missing)."""
    lines = text.splitlines()
    todo = dict(values)
    section = ""
    for i, ln in enumerate(lines):
        h = _HEADER.match(ln)
        if h:
            section = h.group(1)
            continue
        m = _LINE.match(ln)
        if m and f"{section}.{m.group(2)}" in todo:
            v = todo.pop(f"{section}.{m.group(2)}")
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{toml_value(v)}{m.group(5)}"
    for key, v in todo.items():
        sec, name = key.rsplit(".", 1)
        idx = next((i for i, ln in enumerate(lines) if (h := _HEADER.match(ln)) and h.group(1) == sec), None)
        if idx is None:
            lines += ["", f"[{sec}]", f"{name} = {toml_value(v)}"]
        else:
            lines.insert(idx + 1, f"{name} = {toml_value(v)}")
    return "\n".join(lines) + "\n"


def _scene_text(scene: Scene, scene_path) -> str:
    """The text the calibrated scene is written from: the scene file (comments kept), the
    embedded default scene's for ``scene_path = "default"``, else the resolved scene."""
    if scene_path == "default":
        from .scene import default_scene_text

        return default_scene_text()
    if scene_path is not None:
        return Path(scene_path).read_text(encoding="utf-8")
    return toml_text(scene_to_dict(scene))


def write(cal: Calibration, out_dir, scene_path=None) -> list:
    """Write ``out_dir/calibrated.toml`` (the scene with the fitted values, headed by a comment
    naming the data file, its sha256 and the date) and ``out_dir/calibration.json``; both
    appear together or not at all."""
    from .runner import check_out_dir, staging_dir

    out = check_out_dir(out_dir)
    head = (f"# Calibrated by millfmu calibrate on {cal.date_utc}: {', '.join(cal.constants)} fitted to\n"
            f"# {Path(cal.data_source).name} (sha256 {cal.data_sha256}); values, 95 % intervals and residuals in\n"
            f"# calibration.json. Fitted at this scene's operating point.\n")
    for k, c in cal.constants.items():
        ci = f"[{c.ci95[0]:.4g}, {c.ci95[1]:.4g}]" if c.ci95 else "(no interval)"
        head += f"#   {k} = {c.value:.6g} {c.unit}, 95 % interval {ci}\n"
    # the constants with an interval, which the prediction band carries through the model
    fitted = [(k, c.ci95) for k, c in cal.constants.items() if c.ci95]
    text = head + set_toml_values(_scene_text(cal.scene, scene_path),
                                  {**{k: c.value for k, c in cal.constants.items()}, "scene.calibration": cal.record(),
                                   "scene.fitted": [k for k, _ in fitted],
                                   "scene.fitted_ci95_low": [float(ci[0]) for _, ci in fitted],
                                   "scene.fitted_ci95_high": [float(ci[1]) for _, ci in fitted]})
    check = load_any(text)
    for k, c in cal.constants.items():
        if number_key(check, k) != c.value:  # pragma: no cover - set_toml_values is tested
            raise CalibrationError(f"calibrated.toml: {k} did not take the fitted value")
    tmp = staging_dir(out, ".millfmu-")
    try:
        (tmp / "calibrated.toml").write_text(text, encoding="utf-8")
        (tmp / "calibration.json").write_text(json.dumps(cal.to_dict(), indent=1), encoding="utf-8")
        out.mkdir(parents=True, exist_ok=True)
        written = []
        for name in ("calibrated.toml", "calibration.json"):
            os.replace(tmp / name, out / name)
            written.append(out / name)
        return written
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ---- seed 000's one-datum calibration ---------------------------------------------------------
#: Quantities a datum may name: output key -> (whether it rises with the rates, unit).
QUANTITIES = {"disrupted_fraction": (True, "1"), "x50_m": (False, "m")}
#: The constant each model keeps free: model -> (scene section, key).
CONSTANTS = {"simple": ("mill", "stress_frequency_factor"), "detailed": ("kinetics", "energy_transfer")}


@dataclass(frozen=True)
class Datum:
    """One batch result at the reference point: ``quantity`` (a key of :data:`QUANTITIES`)
    has ``value`` [its unit] after ``t_s`` [s]; ``source`` says where the number comes from."""

    quantity: str
    value: float
    t_s: float
    source: str

    def data(self) -> Data:
        return Data("disrupted" if self.quantity == "disrupted_fraction" else "sizes",
                    ((float(self.t_s), self.quantity, None, float(self.value)),), self.source)


@dataclass(frozen=True)
class Pair:
    """A shipped calibration: the simple and the detailed scene of one material at one
    reference point (example file names; None is the embedded default scene), the datum the
    simple model's k_c was fitted to, and the stand-in curve (``data``, a file in
    millfmu/data/examples; the datum is one of its points) the detailed model's material
    constant ``detailed_key`` was fitted to with eta_E at its bound 1."""

    material: str
    simple: str | None
    detailed: str | None
    datum: Datum
    data: str
    detailed_key: str

    def scenes(self) -> tuple[Scene, Scene]:
        return example_scene(self.simple), example_scene(self.detailed)

    def data_path(self):
        return resources.files(__name__.rpartition(".")[0] + ".data").joinpath("examples", self.data)


#: The shipped pairs. Neither datum nor curve is a measurement of this mill: the sources hold
#: no breakage rate measured in it (seed 000's measured rates are in the part of the paper
#: the project does not have). Each stands in for the experiment a user fits to.
SHIPPED = (
    Pair("yeast", "yeast_disruption.toml", "yeast_disruption_detailed.toml",
         Datum("disrupted_fraction", 0.80, 600.0,
               "stand-in datum: 80 % of the cells disrupted after 10 min, the result the shipped simple "
               "example gave before its burst energies were put on a physical footing"),
         "yeast_standin_batch.csv", "material.burst_energy_median_J"),
    Pair("limestone", "limestone_simple.toml", None,
         Datum("x50_m", 2.88e-6, 1800.0,
               "stand-in datum: x50 = 2.88 um after 30 min from the 10 um feed, the shipped simple model's "
               "result with k_c = 1 and the earlier assumed breakage energies, which the flowsheets were tuned with"),
         "limestone_standin_batch.csv", "material.f_mat_kg_per_J_m"),
)


def example_scene(name: str | None) -> Scene:
    """A shipped example scene by file name (None: the embedded default scene)."""
    if name is None:
        return load_scene(None)
    return load_scene(resources.files(__name__.rpartition(".")[0] + ".data").joinpath("examples", name))


def with_model(scene: Scene, model: str) -> Scene:
    """The scene with ``kinetics.model`` set to ``model`` ('simple' or 'detailed')."""
    return replace(scene, kinetics=replace(scene.kinetics, model=model))


def constant(scene: Scene, model: str) -> float:
    """The model's fitted constant in the scene: k_c (simple) or eta_E (detailed)."""
    sec, key = CONSTANTS[model]
    return float(getattr(getattr(scene, sec), key))


def with_constant(scene: Scene, model: str, value: float) -> Scene:
    """The scene with the model's constant set to ``value``."""
    sec, key = CONSTANTS[model]
    return replace(scene, **{sec: replace(getattr(scene, sec), **{key: float(value)})})


def batch_value(scene: Scene, quantity: str, t_s: float) -> float:
    """``quantity`` after ``t_s`` seconds of batch operation at the scene's operating point
    (one exact step with the rates frozen there, equal to any number of smaller steps to
    round-off)."""
    if quantity not in QUANTITIES:
        raise ValueError(f"datum quantity {quantity!r}: allowed {', '.join(QUANTITIES)}")
    d = Datum(quantity, math.nan, t_s, "")
    return float(_Predictor(scene, d.data(), check_sizes=False).values(scene)[0])


def fit(scene: Scene, model: str, datum: Datum, key: str | None = None) -> float:
    """The constant (default: the model's, k_c or eta_E) for which the scene run with
    ``model`` reproduces the datum: :func:`calibrate` with one value and one constant.
    Raises :class:`CalibrationError` (a ValueError) naming what the model reaches when the
    datum is out of reach."""
    base = with_model(scene, model)
    key = key or ".".join(CONSTANTS[model])
    return calibrate(base, datum.data(), [key]).value(key)


def check(pair: Pair, refit: bool = True) -> dict:
    """The pair's calibration, for the record and the tests: both models' results at the
    datum's time with the shipped constants; with ``refit`` the simple model's k_c fitted
    anew to the datum and the detailed model's material constant to the stand-in curve
    (value and 95 % interval)."""
    simple, detailed = pair.scenes()
    d = pair.datum
    out = {
        "material": pair.material,
        "quantity": d.quantity,
        "t_s": d.t_s,
        "datum": d.value,
        "source": d.source,
        "k_c": constant(simple, "simple"),
        "energy_transfer": constant(detailed, "detailed"),
        "detailed_key": pair.detailed_key,
        "detailed_constant": number_key(detailed, pair.detailed_key),
        "detailed_data": pair.data,
        "simple": batch_value(with_model(simple, "simple"), d.quantity, d.t_s),
        "detailed": batch_value(with_model(detailed, "detailed"), d.quantity, d.t_s),
    }
    if refit:
        out["k_c_fit"] = fit(simple, "simple", d)
        with resources.as_file(pair.data_path()) as path:
            c = calibrate(detailed, read_data(path), [pair.detailed_key])
        f = c.constants[pair.detailed_key]
        out["detailed_constant_fit"] = f.value
        out["detailed_constant_ci95"] = list(f.ci95) if f.ci95 else None
        out["detailed_rms_residual"] = c.rms_residual
    return out


# ---- command line ------------------------------------------------------------------------------
def _cmd_calibrate(args) -> int:
    from .runner import OutputError, check_out_dir
    from .scene import SceneError

    try:
        scene = load_scene(args.scene)
        if args.out:
            check_out_dir(args.out)
        say = (lambda line: print(line, file=sys.stderr, flush=True)) if not args.quiet else None
        start = {}
        for item in args.start:
            k, sep, v = item.partition("=")
            try:
                start[k.strip()] = float(v)
            except ValueError:
                raise CalibrationError(f"--start {item!r}: expected KEY=VALUE with a number") from None
            if not sep or k.strip() not in FITTABLE:
                raise CalibrationError(f"--start {item!r}: expected KEY=VALUE with KEY among {', '.join(FITTABLE)}")
        data = read_data(args.data)
        for note in data.notes:
            print(f"millfmu calibrate: warning: {note}", file=sys.stderr)
        cal = calibrate(scene, data, args.fit, start=start, progress=say, error_model=getattr(args, "errors", None))
        print(cal.summary())
        if args.out:
            files = write(cal, args.out, scene_path=args.scene or "default")
            print("wrote " + ", ".join(str(f) for f in files))
    except (CalibrationError, SceneError, OutputError) as e:
        print(f"millfmu: error: {e}", file=sys.stderr)
        return 2
    return 0


def register(sub):
    c = sub.add_parser("calibrate", help="fit one or two scene constants to measured batch data (with 95 %% intervals)",
                       description="Fit scene constants to measured batch grinding data at the scene's operating point. "
                                   f"Fittable: {', '.join(FITTABLE)}.")
    c.add_argument("scene", nargs="?", default=None, help="scene file (TOML); omitted: the embedded default scene")
    c.add_argument("--data", required=True, help="CSV: t_s and x10_m/x50_m/x90_m, or x_m and Q3, or disrupted_fraction")
    c.add_argument("--fit", required=True, help="KEY[,KEY]: the constants to fit (dotted scene keys)")
    c.add_argument("--out", default=None, help="folder for calibrated.toml and calibration.json (omitted: print only)")
    c.add_argument("--start", action="append", default=[], metavar="KEY=VALUE",
                   help="start value of a fitted constant (default: the scene's); repeat for a pair")
    c.add_argument("--errors", choices=("independent", "per-sample"), default=None,
                   help="error model of the intervals: per-sample (an error shared by one time's values, cluster-robust; "
                        "the default when a time has several quantities) or independent (the default otherwise)")
    c.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    c.set_defaults(func=_cmd_calibrate)
