"""``millfmu dem`` subcommands: ``run SCENE --out DIR`` and ``bench``.

The main CLI calls :func:`register` with its subparsers object. Nothing here imports
numba at import time; the handlers import the DEM modules when they run.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from millfmu.dem.coupling.settings import PRESSURE_SOLVERS, SMOOTHINGS


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``dem`` command group to an argparse subparsers object."""
    p = subparsers.add_parser("dem", help="bead DEM: run a scene, benchmark",
                              description="Soft-sphere DEM of the grinding beads.")
    sub = p.add_subparsers(dest="dem_command",
                           metavar="{run,bench,seed001,seed002,compare,work-precision}")
    sub.required = True

    r = sub.add_parser("run", help="run a DEM scene and write statistics, histograms, maps")
    r.add_argument("scene", nargs="?", help="shipped scene name (annulus, disc_slice, "
                                            "accelerator_slice) or a .toml path")
    r.add_argument("--out", help="output folder (required unless --resume)")
    r.add_argument("--checkpoint-every", type=float, dest="checkpoint_every_s", metavar="S",
                   help="keep OUT/checkpoint.pkl, the run's whole state, written every S "
                        "seconds of wall time (removed when the run ends), so that a stopped "
                        "run goes on with --resume (which keeps the interval the run was "
                        "started with unless given)")
    r.add_argument("--resume", metavar="DIR", help="go on with the stopped run in DIR from its "
                   "checkpoint (its scene and options; --threads and --checkpoint-every may "
                   "be given); the outputs are those of a run that was not stopped")
    r.add_argument("--tip-speed", type=float, dest="tip_speed_m_s", metavar="M_S",
                   help="stirrer tip speed [m/s] (overrides the scene)")
    r.add_argument("--rpm", type=float, dest="rotor_speed_rpm", metavar="RPM",
                   help="stirrer speed [1/min] (overrides the scene; instead of --tip-speed)")
    r.add_argument("--filling", type=float, help="grinding-media filling [-]")
    r.add_argument("--sector-deg", type=float, dest="sector_deg", metavar="DEG",
                   help="simulate a rotationally periodic sector of 360/k degrees (k >= 4); "
                        "needs zero gravity (use --no-gravity)")
    r.add_argument("--no-gravity", action="store_true", help="switch gravity off")
    r.add_argument("--fluid", dest="fluid_mode", choices=("coupled", "prescribed", "none"),
                   help="fluid model (overrides the scene's [fluid] mode): coupled CFD-DEM, "
                        "prescribed swirl, or none")
    r.add_argument("--spin-up", type=float, dest="spin_up_s", metavar="S",
                   help="spin-up time excluded from the statistics [s]")
    r.add_argument("--record", type=float, dest="record_s", metavar="S",
                   help="recording time [s]")
    r.add_argument("--sample-every", type=float, dest="sample_every_s", metavar="S",
                   help="sampling interval of positions and velocities [s]")
    r.add_argument("--dt", type=float, dest="dt_s", metavar="S", help="time step [s]")
    r.add_argument("--initial-rotation", type=float, dest="initial_rotation", metavar="F",
                   help="beads and coupled fluid start turning at this fraction of the "
                        "stirrer's angular velocity (default 0: from rest)")
    r.add_argument("--primed", type=float, dest="primed_s", metavar="S",
                   help="coupled fluid: run the bead-free liquid for S seconds first and "
                        "start the beads with its velocity (primed start; default 0)")
    r.add_argument("--theta-cells", type=int, dest="n_theta", metavar="N",
                   help="coupled liquid: N theta cells over the sector (1: axisymmetric with "
                        "swirl; a full circle with gravity wants 16 or more)")
    r.add_argument("--smoothing", choices=SMOOTHINGS,
                   help="coupled liquid: how the beads' fields are smoothed (default the "
                        "scene's; split_implicit costs the same on any cell size, for full "
                        "slices)")
    r.add_argument("--pressure-solver", choices=PRESSURE_SOLVERS,
                   dest="pressure_solver",
                   help="coupled liquid: the pressure equation's solver (default the scene's; "
                        "theta_fft, for theta cells without baffles, solves the same "
                        "equation at a fraction of the cost on full disc slices; direct_ldl, "
                        "the default, a symmetric factor, a third of direct_lu's time on a "
                        "sector)")
    r.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    r.add_argument("--device", choices=("cpu", "gpu"), default=None,
                   help="where the DEM steps: cpu (numba threads, default) or gpu "
                        "(numba.cuda; the coupled liquid stays on the CPU's threads; no "
                        "checkpoints, no vanes)")
    r.add_argument("--windows", type=float, dest="window_s", metavar="S",
                   help="also write windows.csv: zone statistics of consecutive recording "
                        "windows of S seconds (stationarity check)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.set_defaults(func=_run)

    b = sub.add_parser("bench", help="the dense sheared bed: ours (1 and 2 threads), LAMMPS and "
                       "LIGGGHTS when installed, the GPU when present; ratios")
    b.add_argument("--steps", type=int, default=None, help="steps per run (default 1000)")
    b.add_argument("--repeats", type=int, default=None,
                   help="rounds, codes alternating; each code's fastest run counts (default 3)")
    b.add_argument("--cores", type=int, nargs="+", default=None, metavar="N",
                   help="numba threads and MPI ranks to run (default: 1 2)")
    b.add_argument("--ours-only", action="store_true", help="do not run LAMMPS and LIGGGHTS")
    b.add_argument("--device", choices=("cpu", "gpu"), default=None,
                   help="only the CPU rows (with LAMMPS and LIGGGHTS) or only the GPU rows "
                        "(the bed and a million beads; numba.cuda); default: both, the "
                        "GPU rows where a GPU is present")
    b.add_argument("--profile", action="store_true",
                   help="instead: where millfmu.dem's time goes, per kernel (1 and 2 threads; "
                        "with --device gpu, or where a GPU is present, per GPU phase); with "
                        "--coupled, where a coupled interval's time goes, part by part, "
                        "inside the coupled run (the sector; --bed none for it alone)")
    b.add_argument("--regenerate-bed", action="store_true",
                   help="make the bed again (it is made once and cached)")
    b.add_argument("--json", action="store_true", help="also print every run as JSON")
    b.add_argument("--bed", choices=("dense", "dilute", "both", "none"), default="dense",
                   help="the dense sheared bed (default), the dilute one (a granular gas: "
                        "few contacts, frequent neighbour rebuilds), both in turn, or none "
                        "(with --coupled: the coupled row alone)")
    b.add_argument("--coupled", nargs="?", const="sector", default=None,
                   choices=("sector", "full"),
                   help="also the coupled row: disc_slice with the coupled fluid against the "
                        "DEM alone on the same beads, alternating, best of 3 (on the largest "
                        "of --cores threads; the DEM on the GPU with --device gpu): the "
                        "10-degree sector (default) or 'full', the 360-degree slice with "
                        "gravity and 32 theta cells (235 k beads)")
    b.add_argument("--coupled-start", choices=("running", "early"), default=None,
                   help="where the coupled row's beads start: 'running', the running mill "
                        "(the sector's default: after 0.4 s of coupled motion, made once and "
                        "cached beside the bench bed) or 'early', 0.01 s after the start at "
                        "0.1 of the stirrer's rotation, when the bed has about a third of "
                        "the running mill's contacts (the full slice and the GPU always)")
    b.set_defaults(func=_bench)

    s = sub.add_parser("seed001", help="seed 001 side by side: run its cases, print the "
                                       "deviation table")
    s.add_argument("action", choices=("run", "table"), help="run the cases (skipping those "
                   "done) or print the table from their results")
    s.add_argument("--out", required=True, help="folder of the case runs")
    s.add_argument("--fluid", default="coupled,prescribed",
                   help="fluid models to run (comma-separated; default both)")
    s.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    s.set_defaults(func=_seed001)

    s2 = sub.add_parser("seed002", help="seed 002 side by side (accelerator mill): run its "
                                        "cases, print the deviation table")
    s2.add_argument("action", choices=("run", "table"), help="run the cases (skipping those "
                    "done) or print the table from their results")
    s2.add_argument("--out", required=True, help="folder of the case runs")
    s2.add_argument("--method", choices=("physical", "paper", "physical-A"),
                    default="physical",
                    help="run: physical (the slice's own coupling, every contact event "
                         "counted), paper (seed 002's numerics: discrete phase model, CFD "
                         "step 0.01 s, contacts counted at 20 frames per second) or "
                         "physical-A (physical with model A's pressure-gradient force)")
    s2.add_argument("--primed", action="store_true", help="run: start the beads in the "
                    "bead-free liquid's circulation (primed start) instead of from rest")
    s2.add_argument("--baffles", action="store_true", help="run: with stationary baffles "
                    "on the chamber wall between the rotors (seed002.BAFFLES; the liquid in "
                    "12 theta cells per 60 degrees)")
    s2.add_argument("--case", action="append", metavar="RPM:FILLING", help="run only this "
                    "case (e.g. 1200:0.8; repeatable; default all seven)")
    s2.add_argument("--compare", action="append", metavar="LABEL=DIR", help="table: also "
                    "this campaign as a column (repeatable), beside --out's")
    s2.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    s2.add_argument("--export-table", metavar="PREFIX", help="also write the stress-energy "
                    "table of the 80 %% runs over the rotor speeds to PREFIX.npz/.json (e.g. "
                    "millfmu/data/accelerator_table)")
    s2.set_defaults(func=_seed002)

    pg = sub.add_parser("progress", help="where a checkpointed run stands: time simulated and "
                        "to go, its cost, and the bed at the checkpoint (angular velocity, "
                        "first layer, circumferential distribution with gravity)")
    pg.add_argument("run", metavar="RUN_DIR", help="folder of a run started with "
                    "--checkpoint-every")
    pg.add_argument("--json", action="store_true", help="print the figures as JSON")
    pg.set_defaults(func=_progress)

    c = sub.add_parser("compare", help="key results of run folders side by side (sector, grid "
                                       "or run-length checks), relative to the first")
    c.add_argument("runs", nargs="+", metavar="RUN_DIR", help="folders written by 'dem run'")
    c.set_defaults(func=_compare)

    w = sub.add_parser("work-precision", help="error of the tabulated statistics against "
                       "recording length, spin-up, sector, time step and coupling interval, "
                       "with run times (coupled disc slice, 10 m/s, 80 %%)")
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
    w.set_defaults(func=_work_precision)
    return p


def _work_precision(args) -> int:
    from pathlib import Path

    from millfmu.dem.analysis.compare import CompareError
    from millfmu.dem.studies import work_precision as W

    out = Path(args.out)
    try:
        if args.quick:
            if args.action == "run":
                W.run_quick(out / "quick", threads=args.threads, progress=True)
            res = W.analyse_quick(out / "quick")
        else:
            if args.action == "run":
                variants = W.DEFAULT_VARIANTS if args.variants is None else tuple(
                    v.strip() for v in args.variants.split(",") if v.strip())
                W.run_study(out, variants=variants, threads=args.threads)
            res = W.analyse(out)
    except (W.WorkPrecisionError, CompareError) as e:
        print(f"millfmu dem work-precision: {e}", file=sys.stderr)
        return 2
    files = W.write(res, out)
    if args.export and not args.quick:
        files.append(W.export(res, args.export))
    print(W.markdown(res))
    print("wrote " + ", ".join(str(f) for f in files))
    return 0



def _compare(args) -> int:
    from millfmu.dem.analysis.compare import CompareError, markdown

    try:
        print(markdown(args.runs))
    except CompareError as e:
        print(f"millfmu dem compare: {e}", file=sys.stderr)
        return 2
    return 0


def _seed001(args) -> int:
    from millfmu.dem.studies import seed001

    if args.action == "run":
        fluids = [f.strip() for f in args.fluid.split(",") if f.strip()]
        bad = [f for f in fluids if f not in seed001.FLUIDS]
        if bad:
            print(f"millfmu dem seed001: --fluid {args.fluid!r}: allowed "
                  f"{sorted(seed001.FLUIDS)}", file=sys.stderr)
            return 2
        seed001.run_campaign(args.out, fluids=fluids, threads=args.threads)
    print(seed001.markdown(seed001.deviation_rows(args.out)))
    return 0


def _seed002(args) -> int:
    from millfmu.dem.run import DemRunError
    from millfmu.dem.studies import seed002

    cases = seed002.CASES
    try:
        if args.case:
            cases = tuple(_case(c) for c in args.case)
        cols = [(_label(args.out), args.out)] + [_compare_col(c) for c in args.compare or ()]
        if args.action == "run":
            seed002.run_campaign(args.out, cases=cases, threads=args.threads,
                                 method=args.method, primed=args.primed,
                                 baffles=args.baffles)
        if len(cols) == 1:
            print(seed002.markdown(seed002.deviation_rows(args.out), f"ours ({cols[0][0]})"))
        else:
            print(seed002.markdown_columns(seed002.deviation_table(cols)))
    except (ValueError, DemRunError) as e:
        print(f"millfmu dem seed002: {e}", file=sys.stderr)
        return 2
    if args.export_table:
        from millfmu.stress_tables.spec import TableError

        try:
            t = seed002.export_table(args.out, args.export_table)
        except TableError as e:
            print(f"millfmu dem seed002: {e}", file=sys.stderr)
            return 2
        print(f"exported {args.export_table}.npz/.json ({t.axes['tip_speed_m_s'].size} "
              f"tip speeds)")
    return 0


def _case(text: str) -> tuple:
    """'1200:0.8' -> (1200.0, 0.8), one of seed 002's cases."""
    from millfmu.dem.studies import seed002

    try:
        rpm, fill = (float(x) for x in text.split(":"))
    except ValueError:
        raise ValueError(f"--case {text!r}: write RPM:FILLING, e.g. 1200:0.8") from None
    for c in seed002.CASES:
        if abs(c[0] - rpm) < 1e-9 and abs(c[1] - fill) < 1e-9:
            return c
    raise ValueError(f"--case {text!r}: not one of seed 002's cases "
                     f"{[f'{n:g}:{f:g}' for n, f in seed002.CASES]}")


def _label(folder) -> str:
    from millfmu.dem.studies import seed002

    c = seed002.campaign_of(folder)
    return c["method"] + (", primed" if c.get("primed") else "") + \
        (", baffles" if c.get("baffles") else "")


def _compare_col(text: str) -> tuple:
    label, sep, folder = text.partition("=")
    if not sep or not label or not folder:
        raise ValueError(f"--compare {text!r}: write LABEL=DIR")
    return label, folder


def _run(args) -> int:
    from millfmu.dem.scene import DemSceneError, load_scene

    if args.resume is not None:
        return _resume(args)
    try:
        if args.scene is None or args.out is None:
            raise DemSceneError("a scene and --out are required (or --resume DIR)")
        scene = load_scene(args.scene)
        over = {k: getattr(args, k) for k in ("tip_speed_m_s", "filling", "sector_deg",
                                              "spin_up_s", "record_s", "sample_every_s",
                                              "dt_s", "fluid_mode", "initial_rotation",
                                              "primed_s", "n_theta", "smoothing",
                                              "pressure_solver")}
        if args.no_gravity:
            over["gravity_m_s2"] = (0.0, 0.0, 0.0)
        if args.rotor_speed_rpm is not None:
            if args.tip_speed_m_s is not None:
                raise DemSceneError("--rpm and --tip-speed: give one of them")
            if not args.rotor_speed_rpm > 0:
                raise DemSceneError(f"--rpm = {args.rotor_speed_rpm!r}: must be > 0")
            r = scene.geometry.disc_radius_m or scene.geometry.shaft_radius_m
            over["tip_speed_m_s"] = args.rotor_speed_rpm * 2.0 * math.pi / 60.0 * r
        scene = scene.with_overrides(**over)
    except DemSceneError as e:
        print(f"millfmu dem run: {e}", file=sys.stderr)
        return 2
    from millfmu.dem.run import run_scene

    if args.window_s is not None and not args.window_s > 0.0:
        print(f"millfmu dem run: --windows = {args.window_s!r}: must be > 0 s", file=sys.stderr)
        return 2
    from millfmu.dem.run import DemRunError
    from millfmu.dem.scene import scene_advice

    for line in scene_advice(scene):
        print(f"millfmu dem run: note: {line}", file=sys.stderr)
    from millfmu.dem.first_compile import say_if_compiling

    say_if_compiling(coupled=scene.fluid_mode == "coupled")
    try:
        stats = run_scene(scene, args.out, progress=not args.no_progress, threads=args.threads,
                          window_s=args.window_s, checkpoint_every_s=args.checkpoint_every_s,
                          device=args.device or "cpu")
    except DemRunError as e:
        print(f"millfmu dem run: {e}", file=sys.stderr)
        return 2
    return _report(stats, args.out)


def _progress(args) -> int:
    from millfmu.dem.analysis.progress import progress_lines, run_progress
    from millfmu.dem.run import DemRunError

    try:
        p = run_progress(args.run)
    except DemRunError as e:
        print(f"millfmu dem progress: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(p, indent=1))
    else:
        print("\n".join(progress_lines(p)))
    return 0


def _resume(args) -> int:
    """``dem run --resume DIR``: only the options that leave the results alone."""
    from millfmu.dem.run import DemRunError, resume_run

    flags = dict(out="--out", tip_speed_m_s="--tip-speed", rotor_speed_rpm="--rpm",
                 filling="--filling", sector_deg="--sector-deg", fluid_mode="--fluid",
                 spin_up_s="--spin-up", record_s="--record", sample_every_s="--sample-every",
                 dt_s="--dt", initial_rotation="--initial-rotation", primed_s="--primed",
                 n_theta="--theta-cells", window_s="--windows", smoothing="--smoothing",
                 pressure_solver="--pressure-solver")
    fixed = [f for k, f in flags.items() if getattr(args, k) is not None]
    if args.device is not None:
        fixed.append("--device")
    if args.scene is not None or args.no_gravity or fixed:
        given = ([args.scene] if args.scene else []) + fixed + \
            (["--no-gravity"] if args.no_gravity else [])
        print(f"millfmu dem run: --resume {args.resume}: goes on with the stopped run's own "
              f"scene and options; not allowed with {' '.join(given)}", file=sys.stderr)
        return 2
    try:
        stats = resume_run(args.resume, progress=not args.no_progress, threads=args.threads,
                           checkpoint_every_s=args.checkpoint_every_s)
    except DemRunError as e:
        print(f"millfmu dem run: {e}", file=sys.stderr)
        return 2
    return _report(stats, args.resume)


def _report(stats, out) -> int:
    from millfmu.dem.run import summary_table

    print(summary_table(stats))
    print(f"fluid: {stats.fluid_model}")
    print(f"wrote {out}/stats.json, se_histograms.csv, kinetic_energy.csv, map_*.png")
    return 0


def _bench(args) -> int:
    from millfmu.dem.studies import bench as B

    steps = args.steps or B.BENCH_STEPS
    cores = tuple(args.cores or (1, 2))
    beds = dict(both=("dense", "dilute"), none=()).get(args.bed, (args.bed,))
    if args.bed == "none" and not args.coupled:
        print("millfmu dem bench: --bed none: nothing to run without --coupled",
              file=sys.stderr)
        return 2
    if args.profile and args.coupled and (args.coupled == "full" or args.device == "gpu"):
        print(f"millfmu dem bench: --profile --coupled: the 10-degree sector with the DEM on "
              f"the CPU (here --coupled {args.coupled}"
              f"{', --device gpu' if args.device == 'gpu' else ''})", file=sys.stderr)
        return 2
    if args.coupled_start and not args.coupled:
        print(f"millfmu dem bench: --coupled-start {args.coupled_start}: applies to the "
              f"coupled row; add --coupled", file=sys.stderr)
        return 2
    if args.coupled_start == "running" and (args.coupled == "full" or args.device == "gpu"):
        print(f"millfmu dem bench: --coupled-start running: the 10-degree sector on the CPU "
              f"only (here --coupled {args.coupled}"
              f"{', --device gpu' if args.device == 'gpu' else ''}; the full slice takes "
              f"hours to spin up on 2 cores): use --coupled-start early", file=sys.stderr)
        return 2
    if args.device == "gpu" and (args.profile or args.coupled) and not B.gpu_available():
        print("millfmu dem bench: --device gpu: numba.cuda finds no CUDA GPU (numba's "
              "simulator is for tests, not for timing)", file=sys.stderr)
        return 2
    if args.profile:
        if args.coupled:
            from millfmu.dem.studies.coupled_bench import profile_coupled

            profile_coupled(steps=args.steps or 2000, threads=max(cores),
                            start=args.coupled_start or "running")
        for bed in beds:
            path = B.bed_file(B.BEDS[bed], regenerate=args.regenerate_bed)
            if args.device != "gpu":
                for nc in cores:
                    B.profile(path, nc, steps)
            if args.device == "gpu" or (args.device is None and B.gpu_available()):
                B.profile_gpu(path, steps)
        return 0
    runs = []
    for bed in beds:
        runs += B.bench(steps=steps, repeats=args.repeats or B.BENCH_REPEATS, cores=cores,
                        others=not args.ours_only, regenerate=args.regenerate_bed,
                        devices=(args.device,) if args.device else ("cpu", "gpu"), bed=bed)
    out = {"runs": [dict(r.__dict__, rate=r.rate) for r in runs]}
    if args.coupled:
        from millfmu.dem.studies.coupled_bench import run_coupled_bench

        c = out["coupled"] = run_coupled_bench(
            steps=steps, repeats=args.repeats or 3, threads=max(cores), scene=args.coupled,
            device="gpu" if args.device == "gpu" else "cpu",
            start=args.coupled_start).as_dict()
        where = f"DEM on the GPU, liquid on {c['threads']} threads" if c["device"] == "gpu" \
            else f"{c['threads']} threads"
        where += f" ({c['threading_layer']})"
        print(f"coupled row (disc_slice 10 m/s, 80 %, "
              f"{'10 deg' if c['scene'] == 'sector' else '360 deg with gravity'}, "
              f"{c['beads']} beads, "
              f"{c['fluid_cells']} fluid cells, coupling every {c['coupling_steps']} steps, "
              f"{where}, best of {len(c['dem_times_s'])}): DEM alone "
              f"{c['dem_particle_steps_per_s']:.4g}, coupled "
              f"{c['coupled_particle_steps_per_s']:.4g} particle-steps/s; the fluid and the "
              f"coupling add {c['added_cost']:.0%} (median of the "
              f"{len(c['block_added_costs'])} block pairs {c['added_cost_median']:.0%}); "
              f"beads timed from {c['start_s']:.3f} s after the start "
              f"({'the running mill' if c['start'] == 'running' else 'early'})")
    if args.json:
        print(json.dumps(out))
    return 0
