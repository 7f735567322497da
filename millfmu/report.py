"""``millfmu report``: one self-contained HTML page of every error-against-run-time study.

Sections (each with its measured orders, the machine it ran on and the date):

1. population-balance integrators (:func:`millfmu.studies.pbm_integrators.integrator_study`): the exact step,
   the adaptive exponential integrator, scipy's BDF and truncated Taylor steps (Dyssol's
   crusher unit) on a smooth and a stiff case;
2. the co-simulation communication step of flowsheet (a), ``circuit.toml``
   (:func:`flowsheets.wp.work_precision`);
3. the DEM work-precision (:mod:`millfmu.dem.analysis.precision`): a recording-length study run
   now (``--quick``: one short coupled run) or a full study made from a checkout
   (``--dem-runs DIR``: ``python -m validation.work_precision run|table --out DIR``), and the
   full study shipped with millfmu;
4. the rates of both shipped calibrated pairs along each operating parameter, simple against
   detailed model with its band (:func:`millfmu.rates.trend_table`), and the detailed
   model's regime.

The page (``report.html``) has no external CSS or scripts; its PNG images are written
beside it and referenced by relative name. ``--quick`` finishes in minutes (for CI); the
full report repeats the studies of docs/performance.md (tens of minutes; the full DEM study's runs take
hours on one core and are made by the study itself, outside the package, whose result ``--dem-runs`` reads).
"""

from __future__ import annotations

import html
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from .machine import machine

#: The page's sections: id -> title (the test checks that each is present).
SECTIONS = {
    "process": "Process: grinding in the default scene",
    "pbm": "Population-balance integrators",
    "cosim": "Co-simulation communication step",
    "dem": "DEM work-precision",
    "trends": "Rates along the operating parameters",
}
#: Co-simulation study settings: (flowsheet file, t_end [s] or None for the file's,
#: communication steps [s], reference step [s]); quick is the default tests' short version.
COSIM_QUICK = ("circuit.toml", 300.0, (2.5, 5.0, 10.0), 0.625)
COSIM_FULL = ("circuit.toml", None, (0.625, 1.25, 2.5, 5.0, 10.0, 20.0), 0.078125)

CSS = """
body { font-family: sans-serif; max-width: 1200px; margin: 2em auto; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #999; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.85em; }
td, th { border: 1px solid #bbb; padding: 2px 6px; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f6f6f6; padding: 0.6em; font-size: 0.8em; overflow-x: auto; }
.meta { color: #555; font-size: 0.85em; }
"""


def _esc(x) -> str:
    return html.escape(str(x))


def _table(head, rows) -> str:
    out = ["<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in head) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{_esc(c)}</td>" for c in r) + "</tr>")
    return "\n".join(out) + "</table>"


def _meta(m: dict, wall_s: float | None = None) -> str:
    keys = ("date_utc", "platform", "processor", "cpus", "load_average_1min", "python", "numpy",
            "scipy", "numba")
    s = "; ".join(f"{k}: {m[k]}" for k in keys if k in m)
    if wall_s is not None:
        s += f"; section took {wall_s:.0f} s"
    return f'<p class="meta">{_esc(s)}</p>'


#: A table cell whose number is not finite or larger than this (a relative error, a mass
#: over the total mass, an order) shows "diverged": the method blew up, the digits mean nothing.
DIVERGED_ABOVE = 1e3


def _fmt(v, spec=".2e", limit=DIVERGED_ABOVE):
    """A number for a table cell: "n/a" for None, "diverged" where it is inf, nan or beyond
    ``limit`` in size (None: no limit)."""
    if v is None:
        return "n/a"
    v = float(v)
    if not math.isfinite(v) or (limit is not None and abs(v) > limit):
        return "diverged"
    return format(v, spec)


# --- 1. the process ---------------------------------------------------------------------

#: The shipped example with the default case on the detailed model (its zone map).
DETAILED_EXAMPLE = "limestone_detailed.toml"


def process_section(out: Path, quick: bool, log=print) -> str:
    """The embedded default scene run now: its size distribution over time, x50 against time
    and against the specific energy, and a table of the run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .plotstyle import plain_log_ticks
    from .runner import psd_figure, simulate
    from .scene import load_scene

    scene = load_scene(None)
    t0 = time.perf_counter()
    model, records, psds = simulate(scene, progress=False)
    wall = time.perf_counter() - t0
    fig = psd_figure(model, records, psds)
    plain_log_ticks(fig)
    fig.savefig(out / "process_psd.png", dpi=80)
    plt.close(fig)
    t = np.array([r["t_s"] for r in records])
    e_m = np.array([r["specific_energy_J_per_kg"] for r in records]) / 1e3
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12.5, 4.4))
    for key, lab, ls in (("x10_m", "x10", ":"), ("x50_m", "x50", "-"), ("x90_m", "x90", "--")):
        x = np.array([r[key] for r in records]) * 1e6
        a1.plot(t, x, ls, color="C0", label=lab)
        pos = e_m > 0.0  # t = 0 has none: a log axis starts at the first output time
        a2.plot(e_m[pos], x[pos], ls, color="C1", label=lab)
    a1.set(xlabel="time t [s]", ylabel="size [\u00b5m]", yscale="log", title="characteristic sizes against time")
    a2.set(xlabel="specific energy E_m [kJ/kg]", ylabel="size [\u00b5m]", yscale="log", xscale="log",
           title="against the specific energy put in")
    plain_log_ticks(fig)
    for a in (a1, a2):
        a.grid(alpha=0.3, which="both")
        a.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8)
    fig.suptitle(f"{scene.scene.name}: grinding progress", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "process_sizes.png", dpi=80)
    plt.close(fig)
    zone_html = _zone_map(out, model)
    if not zone_html:
        # The default runs the simple model: the zones of the detailed example's table, at the
        # same operating point, say where its stresses would come from.
        from .mill import MillModel
        from .scene import example_path

        zone_html = _zone_map(out, MillModel(load_scene(example_path(DETAILED_EXAMPLE))), DETAILED_EXAMPLE)
    from .runner import prediction_band

    band = prediction_band(scene)
    if band is not None and "x50_m" in band["outputs"]:
        lo, hi = band["outputs"]["x50_m"]
        parts = {"table": "the stress-energy table's stated error (every zone's collision rate and median energy at "
                          "the edges of its stated error)",
                 "calibration": "the fitted constants' 95 % intervals"}
        said = "; ".join(f"{parts[k]}: [{v['outputs']['x50_m'][0] * 1e6:.4g}, {v['outputs']['x50_m'][1] * 1e6:.4g}] "
                         "\u00b5m"
                         for k, v in band["parts"].items())
        zone_html = (f"<p>Prediction band: x50 after {band['t_s']:g} s {records[-1]['x50_m'] * 1e6:.4g} \u00b5m in "
                     f"[{lo * 1e6:.4g}, {hi * 1e6:.4g}] \u00b5m, from {said}.</p>") + zone_html
    idx = np.unique(np.linspace(0, len(records) - 1, min(8, len(records))).round().astype(int))
    rows = [[f"{records[i]['t_s']:g}", _fmt(records[i]["x10_m"] * 1e6, ".3g", None),
             _fmt(records[i]["x50_m"] * 1e6, ".3g", None),
             _fmt(records[i]["x90_m"] * 1e6, ".3g", None), _fmt(e_m[i], ".3g", None),
             _fmt(records[i].get("power_W"), ".3g", None),
             _fmt(100.0 * records[i].get("below_grid_fraction", 0.0), ".2f", None)]
            for i in idx]
    s = scene
    return "\n".join([
        f'<h2 id="process">1. {SECTIONS["process"]}</h2>', _meta(machine(), wall),
        f"<p>The embedded default scene ({_esc(s.scene.name)}: {_esc(s.operation.mode)}, {_esc(s.material.model)}, "
        f"{_esc(s.kinetics.model)} stress model, tip speed {s.mill.tip_speed_m_per_s:g} m/s, bead filling "
        f"{100 * s.mill.bead_filling:g} %, {model.grid.n} size classes), run now for {s.run.t_end_s:g} s of grinding "
        f"({_esc(_what_psd_text(model))}).</p>",
        '<img src="process_psd.png" alt="size distribution over time">',
        '<img src="process_sizes.png" alt="x10, x50, x90 against time and specific energy">',
        _table(["time [s]", "x10 [\u00b5m]", "x50 [\u00b5m]", "x90 [\u00b5m]", "specific energy [kJ/kg]", "power [W]",
                "below the size grid [%]"], rows), zone_html])


def _zone_map(out: Path, model, example: str | None = None) -> str:
    """The zones V1-V4 of the DEM slice behind a detailed model's table, drawn on a half
    section of the mill (radius against axial position) and coloured with the table's
    collision rate and median stress energy there at the scene's operating point, with
    their stated relative error; '' for a model without a DEM table. ``example``: the
    shipped example the model runs (None: the default scene)."""
    src = model.source
    table = getattr(src, "table", None)
    if table is None or (table.manifest.get("scene") or {}).get("kind") != "disc_slice":
        return ""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import LogNorm

    from .dem.mills.zones import Zones
    from .dem.scene import scene_from_dict
    from .plotstyle import plain_log_ticks

    dem = scene_from_dict(table.manifest["scene"])
    zones = Zones(dem.geometry, dem.zones)
    g = dem.geometry
    op = model.operating_point(model.inputs)
    zs = src.zones(op)
    err = src.relative_error()
    r = np.linspace(g.shaft_radius_m, g.chamber_radius_m, 300)
    z = np.linspace(g.disc_z_m - 0.5 * g.height_m, g.disc_z_m + 0.5 * g.height_m, 300)
    rr, zz = np.meshgrid(r, z)
    zid = zones.classify(np.column_stack([rr.ravel(), np.zeros(rr.size), zz.ravel()])).reshape(rr.shape)
    fields = (("collision rate [1/(m3 s)]", np.array([q.collision_rate_per_m3_s for q in zs]),
               err["collision_frequency"]),
              ("median stress energy SE [J]", np.array([q.median_energy_J for q in zs]), err["se_median"]))
    fig, axes = plt.subplots(1, 2, figsize=(12.5, 4.6))
    for ax, (label, vals, rel) in zip(axes, fields):
        img = np.where(zid >= 0, vals[np.clip(zid, 0, None)], np.nan)
        ok = vals[vals > 0]
        m = ax.pcolormesh(zz * 1e3, rr * 1e3, img, shading="auto", cmap="viridis",
                          norm=LogNorm(ok.min(), ok.max()) if ok.size and ok.max() > ok.min() else None)
        disc = (np.abs(zz - g.disc_z_m) < 0.5 * g.disc_thickness_m) & (rr < g.disc_radius_m)
        ax.contourf(zz * 1e3, rr * 1e3, disc.astype(float), levels=[0.5, 1.5], colors=["0.55"])
        for k, name in enumerate(zones.names):
            # labelled on one side of the disc (the zones are mirror images about it)
            sel = (zid == k) & (zz > g.disc_z_m + 0.5 * g.disc_thickness_m)
            if sel.any():
                e = rel[k]
                ax.text(float(np.median(zz[sel])) * 1e3, float(np.median(rr[sel])) * 1e3,
                        f"{name}\n{vals[k]:.2g}" + (f"\n\u00b1{e:.0%}" if np.isfinite(e) else ""),
                        ha="center", va="center", fontsize=8, color="white",
                        bbox=dict(boxstyle="round,pad=0.2", fc="black", alpha=0.45, lw=0))
        ax.set(xlabel="axial position z [mm] (disc in grey)", ylabel="radius r [mm]", title=label)
        fig.colorbar(m, ax=ax, shrink=0.9)
    whose = f"{example}'s" if example else "the default scene's"
    fig.suptitle(f"DEM zones of {whose} table {model.scene.kinetics.stress_distribution.table!r} at "
                 f"{op.tip_speed_m_per_s:g} m/s and "
                 f"{100 * model.inputs['bead_filling']:g} % filling (component {src.component}; \u00b1: stated "
                 "relative error)", fontsize=10)
    plain_log_ticks(fig)
    fig.tight_layout()
    fig.savefig(out / "process_zones.png", dpi=80)
    plt.close(fig)
    if example:
        lead = (f"Where the detailed model's stresses come from (the default scene runs Kwade's simple model; "
                f"{_esc(example)} is this case on the coupled DEM-CFD table, opt-in): its table's zones")
        carried = "which that example's prediction band carries"
    else:
        lead, carried = "Where the stresses come from: the table's zones", "which the run's prediction band carries"
    return (f"<p>{lead} on a half section of the mill (one disc, "
            "axially periodic), each with its collision rate and the median of its stress energies at the scene's "
            "operating point and their stated relative error (interpolation and DEM sampling at the point, plus the "
            f"table's work-precision error), {carried}.</p>"
            '<img src="process_zones.png" alt="zone map of collision rate and median stress energy">')


def _what_psd_text(model) -> str:
    from .runner import _what_psd

    return _what_psd(model)


# --- 2. population balance --------------------------------------------------------------

def pbm_section(out: Path, quick: bool, log=print) -> str:
    from .studies.pbm_integrators import INTEGRATOR_CASES, integrator_study

    t0 = time.perf_counter()
    res = integrator_study(quick=quick, out=log)
    wall = time.perf_counter() - t0
    _plot_pbm(res, out / "pbm_integrators.png")
    (out / "pbm_integrators.json").write_text(json.dumps(res, indent=1, default=float))
    parts = [f'<h2 id="pbm">2. {SECTIONS["pbm"]}</h2>', _meta(machine(), wall),
             "<p>Batch grinding whose breakage operator swings between two operating points, "
             "A(t) = (1 - th) A_lo + th A_hi, th = (1 + sin(2 pi t / P)) / 2; the two operators "
             "do not commute. Reference: the exact step (matrix exponential with the operator "
             "at the step midpoint) at many steps, Richardson-extrapolated. Error: max over "
             "classes of |m - m_ref| / total mass at the end. <b>Exact step</b>: one matrix "
             "exponential per step (exact for rates constant over a step). <b>Adaptive "
             "exponential</b>: the model's adaptive integrator (exponential midpoint, step "
             "doubling), tolerance swept. <b>scipy BDF</b>: solve_ivp with the exact "
             "Jacobian, one call over the whole time, tolerance swept. <b>Taylor 1, Taylor "
             "2</b>: the series of expm(h A) truncated after 1 or 2 terms, as the "
             "transformation matrices of Dyssol's population-balance crusher unit "
             "(CrusherPBMTM, methods Newton and Runge-Kutta), here at fixed steps with the "
             "midpoint operator. Measured order: slope of log error against log step size "
             "(mean step for the adaptive methods) between 10 x the reference's error and "
             "0.1, Taylor steps only where h times the largest rate is at most 1; for BDF, "
             "whose order varies up to 5, only that slope.</p>",
             '<img src="pbm_integrators.png" alt="PBM integrators: error against run time">']
    for case, r in res.items():
        c = INTEGRATOR_CASES[case]
        parts.append(f"<h3>{_esc(case)} case: {r['states']} states, largest rate "
                     f"{r['max_rate_per_s']:.3g} 1/s, period {c['period_s']:g} s, "
                     f"{r['t_end_s']:g} s simulated</h3>")
        parts.append(_table(["method", "measured order [-]"], [[k, _order_cell(k, v)]
                                                              for k, v in r["orders"].items()]))
        parts.append(_table(
            ["method", "steps [-]", "rtol [-]", "error [-] (of total mass)", "run time [s]",
             "smallest mass [-] (of total)", "h x largest rate [-]"],
            [[x["method"], x["steps"], _fmt(x.get("rtol"), ".0e"), _fmt(x["error"]),
              _fmt(x["wall_s"], ".3g", None), _fmt(x["min_mass"], ".1e"),
              _fmt(x.get("h_times_max_rate"), ".2g", None)] for x in r["rows"]]))
        parts.append(f"<p>Reference: {r['reference_steps']} exact steps "
                     f"({r['reference_wall_s']:.1f} s), estimated error "
                     f"{r['reference_error']:.1e}.</p>")
    return "\n".join(parts)


def _order_cell(method, v) -> str:
    if not math.isfinite(v):
        return "none: diverged (or went negative) at every step tried"
    if method == "scipy BDF":
        return f"slope {v:.2f} (variable order 1-5, not an order)"
    return f"{v:.2f}"


def _plot_pbm(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plotstyle import plain_log_ticks

    fig, ax = plt.subplots(2, len(res), figsize=(8.0 * len(res), 9), squeeze=False)
    for j, (case, r) in enumerate(res.items()):
        gone = []
        for k, (name, order) in enumerate(r["orders"].items()):
            rows = [x for x in r["rows"] if x["method"] == name and math.isfinite(x["error"])
                    and x["error"] < 1e3]
            if not rows:
                gone.append(name)
                continue
            lab = (f"{name} (unstable)" if not math.isfinite(order) else
                   f"{name} (slope {order:.1f})" if name == "scipy BDF" else
                   f"{name} (order {order:.2f})")
            ax[0, j].loglog([x["wall_s"] for x in rows], [x["error"] for x in rows], "o-",
                            color=f"C{k}", label=lab)
            ax[1, j].loglog([x["step_s"] for x in rows], [x["error"] for x in rows], "o-",
                            color=f"C{k}", label=lab)
        ax[0, j].set(xlabel="run time [s]", ylabel="error / total mass", title=f"{case}: work-precision")
        for a in ax[:, j]:
            if gone:  # in the legend, beside the axes: a text inside could cover points
                a.plot([], [], " ", label=f"{', '.join(gone)}: diverged at every step tried")
        ax[1, j].set(xlabel="step size [s] (mean for adaptive)", ylabel="error / total mass",
                     title=f"{case}: error against step")
        for a in ax[:, j]:
            a.grid(alpha=0.3, which="both")
            a.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    plain_log_ticks(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


# --- 3. co-simulation -------------------------------------------------------------------

def cosim_section(out: Path, quick: bool, log=print) -> str:
    import flowsheets
    from flowsheets.spec import load_flowsheet
    from flowsheets.wp import work_precision

    name, t_end, steps, ref = COSIM_QUICK if quick else COSIM_FULL
    fs = load_flowsheet(Path(flowsheets.__file__).parent / name)
    if t_end is not None:
        fs = fs.with_(t_end_s=t_end)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="millfmu-report-wp-") as tmp:
        fmu_dir = Path(tmp) / "fmus"
        wp_out = Path(tmp) / "wp"
        wp_out.mkdir()
        table = work_precision(fs, list(steps), ref, wp_out, fmu_dir=fmu_dir, log=log)
        shutil.copyfile(wp_out / "wp.png", out / "cosim_wp.png")
        wp = json.loads((wp_out / "wp.json").read_text())
        (out / "cosim_wp.json").write_text(json.dumps(wp, indent=1))
    wall = time.perf_counter() - t0
    pairs = [r.get("order_to_previous") for r in wp["rows"] if r.get("order_to_previous") is not None]
    unit = "m" if wp["variable"].endswith(("x10", "x50", "x90")) else "-"
    parts = [f'<h2 id="cosim">3. {SECTIONS["cosim"]}</h2>', _meta(machine(), wall),
             f"<p>Flowsheet {_esc(fs.name)} ({_esc(name)}, {fs.t_end_s:g} s simulated, "
             f"{_esc(fs.algorithm)}, fmpy master): error of {_esc(wp['variable'])} against a "
             f"run with step {ref:g} s, max over the common output times; wall time of the "
             f"master's run. Measured order (least squares over all steps): "
             f"{_fmt(wp['order'], '.2f')} for the max error, {_fmt(wp['order_at_end'], '.2f')} for the error at "
             f"the end; between neighbouring steps: "
             f"{', '.join(_fmt(p, '.2f') for p in pairs)}.</p>",
             '<img src="cosim_wp.png" alt="co-simulation step: error against run time">',
             _table(["step [s]", "steps [-]", f"max error [{unit}]", "relative error [-]", "order to previous [-]",
                     f"error at end [{unit}]", "wall time [s]", "mass residual [-] (relative)"],
                    [[f"{r['step_s']:g}", r["steps"], _fmt(r["error"], ".2e", None), _fmt(r["relative_error"]),
                      _fmt(r.get("order_to_previous"), ".2f"), _fmt(r["error_end"], ".2e", None),
                      _fmt(r["wall_s"], ".3g", None), _fmt(r["mass_residual"], ".1e")] for r in wp["rows"]]),
             f"<pre>{_esc(table)}</pre>"]
    return "\n".join(parts)


# --- 4. DEM -----------------------------------------------------------------------------

def _dem_tables(res) -> str:
    from millfmu.dem.analysis import precision as W

    head = ["setting", "run time [CPU s]"] + [f"{c}: relative error [%] (largest in {', '.join(W.TARGET_ZONES)})"
                                      for c in W.COLUMNS]
    parts = [_table(head, W.table_rows(res))]
    sl = W.slopes(res)
    parts.append(_table(["statistic", "measured order [-]: slope of log error against log T "
                         "(median over zones)", "range over zones [-]",
                         "independent contacts: slope [-]", "measured / independent contacts [-]"],
                        [[k, _fmt(v['median'], ".2f"), f"{_fmt(v['min'], '.2f')} ... {_fmt(v['max'], '.2f')}",
                          _fmt(v.get("predicted_slope"), ".2f"), _fmt(v.get("inflation"), ".1f")]
                         for k, v in sl.items()]))
    parts.append(f"<p>{_esc(W.summary_text(res))}</p>")
    return "\n".join(parts)


def dem_section(out: Path, quick: bool, dem_runs=None, log=print) -> str:
    """The DEM section; ``dem_runs``: a full study's folder (its ``work_precision.json``,
    :func:`millfmu.dem.analysis.precision.read_study`)."""
    from millfmu.dem.analysis import precision as W

    parts = [f'<h2 id="dem">4. {SECTIONS["dem"]}</h2>',
             "<p>Coupled disc slice at 10 m/s, 80 % filling, 10 degree sector, no gravity "
             "(seed 001's protocol). Error of each tabulated statistic (per zone: SE_tn "
             "quantiles, collision frequency, local filling, collision power) against a long "
             "reference run. Recording length: batch means over the T-blocks of one long run, "
             "beside what independent contacts would give (Poisson counts, order statistics: "
             "the sampling statistics' T^-1/2); spin-up: windows of the same run; sector, "
             "DEM step and coupling interval: separate runs, each with the 2-sigma sampling "
             "noise of the comparison in brackets. Cells: largest relative error over the "
             "densely filled zones and the column's statistics.</p>"]
    t0 = time.perf_counter()
    import importlib.util

    if importlib.util.find_spec("numba") is None:  # the DEM needs it
        parts.append("<p><b>Not run now:</b> numba is not installed (pip install -e '.[dem]').</p>")
    elif quick:
        from .dem.first_compile import compile_if_cold

        compile_if_cold(coupled=True, log=log, run_s=W.QUICK["spin_up_s"] + W.QUICK["record_s"])
        run_dir = W.run_quick(Path(tempfile.mkdtemp(prefix="millfmu-report-dem-")) / "quick")
        try:
            res = W.analyse_quick(run_dir)
        finally:
            shutil.rmtree(run_dir.parent, ignore_errors=True)
        W.plot(res, out / "dem_recording.png",
               title=f"short coupled run: spin-up {W.QUICK['spin_up_s']:g} s, recording "
                     f"{W.QUICK['record_s']:g} s")
        (out / "dem_recording.json").write_text(json.dumps(res, indent=1))
        parts += [f"<h3>Run now: recording length on a short run (spin-up "
                  f"{W.QUICK['spin_up_s']:g} s, recording {W.QUICK['record_s']:g} s, "
                  f"{res['long_run']['beads']} beads, {res['long_run']['run_s']:.0f} CPU s)</h3>",
                  _meta(machine(), time.perf_counter() - t0),
                  '<img src="dem_recording.png" alt="DEM: error against recording length">',
                  _dem_tables(res),
                  "<p>The short run is not stationary (spun up for 0.02 s only): it checks "
                  "the method on a real run (what independent contacts would give falls as "
                  "T^-1/2; the measured error of this transient does not), not a table's "
                  "error.</p>"]
    else:
        if dem_runs is None:
            parts.append("<p><b>Not run now:</b> the full study's runs take hours on one core; "
                         "make them from a checkout with <code>python -m validation.work_precision "
                         "run --out DIR</code>, analyse them with <code>python -m "
                         "validation.work_precision table --out DIR</code> and pass "
                         "<code>--dem-runs DIR</code>.</p>")
        else:
            res = W.read_study(dem_runs)
            W.plot(res, out / "dem_work_precision.png")
            (out / "dem_work_precision.json").write_text(json.dumps(res, indent=1))
            parts += [f"<h3>The full study in {_esc(dem_runs)}</h3>", _meta(res["machine"]),
                      '<img src="dem_work_precision.png" alt="DEM work-precision">',
                      _dem_tables(res)]
    shipped = W.SUMMARY_PATH
    if shipped.is_file():
        data = json.loads(shipped.read_text())
        res = data["study"]
        W.plot(res, out / "dem_shipped.png")
        parts += [f"<h3>The full study shipped with millfmu "
                  f"(<code>{_esc(W.RUN_COMMAND)}</code>)</h3>", _meta(res["machine"]),
                  f"<p>Long run: {res['long_run']['beads']} beads, recorded "
                  f"{res['long_run']['recorded_s'][0]:g}-{res['long_run']['recorded_s'][1]:g} s, "
                  f"{res['long_run']['run_s']:.0f} CPU s on "
                  f"{res['long_run'].get('threads')} thread(s); reference window "
                  f"{res['reference_window_s'][0]:g}-{res['reference_window_s'][1]:g} s.</p>",
                  '<img src="dem_shipped.png" alt="DEM work-precision, shipped study">',
                  _dem_tables(res)]
    else:
        parts.append("<p>No full study shipped (millfmu/data/dem_work_precision.json).</p>")
    parts.append(_realizations())
    return "\n".join(parts)


def _realizations() -> str:
    """The realizations of the shipped table's version at the operating point (the
    reference of ``python -m validation.equivalence_runs``): their spread beside the study's
    sampling sigma of one recording."""
    from millfmu.dem.tables import equivalence as E

    try:
        ref = E.read_evidence().get("reference")
    except E.EquivalenceError as e:
        return f"<p>Realizations: {_esc(e)}</p>"
    if not ref:
        return ("<p>No realizations of the shipped table's version recorded "
                "(<code>python -m validation.equivalence_runs --reference --write</code>, "
                "from a checkout).</p>")
    runs = ref["runs"]
    head = (["statistic", "zone", "table's point [%]"] +
            [f"run on {r.get('threads')} thread(s), {r.get('wall_time_s', 0):.0f} s [%]"
             for r in runs] +
            ["standard deviation [%]", "study's sigma [%]", "ratio [-]"])
    rows = [[f, z, "0"] + ["-" if x is None else f"{100 * x:+.1f}" for _, x in got] +
            [_fmt(None if sd is None else 100 * sd, ".1f"),
             _fmt(None if law is None else 100 * law, ".1f"),
             _fmt(sd / law if sd is not None and law else None, ".1f")]
            for f, z, got, sd, law in E.spread(ref)]
    return "\n".join([
        "<h3>Realizations of the shipped coupled table's version at the operating point "
        "(<code>python -m validation.equivalence_runs --show</code>)</h3>",
        f"<p>The table's point and runs of the same sources on other thread counts (each "
        f"splits the beads into other chunks: another trajectory from the same start), "
        f"spin-up and recording as the table's ({ref['record_s']:g} s recorded); values "
        f"relative to the table's point. Their standard deviation is the noise of one table "
        f"point as built; the study's sigma is its recording-length law for one recording "
        f"of that length (windows of one long run). A change of the DEM's sources that alters "
        f"only round-off is accepted when its runs here differ from these by less than "
        f"{E.Z_LIMIT:g} standard errors.</p>",
        _table(head, rows)])


def trends_section(out: Path, quick: bool, log=print) -> str:
    """Both shipped pairs' rates along each parameter (the simple and the detailed model,
    the detailed model's band) and where the detailed model is energy-limited."""
    from . import rates as mrates

    t0 = time.perf_counter()
    log("report: rates along the operating parameters (both shipped pairs)")
    pairs = mrates.shipped_pairs()
    head, rows = mrates.trend_table(pairs)
    freq = ("detailed model frequency-limited: breakage probability per stress at the reference at "
            f"least {mrates.ENERGY_LIMITED_P:g}.")
    notes = [f"<p>{_esc(r.name)}: {_esc(r.regime_note() or freq)}</p>" for r in pairs]
    wall = time.perf_counter() - t0
    return "\n".join([
        f'<h2 id="trends">5. {SECTIONS["trends"]}</h2>', _meta(machine(), wall),
        "<p>Each model's rate over its rate at the reference point (* the reference; yeast: the feed's "
        "disruption rate, limestone: S at the feed's x50 and x90), the detailed model on the coupled table with "
        "the band of the table's stated error in brackets. Seed 000's "
        "measurements follow the simple model's trends. The same table: <code>millfmu rates</code>.</p>",
        _table(head, rows), *notes])


# --- the page ---------------------------------------------------------------------------

def build_report(out_dir, quick: bool = False, dem_runs=None, log=print) -> list[Path]:
    """Write ``report.html`` and its PNGs (and the studies' JSON) into ``out_dir``, built in
    a temporary folder beside it and moved into place when complete; returns the files."""
    from .runner import check_out_dir, staging_dir

    out = check_out_dir(out_dir)
    if dem_runs is not None and not quick:  # a folder without a study: refused before the minutes of work
        from .dem.analysis.precision import read_study

        read_study(dem_runs)
    t0 = time.perf_counter()
    start = machine()
    tmp = staging_dir(out, ".millfmu-report-")
    try:
        body = [process_section(tmp, quick, log), pbm_section(tmp, quick, log), cosim_section(tmp, quick, log),
                dem_section(tmp, quick, dem_runs, log), trends_section(tmp, quick, log)]
        wall = time.perf_counter() - t0
        page = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
                f"<title>millfmu: error against run time</title><style>{CSS}</style></head><body>",
                "<h1>millfmu: error against run time</h1>",
                f"<p>{'Quick report (short versions of each study, for CI)' if quick else 'Full report'}; "
                f"built in {wall:.0f} s.</p>", _meta(start),
                "<ul>" + "".join(f'<li><a href="#{k}">{_esc(v)}</a></li>' for k, v in SECTIONS.items()) + "</ul>"]
        page += body + ["</body></html>"]
        (tmp / "report.html").write_text("\n".join(page), encoding="utf-8")
        out.mkdir(parents=True, exist_ok=True)
        files = []
        for f in sorted(tmp.iterdir()):
            dst = out / f.name
            os.replace(f, dst)
            files.append(dst)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return files


def _cmd_report(args) -> int:
    from .dem.analysis.precision import WorkPrecisionError

    t0 = time.perf_counter()
    try:
        files = build_report(args.out, quick=args.quick, dem_runs=args.dem_runs,
                             log=lambda m: print(m, file=sys.stderr, flush=True))
    except WorkPrecisionError as e:
        print(f"millfmu report: --dem-runs: {e}", file=sys.stderr)
        return 2
    print(f"wrote {files[[f.name for f in files].index('report.html')]} and {len(files) - 1} "
          f"files beside it in {time.perf_counter() - t0:.0f} s")
    return 0


def _cmd_bench_integrators(args) -> int:
    from .studies.pbm_integrators import integrator_study

    integrator_study(quick=args.quick)
    return 0


def register(subparsers):
    r = subparsers.add_parser("report", help="one HTML page of every error-against-run-time "
                              "study (PBM integrators, co-simulation step, DEM work-precision)")
    r.add_argument("--out", default="report", help="output folder (default ./report): "
                   "report.html, PNGs beside it, the studies' JSON")
    r.add_argument("--quick", action="store_true", help="short versions of each study "
                   "(about half a minute; a first run on a fresh machine also compiles the DEM's "
                   "kernels, about 2 minutes)")
    r.add_argument("--dem-runs", default=None, metavar="DIR", help="also a full DEM "
                   "work-precision study: its folder, with the work_precision.json that "
                   "'python -m validation.work_precision table --out DIR' writes (from a "
                   "checkout; the runs take hours on one core)")
    r.set_defaults(func=_cmd_report)


def register_bench(bench_subparsers):
    b = bench_subparsers.add_parser("integrators", help="PBM integrators (exact step, adaptive "
                                    "exponential, scipy BDF, truncated Taylor): error against "
                                    "run time and measured orders on a smooth and a stiff case")
    b.add_argument("--quick", action="store_true", help="fewer steps and tolerances")
    b.set_defaults(func=_cmd_bench_integrators)
