"""Run a scene over time and write result.json, psd.csv and PNG plots.

Files are first written to a complete result folder next to the target (hidden,
``.millfmu-<pid>-new-*``) and switched in with one atomic rename (an exchange of the two
folders where Linux offers it), so an interrupted or killed run leaves the old complete set
or the new one, never a mix; result files of an earlier run that this run does not write
(e.g. its plots, with --no-plots) go with the old folder; other files there are kept.
Temporary folders of killed runs are removed by the next run.
result.json carries the run's provenance: the resolved scene (every key), millfmu, Python
and numpy versions, the stress-energy table's identity and stated error, the wall time.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path

import numpy as np

from . import __version__
from .mill import MillModel, q3_at_edges
from .scene import Scene, number_key, scene_to_dict

#: Every file a run writes into its output folder (the plots only with plots on).
RESULT_FILES = ("result.json", "psd.csv", "psd.png", "sizes.png")


class OutputError(ValueError):
    """The output folder cannot take the results: names the option, the path and why."""

    def __init__(self, path, why: str, option: str = "--out"):
        self.path = str(path)
        super().__init__(f"{option} {self.path}: {why}")


#: Hidden temporary folders of a run beside ``--out``: ``.millfmu-<pid>-new-<name>`` holds the
#: new results until they are switched in, ``.millfmu-<pid>-old-<name>`` the replaced ones
#: until they are removed. Those of a process that no longer runs are removed by the next
#: run in that folder (an ``old`` one whose folder is missing is renamed back first).
TEMP_PREFIX = ".millfmu-"
#: Called between the steps of switching results in (a test stops the process there).
_switch_hook = None


def _existing_ancestor(p: Path) -> Path:
    p = Path(os.path.abspath(p))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def current_umask() -> int:
    """The process's file mode creation mask: read from /proc where it is there, else set and
    restored at once."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def staging_dir(out: Path, prefix: str) -> Path:
    """A new hidden folder beside ``out`` (``out``'s parents made where missing) that takes
    the results before they move into ``out``. Its mode is ``out``'s own where ``out`` is a
    folder (the two may be swapped, and the user's folder keeps its mode), else the mode the
    user's umask gives a new folder: mkdtemp's 0700 would otherwise become the results'."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=out.parent))
    mode = stat.S_IMODE(out.stat().st_mode) if out.is_dir() else 0o777 & ~current_umask()
    os.chmod(tmp, mode)
    return tmp


def check_out_dir(out_dir, option: str = "--out", staged: bool = True) -> Path:
    """OutputError unless ``out_dir`` is (or can become) a folder this process can write
    into and beside which it can make its temporary folder: checked by making and removing a
    probe folder in the nearest existing folder. Creates nothing. ``option``: the option that
    gave the folder, for the message; ``staged``: the results are staged beside it (said in
    the message)."""
    if not str(out_dir).strip():  # an empty shell variable: not the current folder
        raise OutputError(repr(str(out_dir)), "is empty; give a folder (. for the current one)", option)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise OutputError(out, "exists and is not a folder; give a folder (new or from an earlier run)", option)
    if Path(os.path.abspath(out)) == Path(os.path.abspath(out)).parent:
        raise OutputError(out, "is the file system's root; give a folder below it", option)
    base = _existing_ancestor(out.parent)
    if not base.is_dir():
        raise OutputError(out, f"cannot write there ({base} is not a folder); give a writable folder", option)
    # Both folders are probed: the results are staged beside ``out`` and then moved into it.
    for where in (base, out) if out.is_dir() else (base,):
        try:
            Path(tempfile.mkdtemp(prefix=TEMP_PREFIX + "probe-", dir=where)).rmdir()
        except OSError as e:
            why = "" if where == out or not staged else (
                f"; the results are first written into a hidden folder {TEMP_PREFIX}* in {where} beside it and "
                "switched in with one rename")
            # the OS's words alone mislead where the folder exists (a pseudo file system such
            # as /proc answers "No such file or directory" to a new folder in it)
            raise OutputError(out, f"cannot write there (making a folder in {where} failed: {e.strerror or e}{why}); "
                              "give a writable folder", option) from None
    return out


def check_record_file(path, option: str = "--json") -> Path:
    """OutputError unless ``path`` names a file (not a folder) whose folder exists and takes
    a new file: checked before a long measurement whose record it is to hold. Creates
    nothing."""
    if not str(path).strip():
        raise OutputError(repr(str(path)), "is empty; give a file name", option)
    p = Path(path)
    if p.is_dir():
        raise OutputError(p, "is a folder; give a file name", option)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(p, f"its folder {parent} does not exist (or is not a folder)", option)
    probe_new_file(p, parent, option)
    return p


def probe_new_file(out, where: Path, option: str, prefix: str = TEMP_PREFIX + "probe-", hint: str = "") -> None:
    """OutputError for ``out`` (given by ``option``) unless the folder ``where`` takes a new
    file: one is made there (named ``prefix``...) and removed at once. ``hint``: what to
    give instead, appended to the message."""
    try:
        if not where.is_dir():
            raise NotADirectoryError(20, "Not a directory")
        fd, probe = tempfile.mkstemp(prefix=prefix, dir=where)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise OutputError(out, f"cannot write there (making a file in {where} failed: {e.strerror or e}){hint}",
                          option) from None


def pid_alive(pid: int) -> bool:
    """Whether a process of this id runs (one of another user counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def clean_leftovers(parent: Path) -> list[Path]:
    """Remove the temporary folders a killed run left in ``parent``; an ``old`` folder whose
    result folder is missing (killed between the two renames of the fallback switch) is
    renamed back. Returns what was removed or restored."""
    done = []
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return done
    for p in entries:
        name = p.name
        if not name.startswith(TEMP_PREFIX) or not p.is_dir() or p.is_symlink():
            continue
        pid, _, rest = name[len(TEMP_PREFIX):].partition("-")
        if not pid.isdigit() or int(pid) == os.getpid() or pid_alive(int(pid)):
            continue
        kind, _, target = rest.partition("-")
        if kind == "old" and target and not (p.parent / target).exists():
            try:
                os.rename(p, p.parent / target)
                done.append(p.parent / target)
                continue
            except OSError:
                pass
        shutil.rmtree(p, ignore_errors=True)
        done.append(p)
    return done


def _exchange(a: Path, b: Path) -> bool:
    """Swap two folders with one atomic rename (Linux renameat2 RENAME_EXCHANGE); False where
    the system or file system cannot."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def _hook(stage: str):
    if _switch_hook is not None:
        _switch_hook(stage)


def _switch_in(tmp: Path, out: Path) -> None:
    """Make the complete result folder ``tmp`` the folder ``out``: the folder holds the old
    complete set or the new one, never a mix. Files of ``out`` that are not results (notes
    of the user) are carried over (hard links) first. Where ``out`` holds sub-folders, or
    is or contains the working folder, it is kept and the files are replaced one by one
    under a marker ``.millfmu-incomplete`` that the next run reports."""
    if not out.exists():
        os.rename(tmp, out)
        return
    entries = list(out.iterdir())
    cwd = Path(os.getcwd()).resolve()
    whole = all(e.is_file() and not e.is_symlink() for e in entries) and not (cwd == out.resolve()
                                                                              or out.resolve() in cwd.parents)
    if whole:
        for e in entries:
            if e.name in RESULT_FILES or e.name == MARKER or (tmp / e.name).exists():
                continue
            try:
                os.link(e, tmp / e.name)
            except OSError:
                shutil.copy2(e, tmp / e.name)
        _hook("carried")
        if _exchange(tmp, out):  # tmp now holds the old results
            _hook("switched")
            shutil.rmtree(tmp, ignore_errors=True)
            return
        old = out.parent / f"{TEMP_PREFIX}{os.getpid()}-old-{out.name}"
        os.rename(out, old)
        _hook("moved-away")
        os.rename(tmp, out)
        _hook("switched")
        shutil.rmtree(old, ignore_errors=True)
        return
    marker = out / MARKER
    marker.write_text("a run of millfmu was moving its results into this folder and did not finish: "
                      "the result files here may come from two runs\n")
    new = {f.name for f in tmp.iterdir()}
    for f in sorted(tmp.iterdir()):
        os.replace(f, out / f.name)
        _hook("file")
    for name in RESULT_FILES:
        if name not in new:
            (out / name).unlink(missing_ok=True)
    marker.unlink()
    shutil.rmtree(tmp, ignore_errors=True)


#: Left in a result folder holding sub-folders while files are replaced one by one.
MARKER = ".millfmu-incomplete"

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
    model.cover_scene_point()  # an on-demand table build before the first step (SceneError if it cannot be built)
    r = scene.run
    n_steps = int(math.ceil(r.t_end_s / r.dt_s - 1e-9))
    every = max(1, int(round(r.output_interval_s / r.dt_s)))
    records, psds = [], []

    def record(out):
        values = {**out, "total_mass_kg": model.total_mass_kg()}
        records.append({k: float(values[k]) for k in RESULT_KEYS if k in values})
        # Q3 at every edge, the lowest one included (the mass below the grid).
        psds.append(q3_at_edges(out))

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
    """The band of the end-of-run outputs from what is known of the scene's data, in parts
    and whole, or None for a scene with neither part.

    - ``table`` (a scene on a stress-energy table): two more runs with every zone's collision
      frequency and median stress energy at the edges of ``multiple`` times their stated
      relative error b (factors (1 + b)^-1 and 1 + b: the lower edge breaks least, the upper
      most; the breakage rates grow with both, so these runs bound the box of zone
      statistics; :meth:`TableStressSource.relative_error` says what b holds).
    - ``calibration`` (a scene whose ``scene.fitted`` constants carry 95 % intervals): two
      runs per constant, at each end of its interval, the others at their values.
    - the whole: the parts' runs and two more, each constant at the end that breaks more
      (less) with the table's upper (lower) edge; the band spans all runs. The parts are
      taken as independent and their worst cases as coinciding: an upper bound of what
      they span together, not a confidence level."""
    has_table = scene.kinetics.model == "detailed" and scene.kinetics.stress_distribution.source == "table"
    info = scene.scene
    fitted, left_out = [], []
    for k, a, b in zip(info.fitted, info.fitted_ci95_low, info.fitted_ci95_high):
        v = number_key(scene, k)
        (fitted if a <= v <= b else left_out).append((k, a, b))
    if not has_table and not fitted:
        return None

    def last(s: Scene, table_multiple: float = 0.0):
        model, records, _ = simulate(s, progress=False, table_error_multiple=table_multiple)
        return model, records[-1]

    def span(recs) -> dict:
        return {k: [min(r[k] for r in recs), max(r[k] for r in recs)] for k in BAND_KEYS if k in recs[0]}

    runs, out = [], {"parts": {}}
    if has_table:
        lo, (m_hi, hi) = last(scene, -multiple)[1], last(scene, multiple)
        err = m_hi.source.relative_error()
        runs += [lo, hi]
        table = {
            "outputs": span([lo, hi]),
            "zones": err["zones"],
            "collision_frequency_relative_error": [float(v) if np.isfinite(v) else None
                                                   for v in err["collision_frequency"]],
            "se_median_relative_error": [float(v) if np.isfinite(v) else None for v in err["se_median"]],
            "method": ("two runs with every zone's collision frequency and median stress energy at the edges of the "
                       "table's stated relative error b, factors (1 + b)^-1 and (1 + b); b = interpolation error + 2 "
                       "sigma of the DEM sampling at the last operating point + the work-precision expected error "
                       "(recording, spin-up, sector, step, coupling) + the spread of independent DEM realizations + "
                       "off the anchor the one-at-a-time axes' separability error measured by the table's checks, per "
                       "zone"),
        }
        out["parts"]["table"] = table
        out.update({k: v for k, v in table.items() if k != "outputs"})  # the table's figures at the top, as before
        unstated = m_hi.source.unstated_zones(err=err)
        if unstated:
            out.setdefault("notes", []).append(
                f"zones {', '.join(unstated)} collide but have no stated error at the last operating point (no check "
                "of the table measured them there): the table's part of the band leaves them unmoved")
    if fitted:
        key = "disrupted_fraction" if scene.material.model == "yeast" else "x50_m"
        sign = 1.0 if key == "disrupted_fraction" else -1.0  # more breakage: more disrupted, finer x50
        ends, cal_runs = [], []
        for k, a, b in fitted:
            r_a, r_b = last(_with_value(scene, k, a))[1], last(_with_value(scene, k, b))[1]
            cal_runs += [r_a, r_b]
            breaks_more = b if sign * (r_b[key] - r_a[key]) >= 0.0 else a
            ends.append((k, breaks_more, a + b - breaks_more))
        runs += cal_runs
        out["parts"]["calibration"] = {
            "outputs": span(cal_runs),
            "constants": [{"key": k, "value": float(number_key(scene, k)), "ci95": [float(a), float(b)]}
                          for k, a, b in fitted],
            "method": "two runs per fitted constant, at each end of its 95 % interval (scene.fitted), the others at "
                      "their values",
        }
        if has_table:
            more, less = scene, scene
            for k, hi_end, lo_end in ends:
                more, less = _with_value(more, k, hi_end), _with_value(less, k, lo_end)
            runs += [last(more, multiple)[1], last(less, -multiple)[1]]
    if left_out:
        out.setdefault("notes", []).extend(
            f"{k} = {number_key(scene, k):.6g} lies outside its recorded 95 % interval [{a:.6g}, {b:.6g}], "
            "which belongs to another value of it: not carried into the band" for k, a, b in left_out)
    out["t_s"] = runs[0]["t_s"]
    out["multiple"] = multiple
    out["outputs"] = span(runs)
    return out


def _with_value(scene: Scene, key: str, value: float) -> Scene:
    """The scene with the number key SECTION.KEY set to ``value`` (an end of its interval)."""
    from dataclasses import replace

    sec, name = key.split(".")
    return replace(scene, **{sec: replace(getattr(scene, sec), **{name: float(value)})})


def run_warnings(model: MillModel, records) -> list:
    """The model's warnings about its data, and those about the outputs (below-grid mass) at
    the output time where that mass is largest."""
    out = list(model.warnings)
    out.extend(model.similarity_warnings().values())
    if records:
        out.extend(model.output_warnings(max(records, key=lambda r: r.get("below_grid_fraction", 0.0))))
        turned = any(float(r.get("tip_speed_m_per_s", 0.0)) > 0.0 for r in records)
        if turned and not model.continuous:  # a continuous mill may start in its steady state
            out.extend(_nothing_breaks(records))
        if not turned:
            out.append("the stirrer does not turn (tip speed 0 m/s throughout: mill.tip_speed_m_per_s, "
                       "run.tip_speed_profile): no bead is stressed and nothing breaks")
    if model.continuous and model.scene.operation.feed_mass_flow_kg_per_s == 0.0:
        out.append("operation.mode = 'continuous' with operation.feed_mass_flow_kg_per_s = 0: nothing flows "
                   "through the mill, which grinds its content as a batch (set the feed mass flow)")
    return out


#: x50 moving by less than this share over a run whose stirrer turned is worth a word: a user
#: who sees an unchanged size distribution otherwise suspects the program, not the case.
UNCHANGED_X50 = 1e-3


def _nothing_breaks(records) -> list:
    """A warning where x50 [m] hardly moved over a batch run (``records``, in which the
    stirrer turned), naming the stress frequency at x50 [1/s] against the run time [s];
    empty otherwise."""
    first, last = records[0], records[-1]
    t_s = float(last.get("t_s", 0.0)) - float(first.get("t_s", 0.0))
    x0, x1 = first.get("x50_m"), last.get("x50_m")
    if not (t_s > 0.0 and x0 and x1 and abs(x1 / x0 - 1.0) < UNCHANGED_X50):
        return []
    sf = max(float(r.get("sf_per_s", 0.0)) for r in records)
    return [f"x50 moved by {abs(x1 / x0 - 1.0):.1e} of itself in {t_s:g} s: the stress model breaks almost "
            f"nothing here (stress frequency at x50 at most {sf:.3g} 1/s, against 1/t = {1.0 / t_s:.3g} 1/s); "
            f"check the feed size and the operating point (`millfmu rates SCENE` shows the rates per size)"]


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
        ident = {"ref": scene.kinetics.stress_distribution.table, "key": m.get("key"),
                 "manifest_sha256": m.get("manifest_sha256"),
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
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_leftovers(out.parent)
    if (out / MARKER).exists():
        print(f"millfmu: warning: --out {out}: an earlier run was stopped while it replaced the result files one by "
              "one (the folder holds sub-folders); this run replaces them all", file=sys.stderr)
    tmp = staging_dir(out, f"{TEMP_PREFIX}{os.getpid()}-new-")
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
        written = [out / f.name for f in sorted(tmp.iterdir())]
        _switch_in(tmp, out)
        return written
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _plots(folder: Path, model: MillModel, records, psds):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name, fig in (("psd.png", psd_figure(model, records, psds)), ("sizes.png", sizes_figure(model, records))):
        fig.savefig(folder / name, dpi=110)
        plt.close(fig)


def _what_psd(model: MillModel) -> str:
    """What the size distribution of a run describes."""
    if model.scene.operation.mode == "continuous":
        n = model.scene.operation.n_tanks
        return f"product at the mill outlet ({'the last of ' + str(n) + ' tanks' if n > 1 else 'one stirred tank'})"
    return "mill content (batch)"


def _legend_right(ax, **kw):
    """A legend beside the axes (right), never over the curves."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8, **kw)


#: Legend of the markers at the grid's lower edge in psd.png.
BELOW_LABEL = "mass fraction below the grid (marker at its lower edge)"


def psd_figure(model: MillModel, records, psds):
    """Q3 and q3,lg of up to 8 output times; the mass below the grid as a marker at the
    grid's lower edge (a fraction, not a density)."""
    import matplotlib.pyplot as plt

    e = model.grid.edges_m
    t = np.array([r["t_s"] for r in records])
    idx = np.unique(np.linspace(0, len(records) - 1, min(8, len(records))).round().astype(int))
    cmap = plt.get_cmap("viridis")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12.5, 4.6))
    for k, i in enumerate(idx):
        c = cmap(k / max(1, len(idx) - 1))
        q3 = psds[i]  # at every edge: q3[0] is the mass below the grid
        a1.semilogx(e * 1e6, q3, color=c, label=f"t = {t[i]:g} s")
        dens = np.diff(q3) / np.diff(np.log10(e))
        a2.semilogx(model.grid.x_m * 1e6, dens, color=c, label=f"t = {t[i]:g} s")
        if q3[0] > 0.0:
            a2.plot([e[0] * 1e6], [q3[0]], "v", color=c, ms=5, label=BELOW_LABEL)
    a1.axvline(e[0] * 1e6, color="0.6", lw=0.8, label=f"grid's lower edge ({e[0] * 1e6:.3g} \u00b5m)")
    b = psds[idx[-1]][0]
    a1.set_title(f"cumulative; below the grid at t = {t[idx[-1]]:g} s: {b:.2%}", fontsize=9)
    a2.set_title("density per decade (\u25bc: below-grid fraction, not per decade)", fontsize=9)
    a1.set_xlabel("particle size x [\u00b5m]")
    a1.set_ylabel("Q3 [-]  (mass fraction below x)")
    a1.grid(True, which="both", alpha=0.3)
    a2.set_xlabel("particle size x [\u00b5m]")
    a2.set_ylabel("q3,lg [-]  (mass density per decade)")
    a2.grid(True, which="both", alpha=0.3)
    # One legend serves both panels: the right panel's lines are the left's output times.
    h1, l1 = a1.get_legend_handles_labels()
    h2, l2 = a2.get_legend_handles_labels()
    first_marker = [(h, lab) for h, lab in zip(h2, l2) if lab == BELOW_LABEL][:1]
    hs, ls = h1 + [h for h, _ in first_marker], l1 + [lab for _, lab in first_marker]
    _legend_right(a2, handles=hs, labels=ls, title="output time")
    from .plotstyle import plain_log_ticks  # matplotlib: only where a plot is drawn

    plain_log_ticks(fig)
    fig.suptitle(f"{model.scene.scene.name}: size distribution of the {_what_psd(model)}")
    fig.tight_layout()
    return fig


def sizes_figure(model: MillModel, records):
    """x10, x50, x90 over time [s]; below them, each in its own panel with its own scale, the
    disrupted fraction (yeast) and the mass fraction below the size grid (when any)."""
    import matplotlib.pyplot as plt

    t = np.array([r["t_s"] for r in records])
    panels = ["sizes"]
    if "disrupted_fraction" in records[0]:
        panels.append("disrupted")
    if any(r.get("below_grid_fraction", 0.0) > 0.0 for r in records):
        panels.append("below")
    heights = [2.2] + [1.0] * (len(panels) - 1)
    fig, axes = plt.subplots(len(panels), 1, figsize=(8.5, 3.2 + 1.5 * (len(panels) - 1)), sharex=True,
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    axes = axes[:, 0]
    for ax, what in zip(axes, panels):
        if what == "sizes":
            for key, lab in (("x10_m", "x10"), ("x50_m", "x50"), ("x90_m", "x90")):
                ax.plot(t, [r[key] * 1e6 for r in records], label=lab)
            ax.set_yscale("log")
            ax.set_ylabel("size [\u00b5m]")
        elif what == "disrupted":
            ax.plot(t, [r["disrupted_fraction"] for r in records], "k--", label="disrupted cells")
            ax.set_ylim(0, 1)
            ax.set_ylabel("fraction [-]")
        else:
            ax.plot(t, [100.0 * r["below_grid_fraction"] for r in records], "k:", label="mass below the size grid")
            ax.set_ylim(bottom=0)
            ax.set_ylabel("below grid [%]")
        ax.grid(True, which="both", alpha=0.3)
        _legend_right(ax)
    axes[-1].set_xlabel("time t [s]")
    from .plotstyle import plain_log_ticks  # matplotlib: only where a plot is drawn

    plain_log_ticks(fig)
    fig.suptitle(f"{model.scene.scene.name}: characteristic sizes of the {_what_psd(model)}", fontsize=11)
    fig.tight_layout()
    return fig


def summary_table(records, rows: int = 8) -> str:
    """A short fixed-width table of the run for the terminal: at most ``rows`` records, every
    k-th (evenly spaced in time where the outputs are) and the last."""
    n = len(records)
    stride = max(1, -(-(n - 1) // max(rows - 1, 1)))
    idx = list(range(0, n, stride))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    yeast = "disrupted_fraction" in records[0]
    head = (f"{'t [s]':>9} {'x10 [um]':>9} {'x50 [um]':>9} {'x90 [um]':>9} {'SF@x50 [1/s]':>13} {'E_m [kJ/kg]':>12} "
            f"{'holdup [kg]':>11}")
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
