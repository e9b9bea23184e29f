"""A scenario as a checked system description: the navigation template plus the scenario's own parts.

`describe_system(scenario)` takes the template's components and connections
(`cosim.scenario.template`), adds `[components.NAME]` and `[[connections]]` (a connection into an
input the template feeds replaces the template's), reads every FMU's interface from its
modelDescription.xml, and checks the whole system. It reports every problem at once: one
`CosimError` with one line per problem, each naming the file and the key, with a "did you mean"
where a name is close to a known one:

- an FMU that does not load; a `ports` key that is no port of the role; a port mapped to a variable
  the FMU lacks; the ports the template connects that the FMU does not have (all of them, with
  the FMU's own variable names);
- a parameter the FMU lacks, or one outside the FMU's declared min/max or of the wrong type;
- a connection end that is no `component.variable`, an unknown component or variable, an output
  wired to an output (or from an input), two connections into one input;
- an input of an added component that is neither connected nor held at a value;
- a rate that is not a whole number of macro steps;
- an algebraic loop (Gauss-Seidel only), naming its components.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from cosim.core.component import closest_names
from cosim.core.master import find_algebraic_loop
from cosim.errors import CosimError
from cosim.scenario.description import (
    TEMPLATE,
    ComponentDescription,
    ConnectionDescription,
    SystemDescription,
)
from cosim.scenario.load import ComponentSpec, Scenario, rate_problem
from cosim.scenario.schema import did_you_mean
from cosim.scenario.template import (
    ROLE_PORTS,
    template_components,
    template_connections,
    template_observed,
)

_LISTED = 12  # names listed in one message before "(and N more)"


class Problems:
    """The problems found so far, each "where: what"; `check()` raises them as one `CosimError`."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.lines: list[str] = []

    def add(self, where: str, problem: str) -> None:
        self.lines.append(f"{self.source}: {where}: {problem}")

    def check(self) -> None:
        if self.lines:
            raise CosimError("\n".join(self.lines))


def describe_system(scenario: Scenario) -> SystemDescription:
    """The system of `scenario`, checked; `CosimError` listing every problem (one per line)."""
    problems = Problems(scenario.source)
    template = template_connections(scenario)
    declared = template_components(scenario) + [
        _added(spec) for spec in scenario.components.values() if spec.added
    ]
    components: dict[str, ComponentDescription] = {}
    broken: set[str] = set()  # components whose FMU did not load: already reported
    for component in declared:
        if component.kind != "fmu":
            components[component.name] = component
            continue
        spec = scenario.components[component.name]
        described = _describe_fmu(
            spec, component, template, problems, scenario.fmi_version, scenario.fmu_max_size
        )
        if described is None:
            broken.add(component.name)
        else:
            components[component.name] = described
    for spec in scenario.components.values():  # the role sections' rates were checked on load
        problem = rate_problem(spec.rate, scenario.macro_step) if spec.added and spec.rate else None
        if problem:
            problems.add(f"{spec.where}.rate", problem)
    connections, replaced = _connections(scenario, components, broken, template, problems)
    _check_unconnected(components, connections, problems)
    if scenario.master == "gauss-seidel":
        _check_loops(components, connections, problems)
    problems.check()
    return SystemDescription(
        components=components,
        connections=tuple(connections),
        macro_step=scenario.macro_step,
        master=scenario.master,
        observed=template_observed(scenario),
        replaced=tuple(replaced),
    )


def _added(spec: ComponentSpec) -> ComponentDescription:
    return ComponentDescription(
        spec.name,
        "fmu",
        spec.where,
        rate=spec.rate,
        parameters={name: float(value) for name, value in spec.parameters.items()},
    )


def fmu_path(spec: ComponentSpec, fmi_version: int = 2) -> Path:
    """The .fmu file of a component: a project FMU is built on first use, in the scenario's
    `[simulation] fmi_version`."""
    from cosim.fmi.builtin import builtin_fmu

    return builtin_fmu(spec.fmu, fmi_version) if spec.is_builtin else Path(spec.fmu)


def _listing(names, around: str = "") -> str:
    names = list(names)
    return closest_names(around, names, limit=_LISTED) if names else "none"


def _describe_fmu(
    spec: ComponentSpec,
    component: ComponentDescription,
    template: list[ConnectionDescription],
    problems: Problems,
    fmi_version: int = 2,
    max_size: float = 1024.0,
) -> ComponentDescription | None:
    """Read the FMU's interface (through the port map); check the map and the parameters. The
    archive may unpack to `max_size` MiB ([simulation] fmu_max_size)."""
    from cosim.fmi.archive import MIB
    from cosim.fmi.component import FmuComponent

    where = component.where
    try:
        path = fmu_path(spec, fmi_version)
        plain = FmuComponent(path, component.name, max_unpacked_size=round(max_size * MIB))
    except CosimError as error:
        problems.add(f"{where}.fmu", str(error))
        return None
    description = plain.model_description
    variables = {variable.name: variable for variable in description.modelVariables}
    port_map = {}
    if component.port_map:
        ports = _role_ports(component, template)
        for port, mapping in component.port_map.items():
            if port not in ports:
                problems.add(
                    f"{where}.ports.{port}",
                    f"unknown port '{port}'{did_you_mean(port, ports)}; the ports of {where}: "
                    f"{_listing(sorted(ports), port)}",
                )
            elif mapping.variable not in variables:
                problems.add(
                    f"{where}.ports.{port}",
                    f"the FMU has no variable '{mapping.variable}' (mapped to port '{port}')"
                    f"{did_you_mean(mapping.variable, variables)}; variables: "
                    f"{_listing(variables, mapping.variable)}",
                )
            else:
                port_map[port] = mapping
    fmu = plain
    if port_map:
        mapped = {port: {"name": m.variable, "scale": m.scale} for port, m in port_map.items()}
        fmu = FmuComponent(path, component.name, port_map=mapped, max_unpacked_size=round(max_size * MIB))
    # A state output: its FMU declares no dependencies for it and the template says it is one.
    declared = {unknown.variable.name for unknown in description.outputs if unknown.dependencies is not None}
    feedthrough = {output: tuple(depends) for output, depends in fmu.feedthrough.items()}
    for port in component.state_outputs:
        variable = port_map[port].variable if port in port_map else port
        if port in feedthrough and variable not in declared:
            feedthrough[port] = ()
    described = replace(
        component,
        fmu=path,
        fmi_version=fmu.fmi_version,
        model_name=description.modelName or "",
        port_map=port_map,
        inputs=tuple(p.name for p in fmu.inputs),
        outputs=tuple(p.name for p in fmu.outputs),
        parameter_names=tuple(p.name for p in fmu.parameters),
        feedthrough=feedthrough,
    )
    return _check_parameters(described, spec, fmu, variables, problems)


def _role_ports(component: ComponentDescription, template: list[ConnectionDescription]) -> set[str]:
    """What a role's `ports` table may map: the role's ports (array ports by element too, as the
    template connects them) and the section's parameters."""
    ports = set(ROLE_PORTS.get(component.name, ())) | set(component.parameters)
    for connection in template:
        for reference in (connection.source, connection.target):
            name, _, port = reference.partition(".")
            if name == component.name:
                ports.add(port)
    return ports


def _check_parameters(
    component: ComponentDescription, spec: ComponentSpec, fmu, variables: dict, problems: Problems
) -> ComponentDescription:
    """Split the section's values into parameters and held inputs; check names, types, ranges."""
    where = component.where
    known = set(component.parameter_names)
    settable = known | (set(component.inputs) if spec.added else set())
    parameters, held = {}, {}
    for name, value in component.parameters.items():
        if name in component.required_parameters and name not in known:
            problems.add(
                where,
                f"the FMU has no parameter '{name}' for {component.required_parameters[name]}; map it with "
                f'ports = {{ {name} = "<variable>" }}; its parameters: {_listing(known, name)}',
            )
            continue
        if name not in settable:
            kind = "parameter or input" if spec.added else "parameter"
            problems.add(f"{where}.{name}", f"the FMU has no {kind} '{name}'{did_you_mean(name, settable)}")
            continue
        mapping = component.port_map.get(name)
        variable = variables[mapping.variable if mapping else name]
        problem = _value_problem(
            variable, value * (mapping.scale if mapping else 1.0), spec.parameters.get(name, value)
        )
        if problem:
            problems.add(f"{where}.{name}", problem)
        (parameters if name in known else held)[name] = value
    for name, value in component.defaults.items():
        if name in known:
            parameters[name] = value
    return replace(component, parameters=parameters, held_inputs=held, defaults={})


def _value_problem(variable, value: float, given) -> str | None:
    """Whether `value` (what the FMU receives) suits the variable's type and declared min/max."""
    kind = variable.type
    if kind in ("Integer", "Enumeration", "Int32", "Int64", "Int16", "Int8", "UInt8", "UInt16", "UInt32"):
        kind = "integer"
    elif kind == "Boolean":
        if value not in (0.0, 1.0):
            return f"must be true or false, got {given}"
        return None
    low = _bound(variable.min)
    high = _bound(variable.max)
    if kind == "integer":
        if isinstance(given, bool) or value != math.floor(value):
            return f"must be an integer, got {given}"
        if (low is not None and value < low) or (high is not None and value > high):
            return f"must be an integer in [{_text(low)}, {_text(high)}], got {given}"
        return None
    # Mapped through a scale, the FMU's bound is not the given value's: name both.
    got = f"got {given:g}" if float(given) == value else f"got {given:g} (the FMU receives {value:g})"
    if low is not None and value < low:
        return f"must be >= {low:g}, {got}"
    if high is not None and value > high:
        return f"must be <= {high:g}, {got}"
    return None


def _bound(text) -> float | None:
    try:
        bound = float(text)
    except (TypeError, ValueError):
        return None
    return bound if math.isfinite(bound) else None


def _text(bound: float | None) -> str:
    return "-inf" if bound is None else f"{bound:g}"


def _connections(
    scenario: Scenario,
    components: dict[str, ComponentDescription],
    broken: set[str],
    template: list[ConnectionDescription],
    problems: Problems,
) -> tuple[list[ConnectionDescription], list[tuple[ConnectionDescription, ConnectionDescription]]]:
    """The template's connections, minus those the scenario's replace, then the scenario's."""
    fed: dict[str, ConnectionDescription] = {}
    scenario_connections = []
    for spec in scenario.connections:
        source = _endpoint(spec.source, f"{spec.where}.from", "output", components, broken, problems)
        target = _endpoint(spec.target, f"{spec.where}.to", "input", components, broken, problems)
        if source is None or target is None:
            continue
        if target in fed:
            problems.add(
                f"{spec.where}.to",
                f"input '{target}' is already fed by {fed[target].where} (from '{fed[target].source}'); "
                "an input takes one connection",
            )
            continue
        connection = ConnectionDescription(source, target, spec.scale, spec.offset, spec.where)
        fed[target] = connection
        scenario_connections.append(connection)
    kept, replaced = [], []
    missing: dict[str, list[str]] = {}
    # Sets: the template connects thousands of ports (waypoints, beams).
    ports = {name: {"inputs": set(c.inputs), "outputs": set(c.outputs)} for name, c in components.items()}

    def has(reference: str, kind: str) -> bool:
        name, _, port = reference.partition(".")
        return name in broken or (name in ports and port in ports[name][kind])

    for connection in template:
        if connection.target in fed:
            replaced.append((connection, fed[connection.target]))
            continue
        ends = ((connection.source, "outputs"), (connection.target, "inputs"))
        absent = [reference for reference, kind in ends if not has(reference, kind)]
        for reference in absent:
            name, _, port = reference.partition(".")
            if name not in broken:
                missing.setdefault(name, []).append(port)
        if not absent:
            kept.append(connection)
    observed = template_observed(scenario)
    for _, reference in observed.references():
        name, _, port = reference.partition(".")
        if name not in broken and not has(reference, "outputs"):
            missing.setdefault(name, []).append(port)
    for name, ports in missing.items():
        _missing_ports(components[name], list(dict.fromkeys(ports)), problems)
    return kept + scenario_connections, replaced


def _missing_ports(component: ComponentDescription, ports: list[str], problems: Problems) -> None:
    """One line for every port the template needs that a role FMU lacks, with the FMU's variables."""
    shown = ", ".join(ports[:_LISTED]) + (
        f" (and {len(ports) - _LISTED} more)" if len(ports) > _LISTED else ""
    )
    example = ", ".join(f'{port} = "<variable>"' for port in ports[:3])
    hint = "; map them with" if component.kind == "fmu" else ";"
    own = f"inputs {_listing(component.inputs, ports[0])}; outputs {_listing(component.outputs, ports[0])}"
    problems.add(
        f"{component.where}.ports",
        f"the {TEMPLATE} connects ports the FMU ({component.model_name or component.name}) does not have: "
        f"{shown}{hint} ports = {{ {example} }}; its variables: {own}",
    )


def _endpoint(
    reference: str,
    where: str,
    direction: str,
    components: dict[str, ComponentDescription],
    broken: set[str],
    problems: Problems,
) -> str | None:
    """`reference` ("component.variable") when it names an existing port of that direction, else None."""
    name, dot, port = reference.partition(".")
    if not dot or not name or not port:
        problems.add(where, f"must be 'component.variable', got '{reference}'")
        return None
    if name in broken:
        return None
    if name not in components:
        problems.add(
            where,
            f"no component '{name}'{did_you_mean(name, components)}; "
            f"components: {_listing(components, name)}",
        )
        return None
    component = components[name]
    wanted, other = (
        (component.outputs, component.inputs)
        if direction == "output"
        else (component.inputs, component.outputs)
    )
    if port in wanted:
        return reference
    key = "from" if direction == "output" else "to"
    if port in other:
        kind = "input" if direction == "output" else "output"
        problems.add(
            where,
            f"'{reference}' is an {kind}, and `{key}` takes an {direction} (an {kind} cannot be wired to "
            f"an {kind}){did_you_mean(port, wanted)}; {direction}s of {name}: {_listing(wanted, port)}",
        )
        return None
    problems.add(
        where,
        f"component '{name}' has no {direction} '{port}'{did_you_mean(port, wanted)}; "
        f"{direction}s: {_listing(wanted, port)}",
    )
    return None


def _check_unconnected(
    components: dict[str, ComponentDescription], connections: list[ConnectionDescription], problems: Problems
) -> None:
    """Every input of an added component is connected or held at a value (template ones are fed)."""
    fed = {connection.target for connection in connections}
    outputs = [f"{c.name}.{port}" for c in components.values() for port in c.outputs]
    for component in components.values():
        if not component.where.startswith("[components."):
            continue
        for port in component.inputs:
            if f"{component.name}.{port}" in fed or port in component.held_inputs:
                continue
            # The same name on another component is the likeliest source.
            close = [o for o in outputs if o.endswith(f".{port}") and o.split(".")[0] != component.name]
            suggestion = f" (did you mean from = '{close[0]}'?)" if close else did_you_mean(port, outputs)
            problems.add(
                component.where,
                f"input '{port}' is not connected: add [[connections]] from = \"<component>.<output>\", "
                f'to = "{component.name}.{port}", or hold it with {port} = <value>{suggestion}',
            )


def _check_loops(
    components: dict[str, ComponentDescription], connections: list[ConnectionDescription], problems: Problems
) -> None:
    feedthrough = {name: component.feedthrough for name, component in components.items()}
    loop = find_algebraic_loop([(c.source, c.target) for c in connections], feedthrough)
    if loop is None:
        return
    names = list(dict.fromkeys(reference.split(".", 1)[0] for reference in loop))
    links = set(zip(loop, loop[1:], strict=False))
    declared = [c.where for c in connections if (c.source, c.target) in links and c.where != TEMPLATE]
    problems.add(
        declared[0] if declared else TEMPLATE,
        f"algebraic loop through components {', '.join(names)}: {' -> '.join(loop)} (each output depends "
        "directly on the input before it; an FMU output without declared dependencies depends on every "
        'input): break it with a component whose output is a state, or use [simulation] master = "jacobi"',
    )
