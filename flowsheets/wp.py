"""Error of the co-simulation against its communication step, with wall time (work-precision).

The flowsheet runs with a reference step h_ref and with each step h in ``steps``; the error
of one output (default mill.x50) at step h is max over t of |y_h(t) - y_ref(t)|, taken at the
times that every run has as output times (multiples of the largest step). The measured
order is the least-squares slope of log(error) against log(h) (for each measure), and per pair of neighbouring
steps log(e_2/e_1)/log(h_2/h_1). Wall time is the master's run (instantiate to terminate),
without building the FMUs. Both the run at h and the reference carry the communication
error; with h_ref well below the smallest h, the reference's own error (about h_ref/h of
the error at h for order one) is small against the measured one.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .master import Master, build_fmus
from .spec import Flowsheet, FlowsheetError


def _series(res, variable, times):
    t = np.round(res.t, 9)
    idx = [int(np.flatnonzero(np.isclose(t, x, rtol=0, atol=1e-6))[0]) for x in times]
    return res.column(variable)[idx]


def work_precision(fs: Flowsheet, steps, reference: float, out: Path, fmu_dir: Path, variable="mill.x50", log=print,
                   fmi_version=2) -> str:
    """Run the study; write wp.csv, wp.json, wp.txt and wp.png into ``out``; return the table text."""
    paths = build_fmus(fs, fmu_dir, log=log, fmi_version=fmi_version)
    h_max = max(steps)
    times = [k * h_max for k in range(1, int(round(fs.t_end_s / h_max)) + 1)]
    runs = {}
    for h in [reference] + sorted(steps):
        log(f"running {fs.name} with step {h:g} s")
        f = fs.with_(step_s=h, output_interval_s=h_max if h_max % h == 0 else h)
        res = Master(f, paths, log=log).run()
        if variable not in res.columns:
            raise FlowsheetError("--variable", variable, "must be one of the flowsheet's outputs: "
                                 + ", ".join(res.columns[1:]), "command line")
        runs[h] = (res, _series(res, variable, times))
    ref = runs[reference][1]
    rows = []
    for h in sorted(steps):
        res, y = runs[h]
        err = float(np.max(np.abs(y - ref)))
        rows.append({"step_s": h, "steps": res.steps, "error": err, "relative_error": err / float(np.max(np.abs(ref))),
                     "error_end": float(abs(y[-1] - ref[-1])),
                     "wall_s": res.wall_s, "mass_residual": res.mass["relative_residual"]})
    hs = np.array([r["step_s"] for r in rows])
    es = np.array([r["error"] for r in rows])
    order = float(np.polyfit(np.log(hs), np.log(es), 1)[0]) if np.all(es > 0) else math.nan
    ee = np.array([r["error_end"] for r in rows])
    order_end = float(np.polyfit(np.log(hs), np.log(ee), 1)[0]) if np.all(ee > 0) else math.nan
    pair = [float(math.log(es[i + 1] / es[i]) / math.log(hs[i + 1] / hs[i])) if es[i] > 0 and es[i + 1] > 0
            else math.nan
            for i in range(len(rows) - 1)]
    for r, p in zip(rows[1:], pair):
        r["order_to_previous"] = p
    lines = [f"{fs.name} ({fs.algorithm}): error of {variable} against a reference run with step {reference:g} s "
             f"({runs[reference][0].steps} steps, {runs[reference][0].wall_s:.3g} s wall), max over t = k * "
             f"{h_max:g} s",
             f"{'step [s]':>9} {'steps':>6} {'max error':>11} {'relative':>9} {'order':>6} {'error at end':>12} "
             f"{'wall [s]':>9} {'mass resid.':>11}"]
    for r in rows:
        o = r.get("order_to_previous")
        lines.append(f"{r['step_s']:9.4g} {r['steps']:6d} {r['error']:11.3e} {r['relative_error']:9.2e} "
                     f"{'' if o is None else f'{o:6.2f}':>6} {r['error_end']:12.3e} {r['wall_s']:9.3g} "
                     f"{r['mass_residual']:11.1e}")
    lines.append(f"measured order (least squares over all steps): {order:.3f} for the max error over t, "
                 f"{order_end:.3f} for the error at t_end")
    table = "\n".join(lines)
    out = Path(out)
    with open(out / "wp.csv", "w") as f:
        f.write("step_s,steps,max_error_m,max_relative_error,error_at_end_m,wall_s,mass_relative_residual\n")
        for r in rows:
            f.write(f"{r['step_s']!r},{r['steps']},{r['error']!r},{r['relative_error']!r},{r['error_end']!r},{r['wall_s']!r},{r['mass_residual']!r}\n")
    (out / "wp.json").write_text(json.dumps({"flowsheet": fs.name, "algorithm": fs.algorithm, "variable": variable,
                                             "reference_step_s": reference,
                                             "reference_wall_s": runs[reference][0].wall_s, "rows": rows,
                                             "order": order, "order_at_end": order_end}, indent=1))
    (out / "wp.txt").write_text(table + "\n")
    _plot(rows, runs, reference, times, variable, fs, order, out / "wp.png")
    return table


def _plot(rows, runs, reference, times, variable, fs, order, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from millfmu.plotstyle import label_points, plain_log_ticks

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.5))
    w = [r["wall_s"] for r in rows]
    e = [r["relative_error"] for r in rows]
    ax[0].loglog(w, e, "o-")
    ax[0].set(xlabel="wall time [s]", ylabel=f"max relative error of {variable}", title="work-precision")
    hs = np.array([r["step_s"] for r in rows])
    ax[1].loglog(hs, e, "o-", label="measured")
    ax[1].loglog(hs, e[0] * hs / hs[0], "--", label="order 1")
    ax[1].set(xlabel="communication step [s]", ylabel="max relative error",
              title=f"error against step (order {order:.2f})")
    ax[1].legend()
    for h, (res, y) in sorted(runs.items()):
        ax[2].plot(np.array(times) / 60, y * (1e6 if variable.endswith("x50") else 1),
                   label=f"{h:g} s" + (" (reference)" if h == reference else ""))
    ax[2].set(xlabel="t [min]", ylabel=variable + (" [um]" if variable.endswith("x50") else ""), title="the runs")
    ax[2].legend(fontsize=7)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    plain_log_ticks(fig)
    fig.suptitle(f"{fs.name}: {fs.algorithm} co-simulation, fmpy master")
    fig.tight_layout()
    # the steps beside their points, placed in pixels once the layout is final
    label_points(ax[0], [(r["wall_s"], r["relative_error"]) for r in rows], [f"step {r['step_s']:g} s" for r in rows],
                 fontsize=8)
    fig.savefig(path, dpi=90)
    plt.close(fig)
