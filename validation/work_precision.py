"""DEM work-precision: the error of the tabulated statistics against run time.

At one operating point of the coupled disc slice (10 m/s, 80 % filling, 10 degree sector,
no gravity; seed 001's protocol of :mod:`validation.seed001`) this measures how far each
statistic a stress-energy table holds (per zone: quantiles of SE_tn, collision frequency,
local filling, collision power) lies from a long reference run, as a function of

- the recording length T: from one long run whose recording is cut into chunks of one
  sampling interval, with every bead-bead contact kept (``contacts.npz``) so that any part
  of the recording gives exact statistics. The error of a recording of length T is the
  root-mean-square deviation of the statistics of the run's consecutive, non-overlapping
  T-blocks (inside the reference window) from the whole window's, times sqrt(n / (n - 1))
  for n blocks (batch means: the standard error of one T-recording against the stationary
  value). Sampling statistics predict that it falls as T^-1/2 once T exceeds the flow's
  correlation time; beside it, the error independent contacts would give (Poisson counts,
  order statistics), and a power law error = a T^b fitted to the measured errors;
- the spin-up s: the window [s, s + RECORD_S] of the same long run against the reference
  window (the run is deterministic, so this is the run a spin-up of s would have made);
- the sector angle, the DEM time step and the coupling interval: separate runs with one
  setting changed, each against the long run's window with the same spin-up and recording
  (the reference setting). Their trajectories separate within milliseconds, so each
  difference also holds the sampling error of two independent recordings, stated beside it
  as the 2-sigma noise from the recording-length law.

Run times are the runs' CPU times on one thread (``cost.json``, written by the study's
runs; the machine is shared, so wall times would measure the other users too; wall time
from ``stats.json`` for runs without it); a recording-length or spin-up row gives the time
a run of that spin-up and recording would take at the long run's cost per simulated
second.

What the installed package needs of it (batch means, the quick study that ``millfmu report
--quick`` runs, the shipped study's summary, the entry a table manifest quotes, the figure)
is :mod:`millfmu.dem.analysis.precision`; this module is the study itself, run from a
checkout's root:

``python -m validation.work_precision run --out DIR`` makes the runs (skipping those done),
``python -m validation.work_precision table --out DIR`` prints the table and writes
``work_precision.json``, ``work_precision.csv`` and ``work_precision.png``; ``--export
FILE`` also writes the summary a table manifest quotes
(:func:`millfmu.dem.analysis.precision.manifest_entry`; millfmu/data/dem_work_precision.json
ships it).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

# The study shares the product's batch means, expected error and output helpers: one
# implementation, so that the shipped summary and a rerun of the study agree.
from millfmu.dem.analysis.precision import (COLUMNS, DRIFT_STATS, LENGTHEN_WITHIN, OPERATING_POINT,
                                            RUN_COMMAND, STATISTICS, TARGET_ZONES, TARGETS, WorkPrecisionError,
                                            analyse_quick, base_scene, block_stats, expected_error,
                                            fit_sampling_law, load, plot, recording_length_errors,
                                            relative_difference, run_quick, sampling_error, slopes,
                                            spin_up_bias, summary_text, table_rows, timed_run, worst_abs)
from millfmu.machine import machine
from validation.seed001 import COUPLED_SPIN_UP_S, RECORD_S

#: Sampling interval [s] = chunk of the contacts file = window of windows.csv.
SAMPLE_S = 0.01
#: The long run: recording from LONG_START_S (the shortest spin-up studied) to LONG_END_S [s].
LONG_START_S = 0.2
LONG_END_S = 3.0
#: Reference window [s] of the long run, after every spin-up window studied. A first run to
#: 1.9 s showed the zones still changing after the protocol's 1.0 s (V1 filling 0.43 ->
#: 0.37 and V4 0.53 -> 0.45 by 1.6 s, then level), hence the later reference.
REFERENCE_WINDOW_S = (1.8, 3.0)
#: Recording lengths studied [s] (blocks inside the reference window).
RECORD_LENGTHS_S = (0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.4)
#: Spin-ups studied [s] (windows [s, s + RECORD_S] of the long run).
SPIN_UPS_S = (0.2, 0.35, 0.5, 0.565, 0.75, 1.0, 1.25, 1.5)
#: Separate runs: name -> (overrides of the long run's scene, coupling steps or None,
#: spin-up [s], what changes). dt variants keep the coupling interval (5e-5 s); the sector
#: run is 3 times the beads, so it spins up for 25 stirrer revolutions (0.565 s) as the
#: sector check of docs/validation-seed001.md did, and is compared with the 10 degree window of the same times.
VARIANTS = {
    "coupling_2.5e-5": (dict(), 5, COUPLED_SPIN_UP_S, "coupling interval 2.5e-5 s (5 steps)"),
    "coupling_1e-4": (dict(), 20, COUPLED_SPIN_UP_S, "coupling interval 1e-4 s (20 steps)"),
    "coupling_2e-4": (dict(), 40, COUPLED_SPIN_UP_S, "coupling interval 2e-4 s (40 steps)"),
    "dt_1e-5": (dict(dt_s=1e-5), 5, COUPLED_SPIN_UP_S, "DEM step 1e-5 s (coupling 5e-5 s)"),
    "dt_2.5e-6": (dict(dt_s=2.5e-6), 20, COUPLED_SPIN_UP_S,
                  "DEM step 2.5e-6 s (coupling 5e-5 s)"),
    "sector_30": (dict(sector_deg=30.0), None, 0.565, "30 degree sector (3 x the beads)"),
}
#: The variants run by default (coupling_2e-4 on request): with the long run about 1.6
#: CPU hours on one core (measured: long run 1541 s, dt_1e-5 409 s, coupling_1e-4 580 s,
#: coupling_2.5e-5 702 s, dt_2.5e-6 1114 s; sector_30 about 1300 s).
DEFAULT_VARIANTS = ("dt_1e-5", "coupling_1e-4", "coupling_2.5e-5", "dt_2.5e-6", "sector_30")


def _scene_of(name: str):
    from dataclasses import replace

    sc = base_scene()
    if name == "long":
        return sc.with_overrides(spin_up_s=LONG_START_S, record_s=LONG_END_S - LONG_START_S,
                                 sample_every_s=SAMPLE_S)
    over, steps, spin, _ = VARIANTS[name]
    sc = sc.with_overrides(spin_up_s=spin, record_s=RECORD_S, sample_every_s=SAMPLE_S, **over)
    if steps is not None:
        sc = replace(sc, coupling=replace(sc.coupling, steps=steps))
    return sc


def run_study(out_dir, variants=DEFAULT_VARIANTS, threads: int | None = 1,
              progress: bool = True, log=print) -> list[Path]:
    """Make the study's runs in ``out_dir`` (``long`` and each of ``variants``), skipping
    those with a ``stats.json``; returns the run folders. CPU time on one core: 26 minutes
    for the long run, 7-19 for a 10 degree variant (see :data:`DEFAULT_VARIANTS`)."""
    from millfmu.dem.run import run_scene

    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise WorkPrecisionError(f"variants {bad}: allowed {sorted(VARIANTS)}")
    out = Path(out_dir)
    dirs = []
    for name in ("long",) + tuple(variants):
        d = out / name
        dirs.append(d)
        if (d / "stats.json").exists():
            continue
        log(f"work-precision: running {name} into {d}")
        timed_run(run_scene, d, _scene_of(name), d, progress=progress, threads=threads,
               window_s=SAMPLE_S, contacts=True)
    return dirs


#: Variants that are the more accurate setting of their axis: their row gives the error of
#: the reference setting against them; the other variants' rows give their own error
#: against the reference setting.
FINER = ("coupling_2.5e-5", "dt_2.5e-6", "sector_30")
#: Recording lengths below this [s] are left out of the power-law fit.
LAW_T_MIN_S = 0.05


def analyse(study_dir) -> dict:
    """The study from the run folders in ``study_dir`` (``long`` and any of
    :data:`VARIANTS`): recording-length rows with the power-law fit, spin-up rows, variant
    rows, the table-build choice and its expected error. Plain JSON data."""
    study = Path(study_dir)
    if not (study / "long" / "stats.json").is_file():
        raise WorkPrecisionError(f"--out {str(study)!r}: no finished long run (long/stats.json); "
                                 f"make the runs with 'python -m validation.work_precision run --out "
                                 f"{study}'")
    long = load(study / "long")
    if not long.has_contacts:
        raise WorkPrecisionError(f"{study / 'long'}: the long run needs contacts.npz")
    rate = long.cost_s / long.simulated_s  # run seconds per simulated second
    zones = long.zone_names
    rec_window = REFERENCE_WINDOW_S
    rec_rows = recording_length_errors(long, rec_window, RECORD_LENGTHS_S)
    for r in rec_rows:
        r["run_s"] = rate * (COUPLED_SPIN_UP_S + r["record_s"])
    law = fit_sampling_law(rec_rows, LAW_T_MIN_S)
    ref_window = REFERENCE_WINDOW_S
    ref = block_stats(long, *ref_window)
    ref_len = ref_window[1] - ref_window[0]

    spin_rows = []
    for s in SPIN_UPS_S:
        if s + RECORD_S > long.recording_s[1] + 1e-9 or s < long.recording_s[0] - 1e-9:
            continue
        x = block_stats(long, s, s + RECORD_S)
        err, noise = {}, {}
        for st in STATISTICS:
            err[st], noise[st] = {}, {}
            for z in zones:
                err[st][z] = relative_difference(x[st][z], ref[st][z])
                a, b = sampling_error(law, st, z, RECORD_S), sampling_error(law, st, z, ref_len)
                noise[st][z] = None if a is None or b is None else 2.0 * math.hypot(a, b)
        spin_rows.append(dict(spin_up_s=s, record_s=RECORD_S, error=err, noise_2sigma=noise,
                              run_s=rate * (s + RECORD_S)))

    var_rows = []
    for name, (over, steps, spin, what) in VARIANTS.items():
        d = study / name
        if not (d / "stats.json").exists():
            continue
        rd = load(d)
        x = block_stats(rd)
        t0, t1 = rd.recording_s
        base = block_stats(long, t0, t1)
        finer = name in FINER
        beads = rd.stats["beads"] / long.stats["beads"]
        err, noise = {}, {}
        for st in STATISTICS:
            err[st], noise[st] = {}, {}
            for z in zones:
                err[st][z] = (relative_difference(base[st][z], x[st][z]) if finer
                              else relative_difference(x[st][z], base[st][z]))
                a = sampling_error(law, st, z, t1 - t0)
                b = sampling_error(law, st, z, t1 - t0, 1.0 / math.sqrt(beads))
                noise[st][z] = None if a is None else 2.0 * math.hypot(a, b)
        pn_var = (rd.stats.get("flow", {}).get("power_number") or {}).get("value")
        var_rows.append(dict(
            name=name, what=what, finer=finer, spin_up_s=t0, record_s=t1 - t0,
            beads=rd.stats["beads"], error=err, noise_2sigma=noise, run_s=rd.cost_s,
            reference_run_s=rate * (t0 + (t1 - t0)) * beads,
            power_number=pn_var, contacts=rd.has_contacts))
    drift = dict(block_s=DRIFT_BLOCK_S, t_s=[], **{st: {z: [] for z in zones} for st in DRIFT_STATS})
    t = long.recording_s[0]
    while t + DRIFT_BLOCK_S <= long.recording_s[1] + 1e-9:
        x = block_stats(long, t, t + DRIFT_BLOCK_S)
        drift["t_s"].append(t + 0.5 * DRIFT_BLOCK_S)
        for st in DRIFT_STATS:
            for z in zones:
                drift[st][z].append(relative_difference(x[st][z], ref[st][z]))
        t += DRIFT_BLOCK_S
    res = dict(operating_point=dict(OPERATING_POINT, scene="disc_slice"), drift=drift,
               long_run=dict(recorded_s=list(long.recording_s), run_s=long.cost_s,
                             run_per_simulated_s=rate, beads=long.stats["beads"],
                             threads=long.stats.get("counts", {}).get("threads")),
               reference_window_s=list(ref_window), recording_window_s=list(rec_window),
               law_t_min_s=LAW_T_MIN_S, recording=rec_rows, law=law, spin_up=spin_rows,
               variants=var_rows, zones=zones, statistics=list(STATISTICS),
               machine=machine())
    res["choice"] = choose(res)
    return res


DRIFT_BLOCK_S = 0.1


#: Recording lengths [s] :func:`choose` considers (beyond the longest studied the
#: recording-length law is extrapolated, which the choice states).
CHOICE_LENGTHS_S = (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0)


def _worst_of(e, zones):
    return max((e[st][z] for st in STATISTICS for z in zones if e[st].get(z) is not None),
               default=None)


def choose(res, targets=TARGETS, zones=TARGET_ZONES) -> dict | None:
    """The table-build choice at the reference resolution (10 degree sector, DEM step
    5e-6 s, coupling every 5e-5 s): for the smallest target in ``targets`` that some
    studied spin-up with a recording of :data:`CHOICE_LENGTHS_S` meets (the error the
    recording and the spin-up add, :func:`expected_error` without the resolution part, at
    most the target for every statistic in ``zones``), the cheapest such setting, its
    recording then lengthened within :data:`LENGTHEN_WITHIN` of its cost (up to the
    longest recording studied). States that error and the total with the resolution part;
    None when no target is met."""
    rate = res["long_run"]["run_per_simulated_s"]
    longest = max((r["record_s"] for r in res["recording"] if r["blocks"] >= 3), default=0.0)
    for target in targets:
        best = None
        for r in res["spin_up"]:
            for t in CHOICE_LENGTHS_S:
                worst = _worst_of(expected_error(res, r["spin_up_s"], t, False), zones)
                if worst is None or worst > target:
                    continue
                cost = rate * (r["spin_up_s"] + t)
                if best is None or cost < best[2] - 1e-9:
                    best = (r["spin_up_s"], t, cost)
        if best is None:
            continue
        su, t, cost = best
        cheapest = dict(spin_up_s=su, record_s=t, run_s=cost)
        for t2 in CHOICE_LENGTHS_S:
            if t < t2 <= longest + 1e-9 and rate * (su + t2) <= LENGTHEN_WITHIN * cost:
                t = t2
        e_rec = expected_error(res, su, t, False)
        e = expected_error(res, su, t, True)
        return dict(spin_up_s=su, record_s=t, run_s=rate * (su + t),
                    worst=_worst_of(e_rec, zones), worst_total=_worst_of(e, zones),
                    expected_error=e, expected_error_recording_spin_up=e_rec,
                    extrapolated=t > longest + 1e-9, cheapest=cheapest, target=target,
                    target_zones=list(zones), sector_deg=OPERATING_POINT["sector_deg"],
                    dt_s=5e-6, coupling_interval_s=5e-5, sample_every_s=SAMPLE_S)
    return None


def markdown(res, zones=TARGET_ZONES) -> str:
    """The table (Markdown) with the measured slopes and the choice below it."""
    head = ["setting", "run time [s]"] + list(COLUMNS)
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(res, zones)]
    lines.append("")
    lines.append(summary_text(res))
    return "\n".join(lines)


def write(res, out_dir) -> list[Path]:
    """Write ``work_precision.json``, ``.csv``, ``.md`` and ``.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "work_precision.json", out / "work_precision.csv", out / "work_precision.md",
             out / "work_precision.png"]
    files[0].write_text(json.dumps(res, indent=1))
    with open(files[1], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["kind", "setting", "run_s", "statistic", "zone", "relative_error",
                    "noise_2sigma"])
        for kind, key in (("recording", "record_s"), ("spin_up", "spin_up_s"),
                          ("variants", "name")):
            for r in res[kind]:
                for s in STATISTICS:
                    for z in res["zones"]:
                        w.writerow([kind, r[key], r["run_s"], s, z, r["error"][s][z],
                                    r.get("noise_2sigma", {}).get(s, {}).get(z)])
    files[2].write_text(markdown(res) + "\n")
    plot(res, files[3])
    return files


def summary(res) -> dict:
    """What a table manifest quotes (plain JSON): the operating point, the choice with its
    expected error, the recording-length law (error = at_1s T^slope), spin-up biases,
    resolution differences with their noise, where and when it was measured."""
    c = res.get("choice")
    return dict(
        operating_point=res["operating_point"],
        command=RUN_COMMAND,
        measured_on=res["machine"],
        long_run=res["long_run"],
        choice=None if c is None else {k: c[k] for k in (
            "spin_up_s", "record_s", "sector_deg", "dt_s", "coupling_interval_s",
            "sample_every_s", "run_s", "worst", "worst_total", "target", "target_zones",
            "extrapolated", "cheapest", "expected_error", "expected_error_recording_spin_up")},
        recording_law={s: {z: ({k: v[k] for k in ("at_1s", "slope")} if v else None)
                           for z, v in d.items()} for s, d in res["law"].items()},
        slopes=slopes(res),
        spin_up_bias={f"{r['spin_up_s']:g}": {s: {z: spin_up_bias(r, s, z) for z in res["zones"]}
                                               for s in STATISTICS}
                      for r in res["spin_up"]},
        resolution=[dict(name=r["name"], what=r["what"], finer=r["finer"],
                         worst_error=worst_abs(r["error"], STATISTICS, TARGET_ZONES),
                         worst_noise_2sigma=worst_abs(r["noise_2sigma"], STATISTICS, TARGET_ZONES),
                         run_s=r["run_s"], reference_run_s=r["reference_run_s"])
                    for r in res["variants"]],
        note="relative errors [-] of a DEM table point's statistics (per zone: SE_tn "
             "quantiles, collision frequency, local filling, collision power density) at the "
             "operating point only; other tip speeds and fillings were not measured")


def export(res, path) -> Path:
    """Write the study's summary (:func:`summary`) and its data to ``path`` (JSON): what
    :func:`manifest_entry` and ``millfmu report`` read."""
    path = Path(path)
    path.write_text(json.dumps({"summary": summary(res), "study": res}, indent=1) + "\n")
    return path


# --- the command: python -m validation.work_precision ------------------------------------

def parser() -> argparse.ArgumentParser:
    """The study's options."""
    w = argparse.ArgumentParser(
        prog="python -m validation.work_precision",
        description="Error of the tabulated statistics against recording length, spin-up, "
                    "sector, time step and coupling interval, with run times (coupled disc "
                    "slice, 10 m/s, 80 %). Run from a checkout's root.")
    w.add_argument("action", choices=("run", "table"), help="make the runs (skipping those "
                   "done; about 1.6 CPU hours on one core) or the table, JSON, CSV and plot "
                   "from them")
    w.add_argument("--out", required=True, help="folder of the study's runs and results")
    w.add_argument("--variants", default=None, help="comma-separated separate runs (default: "
                   "dt_1e-5,coupling_1e-4,coupling_2.5e-5,dt_2.5e-6,sector_30; also "
                   "coupling_2e-4)")
    w.add_argument("--quick", action="store_true", help="instead: one short run and its "
                   "recording-length errors (about a minute)")
    w.add_argument("--export", metavar="FILE", help="table: also write the summary a table "
                   "manifest quotes (millfmu/data/dem_work_precision.json ships it)")
    w.add_argument("--threads", type=int, default=1, help="numba threads (default 1)")
    return w


def main(argv=None) -> int:
    """``python -m validation.work_precision run|table --out DIR [...]``: 0, or 2 with the
    reason on stderr where the runs cannot be made or read."""
    from millfmu.dem.analysis.compare import CompareError

    args = parser().parse_args(argv)
    out = Path(args.out)
    try:
        if args.quick:
            if args.action == "run":
                run_quick(out / "quick", threads=args.threads, progress=True)
            res = analyse_quick(out / "quick")
        else:
            if args.action == "run":
                variants = DEFAULT_VARIANTS if args.variants is None else tuple(
                    v.strip() for v in args.variants.split(",") if v.strip())
                run_study(out, variants=variants, threads=args.threads)
            res = analyse(out)
    except (WorkPrecisionError, CompareError) as e:
        print(f"python -m validation.work_precision: {e}", file=sys.stderr)
        return 2
    files = write(res, out)
    if args.export and not args.quick:
        files.append(export(res, args.export))
    print(markdown(res))
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


if __name__ == "__main__":
    sys.exit(main())
