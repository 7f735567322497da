"""``millfmu calibrate``: the command over :mod:`millfmu.calibration`. Parses the options,
prints the fit and its progress, words the library's refusals with the command's options
and gives the exit status (0 done, 2 bad input or data that cannot pin the constants)."""

from __future__ import annotations

import sys

from ..runner import OutputError, check_out_dir
from ..scene import SCENE_ARG_HELP, SceneError, load_scene
from . import FITTABLE, CalibrationError, calibrate, read_data, write

#: The command's options for the arguments of :func:`millfmu.calibration.calibrate` that a
#: refusal names ({}: what the option gave; for --start, the constant's key).
CLI_WORDS = {"fit": "--fit {}", "data": "--data {}", "error_model": "--errors {}", "start": "--start {}=VALUE"}


def start_values(items: list) -> dict:
    """The --start KEY=VALUE options as {key: value}."""
    start = {}
    for item in items:
        k, sep, v = item.partition("=")
        try:
            start[k.strip()] = float(v)
        except ValueError:
            raise CalibrationError(f"--start {item!r}: expected KEY=VALUE with a number") from None
        if not sep or k.strip() not in FITTABLE:
            raise CalibrationError(f"--start {item!r}: expected KEY=VALUE with KEY among {', '.join(FITTABLE)}")
    return start


def _cmd_calibrate(args) -> int:
    try:
        scene = load_scene(args.scene)
        if args.out:
            check_out_dir(args.out)
        say = (lambda line: print(line, file=sys.stderr, flush=True)) if not args.quiet else None
        start = start_values(args.start)
        data = read_data(args.data)
        for note in data.notes:
            print(f"millfmu calibrate: warning: {note}", file=sys.stderr)
        cal = calibrate(scene, data, args.fit, start=start, progress=say, error_model=getattr(args, "errors", None))
        print(cal.summary())
        if args.out:
            files = write(cal, args.out, scene_path=args.scene or "default")
            print("wrote " + ", ".join(str(f) for f in files))
    except CalibrationError as e:
        print(f"millfmu: error: {e.worded(CLI_WORDS)}", file=sys.stderr)
        return 2
    except (SceneError, OutputError) as e:
        print(f"millfmu: error: {e}", file=sys.stderr)
        return 2
    return 0


def register(sub):
    c = sub.add_parser("calibrate", help="fit one or two scene constants to measured batch data (with 95 %% intervals)",
                       description="Fit scene constants to measured batch grinding data at the scene's operating "
                                   f"point. Fittable: {', '.join(FITTABLE)}.")
    c.add_argument("scene", nargs="?", default=None, help=SCENE_ARG_HELP)
    c.add_argument("--data", required=True, help="CSV: t_s and x10_m/x50_m/x90_m, or x_m and Q3, or disrupted_fraction")
    c.add_argument("--fit", required=True, help="KEY[,KEY]: the constants to fit (dotted scene keys)")
    c.add_argument("--out", default=None, help="folder for calibrated.toml and calibration.json (omitted: print only)")
    c.add_argument("--start", action="append", default=[], metavar="KEY=VALUE",
                   help="start value of a fitted constant (default: the scene's); repeat for a pair")
    c.add_argument("--errors", choices=("independent", "per-sample"), default=None,
                   help="error model of the intervals: per-sample (an error shared by one time's values, "
                        "cluster-robust; the default when a time has several quantities) or independent (the default "
                        "otherwise)")
    c.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    c.set_defaults(func=_cmd_calibrate)
