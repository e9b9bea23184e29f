"""`cosim fmu`: inspect, validate, locate and build FMUs (project FMUs by name, any FMU by file)."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser("fmu", help="inspect, validate, locate and build FMUs")
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
