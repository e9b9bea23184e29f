"""`cosim system X.ssp`: the system an SSP archive runs, as `cosim run X.ssp` builds it.

An SSP that navcosim exported from a scenario runs as that scenario: its system is printed as for
the scenario (`cosim.cli.system.format_system`). Any other SSP runs its FMUs and connections on
the master: this prints each component (its SSP path, archive member, FMI version, interface and
period), each connection with its factor and offset, the macro step with where it comes from, and
the step order. `--set` takes the `[simulation]` keys `cosim run X.ssp` takes.
"""

from __future__ import annotations

from cosim.errors import CosimError


def show_ssp(args, show_scenario) -> int:
    """Print the SSP's system; an exported scenario's through `show_scenario` (cosim.cli.system's)."""
    from cosim.errors import PATH_LIMIT, shorten
    from cosim.ssp.run import named

    try:
        return _show_ssp(args, show_scenario)
    except CosimError as error:  # every SSP error line starts with the archive's name
        raise named(shorten(args.scenario, PATH_LIMIT), error) from None


def _show_ssp(args, show_scenario) -> int:
    from cosim.ssp import export
    from cosim.ssp.read import build_system, open_ssp
    from cosim.ssp.run import experiment, max_unpacked_size, parse_overrides

    values = parse_overrides(args.overrides)
    with open_ssp(args.scenario, max_unpacked_size(values)) as ssp:
        if export.SCENARIO_ANNOTATION in ssp.annotations:
            scenario = export.scenario_of(ssp, values)
            title = f"{scenario.name} (exported scenario in {ssp.source})"
            return show_scenario(args, scenario, title, unpacked=ssp.directory)
        if args.png is not None:
            raise CosimError(
                f"{ssp.source}: --png draws a scenario's block diagram; this SSP holds no scenario"
            )
        run = experiment(ssp, values)
        system, _ = build_system(ssp, run.macro_step, run.master)
        system.handle_loops(run.loops, run.loop_tolerance, run.loop_max_iterations)
        order = [component.name for component in system.order()]
        print(format_ssp_system(ssp, run, system, order))
    return 0


def format_ssp_system(ssp, run, system, order: list[str]) -> str:
    from cosim.cli.wiring import number_text as _number
    from cosim.cli.wiring import table_lines as _table
    from cosim.cli.wiring import unconnected_lines

    lines = [
        f"system of {ssp.name} ({ssp.source}, SSP {ssp.version})",
        f"macro step {_number(run.macro_step)} s ({run.macro_step_source}), master {run.master}",
        "",
        f"components ({len(ssp.components)})",
    ]
    rows = [("name", "SSP element", "FMU", "FMI", "interface", "period")]
    for spec in ssp.components:
        component = system.components[spec.name]
        version = component.describe().get("fmi_version", "")
        period = f"{_number(spec.period)} s" if spec.period else "every step"
        interface = "co-simulation" if spec.interface == "cs" else "model exchange"
        rows.append((spec.name, spec.path, spec.member, version, interface, period))
    lines += _table(rows)
    lines += ["", f"connections ({len(ssp.connections)}; input = output * factor + offset)"]
    if ssp.connections:
        rows = [("from", "to", "factor", "offset")]
        for link in ssp.connections:
            rows.append((link.source, link.target, _number(link.factor), _number(link.offset)))
        lines += _table(rows)
    if system.loop_components():
        lines += ["", f"algebraic loop: {' -> '.join(system.algebraic_loop())}"]
        lines.append(
            f"  handled by {'iteration' if system.loops == 'iterate' else 'delay'} "
            f'(simulation.algebraic_loops = "{system.loops}"): {", ".join(system.loop_components())} '
            + (
                "iterate to a fixed point within each macro step, rolled back with their FMU state"
                if system.loops == "iterate"
                else "step with their inputs from the previous communication point"
            )
        )
    lines += ["", f"step order ({run.master})"]
    lines += [f"  {position}. {name}" for position, name in enumerate(order, start=1)]
    return "\n".join(lines + unconnected_lines(system))
