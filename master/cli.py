"""Command line: `master run|validate|info|plot|build-fmus ...` (argument parsing only)."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

from master import __version__
from master.backends import BACKENDS

SHOWN_FAILURES = 10  # failed cases a sweep lists by name; the table has them all


def _user_errors() -> tuple[type[BaseException], ...]:
    """The errors that are bad input: one line, exit code 1. Imported only once a command runs:
    `master --version` and `--help` load none of the machinery (numpy, fmpy, lxml)."""
    from master import api, extras
    from master.backends.component import SimulationError
    from master.fmu import FmuError
    from master.scenario import ScenarioError

    return (
        api.UsageError,
        extras.MissingExtra,
        FmuError,
        ScenarioError,
        SimulationError,
        FileNotFoundError,
        ValueError,
    )


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="master", description="Multirate FMI co-simulation master")
    p.add_argument("--version", action="version", version=f"master {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    r = sub.add_parser("run", help="run a scenario", description="Run a scenario and write its results.")
    r.add_argument("scenario", help="scenario file (.ssd or .ssp), or a folder holding one")
    _scene_options(r)
    _time_options(r, stop=False)  # --stop-time: in _scene_options
    r.add_argument(
        "-o",
        "--output",
        metavar="CSV",
        help="results file, .csv (default: results/SCENE-DATE-TIME.csv)",
    )
    g = r.add_mutually_exclusive_group()
    g.add_argument("--serial", dest="backend", action="store_const", const="serial", help="serial backend")
    g.add_argument(
        "--parallel", dest="backend", action="store_const", const="parallel", help="parallel backend"
    )
    g.add_argument(
        "--in-process",
        dest="backend",
        action="store_const",
        const="in-process",
        help="run the FMUs inside this process: no worker, but an FMU that crashes takes the "
        "master down with it and a hang is not detected (for debugging)",
    )
    g.add_argument(
        "--backend",
        dest="backend",
        choices=BACKENDS,
        help="backend by name (default: auto, chosen by timing)",
    )
    r.add_argument(
        "--step-timeout",
        type=float,
        metavar="S",
        help="a macro step of one component taking longer than this is a hang (s, default 10)",
    )
    r.add_argument(
        "--cpus",
        type=_cpu_list,
        metavar="LIST",
        help="pin the workers to these processors, e.g. 2,3 or 2-5 (worker w on the w-th, cyclically)",
    )
    r.add_argument("--plot", metavar="PNG", help="plot the recorded variables into this file")
    r.add_argument(
        "--record-coupling-errors",
        action="store_true",
        help="also record, per extrapolated connection, its latest coupling error estimate as a column "
        '"coupling_error(source.output -> consumer.input)" (the prediction of the sample one macro step '
        "before the row, in the signal's unit)",
    )
    r.add_argument(
        "--real-time",
        nargs="?",
        const=1.0,
        type=_positive,
        metavar="FACTOR",
        help="pace the run to the wall clock (FACTOR > 1: faster than real time); workers then ask for "
        "SCHED_FIFO and locked memory (a note says where not permitted)",
    )
    r.add_argument(
        "--progress", action="store_true", help="show a progress bar even when stderr is not a tty"
    )
    r.add_argument("-q", "--quiet", action="store_true", help="print errors only")

    v = sub.add_parser("validate", help="check a scenario file", description="Check a scenario file.")
    v.add_argument("scenario")
    _time_options(v)

    i = sub.add_parser(
        "info", help="describe an FMU or a scenario", description="Variables, capabilities, schedule."
    )
    i.add_argument("path", help=".fmu or scenario file")
    _time_options(i)

    pl = sub.add_parser("plot", help="plot a results CSV file", description="Plot a results CSV file.")
    pl.add_argument("csv")
    pl.add_argument("-o", "--output", metavar="PNG", help="image file (default: CSV name with .png)")
    pl.add_argument("--record", action="append", metavar="COMP.VAR", help="plot only these columns")

    _sweep_parser(sub)

    t = sub.add_parser(
        "tune",
        help="find the fastest configuration within an error tolerance",
        description="Search macro step, step ratios, extrapolation orders, coupling and solvers for the "
        "fastest configuration whose error (against the reference solution, relative to each variable's "
        "range) stays within TOL; write it as a new scenario beside the original with a report.",
    )
    t.add_argument("scenario", help="scenario file (.ssd / .ssp)")
    t.add_argument("--tolerance", required=True, type=_positive, metavar="TOL",
                   help="largest error allowed, relative to each variable's range (e.g. 1e-3)")  # fmt: skip
    t.add_argument("--real-time-budget", type=_positive, metavar="F",
                   help="wall seconds allowed per simulated second (1: real time)")  # fmt: skip
    t.add_argument("--pilot-time", metavar="T", help="simulated s of each pilot run (default: the stop time)")
    t.add_argument("--repeats", type=int, default=3,
                   help="interleaved timings of the two cheapest, at least (3 or more)")  # fmt: skip
    t.add_argument("--rounds", type=int, default=None, metavar="N",
                   help="rounds of coordinate search at most (default 12; fewer: quicker)")  # fmt: skip
    t.add_argument("-o", "--out", metavar="FILE",
                   help="tuned scenario (default: beside the original, NAME.tuned.ssd / .ssp)")  # fmt: skip

    e = sub.add_parser(
        "examples",
        help="copy the example scenes into a folder",
        description="Copy the paper's two scenes and the two-mass oscillator into DIR, each with its files.",
    )
    e.add_argument("dir", nargs="?", default="master-examples", metavar="DIR", help="(master-examples)")
    e.add_argument("--force", action="store_true", help="overwrite files that exist")

    b = sub.add_parser("build-fmus", help="build the project's FMUs", add_help=False)
    b.add_argument("args", nargs=argparse.REMAINDER)

    be = sub.add_parser("bench", help="work-precision bench of a scenario", add_help=False)
    be.add_argument("args", nargs=argparse.REMAINDER)
    p.commands = sub.choices  # type: ignore[attr-defined]  # name -> its parser, for _parse
    return p


def _time_options(p: argparse.ArgumentParser, stop: bool = True) -> None:
    """The times a scenario file may lack (one written by another tool): run, validate, info."""
    if stop:
        p.add_argument("--stop-time", metavar="T", help="stop time in s (overrides the scenario)")
    p.add_argument("--macro-step", metavar="H", help="macro step in s (overrides the scenario)")


def _scene_options(p: argparse.ArgumentParser) -> None:
    """What `run` and `sweep` change of the scenario, alike."""
    p.add_argument("--stop-time", metavar="T", help="stop time in s (overrides the scenario)")
    p.add_argument("--record", action="append", metavar="COMP.VAR", help="record this variable (repeatable)")
    p.add_argument("--set", action="append", metavar="COMP.VAR=VALUE", help="set a parameter (repeatable)")
    p.add_argument("--output-interval", metavar="DT", help="time between recorded rows in s")


def _sweep_parser(sub) -> None:
    s = sub.add_parser(
        "sweep",
        help="run a scenario over many parameter values (Dask)",
        description="Run a scenario once per case on a Dask cluster (local, or --scheduler) and write "
        "DIR/cases.parquet: per case the varied values, status, message, wall time, final/min/max of "
        "every recorded column and the metrics. A rerun skips the cases already in DIR.",
    )
    s.add_argument("scenario", help="scenario file (.ssd or .ssp)")
    s.add_argument(
        "--vary",
        action="append",
        required=True,
        metavar="COMP.VAR=START:STOP:N",
        help="a parameter (or the height of a one-point step stimulus) from START to STOP: N values "
        "for a grid, START:STOP for lhs/sobol (repeatable)",
    )
    s.add_argument(
        "--method", choices=("grid", "lhs", "sobol"), default="grid", help="grid (default), lhs, sobol"
    )
    s.add_argument("--samples", type=int, metavar="N", help="points drawn by lhs or sobol")
    s.add_argument("--seed", type=int, metavar="S", help="seed of lhs/sobol (the same seed, the same points)")
    s.add_argument(
        "--metric",
        action="append",
        metavar="NAME=EXPR",
        help="a number per case from the recorded columns, e.g. peak=max(abs(mass1.x)) (repeatable; "
        "functions: max min mean rms std final first integral at time_of_max abs sqrt exp log sin cos)",
    )
    s.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask cluster, e.g. tcp://host:8786")
    s.add_argument("--workers", type=int, metavar="N", help="local cluster size (default: the usable CPUs)")
    s.add_argument("--out", metavar="DIR", help="results folder (default: results/sweep-SCENE)")
    s.add_argument("--series", action="store_true", help="also keep every case's rows in DIR/series.zarr")
    s.add_argument("--plot", metavar="PNG", help="plot each metric against the varied parameters")
    _scene_options(s)
    _time_options(s, stop=False)
    s.add_argument("--step-timeout", type=float, metavar="S", help="a hang, per macro step of a case (s)")
    s.add_argument("--progress", action="store_true", help="show progress even when stderr is not a tty")
    s.add_argument("-q", "--quiet", action="store_true", help="print errors only")


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a positive number")
    return value


def _cpu_list(text: str) -> list[int]:
    """'2,3' or '2-5' or '0,4-6' -> processor numbers."""
    out: list[int] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.partition("-")
            out.extend(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected processor numbers like 2,3 or 2-5") from None
    return out


def _log_to_stderr(quiet: bool) -> None:
    """master's own messages on stderr, its notes (INFO) too unless quiet; other libraries' stay quiet."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log = logging.getLogger("master")
    log.addHandler(handler)
    log.setLevel(logging.WARNING if quiet else logging.INFO)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 failed run or bad input, 2 bad usage, 128 + n
    stopped by signal n: 129 SIGHUP, 130 SIGINT, 143 SIGTERM)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["build-fmus"]:
        from master.fmubuild import main as build_main

        return int(build_main(argv[1:], prog="master build-fmus") or 0)
    if argv[:1] == ["bench"]:
        from master import extras
        from master.evidence.bench import main as bench_main

        try:
            if not {"-h", "--help"} & set(argv):
                extras.require("bench")
        except extras.MissingExtra as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        _log_to_stderr(bool({"-q", "--quiet"} & set(argv)))
        return int(bench_main(argv[1:]) or 0)
    args = _parse(argv)  # --version and --help end here
    quiet = getattr(args, "quiet", False)
    _log_to_stderr(quiet)
    from master.backends.component import SimulationError

    user_errors = _user_errors()
    try:
        return _dispatch(args, quiet)
    except BrokenPipeError:  # e.g. `master info X | head -1`: the reader has gone, nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SimulationError as e:
        print(f"error: {e}", file=sys.stderr)
        signum = getattr(e, "signal", None)
        return 128 + signum if signum else 1  # the shell's convention: 130 SIGINT, 143 SIGTERM
    except user_errors as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def _parse(argv: list[str]) -> argparse.Namespace:
    """The parsed arguments; `master` alone prints the usage with the list of commands, and an
    unknown option is reported with the usage of the command it was given to."""
    p = _parser()
    if not argv:
        p.print_help(sys.stderr)
        sys.exit(2)
    args, unknown = p.parse_known_args(argv)
    if unknown:
        import difflib

        sub = p.commands[args.command]  # type: ignore[attr-defined]
        known = [o for a in sub._actions for o in a.option_strings]
        close = difflib.get_close_matches(unknown[0].split("=")[0], known, n=1)
        hint = f" (did you mean {close[0]}?)" if close and unknown[0].startswith("-") else ""
        sub.error(f"unrecognized arguments: {' '.join(unknown)}{hint}")
    return args


def _default_output(scenario: str) -> Path:
    """results/<scene>-<date>-<time>.csv: a run without -o still keeps what it computed."""
    return Path("results") / f"{scene_stem(scenario)}-{time.strftime('%Y%m%d-%H%M%S')}.csv"


def scene_stem(scenario: str) -> str:
    """How the files made from a scenario file are named: its stem (an .ssp: the archive's), but
    for the generic SystemStructure.ssd the name of its folder (models/hydraulic-manipulator/)."""
    path = Path(scenario)
    if path.name == "SystemStructure.ssd" and path.resolve().parent.name:
        return path.resolve().parent.name
    return path.stem


def _dispatch(args: argparse.Namespace, quiet: bool) -> int:
    from master import api, extras
    from master.backends.component import SimulationError

    extras.require(args.command, vars(args))  # before any work: one line if an extra is missing
    if args.command == "run":
        progress = args.progress or (sys.stderr.isatty() and not quiet)
        output = Path(args.output) if args.output else _default_output(args.scenario)
        if output.suffix.lower() != ".csv":
            raise api.UsageError(f"-o {output}: results are written as CSV; name a .csv file")
        try:
            result = api.run(
                args.scenario,
                stop_time=args.stop_time,
                macro_step=args.macro_step,
                output=output,
                record=args.record,
                set_values=args.set,
                output_interval=args.output_interval,
                backend=args.backend or "auto",
                step_timeout=args.step_timeout,
                real_time=args.real_time,
                progress=progress,
                plot=args.plot,
                cpus=args.cpus,
                record_coupling_errors=args.record_coupling_errors,
            )
        except SimulationError as e:
            res = getattr(e, "result", None)
            if res is not None and not quiet:
                print(res.summary, file=sys.stderr)
            raise
        if not quiet:
            print(result.summary)
            if args.plot:
                print(f"  plot written to {args.plot}")
        return 0
    if args.command == "sweep":
        return _sweep(args, quiet)
    if args.command == "tune":
        return _tune(args, quiet)
    if args.command == "examples":
        from master.examples import main as examples_main

        return examples_main(args.dir, args.force)
    if args.command == "validate":
        problems = api.validate(args.scenario, args.stop_time, args.macro_step)
        for pr in problems:
            print(pr)
        if not problems:
            print(f"{args.scenario}: ok")
            for note in api.loop_notes(args.scenario, args.stop_time, args.macro_step):
                print(f"  note: {note}")
        return 1 if problems else 0
    if args.command == "info":
        print(api.info(args.path, args.stop_time, args.macro_step))
        return 0
    if args.command == "plot":
        from master.recorder import number_columns, plot_result, read_csv

        csv = Path(args.csv)
        if not csv.is_file():
            raise api.UsageError(f"{csv}: no such results file")
        try:
            data = read_csv(str(csv))
        except (ValueError, IndexError, UnicodeDecodeError) as e:
            raise api.UsageError(f"{csv}: not a results CSV file ({e})") from None
        if not data.dtype.names or "time" not in data.dtype.names:
            raise api.UsageError(f"{csv}: not a results CSV file (no 'time' column)")
        if args.record:
            missing = [r for r in args.record if r not in data.dtype.names]
            if missing:
                raise api.UsageError(
                    f"{csv}: no column {missing[0]!r}; columns: {', '.join(data.dtype.names)}"
                )
            text = [r for r in args.record if r != "time" and r not in number_columns(data)]
            if text:
                raise api.UsageError(f"{csv}: column {text[0]!r} holds text, not numbers to plot")
        png = Path(args.output) if args.output else csv.with_suffix(".png")
        units, title = None, csv.name
        try:  # the run's metadata beside the CSV: each column's unit (a panel per unit), the scene's name
            meta = json.loads(api.metadata_path(csv).read_text())
            units, title = meta.get("units"), str(meta.get("summary", {}).get("scenario") or title)
        except (OSError, ValueError, AttributeError):
            pass
        units = units if isinstance(units, dict) else None
        plot_result(data, png, title=title, columns=args.record, units=units)
        print(f"wrote {png}")
        return 0
    raise api.UsageError(f"unknown command {args.command}")


def _tune(args: argparse.Namespace, quiet: bool) -> int:
    from master import api, tune
    from master.scenario.writer import write_settings

    sc = api.load_scenario(Path(args.scenario))
    source = sc.path  # a folder's scenario file
    out = Path(args.out) if args.out else source.with_name(f"{source.stem}.tuned{source.suffix}")
    if out.resolve() == source.resolve() or out.suffix != source.suffix:
        raise api.UsageError(f"--out {out}: a new {source.suffix} file, not the original")
    if args.repeats < 1:
        raise api.UsageError(f"--repeats {args.repeats}: at least 1")
    if args.rounds is not None and args.rounds < 0:
        raise api.UsageError(f"--rounds {args.rounds}: 0 or more")
    pilot = api._parse_time("--pilot-time", args.pilot_time) if args.pilot_time else None
    rounds = tune.ROUNDS if args.rounds is None else args.rounds
    result = tune.tune(sc, args.tolerance, args.real_time_budget, pilot, args.repeats, rounds)
    report = out.with_suffix(".txt")
    report.write_text(tune.report(result) + "\n")
    if not quiet:  # the detail is in the report
        print(tune.summary(result, report))
    if result.best is None:
        print(f"error: no configuration tried meets {args.tolerance:g}; report: {report}", file=sys.stderr)
        return 1
    if not result.within_budget:
        print(f"error: the fastest configuration within {args.tolerance:g} needs more than "
              f"{args.real_time_budget:g} s per simulated s; report: {report}", file=sys.stderr)  # fmt: skip
        return 1
    write_settings(sc, tune.tuned_scenario(result), out, f"tuned by master tune to {args.tolerance:g}: "
                   f"{result.best.family}")  # fmt: skip
    if not quiet:
        print(f"wrote {out}")
    return 0


def _sweep(args: argparse.Namespace, quiet: bool) -> int:
    from master.sweeps import sweep

    out = Path(args.out) if args.out else Path("results") / f"sweep-{scene_stem(args.scenario)}"
    try:
        result = sweep(
            args.scenario,
            args.vary,
            method=args.method,
            samples=args.samples,
            seed=args.seed,
            metrics=args.metric,
            out=out,
            series=args.series,
            scheduler=args.scheduler,
            workers=args.workers,
            stop_time=args.stop_time,
            macro_step=args.macro_step,
            set_values=args.set,
            record=args.record,
            output_interval=args.output_interval,
            step_timeout=args.step_timeout,
            progress=args.progress or (sys.stderr.isatty() and not quiet),
        )
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM / SIGHUP (driver.Interrupted has .signum)
        print(
            f"interrupted: the cases finished so far are in {out}; the same command goes on", file=sys.stderr
        )
        return 128 + getattr(e, "signum", signal.SIGINT)
    if args.plot:
        from master.sweeps.plot import plot_sweep

        plot_sweep(result, args.plot, title=f"{result.scene}: {len(result.rows)} cases")
    if not quiet:
        print(
            f"{len(result.rows)} cases: {result.ran} run ({result.failed} failed), {result.skipped} done "
            f"earlier; {out / 'cases.parquet'}" + (f", {out / 'series.zarr'}" if args.series else "")
        )
        failed = [row for row in result.rows if row["status"] != "ok"]
        for row in failed[:SHOWN_FAILURES]:
            print(f"  case {row['index']} {row['status']}: {row['message']}")
        if len(failed) > SHOWN_FAILURES:
            print(f"  ... and {len(failed) - SHOWN_FAILURES} more: see the status column")
        if args.plot:
            print(f"  plot written to {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
