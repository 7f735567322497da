"""``millfmu dem`` subcommands: ``run SCENE --out DIR``, ``progress RUN_DIR`` and ``compare
RUN_DIR...``.

The main CLI calls :func:`register` with its subparsers object. Nothing here imports
numba at import time; the handlers import the DEM modules when they run. The DEM's
benchmarks and paper campaigns are not installed with the package: from a checkout's root,
``python -m benchmarks.dem_peers`` (the former ``dem bench``) and ``python -m
validation.seed001``, ``validation.seed002``, ``validation.work_precision``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from millfmu.dem.coupling.settings import PRESSURE_SOLVERS, SMOOTHINGS


def thread_count(text: str) -> int:
    """An argparse type for ``--threads``: a whole number from 1 to the threads numba may
    start (its NUMBA_NUM_THREADS, by default the cores this process may use)."""
    from numba.core.config import NUMBA_NUM_THREADS

    from millfmu.arg_types import whole_number

    return whole_number(1, NUMBA_NUM_THREADS, " (the cores numba may use here, NUMBA_NUM_THREADS)")(text)


def check_run_folder(out: str, option: str = "--out") -> None:
    """DemSceneError unless ``out`` is, or can become, a folder this process can write into
    (checked before a run starts, so that a bad folder is not found after the run)."""
    from millfmu.dem.scene import DemSceneError
    from millfmu.runner import OutputError, check_out_dir

    try:
        check_out_dir(out, option, staged=False)
    except OutputError as e:
        raise DemSceneError(str(e)) from None


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``dem`` command group to an argparse subparsers object."""
    p = subparsers.add_parser("dem", help="bead DEM: run a scene, follow and compare runs",
                              description="Soft-sphere DEM of the grinding beads.")
    sub = p.add_subparsers(dest="dem_command", metavar="{run,progress,compare}")
    sub.required = True
    _register_run(sub)

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
    return p


def _register_run(sub) -> None:
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
    r.add_argument("--tip-speed", type=float, dest="tip_speed_m_per_s", metavar="M_S",
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
    r.add_argument("--threads", type=thread_count, help="numba threads, and the processes that "
                   "compile the kernels on a first run (default: all cores)")
    r.add_argument("--device", choices=("cpu", "gpu"), default=None,
                   help="where the DEM steps: cpu (numba threads, default) or gpu "
                        "(numba.cuda; the coupled liquid stays on the CPU's threads; no "
                        "checkpoints, no vanes)")
    r.add_argument("--windows", type=float, dest="window_s", metavar="S",
                   help="also write windows.csv: zone statistics of consecutive recording "
                        "windows of S seconds (stationarity check)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.set_defaults(func=_run)


def _compare(args) -> int:
    from millfmu.dem.analysis.compare import CompareError, markdown

    try:
        print(markdown(args.runs))
    except CompareError as e:
        print(f"millfmu dem compare: {e}", file=sys.stderr)
        return 2
    return 0


def _run(args) -> int:
    from millfmu.dem.scene import DemSceneError, load_scene

    if args.resume is not None:
        return _resume(args)
    try:
        if args.scene is None or args.out is None:
            raise DemSceneError("a scene and --out are required (or --resume DIR)")
        check_run_folder(args.out)
        scene = load_scene(args.scene)
        over = {k: getattr(args, k) for k in ("tip_speed_m_per_s", "filling", "sector_deg",
                                              "spin_up_s", "record_s", "sample_every_s",
                                              "dt_s", "fluid_mode", "initial_rotation",
                                              "primed_s", "n_theta", "smoothing",
                                              "pressure_solver")}
        if args.no_gravity:
            over["gravity_m_per_s2"] = (0.0, 0.0, 0.0)
        if args.rotor_speed_rpm is not None:
            if args.tip_speed_m_per_s is not None:
                raise DemSceneError("--rpm and --tip-speed: give one of them")
            if not args.rotor_speed_rpm > 0:
                raise DemSceneError(f"--rpm = {args.rotor_speed_rpm!r}: must be > 0")
            r = scene.geometry.disc_radius_m or scene.geometry.shaft_radius_m
            over["tip_speed_m_per_s"] = args.rotor_speed_rpm * 2.0 * math.pi / 60.0 * r
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
    from millfmu.dem.first_compile import compile_if_cold

    # the cores the user gave the run (--threads) are those its compilation takes too
    compile_if_cold(coupled=scene.fluid_mode == "coupled", processes=args.threads,
                    run_s=scene.spin_up_s + scene.record_s)
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

    flags = dict(out="--out", tip_speed_m_per_s="--tip-speed", rotor_speed_rpm="--rpm",
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
    _compile_for_resume(args.resume, args.threads)
    try:
        stats = resume_run(args.resume, progress=not args.no_progress, threads=args.threads,
                           checkpoint_every_s=args.checkpoint_every_s)
    except DemRunError as e:
        print(f"millfmu dem run: {e}", file=sys.stderr)
        return 2
    return _report(stats, args.resume)


def _compile_for_resume(folder, threads) -> None:
    """A stopped run resumed on a machine whose kernel cache is cold (another machine, or
    other sources) compiles first, as a new run does, in ``threads`` processes; the stopped
    run's scene says whether with the coupled liquid. The checkpoint is read for that only
    where a kernel is missing; one that cannot be read is left to resume_run to refuse."""
    from millfmu.dem import first_compile as fc
    from millfmu.dem.run import DemRunError, load_checkpoint

    jobs = fc.load_plan("coupled")  # the coupled run's kernels include the DEM's
    if jobs is not None and not fc.missing(jobs):
        return
    try:
        scene = load_checkpoint(folder)["scene"]
    except (DemRunError, KeyError, TypeError):
        return
    fc.compile_if_cold(coupled=scene.fluid_mode == "coupled", processes=threads)


def _report(stats, out) -> int:
    from millfmu.dem.run import summary_table

    print(summary_table(stats))
    print(f"fluid: {stats.fluid_model}")
    print(f"wrote {out}/stats.json, se_histograms.csv, kinetic_energy.csv, map_*.png, collision_maps.npz")
    return 0
