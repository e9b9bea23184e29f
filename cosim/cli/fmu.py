"""`cosim fmu`: inspect, validate, locate, build and simulate FMUs (project FMUs by name, any FMU
by file)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    parser = subparsers.add_parser("fmu", help="inspect, validate, locate, build and simulate FMUs")
    actions = parser.add_subparsers(dest="fmu_command", required=True, metavar="ACTION")

    info = actions.add_parser(
        "info", help="model, GUID and every variable (causality, unit, start) of an FMU"
    )
    info.add_argument("fmu", metavar="FILE|NAME", help="an .fmu file (FMI 2.0 or 3.0) or a project FMU name")
    _fmi_option(info)
    info.set_defaults(handler=_info)

    validate = actions.add_parser(
        "validate", help="check an FMU: description, binary, exported FMI functions"
    )
    validate.add_argument(
        "fmu", metavar="FILE|NAME", help="an .fmu file (FMI 2.0 or 3.0) or a project FMU name"
    )
    _fmi_option(validate)
    validate.set_defaults(handler=_validate)

    path = actions.add_parser(
        "path", help="print the path of a project FMU's built .fmu (builds it if needed)"
    )
    path.add_argument("name", metavar="NAME", help="project FMU name, e.g. DifferentialDrive")
    _fmi_option(path)
    path.set_defaults(handler=_path)

    build = actions.add_parser("build", help="build every project FMU (FMI 2.0 and 3.0) and print the paths")
    build.add_argument(
        "--fmi", type=int, choices=(2, 3), default=None, help="build only this FMI version (default: both)"
    )
    build.set_defaults(handler=_build)

    simulate = actions.add_parser(
        "simulate",
        help="run one FMU alone (as fmpy simulate): log every input and output, optionally a CSV",
        description="Run one FMU alone from its start to its stop time, as fmpy simulate and fmusim "
        "do: every input and output goes to the MCAP log (/signals/<model>); --csv writes time and "
        "every output. Exit 0 when the run reaches its stop time or the FMU ends it, 1 interrupted, "
        "2 bad input or a failed FMU.",
    )
    simulate.add_argument(
        "fmu", metavar="FILE|NAME", help="an .fmu file (FMI 1.0, 2.0 or 3.0) or a project FMU name"
    )
    _fmi_option(simulate)
    simulate.add_argument(
        "--start-time",
        type=float,
        metavar="S",
        help="start time [s] (default: DefaultExperiment startTime, else 0)",
    )
    simulate.add_argument(
        "--stop-time",
        type=float,
        metavar="S",
        help="stop time [s] (default: DefaultExperiment stopTime, else 1 s after the start)",
    )
    simulate.add_argument(
        "--step",
        type=float,
        metavar="H",
        help="communication step [s] (default: DefaultExperiment stepSize, else the power of ten "
        "nearest to a thousandth of the run, as fmpy: 0.001 s for a 1 s run)",
    )
    simulate.add_argument(
        "--start-values",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="parameters and inputs, by FMU variable name, e.g. x0=1.5 v=0.2 (a number or true/false; "
        "text for a String, hex for a Binary); "
        "an input keeps its value for the whole run, the others their start values",
    )
    simulate.add_argument(
        "--interface",
        choices=("cs", "me"),
        help="co-simulation or Model Exchange (default: cs when the FMU has it)",
    )
    simulate.add_argument(
        "--solver",
        choices=("cvode", "rk4", "euler"),
        help="the Model Exchange integrator (with --interface me; default cvode)",
    )
    simulate.add_argument(
        "--tolerance",
        type=float,
        metavar="RTOL",
        help="CVode's relative tolerance (default: DefaultExperiment tolerance, else 1e-5, as fmpy)",
    )
    simulate.add_argument(
        "--max-step",
        type=float,
        metavar="S",
        help="the solver's largest step [s] (default: unbounded for cvode, one --step for rk4 and euler)",
    )
    simulate.add_argument(
        "--out", type=Path, metavar="LOG", help="log file (default: logs/<model>-<timestamp>.mcap)"
    )
    simulate.add_argument("--csv", type=Path, metavar="FILE", help="also write time and every output as CSV")
    simulate.add_argument("--force", action="store_true", help="overwrite --out and --csv if they exist")
    simulate.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    simulate.set_defaults(handler=_simulate)


def _fmi_option(parser) -> None:
    parser.add_argument(
        "--fmi",
        type=int,
        choices=(2, 3),
        default=2,
        help="FMI version of a project FMU given by name (default 2; 3: arrays as FMI 3.0 array variables)",
    )


def _info(args: argparse.Namespace) -> int:
    from cosim.fmi.inspect import format_info, resolve

    print(format_info(resolve(args.fmu, args.fmi)))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from cosim.fmi.inspect import resolve, validate

    path = resolve(args.fmu, args.fmi)
    problems = validate(path)
    if not problems:
        print(f"{path}: valid")
        return 0
    print(f"{path}: {len(problems)} problem(s)")
    for problem in problems:
        print(f"  - {problem}")
    return 1


def _path(args: argparse.Namespace) -> int:
    from cosim.fmi.builtin import builtin_fmu

    print(builtin_fmu(args.name, args.fmi))
    return 0


def _build(args: argparse.Namespace) -> int:
    from cosim.fmi.builtin import build_all

    for path in build_all((2, 3) if args.fmi is None else (args.fmi,)):
        print(path)
    return 0


def _simulate(args: argparse.Namespace) -> int:
    import sys

    from cosim.fmi.inspect import resolve
    from cosim.ssp.simulate import parse_start_values, prepare, simulate, summary

    simulation = prepare(
        resolve(args.fmu, args.fmi),
        stop_time=args.stop_time,
        step=args.step,
        start_time=args.start_time,
        start_values=parse_start_values(args.start_values),
        interface=args.interface,
        solver=args.solver,
        tolerance=args.tolerance,
        max_step=args.max_step,
    )
    result = simulate(simulation, args.out, args.csv, progress=not args.quiet, force=args.force)
    if not args.quiet:
        print(summary(result))
    if result.failure is not None:
        print(f"cosim: error: {result.failure}; log (up to the failure): {result.log_path}", file=sys.stderr)
    return result.exit_code
