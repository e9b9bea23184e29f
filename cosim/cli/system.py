"""`cosim system SCENARIO`: print the expanded system (components, connections, step order).

What runs is the navigation template plus the scenario's `[components.NAME]` and `[[connections]]`
(`cosim.scenario.compose.describe_system`); this prints it: each component with its FMU, FMI
version and rate, each connection with its scale and offset and who declared it (connections
between elements of two arrays are folded into one line, e.g. `lidar.ranges[1..360] ->
vfh.ranges[1..360]`), the template connections the scenario replaced, the template components it
removed (`[system] remove`) or replaced (`[components.NAME]` of a template name) with the template
connections dropped with them, the order in which the master steps the components, what the run
reads besides the recording (robot pose, command, avoidance mode, scan), and the inputs that no
connection feeds with the values they keep (start values, as FMI defines, or held ones). `--png FILE` draws
the wiring as a block diagram.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from cosim.cli.wiring import fold, unconnected_lines
from cosim.cli.wiring import number_text as _number
from cosim.cli.wiring import table_lines as _table
from cosim.scenario.description import SystemDescription


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "system",
        help="print the expanded system of a scenario: components, connections, step order",
        description="Print the system a scenario runs (the navigation template plus its own "
        "[components.*] and [[connections]]): each component's FMU, FMI version and rate, each "
        "connection with scale and offset, and the step order.",
    )
    parser.add_argument("scenario", type=Path, help="scenario file (.toml) or SSP archive (.ssp)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key, as for cosim run (repeatable)",
    )
    parser.add_argument("--png", type=Path, metavar="FILE", help="also draw the wiring as a block diagram")
    parser.add_argument("--force", action="store_true", help="overwrite --png if it exists")
    parser.set_defaults(handler=_handler)


def _handler(args) -> int:
    from cosim.errors import file_kind
    from cosim.record.output import checked_output
    from cosim.scenario.load import load_scenario

    if args.png is not None:
        checked_output(args.png, args.force)
    if args.scenario.suffix.lower() == ".ssp" or file_kind(args.scenario) == "ssp":
        from cosim.cli.system_ssp import show_ssp

        return show_ssp(args, show_scenario)
    scenario = load_scenario(args.scenario, args.overrides, fleet=True)
    if hasattr(scenario, "robots"):  # a fleet ([[robots]])
        from cosim.cli.system_fleet import show_fleet

        return show_fleet(args, scenario, format_system)
    return show_scenario(args, scenario, f"{scenario.name} ({scenario.source})")


def show_scenario(args, scenario, title: str, unpacked: Path | None = None) -> int:
    """Print (and with --png draw) the system `scenario` runs; files under `unpacked` (an SSP's
    temporary folder) are named by their archive member."""
    from cosim.navigation.build import build_run
    from cosim.record.output import atomic_output

    built = build_run(scenario)  # the system that `cosim run` steps, not initialised
    order = [component.name for component in built.system.order()]
    constant = {name for name, component in built.system.components.items() if component.constant_outputs}
    description = built.description
    if unpacked is not None:
        description = replace(
            description, components={name: _member(c, unpacked) for name, c in description.components.items()}
        )
    text = format_system(description, order, constant, title)
    print("\n".join([text, *unconnected_lines(built.system, description)]))
    if args.png is not None:
        from cosim.cli.system_plot import draw_system

        with atomic_output(args.png, args.force) as temporary:
            draw_system(built.description, order, temporary, title=scenario.name)
        print(f"block diagram: {args.png}")
    return 0


def _member(component, unpacked: Path):
    """`component` with its FMU named by its path inside the archive unpacked at `unpacked`."""
    if component.fmu is None or not component.fmu.is_relative_to(unpacked):
        return component
    return replace(component, fmu=component.fmu.relative_to(unpacked))


def _rate(rate: float | None, macro_step: float) -> str:
    if rate is None:
        return f"{1 / macro_step:g} Hz (every step)"
    steps = round(1.0 / (rate * macro_step))
    return f"{rate:g} Hz (every {steps} steps)" if steps > 1 else f"{rate:g} Hz (every step)"


def format_system(description: SystemDescription, order: list[str], constant: set[str], title: str) -> str:
    """The text `cosim system` prints."""
    lines = [
        f"system of {title}",
        f"macro step {_number(description.macro_step)} s, master {description.master}",
        "",
        f"components ({len(description.components)})",
    ]
    rows = [("name", "FMU", "FMI", "rate", "declared in")]
    for component in description.components.values():
        if component.kind == "fmu":
            fmu = f"{component.model_name} ({component.fmu})"
            version = f"{component.fmi_version}.0"
            if component.integration.interface == "me":
                version += f" ME {component.integration.solver}"
        else:
            fmu, version = f"Python {component.kind} (navcosim)", "-"
        rows.append(
            (component.name, fmu, version, _rate(component.rate, description.macro_step), component.where)
        )
    lines += _table(rows)
    links = fold(description.connections)
    lines += ["", f"connections ({len(description.connections)}; input = output * scale + offset)"]
    rows = [("from", "to", "scale", "offset", "declared in")]
    for link in links:
        count = f" ({link.count} connections)" if link.count > 1 else ""
        rows.append((link.source, link.target, _number(link.scale), _number(link.offset), link.where + count))
    lines += _table(rows)
    if description.replaced:
        lines += ["", "template connections replaced by the scenario's"]
        rows = [
            (old.source, "->", old.target, "replaced by", new.where, f"(from {new.source})")
            for old, new in description.replaced
        ]
        lines += _table(rows)
    if description.removed:
        lines += ["", f"template components removed ([system].remove): {', '.join(description.removed)}"]
    if description.replacing:
        replacing = ", ".join(f"{name} (by [components.{name}])" for name in description.replacing)
        lines += ["", f"template components replaced: {replacing}"]
    if description.dropped:
        # Fold with the reason as the "declared in" column: runs of array elements share it.
        dropped = [replace(connection, where=why) for connection, why in description.dropped]
        lines += ["", f"template connections dropped with them ({len(dropped)})"]
        rows = [("from", "to", "why")]
        for link in fold(dropped):
            count = f" ({link.count} connections)" if link.count > 1 else ""
            rows.append((link.source, link.target, link.where + count))
        lines += _table(rows)
    if description.loop:
        lines += [
            "",
            f"algebraic loop: {' -> '.join(description.loop)}",
            f"  handled by {'iteration' if description.algebraic_loops == 'iterate' else 'delay'} "
            f'(simulation.algebraic_loops = "{description.algebraic_loops}"): the loop\'s components '
            + (
                "iterate to a fixed point within each macro step, rolled back with their FMU state"
                if description.algebraic_loops == "iterate"
                else "step with their inputs from the previous communication point"
            ),
        ]
    lines += ["", f"step order ({description.master})"]
    for position, name in enumerate(order, start=1):
        note = "  (outputs fixed after initialisation: not stepped)" if name in constant else ""
        lines.append(f"  {position}. {name}{note}")
    observed = description.observed
    if observed is not None:
        lines += ["", f"robot pose for the outcome and /odom: {', '.join(observed.pose)}"]
        command = ", ".join(observed.command) if observed.command else "none (no /cmd_vel; /odom twist NaN)"
        lines.append(f"command for /cmd_vel and the /odom twist: {command}")
        mode = observed.mode or "none (the VFH counts of the outcome stay 0)"
        lines.append(f"avoidance mode for the outcome: {mode}")
        scan = f"{observed.scan.component}.ranges" if observed.scan else "none (no /scan)"
        lines.append(f"scan for /scan: {scan}")
    return "\n".join(lines)
