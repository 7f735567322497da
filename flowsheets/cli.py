"""``millfmu flowsheet ...``: run flowsheets with the fmpy master, export them as SSP, and
measure the error of the co-simulation against its communication step.

Exit status: 0 on success, 2 for bad input (flowsheet file, options; nothing is written),
1 for a failure while running.
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
from pathlib import Path


def _limit_blas_threads():
    """One BLAS thread: the co-simulation's matrices are small (a few hundred rows), where
    threads only add synchronisation, and on a loaded machine oversubscribed BLAS threads
    made a flowsheet run about 50 times slower. Only effective before numpy is imported;
    a value the user set is kept."""
    if "numpy" not in sys.modules:
        for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(k, "1")


def _load(path):
    from .spec import FlowsheetError, load_flowsheet

    p = shipped_or_path(path)
    if not p.exists() and str(p) == p.name:
        from millfmu.scene import closest

        near = closest(p.name if p.suffix else p.name + ".toml", shipped_flowsheets())
        if near:
            raise FlowsheetError("file", str(p), f"cannot be read (No such file or directory; did you mean "
                                 f"{near.removesuffix('.toml')}, a shipped flowsheet?)", str(p))
    return load_flowsheet(p)


def shipped_flowsheets() -> dict:
    """The flowsheets shipped with the package: file name -> path (wherever it is installed)."""
    return {f.name: f for f in sorted(Path(__file__).resolve().parent.glob("*.toml"))}


def shipped_or_path(name: str) -> Path:
    """``name`` as given where such a file exists, else the shipped flowsheet of that name
    (``.toml`` optional), as the scene commands take the shipped examples; else ``name`` as
    given (its reading then says it cannot be read); the scene commands' rule
    (:func:`millfmu.scene.shipped_file`)."""
    from millfmu.scene import shipped_file

    return Path(shipped_file(name, shipped_flowsheets()))


def _bad(e) -> int:
    print(f"millfmu flowsheet: error: {e}", file=sys.stderr)
    return 2


def _publish(tmp: Path, out: Path):
    """Move the finished results from tmp into out (created), file by file."""
    out.mkdir(parents=True, exist_ok=True)
    moved = []
    for f in sorted(tmp.iterdir()):
        dst = out / f.name
        if dst.is_dir() and f.is_dir():
            shutil.rmtree(dst)
        shutil.move(str(f), str(dst))
        moved.append(dst)
    return moved


def _check_out(out: Path, option: str = "--out"):
    """FlowsheetError unless ``out`` is, or can become, a folder this process can write into
    (before anything is built or run)."""
    from millfmu.runner import OutputError, check_out_dir

    from .spec import FlowsheetError

    if out is None:
        return
    if Path(out).exists() and not Path(out).is_dir():
        raise FlowsheetError(option, str(out), "must be a folder (it is a file)", "command line")
    try:
        check_out_dir(out, option, staged=False)
    except OutputError as e:
        raise FlowsheetError(option, str(out), str(e).split(": ", 1)[1], "command line") from None


def _positive_seconds(option: str, value: float):
    """FlowsheetError unless ``value`` is a finite number > 0 (a time option)."""
    from .spec import FlowsheetError

    if not (math.isfinite(value) and value > 0):
        raise FlowsheetError(option, value, "must be a finite number > 0 s", "command line")


def cmd_run(args) -> int:
    _limit_blas_threads()
    from fmu_build.fmi3_wrapper import WrapperError

    from .master import MasterError, run_flowsheet, write_results
    from .spec import FlowsheetError

    out = Path(args.out)
    try:
        fs = _load(args.file)
        if args.step is not None:
            _positive_seconds("--step", args.step)
            if (abs(fs.t_end_s / args.step - round(fs.t_end_s / args.step))
                                     > 1e-9 * fs.t_end_s / args.step):
                raise FlowsheetError("--step", args.step,
                                     f"must be > 0 s and divide t_end_s = {fs.t_end_s!r} s into whole steps",
                                     "command line")
            fs = fs.with_(step_s=args.step, output_interval_s=max(fs.output_interval_s, args.step))
        if args.algorithm:
            fs = fs.with_(algorithm=args.algorithm)
        if args.output_interval is not None:
            _positive_seconds("--output-interval", args.output_interval)
            n = args.output_interval / fs.step_s
            if not args.output_interval > 0 or abs(n - round(n)) > 1e-9 * n:
                raise FlowsheetError("--output-interval", args.output_interval,
                                     f"must be a whole multiple of the step {fs.step_s!r} s", "command line")
            fs = fs.with_(output_interval_s=args.output_interval)
        _check_out(out)
        _check_out(args.fmu_dir and Path(args.fmu_dir), "--fmu-dir")
        with tempfile.TemporaryDirectory(prefix="flowsheet_") as tmp:
            # FMUs are built into the results (OUT/fmus), reusing those of earlier runs.
            fmu_dir = Path(args.fmu_dir) if args.fmu_dir else Path(tmp) / "fmus"
            res = run_flowsheet(fs, fmu_dir, log=lambda m: print(m, flush=True), reuse=[out / "fmus"],
                                fmi_version=args.fmi_version)
            write_results(res, fs, Path(tmp), plots=not args.no_plots)
            moved = _publish(Path(tmp), out)
    except FlowsheetError as e:
        return _bad(e)
    except (MasterError, WrapperError) as e:
        print(f"millfmu flowsheet: failed: {e}", file=sys.stderr)
        return 1
    mb = res.mass
    print(f"flowsheet {fs.name}: FMI {args.fmi_version}.0 units, {fs.algorithm}, step {fs.step_s:g} s, {res.steps} "
          f"steps, {len(res.retries)} retried; {res.wall_s:.3g} s wall")
    print(f"mass balance: fed {mb['fed_kg']:.6g} kg, products {mb['products_kg']:.6g} kg, holdup "
          f"{mb['holdup0_kg']:.6g} -> {mb['holdup_kg']:.6g} kg, in flow buffers {mb['buffered_kg']:.3g} kg; relative "
          f"residual {mb['relative_residual']:.2e}")
    for c in res.columns:
        if c.endswith("x50"):
            print(f"  {c:28s} {res.column(c)[0] * 1e6:9.4g} -> {res.column(c)[-1] * 1e6:9.4g} um")
    print("wrote " + ", ".join(str(f) for f in moved))
    return 0


def cmd_export_ssp(args) -> int:
    _limit_blas_threads()
    from .spec import FlowsheetError
    from .ssp import export_ssp

    try:
        fs = _load(args.file)
        out = Path(args.output)
        if out.suffix != ".ssp":
            raise FlowsheetError("-o", str(out), "must end in .ssp", "command line")
        if out.is_dir():
            raise FlowsheetError("-o", str(out), "is a folder; give a file name ending in .ssp", "command line")
        try:
            _check_out(out.parent, "-o")
        except FlowsheetError as e:
            raise FlowsheetError("-o", str(out), f"its folder {e.value}: {e.allowed}", "command line") from None
        _check_out(args.fmu_dir and Path(args.fmu_dir), "--fmu-dir")
        path = export_ssp(fs, out, fmu_dir=Path(args.fmu_dir) if args.fmu_dir else None,
                          log=lambda m: print(m, flush=True))
    except FlowsheetError as e:
        return _bad(e)
    print(f"wrote {path}")
    return 0


def cmd_wp(args) -> int:
    _limit_blas_threads()
    from fmu_build.fmi3_wrapper import WrapperError

    from .spec import FlowsheetError
    from .wp import work_precision

    try:
        fs = _load(args.file)
        if args.t_end is not None:
            _positive_seconds("--t-end", args.t_end)
            fs = fs.with_(t_end_s=args.t_end)
        steps = sorted(set(args.steps))
        for h in steps + [args.reference]:
            n = fs.t_end_s / h if math.isfinite(h) and h > 0 else math.nan
            if not (math.isfinite(n) and abs(n - round(n)) <= 1e-9 * n):
                raise FlowsheetError("--steps/--reference", h,
                                     f"each must be > 0 s and divide t_end_s = {fs.t_end_s!r} s into whole steps",
                                     "command line")
        if len(steps) < 2 or args.reference >= min(steps):
            raise FlowsheetError("--steps", steps, "need at least two step sizes, all above --reference",
                                 "command line")
        unit = args.variable.partition(".")[0]
        if unit not in fs.units and unit != "total":
            raise FlowsheetError("--variable", args.variable, "must be UNIT.VARIABLE with UNIT among the flowsheet's "
                                 "units (" + ", ".join(fs.units) + ") or total", "command line")
        _check_out(Path(args.out))
        _check_out(args.fmu_dir and Path(args.fmu_dir), "--fmu-dir")
        with tempfile.TemporaryDirectory(prefix="flowsheet_wp_") as tmp:
            table = work_precision(fs, steps, args.reference, Path(tmp),
                                   fmu_dir=Path(args.fmu_dir) if args.fmu_dir else Path(args.out) / "fmus",
                                   variable=args.variable, log=lambda m: print(m, flush=True),
                                   fmi_version=args.fmi_version)
            moved = _publish(Path(tmp), Path(args.out))
    except FlowsheetError as e:
        return _bad(e)
    except WrapperError as e:
        print(f"millfmu flowsheet: failed: {e}", file=sys.stderr)
        return 1
    print(table)
    print("wrote " + ", ".join(str(f) for f in moved))
    return 0


def register(subparsers):
    file_help = ("flowsheet file (TOML), or a shipped one by name ("
                 + ", ".join(f[:-5] for f in shipped_flowsheets()) + ")")
    p = subparsers.add_parser("flowsheet",
                              help="flowsheets: the mill with feed, tanks, classifiers and controllers (FMUs)")
    sub = p.add_subparsers(dest="flowsheet_command", metavar="WHAT")
    sub.required = True

    r = sub.add_parser("run", help="run a flowsheet file with the fmpy master")
    r.add_argument("file", help=file_help)
    r.add_argument("--out", default="out",
                   help="output folder (default: ./out): results.csv, psd_<unit>.csv, summary.json, flowsheet.png")
    r.add_argument("--fmu-dir", default=None,
                   help="where the unit FMUs are built and reused (default: OUT/fmus, written with the results)")
    r.add_argument("--step", type=float, default=None, help="communication step [s] instead of the file's")
    r.add_argument("--algorithm", choices=("jacobi", "gauss-seidel"), default=None, help="instead of the file's")
    r.add_argument("--output-interval", type=float, default=None,
                   help="output interval [s] instead of the file's (a multiple of the step)")
    r.add_argument("--no-plots", action="store_true", help="skip the PNG")
    r.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version of all the unit FMUs (default 2)")
    r.set_defaults(func=cmd_run)

    e = sub.add_parser("export-ssp", help="write the flowsheet as an SSP archive (SSD + the units' FMUs)")
    e.add_argument("file", help=file_help)
    e.add_argument("-o", "--output", required=True, help="the .ssp file to write")
    e.add_argument("--fmu-dir", default=None,
                   help="where the unit FMUs are built and reused (default: a temporary folder)")
    e.set_defaults(func=cmd_export_ssp)

    w = sub.add_parser("wp", help="error of a size against the communication step, with wall time (work-precision)")
    w.add_argument("file", help=file_help)
    w.add_argument("--steps", type=float, nargs="+", default=[1.0, 2.0, 4.0, 8.0, 16.0, 32.0],
                   help="communication steps [s]")
    w.add_argument("--reference", type=float, default=0.125, help="communication step [s] of the reference run")
    w.add_argument("--t-end", type=float, default=None, help="simulated time [s] instead of the file's t_end_s")
    w.add_argument("--variable", default="mill.x50", help="output compared (unit.variable; default mill.x50)")
    w.add_argument("--out", default="out_wp",
                   help="output folder: wp.csv, wp.json, wp.txt, wp.png (default %(default)s)")
    w.add_argument("--fmu-dir", default=None, help="where the unit FMUs are built and reused (default: OUT/fmus)")
    w.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version of all the unit FMUs (default 2)")
    w.set_defaults(func=cmd_wp)


def main(argv=None) -> int:
    """``python -m flowsheets.cli run FILE ...``: the same commands without the millfmu CLI."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m flowsheets.cli")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    register(sub)
    args = p.parse_args(["flowsheet"] + list(sys.argv[1:] if argv is None else argv))
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
