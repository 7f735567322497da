"""Run a scene over time and write result.json, psd.csv and PNG plots.

Files are first written to a temporary folder next to the target and moved into place
only when all of them are complete, so an interrupted or failed run leaves no
half-written results; result files of an earlier run in the folder that this run does not
write (e.g. its plots, with --no-plots) are removed then, so a folder never mixes runs.
result.json carries the run's provenance: the resolved scene (every key), millfmu, Python
and numpy versions, the stress-energy table's identity and stated error, the wall time.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from . import __version__
from .mill import MillModel
from .scene import Scene, scene_to_dict

#: Every file a run writes into its output folder (the plots only with plots on).
RESULT_FILES = ("result.json", "psd.csv", "psd.png", "sizes.png")


class OutputError(ValueError):
    """The output folder cannot take the results: names the option, the path and why."""

    def __init__(self, path, why: str):
        self.path = str(path)
        super().__init__(f"--out {self.path}: {why}")


def check_out_dir(out_dir) -> Path:
    """OutputError unless ``out_dir`` is (or can become) a folder this process can write
    into: checked by making and removing a temporary folder beside it before a run."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise OutputError(out, "exists and is not a folder; give a folder (new or from an earlier run)")
    parent = out.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        probe = Path(tempfile.mkdtemp(prefix=".millfmu-probe-", dir=parent))
        probe.rmdir()
        if out.is_dir():
            probe = Path(tempfile.mkdtemp(prefix=".millfmu-probe-", dir=out))
            probe.rmdir()
    except OSError as e:
        raise OutputError(out, f"cannot write there ({e.strerror or e}); give a writable folder") from None
    return out

#: Scalars written per output time to result.json, with their units.
RESULT_KEYS = {
    "t_s": "s",
    "x10_m": "m",
    "x50_m": "m",
    "x90_m": "m",
    "below_grid_fraction": "1",
    "total_mass_kg": "kg",
    "holdup_kg": "kg",
    "product_mass_flow_kg_per_s": "kg/s",
    "disrupted_fraction": "1",
    "se_beads_J": "J",
    "se_product_J": "J",
    "sf_per_s": "1/s",
    "stress_number": "1",
    "specific_energy_J_per_kg": "J/kg",
    "power_W": "W",
    "tip_speed_m_per_s": "m/s",
}


def tip_speed_at(scene: Scene, t_s: float) -> float:
    """Tip speed [m/s] at time t_s from the scene's profile (linear), or the constant one."""
    prof = scene.run.tip_speed_profile
    if not prof:
        return scene.mill.tip_speed_m_per_s
    ts = [p[0] for p in prof]
    vs = [p[1] for p in prof]
    return float(np.interp(t_s, ts, vs))


def simulate(scene: Scene, progress: bool = True, table_error_multiple: float = 0.0):
    """Run the scene; returns (model, records, psd rows) with one record per output time.
    ``table_error_multiple``: see :class:`MillModel` (the prediction band's edges)."""
    model = MillModel(scene, table_error_multiple=table_error_multiple)
    r = scene.run
    n_steps = int(math.ceil(r.t_end_s / r.dt_s - 1e-9))
    every = max(1, int(round(r.output_interval_s / r.dt_s)))
    records, psds = [], []

    def record(out):
        values = {**out, "total_mass_kg": model.total_mass_kg()}
        records.append({k: float(values[k]) for k in RESULT_KEYS if k in values})
        # Q3 at every edge, the lowest one included (the mass below the grid).
        psds.append(np.concatenate(([out["below_grid_fraction"]], np.cumsum(out["psd"]))))

    profile = bool(r.tip_speed_profile)
    if profile:
        model.set_inputs(tip_speed_m_per_s=tip_speed_at(scene, 0.0))
    record(model.outputs())
    bar = None
    if progress:
        from tqdm import tqdm

        # Shown only for runs that take longer than a couple of seconds.
        bar = tqdm(total=n_steps, unit="step", delay=2.0, desc=scene.scene.name, leave=False)
    try:
        for i in range(n_steps):
            t0 = model.t_s
            h = min(r.dt_s, r.t_end_s - t0)
            if h <= 1e-12 * r.t_end_s:
                break
            if profile:
                v0, v1 = tip_speed_at(scene, t0), tip_speed_at(scene, t0 + h)
                end = {"tip_speed_m_per_s": v1} if v1 != v0 else None
                out = model.step(h, inputs_end=end, tip_speed_m_per_s=v0)
            else:
                out = model.step(h)
            if (i + 1) % every == 0 or i + 1 == n_steps:
                record(out)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return model, records, psds


#: Outputs whose prediction band result.json states, at the end of a run.
BAND_KEYS = ("x10_m", "x50_m", "x90_m", "disrupted_fraction")


def prediction_band(scene: Scene, multiple: float = 1.0) -> dict | None:
    """The band of the end-of-run outputs that the stress-energy table's stated error spans,
    or None for a scene without a table. Two more runs of the scene with every zone's
    collision frequency and median stress energy at the edges of ``multiple`` times their
    stated relative error b (factors (1 + b)^-1 and 1 + b: the lower edge breaks least, the
    upper most; the breakage rates grow with both, so these runs bound the box of zone
    statistics; :meth:`TableStressSource.relative_error` says what b holds)."""
    if scene.kinetics.model != "detailed" or scene.kinetics.stress_distribution.source != "table":
        return None
    ends = {}
    for sign in (-1.0, 1.0):
        model, records, _ = simulate(scene, progress=False, table_error_multiple=sign * multiple)
        ends[sign] = (records[-1], model.source.relative_error())
    lo, hi = ends[-1.0][0], ends[1.0][0]
    err = ends[1.0][1]
    band = {k: sorted((lo[k], hi[k])) for k in BAND_KEYS if k in lo}
    return {
        "t_s": lo["t_s"],
        "multiple": multiple,
        "outputs": band,
        "zones": err["zones"],
        "collision_frequency_relative_error": [float(v) if np.isfinite(v) else None for v in err["collision_frequency"]],
        "se_median_relative_error": [float(v) if np.isfinite(v) else None for v in err["se_median"]],
        "method": ("two runs with every zone's collision frequency and median stress energy at the edges of the table's "
                   "stated relative error b, factors (1 + b)^-1 and (1 + b); b = interpolation error + 2 sigma of the DEM "
                   "sampling at the last operating point + the work-precision expected error (recording, spin-up, sector, "
                   "step, coupling), per zone"),
    }


def run_warnings(model: MillModel, records) -> list:
    """The model's warnings about its data, and those about the outputs (below-grid mass) at
    the output time where that mass is largest."""
    out = list(model.warnings)
    if records:
        out.extend(model.output_warnings(max(records, key=lambda r: r.get("below_grid_fraction", 0.0))))
    return out


def provenance(scene: Scene, model: MillModel, wall_s: float | None = None) -> dict:
    """What reproduces a run: the resolved scene (every key with its value), versions, the
    stress-energy table's identity and stated error at the final operating point, wall time."""
    import platform

    prov = {
        "scene": scene_to_dict(scene),
        "millfmu_version": __version__,
        "python_version": platform.python_version(),
        "numpy_version": np.__version__,
        "inputs_final": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in model.inputs.items()},
        "wall_time_s": wall_s,
    }
    src = model.source
    table = getattr(src, "table", None)
    if table is not None:
        m = table.manifest
        ident = {"ref": scene.kinetics.stress_distribution.table, "key": m.get("key"), "manifest_sha256": m.get("manifest_sha256"),
                 "files": m.get("files"), "kernel_version": m.get("kernel_version"), "builder": m.get("builder"),
                 "grid": m.get("grid"), "resolution": m.get("resolution"), "rebuild_command": m.get("rebuild_command")}
        lk = getattr(src, "last_lookup", None)
        if lk is not None:
            # Stated relative error per zone, as the prediction band uses it (None: no collisions).
            err = src.relative_error(lk)

            def plain(a):
                return [float(x) if np.isfinite(x) else None for x in a]

            ident["stated_error"] = {"point": lk.point, "zones": err["zones"],
                                     "collision_frequency_relative": plain(err["collision_frequency"]),
                                     "se_median_relative": plain(err["se_median"]),
                                     "notes": list(getattr(src, "last_notes", []))}
        prov["table"] = ident
    return prov


def write_results(out_dir: str | Path, scene: Scene, model: MillModel, records, psds, plots: bool = True,
                  wall_s: float | None = None, band: dict | None = None) -> list[Path]:
    """Write result.json, psd.csv and PNG plots into out_dir atomically; returns the paths.
    ``band``: the prediction band (:func:`prediction_band`; computed here when None and the
    scene reads a table).

    Result files of an earlier run there that this run does not write are removed."""
    out = check_out_dir(out_dir)
    if band is None:
        band = prediction_band(scene)
    tmp = Path(tempfile.mkdtemp(prefix=".millfmu-", dir=out.parent))
    try:
        op = model.operating_point(model.inputs)
        result = {
            "scene": {
                "name": scene.scene.name,
                "description": scene.scene.description,
                "mode": scene.operation.mode,
                "material": scene.material.model,
                "kinetics": scene.kinetics.model,
                "eta_eff_Pa_s": op.eta_eff_Pa_s,
                "reynolds": op.reynolds,
                "rho_eff_kg_per_m3": op.rho_eff_kg_per_m3,
                "n_classes": model.grid.n,
                "class_edges_m": model.grid.edges_m.tolist(),
            },
            "units": {k: v for k, v in RESULT_KEYS.items()},
            "outputs": records,
            "prediction_band": band,
            "warnings": run_warnings(model, records),
            "provenance": provenance(scene, model, wall_s),
        }
        (tmp / "result.json").write_text(json.dumps(result, indent=1, allow_nan=True))
        with open(tmp / "psd.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            # The first Q3 column, at the grid's lowest edge, is the mass below the grid.
            w.writerow(["t_s"] + [f"Q3_x_le_{e:.6g}_m" for e in model.grid.edges_m])
            for rec, q in zip(records, psds):
                w.writerow([repr(rec["t_s"])] + [f"{v:.12g}" for v in q])
        if plots:
            _plots(tmp, model, records, psds)
        out.mkdir(parents=True, exist_ok=True)
        written = []
        for f in sorted(tmp.iterdir()):
            os.replace(f, out / f.name)
            written.append(out / f.name)
        for name in RESULT_FILES:
            if not (tmp / name).exists() and (out / name) not in written:
                (out / name).unlink(missing_ok=True)
        return written
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _plots(folder: Path, model: MillModel, records, psds):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    e = model.grid.edges_m
    t = np.array([r["t_s"] for r in records])
    idx = np.unique(np.linspace(0, len(records) - 1, min(8, len(records))).round().astype(int))
    cmap = plt.get_cmap("viridis")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, i in enumerate(idx):
        c = cmap(k / max(1, len(idx) - 1))
        q3 = psds[i]  # at every edge: q3[0] is the mass below the grid
        a1.semilogx(e * 1e6, q3, color=c, label=f"t = {t[i]:g} s")
        dens = np.diff(q3) / np.diff(np.log10(e))
        a2.semilogx(model.grid.x_m * 1e6, dens, color=c)
        if q3[0] > 0.0:
            a2.plot([e[0] * 1e6], [q3[0]], "v", color=c, ms=5)
    b = psds[idx[-1]][0]
    a1.axvline(e[0] * 1e6, color="0.6", lw=0.8)
    a1.text(e[0] * 1e6, 0.98, f" below grid at t = {t[idx[-1]]:g} s: {b:.2%}", fontsize=8, va="top")
    a2.set_title("v: mass fraction below the grid (not per decade)", fontsize=8)
    a1.set_xlabel("particle size x [µm]")
    a1.set_ylabel("Q3 [-]")
    a1.grid(True, which="both", alpha=0.3)
    a1.legend(fontsize=8)
    a2.set_xlabel("particle size x [µm]")
    a2.set_ylabel("q3,lg [-]  (mass density per decade)")
    a2.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"{model.scene.scene.name}: size distribution over time")
    fig.tight_layout()
    fig.savefig(folder / "psd.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for key, lab in (("x10_m", "x10"), ("x50_m", "x50"), ("x90_m", "x90")):
        ax.plot(t / 60.0, [r[key] * 1e6 for r in records], label=lab)
    ax.set_yscale("log")
    ax.set_xlabel("time [min]")
    ax.set_ylabel("characteristic size [µm]")
    ax.grid(True, which="both", alpha=0.3)
    if any(r.get("below_grid_fraction", 0.0) > 0.0 for r in records):
        ax.plot([], [], "k:", label="below grid (right axis)")
        axb = ax.twinx()
        axb.plot(t / 60.0, [r["below_grid_fraction"] for r in records], "k:")
        axb.set_ylabel("mass fraction below the grid [-]")
    ax.legend()
    if "disrupted_fraction" in records[0]:
        ax2 = ax.twinx()
        ax2.plot(t / 60.0, [r["disrupted_fraction"] for r in records], "k--", label="disrupted")
        ax2.set_ylabel("disrupted fraction [-]")
        ax2.set_ylim(0, 1)
    fig.suptitle(f"{model.scene.scene.name}: characteristic sizes")
    fig.tight_layout()
    fig.savefig(folder / "sizes.png", dpi=110)
    plt.close(fig)


def summary_table(records, rows: int = 8) -> str:
    """A short fixed-width table of the run for the terminal."""
    idx = np.unique(np.linspace(0, len(records) - 1, min(rows, len(records))).round().astype(int))
    yeast = "disrupted_fraction" in records[0]
    head = f"{'t [s]':>9} {'x10 [um]':>9} {'x50 [um]':>9} {'x90 [um]':>9} {'SF@x50 [1/s]':>13} {'E_m [kJ/kg]':>12} {'holdup [kg]':>11}"
    if yeast:
        head += f" {'disrupted':>9}"
    lines = [head, "-" * len(head)]
    for i in idx:
        r = records[i]
        line = (
            f"{r['t_s']:9.1f} {r['x10_m'] * 1e6:9.3f} {r['x50_m'] * 1e6:9.3f} {r['x90_m'] * 1e6:9.3f} "
            f"{r['sf_per_s']:13.4g} {r['specific_energy_J_per_kg'] / 1e3:12.4g} {r['holdup_kg']:11.6g}"
        )
        if yeast:
            line += f" {r['disrupted_fraction']:9.4f}"
        lines.append(line)
    return "\n".join(lines)
