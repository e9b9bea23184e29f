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
    info.set_defaults(handler=_info)

    validate = actions.add_parser(
        "validate", help="check an FMU: description, binary, exported FMI functions"
    )
    validate.add_argument(
        "fmu", metavar="FILE|NAME", help="an .fmu file (FMI 2.0 or 3.0) or a project FMU name"
    )
    validate.set_defaults(handler=_validate)

    path = actions.add_parser(
        "path", help="print the path of a project FMU's built .fmu (builds it if needed)"
    )
    path.add_argument("name", metavar="NAME", help="project FMU name, e.g. DifferentialDrive")
    path.set_defaults(handler=_path)

    build = actions.add_parser("build", help="build every project FMU and print the paths")
    build.set_defaults(handler=_build)


def _info(args: argparse.Namespace) -> int:
    from cosim.fmi.inspect import format_info, resolve

    print(format_info(resolve(args.fmu)))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from cosim.fmi.inspect import resolve, validate

    path = resolve(args.fmu)
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

    print(builtin_fmu(args.name))
    return 0


def _build(args: argparse.Namespace) -> int:
    from cosim.fmi.builtin import build_all

    for path in build_all():
        print(path)
    return 0
