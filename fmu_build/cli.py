"""``millfmu build-fmu``, ``millfmu host-env`` and ``millfmu bench fmu``.

pythonfmu and fmpy are imported inside the handlers only, so that ``millfmu`` starts fast
and works without them.
"""

from __future__ import annotations

import sys

from millfmu.arg_types import whole_number
from millfmu.scene import SCENE_ARG_HELP


def _cmd_build_fmu(args) -> int:
    import time
    import zipfile

    from .build import build_fmu

    from .fmi3_wrapper import WrapperError

    if args.yes:
        from millfmu.dem.tables.on_demand import assume_yes

        assume_yes()
    t0 = time.perf_counter()
    try:
        r = build_fmu(args.scene, args.output, fmi_version=args.fmi_version, log=print)
    except WrapperError as e:
        print(f"millfmu build-fmu: error: {e}", file=sys.stderr)
        return 1
    except (RuntimeError, ValueError) as e:
        if type(e).__name__ in ("SceneError", "InputError", "OutputError"):
            raise  # the main command reports these with exit status 2
        print(f"millfmu build-fmu: error: {e}", file=sys.stderr)
        return 1
    with zipfile.ZipFile(r.fmu) as z:
        n_files = len(z.namelist())
    size = r.fmu.stat().st_size
    print(f"wrote {r.fmu} (FMI {r.fmi_version}.0, {size / 1024:.1f} KiB, {n_files} files) in "
          f"{time.perf_counter() - t0:.2f} s")
    print(f"model identifier {r.model_identifier}; {r.n_classes} size classes; code package {r.package}: "
          f"{', '.join(r.modules)}")
    from . import fmi3_wrapper, wrapper

    print(f"platforms: {(wrapper if r.fmi_version == 2 else fmi3_wrapper).PLATFORM_NOTE}")
    return 0


def _cmd_host_env(args) -> int:
    from .hostenv import host_env, shell_lines

    try:
        env = host_env(args.fmu)
    except (OSError, ValueError) as e:
        why = f"{args.fmu}: cannot be read ({e.strerror})" if isinstance(e, OSError) and e.strerror else str(e)
        print(f"millfmu host-env: error: {why}", file=sys.stderr)
        return 2
    print("\n".join(shell_lines(env)))
    return 0


#: ``millfmu bench fmu``'s default size classes (its --json record names others)
BENCH_FMU_CLASSES = 100


def _cmd_bench_fmu(args) -> int:
    from .step_cost import bench_fmu

    from .fmi3_wrapper import WrapperError

    from millfmu.machine import write_record
    from millfmu.runner import check_record_file

    if args.json is not None:
        check_record_file(args.json)  # before the builds: OutputError -> exit 2
    figures = {}
    try:
        rc = bench_fmu(classes=args.classes, steps=args.steps, repeats=args.repeats,
                       fmi_versions=args.fmi_version or (2, 3),
                       required=bool(args.fmi_version), figures=figures)
    except WrapperError as e:
        print(f"millfmu bench fmu: error: {e}", file=sys.stderr)
        return 1
    if args.json is not None:
        opts = "" if args.classes == BENCH_FMU_CLASSES else f" --classes {args.classes}"
        opts += "".join(f" --fmi-version {v}" for v in args.fmi_version or ())
        wrote = write_record(args.json, "millfmu bench fmu" + opts, figures, host=args.host,
                             unit="doStep + reading all outputs, per step [us], and over the same for a trivial FMU of "
                                  "that FMI version in the same run [-]; best of "
                                  f"{args.repeats} x {args.steps} steps of 1 s, {args.classes} size classes",
                             aim={"fmi2_over_floor": 1.5, "fmi3_over_floor": 2})
        print(f"wrote {wrote}")
    return rc


def register(subparsers) -> None:
    b = subparsers.add_parser("build-fmu",
                              help="build an FMI 2.0 (pythonfmu) or 3.0 (pythonfmu3) co-simulation FMU of a scene")
    b.add_argument("scene", nargs="?", default=None, help=SCENE_ARG_HELP)
    b.add_argument("-o", "--output", required=True, help="FMU file to write (.fmu)")
    b.add_argument("--fmi-version", type=int, choices=(2, 3), default=2, help="FMI version of the FMU (default 2)")
    b.add_argument("--yes", action="store_true",
                   help="run the on-demand table build the scene may need however long it is estimated to take")
    b.set_defaults(func=_cmd_build_fmu)

    h = subparsers.add_parser("host-env", help="environment a C/C++ host needs to load an FMU built by build-fmu")
    h.add_argument("fmu", help="FMU file")
    h.set_defaults(func=_cmd_host_env)


def register_bench(bench_subparsers) -> None:
    f = bench_subparsers.add_parser("fmu",
                                    help="FMU doStep + reading all outputs, against a trivial FMU of the same FMI "
                                         "version in the same run")
    f.add_argument("--classes", type=whole_number(2), default=BENCH_FMU_CLASSES,
                   help="size classes of the mill FMU (default %(default)s)")
    f.add_argument("--steps", type=whole_number(1), default=2000, help="steps per timing run (default %(default)s)")
    f.add_argument("--repeats", type=whole_number(1), default=5,
                   help="timing runs; the best is reported (default %(default)s)")
    f.add_argument("--fmi-version", type=int, choices=(2, 3), action="append",
                   help="FMI version to measure (repeatable; default: 2 and 3)")
    f.add_argument("--json", metavar="FILE", help="also write the figures to FILE as one JSON record (with the "
                                                  "commit, the date and the machine)")
    f.add_argument("--host", default="", help="the machine in words, for --json's record")
    f.set_defaults(func=_cmd_bench_fmu)
