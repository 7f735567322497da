"""Fitting scene constants to measured batch data: the constants that may be fitted, the
model's values at the data, least squares in ln(constant), and the refusals of constants the
data cannot pin. The method is described in :mod:`millfmu.calibration`; the intervals and
lack-of-fit tests are :mod:`.intervals`.
"""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..api import load_scene as load_any
from ..mill import MillModel, StepError, q3_at_edges
from ..scene import Scene, did_you_mean, number_key
from .intervals import ERROR_MODELS, Intervals, dof_words, error_model as choose_error_model, intervals, lack_of_fit
from .measured import SIZE_COLUMNS, CalibrationError, Data, parse_data, read_data


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


def _check_scene(scene: Scene):
    if scene.operation.mode != "batch" or scene.run.tip_speed_profile or scene.kinetics.capture != "class":
        raise CalibrationError(f"scene {scene.scene.name!r}: a calibration needs a batch scene at one operating point "
                               "(operation.mode = 'batch', no run.tip_speed_profile, kinetics.capture = 'class')")


def with_values(scene: Scene, values: dict) -> Scene:
    """The scene with dotted keys set to ``values`` (validated as a scene file is)."""
    return load_any(scene, overrides={k: float(v) for k, v in values.items()})


#: Relative distance beyond the size grid's end edges within which a measured size is taken
#: as at the edge: psd.csv writes the edges with 6 significant digits (5e-6 relative).
EDGE_TOLERANCE = 1e-5
#: A measured feed (rows at t_s = 0) further than this from the scene's feed draws a warning:
#: sizes by this factor (ln), Q3 and disrupted fractions by this much.
FEED_MISMATCH_LN = math.log(1.1)
FEED_MISMATCH_FRACTION = 0.05


def model_value(out: dict, log_edges, col: str, x: float | None) -> float | None:
    """The model's value of a data row's column: Q3 at size x [m] from the outputs ``out``
    (log_edges: ln of the grid's edges), else the output of that name; None where the
    outputs have none."""
    if col == "Q3":
        return float(np.interp(math.log(x), log_edges, q3_at_edges(out)))
    return float(out[col]) if col in out else None


def feed_mismatch(scene: Scene, data: Data) -> list:
    """A warning (a list of none or one) where the data's feed (rows at t_s = 0) differs
    from the scene's feed, which the fit starts from: sizes beyond 10 %, Q3 or disrupted
    fractions beyond 0.05."""
    if not data.feed:
        return []
    model = MillModel(scene)
    out = model.outputs()
    e = np.log(model.grid.edges_m)
    off = []
    for _t, col, x, v in data.feed:
        m = model_value(out, e, col, x)
        if m is None:
            continue
        if col == "Q3":
            if abs(m - v) > FEED_MISMATCH_FRACTION:
                off.append(f"Q3 at x_m = {x:g} m {v:g} against {m:.3g}")
        elif (abs(math.log(v / m)) > FEED_MISMATCH_LN if col in SIZE_COLUMNS
              else abs(m - v) > FEED_MISMATCH_FRACTION):
            off.append(f"{col} {v:g} against {m:.4g}")
    if not off:
        return []
    return [f"{data.source}: the measured feed (t_s = 0) differs from the scene's ({', '.join(off)}); the fit "
            "starts from the scene's feed: set [feed] to the measured one"]


class Predictor:
    """The model's values at the data's times and sizes for given constants."""

    def __init__(self, scene: Scene, data: Data, check_sizes: bool = True):
        _check_scene(scene)
        self.scene, self.data = scene, data
        self.times = data.times_s
        model = MillModel(scene)
        lo, hi = model.grid.edges_m[0], model.grid.edges_m[-1]
        for t, col, x, v in data.rows:
            size = x if x is not None else (v if col in SIZE_COLUMNS else None)
            # an edge written with 6 significant digits (psd.csv's header) may lie just outside
            if check_sizes and size is not None and not lo * (1 - EDGE_TOLERANCE) <= size <= hi * (1 + EDGE_TOLERANCE):
                raise CalibrationError(f"{data.source}: {('x_m' if x is not None else col)} = {size:.6g} m at t_s = "
                                       f"{t:g}: outside the scene's size grid [{lo:.6g}, {hi:.6g}] m; widen [grid] "
                                       "(x_min_m, x_max_m)")
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
            m = model_value(at[t], e, col, x)
            if m is None:
                raise CalibrationError(f"{self.data.source}: scene {scene.scene.name!r} has no output {col}")
            res.append(m)
        return np.asarray(res)

    def residuals(self, model_values: np.ndarray) -> np.ndarray:
        obs = np.array([r[3] for r in self.data.rows])
        if self.data.kind == "sizes":
            return np.log(model_values / obs)
        return model_values - obs


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
                              "ci95": list(c.ci95) if c.ci95 else None, "sd_ln": c.sd_ln}
                          for k, c in self.constants.items()},
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
            parts.append(f"{k} = {c.value:.6g}{unit_after(c.unit)}{ci}")
        return (f"{', '.join(parts)} fitted at this operating point to {Path(self.data_source).name} (sha256 "
                f"{self.data_sha256[:16]}...) by millfmu calibrate on {self.date_utc}, rms residual "
                f"{self.rms_residual:.3g} ({self.residual_unit})")

    def summary(self) -> str:
        n = len(self.residuals)
        out = [f"calibration of {self.scene.scene.name!r} to {self.data_source} ({n} value{'s' if n != 1 else ''}, "
               f"{dof_words(self.dof)})"]
        for k, c in self.constants.items():
            ci = f"95 % interval [{c.ci95[0]:.4g}, {c.ci95[1]:.4g}]" if c.ci95 else "no interval (no degree of freedom)"
            out.append(f"  {k} = {c.value:.5g}{unit_after(c.unit)}  ({ci}; start {c.start:.4g})")
        if self.correlation is not None and len(self.constants) == 2:
            out.append(f"  correlation of the pair: {self.correlation[0][1]:+.3f}")
        out.append(f"  rms residual {self.rms_residual:.3g} ({self.residual_unit})")
        if self.interval_method:
            out.append(f"  errors: {self.error_model.replace('_', '-')}; intervals: {self.interval_method}")
        out.extend(f"  warning: lack of fit: {w}" for w in self.lack_of_fit)
        out.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(out)


def unit_after(unit: str) -> str:
    """' UNIT' after a value; nothing for a dimensionless constant (unit '1')."""
    return "" if unit in ("1", "") else f" {unit}"


def _other_constants(scene: Scene, key: str) -> list:
    """The constants that could be freed instead of ``key`` in this scene (not those already
    at their finite upper bound, such as eta_E = 1)."""
    return [k for k, c in FITTABLE.items() if k != key and scene.kinetics.model in c.models
            and scene.material.model in c.materials
            and not number_key(scene, k) >= c.hi]



def _resolve_fit(scene: Scene, fit) -> list:
    keys = [k.strip() for k in (fit.split(",") if isinstance(fit, str) else fit) if k.strip()]
    if not 1 <= len(keys) <= 2 or len(set(keys)) != len(keys):
        raise CalibrationError(f"give one or two different constants among {', '.join(FITTABLE)}", "fit",
                               repr(",".join(keys)))
    for k in keys:
        c = FITTABLE.get(k)
        if c is None:
            raise CalibrationError(f"not a fittable constant{did_you_mean(k, FITTABLE)}; allowed {', '.join(FITTABLE)}",
                                   "fit", k)
        if scene.kinetics.model not in c.models or scene.material.model not in c.materials:
            raise CalibrationError(f"has no effect in scene {scene.scene.name!r} (kinetics.model = "
                                   f"{scene.kinetics.model!r}, material.model = {scene.material.model!r}); free one of "
                                   f"{', '.join(_other_constants(scene, k)) or '(none)'}", "fit", k)
    return keys


def calibrate(scene, data, fit, start: dict | None = None, progress=None,
              error_model: str | None = None) -> Calibration:
    """Fit the constants ``fit`` (dotted keys of :data:`FITTABLE`, one or two) of ``scene`` to
    measured batch ``data`` (a :class:`Data`, a CSV path, or CSV text) at the scene's
    operating point. ``start``: start values by key (default: the scene's). ``progress``: a
    callable taking one line per model-evaluation batch (the Jacobian of an iteration).
    ``error_model``: "per_sample" (an error shared by the values of one time, cluster-robust
    intervals; the default where a time has more than one value) or "independent" (the
    default for one value per time).

    Returns a :class:`Calibration`; raises :class:`CalibrationError` when the data cannot pin
    the constants (see :mod:`millfmu.calibration`) or are malformed."""
    from scipy.optimize import least_squares

    scene, data, keys = _arguments(scene, data, fit, error_model)
    pred = Predictor(scene, data)
    n, p = data.n, len(keys)
    if n < p:
        raise CalibrationError(f"{data.source}: {n} measured value(s) cannot pin {p} constants ({', '.join(keys)}): "
                               f"fit one of them, or measure at more times")
    x0, lo, hi = _search_range(scene, keys, start)
    obj = _Objective(scene, keys, pred, hi, progress)
    res = least_squares(obj.residuals, x0, jac=obj.jacobian, bounds=(lo, hi), method="trf", x_scale=1.0, xtol=1e-10,
                        ftol=1e-12,
                        gtol=1e-12, max_nfev=200)
    x, r = res.x, res.fun
    J = obj.jacobian(x)
    _refuse_unpinned(scene, keys, x, lo, hi, J, pred, obj.scene_at)
    notes = []
    if data.feed_rows:
        notes.append(f"{data.feed_rows} row(s) at t_s = 0 describe the feed (the scene's) and were not fitted")
    notes += feed_mismatch(scene, data)
    model = choose_error_model(data, p, error_model, notes)
    iv = None
    if n > p:
        iv = intervals(data, J, r, model)
        _refuse_wide(scene, keys, x, iv)
        _refuse_plateau(scene, keys, x, lo, hi, obj.residuals, r, iv)
    else:
        notes.append("as many values as constants: the exact solution, no interval (no residual degree of freedom)")
    fitted = {}
    for j, k in enumerate(keys):
        ci = None if iv is None else (math.exp(x[j] - iv.tq * iv.sd[j]), math.exp(x[j] + iv.tq * iv.sd[j]))
        fitted[k] = Fitted(k, FITTABLE[k].unit, math.exp(x[j]), math.exp(x0[j]), ci,
                           None if iv is None else float(iv.sd[j]))
    model_values = pred.values(obj.scene_at(x))
    unit = "ln(x_model / x_data)" if data.kind == "sizes" else ("Q3_model - Q3_data" if data.kind == "q3" else
                                                                    "f_model - f_data")
    rows = [{"t_s": t, "quantity": col, **({"x_m": xx} if xx is not None else {}), "data": v, "model": float(m),
             "residual": float(rr)} for (t, col, xx, v), m, rr in zip(data.rows, model_values, r)]
    return Calibration(scene=obj.scene_at(x), constants=fitted, correlation=None if iv is None else iv.corr,
                       residuals=rows,
                       rms_residual=float(math.sqrt(np.mean(r ** 2))), residual_unit=unit, dof=n - p,
                       data_source=data.source, data_sha256=data.sha256, evaluations=obj.evals,
                       date_utc=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                       notes=notes,
                       error_model=model, interval_method="" if iv is None else iv.method,
                       interval_dof=None if iv is None else iv.dof,
                       lack_of_fit=lack_of_fit(data, r, J) if iv is not None else [])


def _arguments(scene, data, fit, error_model) -> tuple[Scene, Data, list]:
    """:func:`calibrate`'s scene, data and constants, each read and checked, in that order."""
    if not isinstance(scene, Scene):
        scene = load_any(scene)
    if not isinstance(data, Data):
        data = parse_data(data, "data") if isinstance(data, str) and "\n" in data else read_data(data)
    keys = _resolve_fit(scene, fit)
    if error_model is not None and error_model.replace("-", "_") not in ERROR_MODELS:
        raise CalibrationError(f"allowed {', '.join(repr(m) for m in ERROR_MODELS)}, or None (per_sample where a time "
                               "has several values, else independent)", "error_model", repr(error_model))
    return scene, data, keys


def _search_range(scene: Scene, keys: list, start: dict | None) -> tuple[np.ndarray, list, list]:
    """Start, lower and upper end of the search in ln(constant): :data:`SEARCH_DECADES` either
    side of the start, capped by a finite physical upper bound (the start too)."""
    for k, v in (start or {}).items():
        if k not in keys:
            raise CalibrationError(f"a start value of a constant not fitted; the fitted: {', '.join(keys)}", "start",
                                   k)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0.0):
            raise CalibrationError(f"VALUE = {v!r}: must be a finite number > 0 (the fit works in ln({k}))", "start",
                                   k)
    starts = [float((start or {}).get(k, number_key(scene, k))) for k in keys]
    for k, v in zip(keys, starts):
        if not v > 0.0:
            raise CalibrationError(f"starts from {v:g} {FITTABLE[k].unit}, the scene's value; a fit in ln({k}) needs "
                                   f"a positive start: set one in the scene", "fit", k, start_key=k)
    x0 = np.log(starts)
    lo, hi = [], []
    for k, s in zip(keys, x0):
        c = FITTABLE[k]
        hi.append(min(s + SEARCH_DECADES * math.log(10), math.log(c.hi)) if math.isfinite(c.hi) else s
                  + SEARCH_DECADES * math.log(10))
        lo.append(s - SEARCH_DECADES * math.log(10))
    return np.minimum(x0, hi), lo, hi


class _Objective:
    """The residuals and their Jacobian at ln(constants) ``x``, counting model runs; a
    ``progress`` line per Jacobian (one per iteration of the fit)."""

    def __init__(self, scene: Scene, keys: list, pred: Predictor, hi: list, progress=None):
        self.scene, self.keys, self.pred, self.hi, self.progress = scene, keys, pred, hi, progress
        self.evals = self.iterations = 0

    def scene_at(self, x) -> Scene:
        return with_values(self.scene, {k: math.exp(v) for k, v in zip(self.keys, x)})

    def residuals(self, x) -> np.ndarray:
        self.evals += 1
        try:
            r = self.pred.residuals(self.pred.values(self.scene_at(x)))
        except StepError as e:
            raise CalibrationError(f"the model failed at {_fmt(self.keys, x)}: {e}") from None
        # A size the model grinds below the grid gives ln(0): make it a large, finite residual.
        return np.nan_to_num(r, nan=1e3, posinf=1e3, neginf=-1e3)

    def jacobian(self, x) -> np.ndarray:
        """Forward differences of :data:`JAC_STEP` in ln(constant), backwards at the upper end."""
        f0 = self.residuals(x)
        J = np.empty((len(f0), len(self.keys)))
        for j in range(len(self.keys)):
            h = JAC_STEP if x[j] + JAC_STEP <= self.hi[j] else -JAC_STEP
            xj = x.copy()
            xj[j] += h
            J[:, j] = (self.residuals(xj) - f0) / h
        self.iterations += 1
        if self.progress is not None:
            self.progress(f"calibrate: iteration {self.iterations}, {self.evals} model runs, rms residual "
                          f"{math.sqrt(np.mean(f0 ** 2)):.4g}, {_fmt(self.keys, x)}")
        return J


def _refuse_wide(scene: Scene, keys: list, x, iv: Intervals):
    """CalibrationError for a constant whose 95 % interval spans more than
    :data:`MAX_INTERVAL_FACTOR`, and for a pair the data cannot tell apart
    (|design correlation| over :data:`MAX_CORRELATION`)."""
    p = len(keys)
    for k, v, s in zip(keys, x, iv.sd):
        tq = iv.tq
        if 2.0 * tq * s > math.log(MAX_INTERVAL_FACTOR):
            span = f"a factor {math.exp(2 * tq * s):.3g}" if 2 * tq * s < 700 else "more than 300 decades"
            raise CalibrationError(f"not pinned by the data: its 95 % interval [{math.exp(max(v - tq * s, -700)):.3g}, "
                                   f"{math.exp(min(v + tq * s, 700)):.3g}] spans {span} (at most a factor "
                                   f"{MAX_INTERVAL_FACTOR:g} allowed); "
                                   + (f"fit {next(o for o in keys if o != k)} alone with {k} set in the scene, or "
                                      "measure more" if p == 2
                                      else f"fit {_others_text(scene, k, keys)} instead, or measure more"),
                                   "fit", k)
    design = iv.design_correlation()
    if p == 2 and abs(design) > MAX_CORRELATION:
        raise CalibrationError(f"the data cannot tell the two apart (correlation {design:+.4f}, at most "
                               f"{MAX_CORRELATION} allowed); fit one of them alone with the other set in the scene",
                               "fit",
                               ",".join(keys))


def _refuse_plateau(scene, keys, x, lo, hi, fun, r, iv: Intervals):
    """CalibrationError for a constant on a plateau: at the far end of its search range (the
    other constant kept at its fit) the sum of squared residuals rises above the optimum's by
    less than it does at the edge of the 95 % interval (tq^2 var / (J^T J)^-1_jj), so the data
    do not exclude that end: a finite interval from the local slope would be false."""
    s_min = float(r @ r)
    for j, k in enumerate(keys):
        c = FITTABLE[k]
        allowed = iv.tq ** 2 * float(iv.cov[j, j]) / float(iv.JtJinv[j, j])
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
                    f"lies on a plateau: at the {side} end of its search range ({math.exp(end):.3g} {c.unit}, "
                    f"{SEARCH_DECADES:g} decades from the start) the sum of squared residuals rises by only {rise:.3g} "
                    f"above the fit's at {math.exp(x[j]):.4g} {c.unit}, less than the noise allows at the edge of a 95 "
                    f"% interval ({allowed:.3g}): the data bound it from {bound} only (the model no longer responds to "
                    f"it there), so no two-sided interval holds; fit {_others_text(scene, k, keys)} instead, or "
                    "measure where it acts (other times, sizes or operating point)", "fit", k)


def _fmt(keys, x) -> str:
    return ", ".join(f"{k.rpartition('.')[2]} = {math.exp(v):.5g}" for k, v in zip(keys, x))


def _others_text(scene, key, keys) -> str:
    return " or ".join(o for o in _other_constants(scene, key) if o not in keys) or "(none: measure more)"


def _refuse_unpinned(scene, keys, x, lo, hi, J, pred: Predictor, scene_at):
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
            raise CalibrationError(f"the model stops responding to it at {math.exp(x[j]):.4g} {c.unit} (its effect "
                                   f"has vanished or saturated there) and gives {got}: the data need what it cannot "
                                   f"give; free {others} instead, or start it elsewhere", "fit", k)
        if len(keys) == 2:
            other = next(o for o in keys if o != k)
            raise CalibrationError(f"the data do not pin the pair: {k} ended on the "
                                   f"{'upper' if at_hi else 'lower'} end of its range ({math.exp(x[j]):.4g} {c.unit}); "
                                   f"fit {other} alone with {k} set in the scene", "fit", ",".join(keys))
        if at_hi and math.isfinite(c.hi) and abs(math.exp(x[j]) - c.hi) <= 1e-9 * c.hi:
            raise CalibrationError(f"the data are out of reach; {k.rpartition('.')[2]} = {c.hi:g} (its upper bound: "
                                   f"{c.meaning}) gives {got}; free {others} instead", "fit", k)
        side = "upper" if at_hi else "lower"
        raise CalibrationError(f"ran to the {side} end of its search range ({math.exp(x[j]):.3g} {c.unit}, "
                               f"{SEARCH_DECADES:g} decades from the start) where it stops acting: the data do not pin "
                               f"it (there the model gives {got}); fit {others} instead or start from another value",
                               "fit", k)

