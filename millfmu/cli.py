"""The ``millfmu`` command.

Exit status: 0 on success, 2 for bad input (scene, options), 1 for a failure while running.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
import time
import warnings

from .arg_types import positive_number, whole_number
from .scene import SCENE_ARG_HELP

# The population balance works on small matrices, where multithreaded BLAS only adds
# overhead (and, on a busy machine, oversubscription slows expm a hundredfold). Set before
# numpy loads; the user's own setting wins. The DEM's parallelism (numba) is unaffected.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: Commands contributed by sub-packages: a module with ``register(subparsers)`` and,
#: optionally, ``register_bench(bench_subparsers)`` for ``millfmu bench ...``. They are
#: imported only to register their parsers; heavy imports (numba, pythonfmu) stay inside
#: their handlers.
PLUGINS = ("millfmu.dem.cli", "millfmu.dem.tables.cli", "fmu_build.cli", "flowsheets.cli", "millfmu.rates",
           "millfmu.report", "millfmu.calibration.cli")


def _cmd_run(args) -> int:
    from .mill import MillModel
    from .runner import check_out_dir, prediction_band, run_warnings, simulate, summary_table, write_results
    from .scene import load_scene

    if args.yes:
        from .dem.tables.on_demand import assume_yes

        assume_yes()
    scene = load_scene(args.scene)  # SceneError -> exit 2 before anything is written
    if args.on_stale is not None:
        scene = with_on_stale(scene, args.on_stale)
    check_out_dir(args.out)  # OutputError -> exit 2 before running
    for w in MillModel(scene).warnings:  # the data's warnings before a long run, not after
        print(f"millfmu: warning: {w}", file=sys.stderr)
    t0 = time.perf_counter()
    model, records, psds = simulate(scene, progress=not args.quiet)
    wall = time.perf_counter() - t0
    for w in run_warnings(model, records)[len(model.warnings):]:
        print(f"millfmu: warning: {w}", file=sys.stderr)
    band = prediction_band(scene)
    files = write_results(args.out, scene, model, records, psds, plots=not args.no_plots, wall_s=wall, band=band)
    op = model.operating_point(model.inputs)
    print(f"scene: {scene.scene.name}  ({scene.operation.mode}, {scene.material.model}, {scene.kinetics.model} model, "
          f"{model.grid.n} classes)")
    print(f"eta_eff = {op.eta_eff_Pa_s:.4g} Pa s, Re = {op.reynolds:.4g}, SE = {op.se_beads_J:.4g} J, SE_P = "
          f"{op.se_product_J:.4g} J")
    if model.source is not None:
        # The detailed model's stress conditions at the final operating point, per zone.
        sd = scene.kinetics.stress_distribution
        print(f"stress-energy source: {sd.source}"
              + (f" {sd.table!r}, component {sd.component}" if sd.source == "table" else ""))
        for z in model.source.zones(op):
            print(f"  {z.name:4s} volume share {z.volume_fraction:.3f}, collisions {z.collision_rate_per_m3_s:.3g} "
                  f"1/(m3 s), median energy {z.median_energy_J:.3g} J")
        for note in getattr(model.source, "last_notes", []):
            print(f"  note: {note}")
    print(summary_table(records))
    if band is not None:
        for line in band_lines(band, records[-1]):
            print(line)
    else:
        print("prediction band: none (the scene records no fitted constant with its interval, [scene] fitted, and "
              "takes no DEM table): what is known of its constants is not carried into the result")
    m_err = abs(records[-1]["total_mass_kg"] - (model.m0_kg + model.fed_kg)) / max(model.m0_kg + model.fed_kg, 1e-300)
    print(f"mass balance: relative residual {m_err:.2e}; simulated {scene.run.t_end_s:g} s in {wall:.3g} s wall")
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def band_lines(band: dict, last: dict) -> list:
    """The prediction band (:func:`millfmu.runner.prediction_band`) in words: the whole, then
    each part with what it rests on."""
    key, f, unit = ("disrupted_fraction", 1.0, "") if "disrupted_fraction" in band["outputs"] else ("x50_m", 1e6, " um")

    def rng(outputs) -> str:
        lo, hi = outputs[key]
        return f"[{lo * f:.4g}, {hi * f:.4g}]{unit}"

    parts = band["parts"]
    lines = [f"prediction band at t = {band['t_s']:g} s: {key} {last[key] * f:.4g}{unit} in {rng(band['outputs'])} "
             f"({' and '.join(parts)}{'' if len(parts) == 1 else ', their worst cases together'})"]
    if "table" in parts:
        t = parts["table"]
        freq, energy = t["collision_frequency_relative_error"], t["se_median_relative_error"]
        if all(v is None for v in freq + energy):
            why = "no zone had collisions (the stirrer at rest): the table's error reaches no result"
        else:
            why = f"zones' collision frequency {_percents(freq)}, median energy {_percents(energy)}"
        lines.append(f"  from the table's stated error: {rng(t['outputs'])} ({why})")
    if "calibration" in parts:
        c = parts["calibration"]
        consts = ", ".join(f"{x['key']} = {x['value']:.5g} in [{x['ci95'][0]:.4g}, {x['ci95'][1]:.4g}]"
                           for x in c["constants"])
        lines.append(f"  from the calibration's 95 % intervals: {rng(c['outputs'])} ({consts})")
    lines += [f"  note: {n}" for n in band.get("notes", [])]
    return lines


def _percents(errors) -> str:
    """Relative errors as "+-12%, -, ..." ("-": a zone without collisions)."""
    return ", ".join("-" if v is None else f"+-{v:.0%}" for v in errors)


def with_on_stale(scene, policy: str):
    """The scene with kinetics.stress_distribution.on_stale = ``policy`` (the --on-stale flag)."""
    from dataclasses import replace

    k = scene.kinetics
    return replace(scene, kinetics=replace(k, stress_distribution=replace(k.stress_distribution, on_stale=policy)))


def _cmd_scene_keys(args) -> int:
    from .scene import default_scene_text, iter_keys

    if args.default:
        sys.stdout.write(default_scene_text())
        return 0
    for key, unit, default, allowed, doc in iter_keys():
        print(f"{key:42s} {unit:9s} default {default!r:<14} {allowed}; {doc}")
    return 0


#: ``millfmu bench pbm``'s defaults: the options' and those its --json record leaves unnamed
BENCH_PBM_DEFAULTS = {"classes": [50, 100, 200], "hours": 1.0, "repeats": 3, "tanks": 50}


def _cmd_bench_pbm(args) -> int:
    from .studies.pbm_integrators import bench_pbm, micro_blocks

    if args.hours * 3600.0 < 1.0:
        print(f"millfmu: error: bench pbm: --hours {args.hours:g}: allowed 1/3600 h (one 1 s step) or more",
              file=sys.stderr)
        return 2
    if args.json is not None:
        from .runner import check_record_file

        check_record_file(args.json)  # before the timings: OutputError -> exit 2
    rows = bench_pbm(classes=args.classes, hours=args.hours, repeats=args.repeats, tanks=args.tanks,
                     dense=not args.no_dense)
    if args.json is not None:
        from .machine import write_record

        figures = {}
        for r in rows:
            if "classes" in r:
                n = r["classes"]
                # rounded as the table prints them
                figures.update({f"step_us_{n}_classes": round(r["model_step_us"], 1),
                                f"exact_step_us_{n}_classes": round(r["step_us"], 2),
                                f"bdf_restarted_over_ours_{n}_classes": round(r["ratio_steps"]),
                                f"bdf_span_over_ours_{n}_classes": round(r["ratio_span"], 1)})
        tanks = [r for r in rows if "tanks" in r]
        for r, what in zip(tanks, ("default", "stiff")):
            figures[f"tanks_{r['tanks']}_{what}_step_us"] = round(r["step_us"], 1)
            figures[f"tanks_{r['tanks']}_{what}_propagator_ms"] = round(r["setup_ms"], 2)
        opts = "".join(f" --{k} {' '.join(map(str, v)) if isinstance(v, list) else v}"
                       for k, default in BENCH_PBM_DEFAULTS.items() if (v := getattr(args, k)) != default)
        opts += " --no-dense" if args.no_dense else ""
        wrote = write_record(args.json, "millfmu bench pbm" + opts, figures, host=args.host,
                             aim={"step_us_100_classes": 10},
                             unit="us per MillModel.step with all outputs (step_us), per exact step alone "
                                  "(exact_step_us); scipy BDF's time over ours at equal accuracy, restarted at every "
                                  f"1 s step and over the whole span; {args.hours:g} h at 1 s steps, best of "
                                  f"{args.repeats} (the steps in us: of {micro_blocks(args.repeats)} blocks of "
                                  "1000); tanks: the continuous mill's step and propagator")
        print(f"wrote {wrote}")
    return 0


#: Per command, the arguments that name a file of the user's and may instead name a shipped
#: example by its bare file name (``millfmu examples`` lists them): an installed package's
#: examples lie in site-packages, which no one should have to type.
EXAMPLE_ARGS = {"run": ("scene",), "calibrate": ("scene", "data"), "build-fmu": ("scene",), "rates": ("scene",)}


def shipped_example(arg):
    """The file a command-line file argument stands for: ``arg`` itself where it exists, has a
    folder in it or is None; else the shipped example of that name (``.toml`` optional) as
    a string; else ``arg`` unchanged, whose command then reports the missing file. A file
    of the user's wins over an example of the same name (:func:`~millfmu.scene.shipped_file`)."""
    from .scene import example_files, shipped_file

    path = shipped_file(arg, example_files())
    return path if path is arg else str(path)


def _use_shipped_examples(args) -> None:
    """Put the shipped example's path in each of the command's file arguments (EXAMPLE_ARGS)
    that names one, saying so on stderr."""
    for name in EXAMPLE_ARGS.get(getattr(args, "command", None), ()):
        value = getattr(args, name, None)
        values = value if isinstance(value, list) else [value]
        resolved = [shipped_example(v) for v in values]
        for v, r in zip(values, resolved):
            if r != v:
                print(f"millfmu: no file {v} here: using the shipped example {r}", file=sys.stderr)
        setattr(args, name, resolved if isinstance(value, list) else resolved[0])


def _cmd_examples(args) -> int:
    from .scene import example_files

    files = example_files()
    width = max(map(len, files))
    for name, path in files.items():
        print(f"{name:{width}s}  {path}")
    print("Run one by name (millfmu run limestone_detailed.toml; millfmu calibrate --data limestone_standin_batch.csv "
          "...); to change one, copy it and run the copy.")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse's parser that also reads negative numbers in exponent form (-1e-6) as values, as Python 3.13's
    does, so that a bad value reaches the option's own check and message instead of "expected one argument"."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="millfmu",
                description="Wet stirred media mill (bead mill) model: population balance with Kwade's stress model.")
    from . import __version__

    p.add_argument("--version", action="version", version=f"millfmu {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    r = sub.add_parser("run", help="run a scene (default: the embedded default scene)")
    r.add_argument("scene", nargs="?", default=None, help=SCENE_ARG_HELP)
    r.add_argument("--out", default="out", help="output folder for result.json, psd.csv and plots (default: ./out)")
    r.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.add_argument("--on-stale", choices=("refuse", "rebuild", "accept"), default=None,
                   help="a table built on demand (on_outside = 'build') whose DEM kernel version is not the installed "
                        "DEM's: refuse, rebuild every point, or accept its points and run only the new ones "
                        "(default: the scene's kinetics.stress_distribution.on_stale)")
    r.add_argument("--yes", action="store_true",
                   help="run an on-demand table build however long it is estimated to take (without it, a build "
                        "over MILLFMU_BUILD_LIMIT_S, default 1800 s, is asked about at a terminal and refused "
                        "elsewhere)")
    r.set_defaults(func=_cmd_run)

    e = sub.add_parser("examples",
                       help="list the shipped example scenes and data with their paths (commands take them by name)",
                       description="List the shipped example scenes and stand-in data with their paths; run, "
                                   "calibrate and rates take them by name.")
    e.set_defaults(func=_cmd_examples)

    k = sub.add_parser("scene-keys", help="list every scene key with unit, default and allowed values")
    k.add_argument("--default", action="store_true", help="print the embedded default scene instead")
    k.set_defaults(func=_cmd_scene_keys)

    b = sub.add_parser("bench", help="benchmarks (printed ratios against a baseline in the same run)",
                       description="Benchmarks: each prints its cost as a ratio against a baseline timed in the "
                                   "same run.")
    bsub = b.add_subparsers(dest="bench", metavar="WHAT")
    bsub.required = True
    bp = bsub.add_parser("pbm", help="population balance step cost, and against scipy's BDF at equal accuracy")
    bp.add_argument("--classes", type=whole_number(2), nargs="+", default=BENCH_PBM_DEFAULTS["classes"],
                    help="size classes of the grids to time (default: 50 100 200)")
    bp.add_argument("--hours", type=positive_number, default=BENCH_PBM_DEFAULTS["hours"],
                    help="simulated batch time [h] at 1 s steps (default: %(default)g)")
    bp.add_argument("--repeats", type=whole_number(1), default=BENCH_PBM_DEFAULTS["repeats"],
                    help="timed repeats, the best counted (default: %(default)s)")
    bp.add_argument("--tanks", type=whole_number(0), default=BENCH_PBM_DEFAULTS["tanks"],
                    help="tanks in series of the continuous row (0: leave it out)")
    bp.add_argument("--no-dense", action="store_true",
                    help="continuous row without the dense matrix exponential (the method before; tens of seconds at "
                         "50 tanks)")
    bp.add_argument("--json", metavar="FILE", help="also write the figures to FILE as one JSON record (with the "
                                                   "commit, the date and the machine)")
    bp.add_argument("--host", default="", help="the machine in words, for --json's record")
    bp.set_defaults(func=_cmd_bench_pbm)

    for mod in PLUGINS:
        try:
            plugin = importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name != mod:
                raise
            continue
        plugin.register(sub)
        if hasattr(plugin, "register_bench"):
            plugin.register_bench(bsub)
    return p


def main(argv=None) -> int:
    from .mill import InputError
    from .runner import OutputError
    from .scene import SceneError

    parser = build_parser()
    args = parser.parse_args(argv)
    _use_shipped_examples(args)
    shown_as = warnings.formatwarning
    warnings.formatwarning = _one_line_warning  # a note to the user, not a source line of millfmu
    try:
        return int(args.func(args) or 0)
    except (SceneError, InputError, OutputError) as e:
        # a scene's own checks name it by its name; say which file too
        where = getattr(args, "scene", None)
        shown = f"{where}: {e}" if isinstance(e, SceneError) and isinstance(where, str) and where not in str(e) \
            else str(e)
        print(f"millfmu: error: {shown}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("millfmu: interrupted; no results written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. head, which stopped reading
        sys.stderr.close()
        return 0
    finally:
        warnings.formatwarning = shown_as


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    """A warning as the command shows it: one line "millfmu: warning: ..." (an earlier
    release's key spelling, a data warning), without the file and line of millfmu's code
    that issued it."""
    return f"millfmu: warning: {message}\n"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
