"""Benchmarks that print ratios against a baseline run in the same process.

``bench_pbm``: the exact population-balance step against scipy's solve_ivp (BDF, with the
exact Jacobian) on the same batch grinding problem, at equal accuracy: BDF's tolerances are
tightened until its error against the closed-form solution expm(A t) m0 is no larger than
the accuracy target, and the exact stepper's error is measured the same way.

``integrator_study``: error against run time of the population-balance integrators (the
exact step, the adaptive exponential integrator, scipy's BDF and truncated Taylor steps as
Dyssol's crusher unit uses, :func:`taylor_step`) on a smooth and a stiff case whose rates
change in time, with measured orders (``millfmu bench integrators``, ``millfmu report``).
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from ..kinetics.grid import SizeGrid
from ..kinetics import pbm
from ..mill import MillModel
from ..scene import load_scene

#: Accuracy target: max over output times and classes of |m - m_exact| / total mass [-].
ACCURACY_TARGET = 1e-6


#: Blocks of 1000 calls timed for a per-call figure in microseconds (the best is kept)
MICRO_REPEATS = 15


def micro_blocks(repeats: int) -> int:
    """Blocks of 1000 calls timed for a per-call figure in microseconds: a shared machine's
    pauses hit single blocks, so the best of many short blocks (a few ms each), at least
    :data:`MICRO_REPEATS` whatever ``repeats`` says."""
    return max(repeats, MICRO_REPEATS)


def _best(f, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = f()
        best = min(best, time.perf_counter() - t0)
    return best, r


#: Austin selection S = 1e8 (x / 200 um)^4.85 1/s on the default grid: rates spanning
#: 1e-8 ... 1e8 1/s, the stiff case of tests/stability.
STIFF = {"model": "austin", "selection": {"a_per_s": 1e8, "x0_m": 200e-6, "alpha": 4.85, "Lambda": 0.0}}


def bench_tanks(n_tanks=50, dt_s=1.0, repeats=3, dense=True, stiff=False, out=print):
    """Continuous mill of the default scene (``stiff``: with rates spanning 1e-8 ... 1e8 1/s)
    as ``n_tanks`` tanks in series: cost of building the exact propagator and of one step
    with the block structure (pbm.TanksInSeries), against one dense matrix exponential of
    the whole system (the method before) in the same run, and their largest difference
    over 10 steps relative to the total mass."""
    import tomllib

    from ..scene import default_scene_text, scene_from_dict

    d = tomllib.loads(default_scene_text())
    d["operation"] = {"mode": "continuous", "n_tanks": n_tanks, "feed_mass_flow_kg_per_s": 1e-3}
    if stiff:
        d["material"], d["kinetics"] = dict(STIFF), {"model": "none"}
    model = MillModel(scene_from_dict(d))
    series, u, _ = model._system(model.inputs)
    y0 = model.y.copy()
    t_setup, prop = _best(lambda: series.propagator(dt_s), repeats)
    t_step, _ = _best(lambda: [prop.apply(y0, u) for _ in range(100)], repeats)
    t_step /= 100
    row = dict(tanks=n_tanks, states=series.size, setup_ms=t_setup * 1e3, step_us=t_step * 1e6)
    if dense:
        g, f = series.matrices()
        t_dense, (phi, gam) = _best(lambda: pbm.propagators(g, f, dt_s), 1)
        t_dstep, _ = _best(lambda: [phi @ y0 + gam @ u for _ in range(100)], repeats)
        t_dstep /= 100
        a, b = y0.copy(), y0.copy()
        diff = 0.0
        for _ in range(10):
            a, b = prop.apply(a, u), phi @ b + gam @ u
            diff = max(diff, float(np.max(np.abs(a - b)) / b.sum()))
        row.update(dense_setup_s=t_dense, dense_step_us=t_dstep * 1e6, setup_ratio=t_dense / t_setup, max_diff=diff)
    what = "rates 1e-8 ... 1e8 1/s" if stiff else "default scene"
    out(f"continuous, {what}, {n_tanks} tanks in series ({series.size} states), {dt_s:g} s step:")
    out(f"  block-structured: propagator {row['setup_ms']:.2f} ms, step {row['step_us']:.1f} us")
    if dense:
        out(f"  dense expm (before): propagator {row['dense_setup_s']:.2f} s, step {row['dense_step_us']:.1f} us; "
            f"propagator {row['setup_ratio']:.0f} times slower; largest difference over 10 steps {row['max_diff']:.1e} "
            "of the total mass")
    return row


def bench_pbm(classes=(50, 100, 200), hours=1.0, repeats=3, dt_s=1.0, out=print, tanks=50, dense=True):
    """Print the cost of one step and of ``hours`` of batch grinding at 1 s steps, vs BDF;
    then the ``tanks``-tank row (:func:`bench_tanks`; 0 leaves it out)."""
    scene = load_scene()
    n_steps = int(round(hours * 3600.0 / dt_s))
    t_eval = np.arange(n_steps + 1) * dt_s
    out(f"batch grinding, default scene's material and mill, {hours:g} h at {dt_s:g} s steps ({n_steps} steps)")
    out(f"accuracy: max |m - expm(A t) m0| / total mass over all steps and classes; target {ACCURACY_TARGET:g}")
    head = (f"{'classes':>7} {'step [us]':>10} {'model step [us]':>15} {'expm setup [ms]':>15} {'ours total [s]':>14} "
            f"{'ours err':>9} {'BDF rtol':>9} {'BDF err':>9} {'BDF [s]':>9} {'BDF/ours':>9} {'span rtol':>9} "
            f"{'span err':>9} {'span [s]':>9} {'span/ours':>9}")
    out("BDF: restarted at every 1 s step (as a co-simulation unit must); span: one solve_ivp call over the whole time")
    out(head)
    out("-" * len(head))
    rows = []
    for n in classes:
        grid = SizeGrid.with_classes(scene.grid.x_min_m, scene.grid.x_max_m, n)
        model = MillModel(scene, grid=grid)
        a = model.operator.matrix(model.selection_nodes(model.operating_point(model.inputs)))
        g = pbm.system_matrix(a, 1, 0.0)  # dense on purpose: the closed-form reference below
        y0 = model.y.copy()
        total = y0.sum()

        # Reference: the closed form m(t) = expm(A t) m0, one expm over the whole span for each
        # checked time (repeating our own 1 s propagator would compare it with itself).
        check = np.unique(np.concatenate((np.linspace(0, n_steps // 10, 7),
                                          np.linspace(0, n_steps, 13))).round().astype(int))
        ref = {k: expm(g * t_eval[k]) @ y0 for k in check}

        def ours():
            phi, _ = pbm.propagators(g, None, dt_s)
            y = y0.copy()
            hist = {}
            for k in range(1, n_steps + 1):
                y = phi @ y
                if k in ref:
                    hist[k] = y
            return hist

        t_ours, hist = _best(ours, repeats)
        err_ours = max(np.max(np.abs(hist[k] - ref[k])) for k in check if k > 0) / total
        t_setup, (phi_only, _) = _best(lambda: pbm.propagators(g, None, dt_s), repeats)
        y = y0.copy()
        micro = micro_blocks(repeats)
        t_step, _ = _best(lambda: [phi_only @ y for _ in range(1000)], micro)
        t_step /= 1000
        model.step(dt_s)
        t_model, _ = _best(lambda: [model.step(dt_s) for _ in range(1000)], micro)
        t_model /= 1000

        def bdf_span(rtol):
            return solve_ivp(lambda t, m: g @ m, (0.0, t_eval[-1]), y0, method="BDF", jac=g, t_eval=t_eval, rtol=rtol,
                             atol=rtol * total * 1e-3)

        def bdf_steps(rtol, upto=n_steps):
            # As a co-simulation unit must: restart at every communication step, since the
            # inputs may change there.
            y = y0.copy()
            hist = {0: y0}
            for k in range(1, upto + 1):
                y = solve_ivp(lambda t, m: g @ m, (0.0, dt_s), y, method="BDF", jac=g, rtol=rtol,
                              atol=rtol * total * 1e-3).y[:, -1]
                if k in ref:
                    hist[k] = y
            return hist

        def tune(run, get, ks):
            for rtol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10):
                err = max(np.max(np.abs(get(run(rtol), k) - ref[k])) for k in ks) / total
                if err <= max(ACCURACY_TARGET, err_ours):
                    return rtol, err
            return None

        c_span = tune(bdf_span, lambda sol, k: sol.y[:, k], check)
        # Tolerance chosen on the first tenth of the run (the error grows with the number
        # of restarts), then checked over the whole run below.
        early = [k for k in check if k <= n_steps // 10] or [check[1]]
        c_steps = tune(lambda r: bdf_steps(r, max(early)), lambda h, k: h[k], early)
        if c_span is None or c_steps is None:
            out(f"{n:7d}  BDF did not reach the accuracy target down to rtol 1e-10")
            continue
        t_span, _ = _best(lambda: bdf_span(c_span[0]), repeats)
        t_steps, hist_b = _best(lambda: bdf_steps(c_steps[0]), 1)
        c_steps = (c_steps[0], max(np.max(np.abs(hist_b[k] - ref[k])) for k in check) / total)
        row = dict(classes=n, step_us=t_step * 1e6, model_step_us=t_model * 1e6, setup_ms=t_setup * 1e3, ours_s=t_ours,
                   ours_err=err_ours,
                   bdf_steps_rtol=c_steps[0], bdf_steps_err=c_steps[1], bdf_steps_s=t_steps,
                   ratio_steps=t_steps / t_ours,
                   bdf_span_rtol=c_span[0], bdf_span_err=c_span[1], bdf_span_s=t_span, ratio_span=t_span / t_ours)
        rows.append(row)
        out(f"{n:7d} {t_step * 1e6:10.2f} {t_model * 1e6:15.1f} {t_setup * 1e3:15.2f} {t_ours:14.4f} {err_ours:9.1e} "
            f"{c_steps[0]:9.0e} {c_steps[1]:9.1e} {t_steps:9.3f} {t_steps / t_ours:9.0f} "
            f"{c_span[0]:9.0e} {c_span[1]:9.1e} {t_span:9.4f} {t_span / t_ours:9.1f}")
    out("ours total = expm setup + all steps; step = one exact step (matrix-vector product); ratios = BDF time / ours "
        "total;")
    out("model step = MillModel.step with all outputs (x10/x50/x90, SF, power, ...).")
    if tanks:
        for stiff in (False, True):
            rows.append(bench_tanks(tanks, dt_s, repeats, dense, stiff, out))
    return rows


# --- Integrators of the population balance: error against run time -----------------------

def taylor_step(a: np.ndarray, y: np.ndarray, h_s: float, order: int) -> np.ndarray:
    """One step of dy/dt = A y by the Taylor series of expm(h A) truncated after ``order``
    terms: y + h A y (+ h^2 A^2 y / 2 ...). Orders 1 and 2 are the transformation matrices
    I + A h and (I + A h)(I + A h / 2) - A h / 2 = I + A h + (A h)^2 / 2 that Dyssol's
    population-balance crusher unit (CrusherPBMTM, methods "Newton" and "Runge-Kutta")
    applies per time step. It conserves mass (A's columns sum to zero) but is stable only
    for h below about 2 / max S and keeps masses non-negative only below 1 / max S."""
    out = np.array(y, dtype=float)
    term = out
    for k in range(1, order + 1):
        term = (h_s / k) * (a @ term)
        out = out + term
    return out


#: The integrator study's cases: the breakage operator swings between two operating points,
#: A(t) = (1 - th(t)) A_lo + th(t) A_hi with th(t) = (1 + sin(2 pi t / P)) / 2, over t_end_s.
#: Smooth: the detailed example (examples/limestone_detailed.toml: the default case with the
#: detailed model on the coupled DEM table; the default scene's simple model reaches 1.6 and
#: 5.4 1/s in the coarsest class, too fast for the Taylor steps compared) at 8 and 12 m/s
#: (rates up to 0.04 and 0.17 1/s, the coarsest classes; over 90 s, so that Taylor steps of
#: up to a quarter of the span keep h S_max <= 1 as they did over 3600 s on the prescribed
#: table's lower rates); stiff: Austin rates a (x / 200 um)^alpha spanning 1e-8 ... 1e8 1/s
#: (STIFF) with alpha 4.85 and 4.0. The two operators do not commute, so no closed form:
#: the reference is the exact step at 2^14 and 2^15 steps, Richardson-extrapolated.
INTEGRATOR_CASES = {
    "smooth": dict(period_s=33.0, t_end_s=90.0),
    "stiff": dict(period_s=0.37, t_end_s=1.0),
}


#: The shipped example whose operators the study's cases use (the stiff case replaces its
#: material and kinetics).
SMOOTH_SCENE = "limestone_detailed.toml"


def _case_operators(case: str):
    """(A_lo, A_hi) [1/s] (state: classes and below-grid mass) and the initial masses [kg]
    of a study case (:data:`INTEGRATOR_CASES`)."""
    import tomllib

    from ..scene import example_path, scene_from_dict

    d = tomllib.loads(example_path(SMOOTH_SCENE).read_text())
    mats = []
    for k in range(2):
        if case == "stiff":
            sel = dict(STIFF["selection"], alpha=(4.85, 4.0)[k])
            d["material"], d["kinetics"] = dict(STIFF, selection=sel), {"model": "none"}
        else:
            d["mill"]["tip_speed_m_per_s"] = (8.0, 12.0)[k]
        model = MillModel(scene_from_dict(d))
        mats.append(model.operator.matrix(model.selection_nodes(model.operating_point(model.inputs))))
    return mats[0], mats[1], model.y[1:].copy()


def _order(x, e, floor):
    """Least-squares slope of log(e) against log(x) over the points above 10 x ``floor``
    (the reference's error) and below 0.1 (the asymptotic range); nan with fewer than 2."""
    x, e = np.asarray(x, float), np.asarray(e, float)
    ok = np.isfinite(e) & np.isfinite(x) & (x > 0) & (e > 10.0 * floor) & (e < 0.1)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(x[ok]), np.log(e[ok]), 1)[0])


def _exact_steps(a_of_t, m0, t_end, n):
    """n exact steps with the operator at each step's midpoint (exponential midpoint rule)."""
    h = t_end / n
    y = m0.copy()
    for k in range(n):
        y = pbm.propagators(a_of_t((k + 0.5) * h), None, h)[0] @ y
    return y


def integrator_study(quick: bool = False, repeats: int | None = None, out=print) -> dict:
    """Error against run time of the population-balance integrators on a smooth and a
    stiff case of batch grinding whose rates change in time (:data:`INTEGRATOR_CASES`).
    Methods:

    - ``exact step``: the matrix exponential of each step with the operator at the step's
      midpoint (exact for rates constant over the step; second order for changing ones);
    - ``adaptive exponential``: :func:`millfmu.kinetics.pbm.adaptive_exponential_step`
      (the model's ``adaptive`` integrator) over the whole time, tolerance swept;
    - ``scipy BDF``: solve_ivp over the whole time with the exact Jacobian, tolerance swept;
    - ``Taylor 1`` and ``Taylor 2``: :func:`taylor_step` with the midpoint operator
      (the transformation matrices of Dyssol's crusher unit), fixed steps.

    Error: max over classes of |m(T) - m_ref(T)| / total mass, m_ref the exact step at
    2^13 and 2^14 steps (quick: 2^9, 2^10), Richardson-extrapolated (the midpoint rule is
    symmetric, so its error expands in even powers of h); the same extrapolation one level
    coarser estimates the reference's error. Run time: best of ``repeats``. Measured order:
    least-squares slope of log error against log step size (for the adaptive methods the
    mean step, t_end / steps taken), over the points between 10 x the reference's error
    and 0.1, Taylor steps only where h times the largest rate is at most 1 (for BDF, whose
    order varies up to 5, only a slope).
    Returns {case: {"rows": [...], "orders": {...}, ...}}.
    """
    repeats = repeats or (1 if quick else 3)
    res = {}
    for case, c in INTEGRATOR_CASES.items():
        r = res[case] = _integrator_case(case, c, quick, repeats)
        out(f"{case}: {r['states']} states, operator swinging between two operating points with period "
            f"{r['period_s']:g} s, {r['t_end_s']:g} s simulated, largest rate {r['max_rate_per_s']:.3g} 1/s; "
            f"reference: exact steps at {r['reference_steps'] // 2} and {r['reference_steps']}, extrapolated (error "
            f"estimate {r['reference_error']:.1e})")
        out(f"  {'method':22s} {'steps':>7s} {'rtol':>7s} {'error':>9s} {'wall [s]':>9s} {'min mass':>9s}")
        for row in r["rows"]:
            rtol = row.get("rtol", float("nan"))
            # a fixed-step method has no tolerance
            rtol = f"{rtol:7.0e}" if math.isfinite(rtol) else f"{'-':>7s}"
            out(f"  {row['method']:22s} {row['steps']:7d} {rtol} {row['error']:9.2e} "
                f"{row['wall_s']:9.3g} {row['min_mass']:9.1e}")
        out("  measured orders: " + ", ".join(f"{k} {v:.2f}" if math.isfinite(v) else f"{k} none (its error grows)"
                                              for k, v in r["orders"].items()))
    return res


def _integrator_case(case: str, c: dict, quick: bool, repeats: int) -> dict:
    """:func:`integrator_study` of one case of :data:`INTEGRATOR_CASES`: its rows (one per
    method and step count or tolerance), measured orders and reference."""
    a_lo, a_hi, m0 = _case_operators(case)
    per, t_end = c["period_s"], c["t_end_s"]
    w = 2.0 * np.pi / per

    def a_of_t(t):
        th = 0.5 * (1.0 + np.sin(w * t))
        return (1.0 - th) * a_lo + th * a_hi

    total = float(m0.sum())
    n_ref = 2 ** (8 if quick else 12)
    t0 = time.perf_counter()
    y = [_exact_steps(a_of_t, m0, t_end, n_ref * 2 ** k) for k in range(3)]
    ref = (4.0 * y[2] - y[1]) / 3.0
    # the same extrapolation one level coarser: their difference bounds the reference's
    # error, and only errors well above it count for the orders
    ref_err = float(np.max(np.abs(ref - (4.0 * y[1] - y[0]) / 3.0)) / total)
    t_ref = time.perf_counter() - t0
    floor = max(1e-15, ref_err)
    s_max = float(max(-np.diag(a_lo).min(), -np.diag(a_hi).min()))
    rows = []

    def err(y):
        return float(np.max(np.abs(y - ref)) / total) if np.all(np.isfinite(y)) else float("inf")

    def mmin(y):
        return float(np.min(y) / total) if np.all(np.isfinite(y)) else float("nan")

    n_steps = [2 ** k for k in ((2, 4, 6) if quick else range(2, 11))]
    for name, kind in (("exact step", 0), ("Taylor 1", 1), ("Taylor 2", 2)):
        for n in n_steps:
            h = t_end / n

            def run(h=h, n=n, kind=kind):
                if kind == 0:
                    return _exact_steps(a_of_t, m0, t_end, n)
                y = m0.copy()
                with np.errstate(over="ignore", invalid="ignore"):
                    for k in range(n):
                        y = taylor_step(a_of_t((k + 0.5) * h), y, h, kind)
                return y

            t, y = _best(run, repeats)
            rows.append(dict(method=name, steps=n, step_s=h, error=err(y), wall_s=t,
                             min_mass=mmin(y), h_times_max_rate=h * s_max))

    def system(t, y):
        return pbm.TanksInSeries(a_of_t(t), 1, 0.0), None

    y0 = np.concatenate(([0.0], m0))
    for rtol in ((1e-3, 1e-4, 1e-5) if quick else (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)):
        t, (y, n_sub) = _best(lambda: pbm.adaptive_exponential_step(y0, 0.0, t_end, system, rtol=rtol,
                                                                    atol=rtol * 1e-6 * total), repeats)
        rows.append(dict(method="adaptive exponential", rtol=rtol, steps=int(n_sub), step_s=t_end / n_sub,
                         error=err(y[1:]), wall_s=t, min_mass=mmin(y)))
    for rtol in ((1e-4, 1e-6, 1e-8) if quick else (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)):
        def bdf():
            return solve_ivp(lambda t, m: a_of_t(t) @ m, (0.0, t_end), m0, method="BDF",
                             jac=lambda t, m: a_of_t(t), rtol=rtol, atol=rtol * 1e-3 * total)
        t, sol = _best(bdf, repeats)
        y = sol.y[:, -1]
        rows.append(dict(method="scipy BDF", rtol=rtol, steps=int(sol.t.size - 1),
                         step_s=t_end / max(sol.t.size - 1, 1),
                         error=err(y), wall_s=t, min_mass=mmin(y), nfev=int(sol.nfev)))
    orders = {}
    for name in ("exact step", "Taylor 1", "Taylor 2", "adaptive exponential", "scipy BDF"):
        # Taylor steps: only h S_max <= 1, where they keep masses positive (asymptotic range)
        rr = [r for r in rows if r["method"] == name and
              (not name.startswith("Taylor") or r["h_times_max_rate"] <= 1.0)]
        orders[name] = _order([r["step_s"] for r in rr], [r["error"] for r in rr], floor)
    return dict(rows=rows, orders=orders, states=int(a_lo.shape[0]), t_end_s=t_end,
                period_s=per, max_rate_per_s=s_max, reference_steps=4 * n_ref,
                reference_wall_s=t_ref, reference_error=ref_err)
