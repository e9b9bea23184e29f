"""`cosim ssp export SCENARIO --out X.ssp`: write a scenario's whole system as an SSP 1.0 archive.

The FMUs go in `resources/`, their parameters in `resources/parameters.ssv` and in each component's
own binding, the units in `<ssd:Units>` (`cosim.ssp.write`), the navigation parts
(planner, lidar, world, outcome settings) in a navcosim annotation with the scenario TOML and its
map as resources (`cosim.ssp.export`). `cosim run X.ssp` reproduces the scenario's run.
"""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "ssp",
        help="SSP 1.0 archives: export a scenario (cosim run runs any .ssp)",
        description="System Structure and Parameterization (SSP 1.0) archives.",
    )
    actions = parser.add_subparsers(dest="ssp_command", required=True, metavar="ACTION")
    export = actions.add_parser(
        "export",
        help="write a scenario's whole system as an .ssp archive",
        description="Write the scenario's FMUs, parameters, connections and navigation parts as an SSP.",
    )
    export.add_argument("scenario", type=Path, help="scenario file (.toml)")
    export.add_argument("--out", type=Path, required=True, help="the .ssp archive to write")
    export.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    export.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key before exporting, as for cosim run (repeatable)",
    )
    export.set_defaults(handler=_export)


def _export(args) -> int:
    from cosim.record.output import atomic_output, checked_output
    from cosim.scenario.load import load_scenario
    from cosim.ssp.export import export_scenario

    checked_output(args.out, args.force)  # before the work, not only after it
    scenario = load_scenario(args.scenario, args.overrides)
    with atomic_output(args.out, args.force) as temporary:
        export_scenario(scenario, temporary)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e3:.0f} kB)")
    return 0
