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
  wired to an output (or from an input), two connections into one input; a String or Binary
  variable connected to anything but its own type (naming both ends), or with a scale or offset;
- a `[system] remove` name that is no template component (or is the vehicle, whose pose the run
  needs);
- an input of a template component whose template connection was dropped (its source removed, or
  replaced by an FMU without that output) that is neither connected nor held (a lost feed); an
  input neither connected nor held whose FMU gives it no start value (FMI 2.0 and 3.0 require one
  on every input); an input both connected and held (an added component's other unconnected
  inputs keep their start values, as FMI defines and as other importers run them);
- a rate that is not a whole number of macro steps;
- an algebraic loop (Gauss-Seidel with `[simulation] algebraic_loops = "error"` only), naming its
  components; with "delay" (the default) the loop is kept in the description (`loop`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

from cosim.core.component import closest_names
from cosim.core.loops import find_algebraic_loop
from cosim.errors import WHERE_LIMIT, CosimError, shorten, shorten_words
from cosim.scenario.description import (
    TEMPLATE,
    ComponentDescription,
    ConnectionDescription,
    SystemDescription,
)
from cosim.scenario.load import ComponentSpec, Integration, PortMapping, Scenario, rate_problem
from cosim.scenario.params import pair_key, unstarted_inputs, unstarted_problem
from cosim.scenario.schema import did_you_mean
from cosim.scenario.template import (
    ORDER,
    POSE,
    POSE_COMPONENT,
    ROLE_PORTS,
    template_components,
    template_connections,
    template_ends,
    template_observed,
)

_LISTED = 12  # names listed in one message before "(and N more)"
SHOWN_PROBLEMS = 20  # problem lines of one error before "... and N more problems"


class Problems:
    """The problems found so far, each "where: what"; `check()` raises them as one `CosimError`."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.lines: list[str] = []

    def add(self, where: str, problem: str) -> None:
        # A name or reference the user wrote may be megabytes long: each line stays short.
        self.lines.append(f"{self.source}: {shorten(where, WHERE_LIMIT)}: {shorten_words(problem)}")

    def check(self) -> None:
        """Raise the problems, the first `SHOWN_PROBLEMS` of them and how many more (10,000 bad
        connections are 20,000 problems: the first ones say what is wrong)."""
        if not self.lines:
            return
        lines = self.lines[:SHOWN_PROBLEMS]
        if len(self.lines) > SHOWN_PROBLEMS:
            lines.append(f"{self.source}: ... and {len(self.lines) - SHOWN_PROBLEMS} more problems")
        raise CosimError("\n".join(lines))


def describe_system(scenario: Scenario) -> SystemDescription:
    """The system of `scenario`, checked; `CosimError` listing every problem (one per line)."""
    return _Composer(scenario).describe()


def fmu_path(spec: ComponentSpec, fmi_version: int = 2) -> Path:
    """The .fmu file of a component: a project FMU is built on first use, in the scenario's
    `[simulation] fmi_version`."""
    from cosim.fmi.builtin import builtin_fmu

    return builtin_fmu(spec.fmu, fmi_version) if spec.is_builtin else Path(spec.fmu)


def _first(names) -> str:
    """The names in their order, the first `_LISTED` of them, and how many more."""
    names = list(names)
    more = f" (and {len(names) - _LISTED} more)" if len(names) > _LISTED else ""
    return ", ".join(names[:_LISTED]) + more


def _listing(names, around: str = "") -> str:
    names = list(names)
    return closest_names(around, names, limit=_LISTED) if names else "none"


class _Composer:
    """One `describe_system` call: what is known so far and the problems found."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.problems = Problems(scenario.source)
        self.template = template_connections(scenario)
        self.template_ends = template_ends(scenario)  # (source component, output, target, input) of each
        self.components: dict[str, ComponentDescription] = {}
        self.broken: set[str] = set()  # components whose FMU did not load: reported once
        self.missing: dict[str, list[str]] = {}  # role component -> ports the template needs, absent
        self.own: dict[str, dict[str, list[str]]] = {}  # component -> causality -> FMU variable names
        self.unstarted: dict[str, tuple[str, ...]] = {}  # component -> input ports without a start value
        self.text_ports: dict[str, dict[str, tuple[str, str]]] = {}  # component -> `_FmuInterface.text`
        self.text_outputs: dict[str, dict[str, str]] = {}  # component -> `_FmuInterface.text_outputs`
        # The template components left out ([system] remove); every other name there is a problem.
        self.removed = [n for n in dict.fromkeys(scenario.removed) if n in ORDER and n != POSE_COMPONENT]
        self.replacing = {name for name, spec in scenario.components.items() if spec.added and name in ORDER}

    def describe(self) -> SystemDescription:
        scenario = self.scenario
        self._check_removed()
        for component in template_components(scenario):
            if component.kind == "fmu":
                self._add_fmu(scenario.components[component.name], component)
            else:
                self.components[component.name] = component
        for spec in scenario.components.values():
            if spec.added:
                if spec.name not in self.replacing:
                    self._add_fmu(spec, ComponentDescription(spec.name, "fmu", spec.where, rate=spec.rate))
                # The role sections' rates were checked on load.
                problem = rate_problem(spec.rate, scenario.macro_step) if spec.rate else None
                if problem:
                    self.problems.add(f"{spec.where}.rate", problem)
        connections, replaced, attempted, dropped = self._connections()
        for name, ports in self.missing.items():
            self._missing_ports(self.components[name], list(dict.fromkeys(ports)))
        self._check_unconnected(connections, attempted, dropped)
        loop: list[str] | None = None
        if scenario.master == "gauss-seidel":
            loop = self._check_loops(connections, scenario.algebraic_loops)
        self.problems.check()
        return SystemDescription(
            components=self.components,
            connections=tuple(connections),
            macro_step=scenario.macro_step,
            master=scenario.master,
            observed=template_observed(scenario, self.components, connections),
            replaced=tuple(replaced),
            removed=tuple(self.removed),
            replacing=tuple(name for name in ORDER if name in self.replacing),
            dropped=tuple(dropped),
            algebraic_loops=scenario.algebraic_loops,
            loop=tuple(loop or ()),
        )

    def _check_removed(self) -> None:
        """Each `[system] remove` name is a template component other than the vehicle, once."""
        where = "[system].remove"
        removable = [name for name in ORDER if name != POSE_COMPONENT]
        seen = set()
        for name in self.scenario.removed:
            if name in seen:
                self.problems.add(where, f"'{name}' is listed twice")
            seen.add(name)
            if name == POSE_COMPONENT:
                pose = ", ".join(f"{POSE_COMPONENT}.{axis}" for axis in POSE)
                self.problems.add(
                    where,
                    f"'{name}' cannot be removed: the run needs the robot pose ({pose}) for the outcome, "
                    "/odom and /tf; swap its FMU in [vehicle] (fmu, ports) instead",
                )
            elif name in self.scenario.components and self.scenario.components[name].added:
                self.problems.add(
                    where, f"'{name}' is not a template component but [components.{name}]: delete that table"
                )
            elif name not in ORDER:
                self.problems.add(
                    where,
                    f"no template component '{name}'{did_you_mean(name, removable)}; "
                    f"removable: {', '.join(removable)}",
                )

    # ---- components --------------------------------------------------------------------------

    def _add_fmu(self, spec: ComponentSpec, component: ComponentDescription) -> None:
        """Read the FMU's interface (through the port map); check the map and the values. The
        archive may unpack to [simulation] fmu_max_size MiB."""
        from cosim.fmi.archive import MIB

        where = component.where
        max_size = round(self.scenario.fmu_max_size * MIB)
        try:
            path = fmu_path(spec, self.scenario.fmi_version)
            plain = _fmu_interface(path, component.name, {}, max_size)
        except CosimError as error:
            self.problems.add(f"{where}.fmu", str(error))
            self.broken.add(component.name)
            return
        description = plain.model_description
        variables, own, declared = _variables(description)
        self.own[component.name] = own
        port_map = self._port_map(component, variables)
        fmu = plain
        if port_map:
            mapped = {port: {"name": m.variable, "scale": m.scale} for port, m in port_map.items()}
            fmu = _fmu_interface(path, component.name, mapped, max_size)
        if fmu.unstarted:
            self.unstarted[component.name] = fmu.unstarted
        self.text_ports[component.name] = fmu.text
        self.text_outputs[component.name] = fmu.text_outputs
        # A state output: the template says it is one and the FMU declares no dependencies for it.
        feedthrough = dict(fmu.feedthrough)
        for port in component.state_outputs:
            variable = port_map[port].variable if port in port_map else port
            if port in feedthrough and variable not in declared:
                feedthrough[port] = ()
        integration = self._integration(spec, description, where)
        described = replace(
            component,
            integration=integration,
            fmu=path,
            fmi_version=fmu.fmi_version,
            model_name=description.modelName or "",
            port_map=port_map,
            inputs=fmu.inputs,
            outputs=fmu.outputs,
            parameter_names=fmu.parameters,
            feedthrough=feedthrough,
        )
        self.components[component.name] = self._values(described, spec, variables)

    def _integration(self, spec: ComponentSpec, description, where: str) -> Integration:
        """The section's interface, resolved against the FMU (co-simulation when it has it, unless
        interface = "me"), with the Model Exchange solver (cvode unless given); a setting the FMU
        cannot take is reported."""
        given = spec.integration
        interface = given.interface or ("cs" if description.coSimulation is not None else "me")
        if interface == "me" and description.modelExchange is None:
            self.problems.add(
                f"{where}.interface", 'interface = "me": the FMU has no Model Exchange interface'
            )
        if interface == "cs":
            for key in ("solver", "tolerance", "max_step"):
                if getattr(given, key) is not None:
                    self.problems.add(
                        f"{where}.{key}",
                        f"{key} integrates a Model Exchange FMU, and this one runs as co-simulation: "
                        'add interface = "me" (or drop the key)',
                    )
            return Integration(interface="cs")
        return replace(given, interface="me", solver=given.solver or "cvode")

    def _port_map(self, component: ComponentDescription, variables: dict) -> dict[str, PortMapping]:
        """The valid part of a role's `ports` table; each bad entry is reported."""
        if not component.port_map:
            return {}
        ports = self._role_ports(component)
        valid = {}
        for port, mapping in component.port_map.items():
            where = f"{component.where}.ports.{port}"
            if port not in ports:
                self.problems.add(
                    where,
                    f"unknown port '{port}'{did_you_mean(port, ports)}; the ports of {component.where}: "
                    f"{_listing(sorted(ports), port)}",
                )
            elif mapping.variable not in variables:
                self.problems.add(
                    where,
                    f"the FMU has no variable '{mapping.variable}' (mapped to port '{port}')"
                    f"{did_you_mean(mapping.variable, variables)}; variables: "
                    f"{_listing(variables, mapping.variable)}",
                )
            else:
                valid[port] = mapping
        return valid

    def _role_ports(self, component: ComponentDescription) -> set[str]:
        """What a role's `ports` table may map: the role's ports (array ports by element too, as
        the template connects them) and the section's parameters."""
        ports = set(ROLE_PORTS.get(component.name, ())) | set(component.parameters)
        for connection in self.template:
            for reference in (connection.source, connection.target):
                name, _, port = reference.partition(".")
                if name == component.name:
                    ports.add(port)
        return ports

    def _values(self, component: ComponentDescription, spec: ComponentSpec, variables: dict):
        """Split the section's values into parameters and held inputs; check names, types, ranges."""
        where = component.where
        known = set(component.parameter_names)
        text = self.text_ports.get(component.name, {})
        settable = known | set(component.inputs) | set(text)  # an input given a value is held at it
        values = dict(component.parameters) if not spec.added else dict(spec.parameters)
        parameters, held = {}, {}
        for name, value in values.items():
            if name in component.required_parameters and name not in known:
                self.missing.setdefault(component.name, []).append(name)
                continue
            if name not in settable:
                # (A role section may hold an input too; its message names the parameter.)
                kind = "parameter or input" if spec.added else "parameter"
                self.problems.add(
                    f"{where}.{name}", f"the FMU has no {kind} '{name}'{did_you_mean(name, settable)}"
                )
                continue
            mapping = component.port_map.get(name)
            variable = variables[mapping.variable if mapping else name]
            if name in text or isinstance(value, str):
                problem = _text_problem(text.get(name, ("", ""))[1], variable, value)
                if problem:
                    self.problems.add(f"{where}.{name}", problem)
                else:
                    (parameters if text[name][0] == "parameter" else held)[name] = value
                continue
            received = float(value) * (mapping.scale if mapping else 1.0)
            problem = _value_problem(variable, received, spec.parameters.get(name, value))
            if problem:
                pair = pair_key(name) if not spec.added else None
                if pair:  # the section may have set it through the pair
                    problem += f" ({pair} = [low, high] sets it too)"
                self.problems.add(f"{where}.{name}", problem)
            (parameters if name in known else held)[name] = float(value)
        for name, value in component.defaults.items():
            if name in known:
                parameters[name] = value
        return replace(component, parameters=parameters, held_inputs=held, defaults={})

    # ---- connections -------------------------------------------------------------------------

    def _connections(self):
        """The template's connections, minus those the scenario replaces and those that lost an
        end, then the scenario's; the replaced pairs; the inputs named by a scenario connection
        (even one that failed); the dropped template connections (connection, why)."""
        fed: dict[str, ConnectionDescription] = {}
        attempted: set[str] = set()
        added = []
        for spec in self.scenario.connections:
            target = self._endpoint(spec.target, f"{spec.where}.to", "input")
            source = self._endpoint(spec.source, f"{spec.where}.from", "output")
            if target is not None:
                attempted.add(target)
            if source is None or target is None:
                continue
            if target in fed:
                self.problems.add(
                    f"{spec.where}.to",
                    f"input '{target}' is already fed by {fed[target].where} (from '{fed[target].source}'); "
                    "an input takes one connection",
                )
                continue
            problem = self._text_connection_problem(source, target, spec)
            if problem is not None:
                self.problems.add(spec.where, problem)
                continue
            fed[target] = ConnectionDescription(source, target, spec.scale, spec.offset, spec.where)
            added.append(fed[target])
        # Sets: the template connects thousands of ports (waypoints, beams).
        ports = {
            name: {"inputs": set(c.inputs), "outputs": set(c.outputs)} for name, c in self.components.items()
        }

        def present(reference: str, kind: str) -> bool:
            name, _, port = reference.partition(".")
            if name in self.broken or (name in ports and port in ports[name][kind]):
                return True
            self.missing.setdefault(name, []).append(port)
            return False

        def lost(reference: str, kind: str) -> str | None:
            """Why a template connection's end is gone: its component removed, or replaced by an
            FMU without that port; None if it is there (or its absence is a problem)."""
            name, _, port = reference.partition(".")
            if name in self.removed:
                return f"{name} is removed by [system].remove"
            if name in self.replacing and name not in self.broken and port not in ports[name][kind]:
                return f"[components.{name}] has no such {kind[:-1]}"
            return None

        kept, replaced, dropped = [], [], []
        # The usual template connection first: both ends there, neither component removed, replaced
        # or broken, the input not fed by the scenario (the loop below would keep it too).
        unusual = set(self.removed) | self.replacing | self.broken
        outputs_of = {name: sets["outputs"] for name, sets in ports.items() if name not in unusual}
        inputs_of = {name: sets["inputs"] for name, sets in ports.items() if name not in unusual}
        for connection, ends in zip(self.template, self.template_ends, strict=True):
            source_name, source_port, target_name, target_port = ends
            if (
                source_port in outputs_of.get(source_name, ())
                and target_port in inputs_of.get(target_name, ())
                and connection.target not in fed
            ):
                kept.append(connection)
                continue
            reason = lost(connection.source, "outputs") or lost(connection.target, "inputs")
            if reason is not None:
                dropped.append((connection, reason))
            elif connection.target in fed:
                replaced.append((connection, fed[connection.target]))
            # `&`, not `and`: both ends are looked at, so every missing port is reported.
            elif present(connection.source, "outputs") & present(connection.target, "inputs"):
                kept.append(connection)
        # What the run observes of a template component must be there (a replacement's is optional).
        observed = template_observed(self.scenario, self.components, kept + added)
        for _, reference in observed.references():
            if reference.partition(".")[0] not in self.replacing:
                present(reference, "outputs")
        return kept + added, replaced, attempted, dropped

    def _text_type(self, reference: str, direction: str) -> str | None:
        """The FMI type ("String", "Binary") of a text input or output "component.port", else None."""
        name, _, port = reference.partition(".")
        if direction == "output":
            return self.text_outputs.get(name, {}).get(port)
        causality, fmi_type = self.text_ports.get(name, {}).get(port, ("", None))
        return fmi_type if causality == "input" else None

    def _text_connection_problem(self, source: str, target: str, spec) -> str | None:
        """Why a connection with a String or Binary end cannot be made (None: it can, or it has none)."""
        source_type, target_type = self._text_type(source, "output"), self._text_type(target, "input")
        if source_type is None and target_type is None:
            return None
        if source_type != target_type:
            return (
                f"connection {source} ({source_type or 'a number'}) -> {target} "
                f"({target_type or 'a number'}) cannot convert: a String or Binary connects only to its "
                "own type"
            )
        if spec.scale != 1.0 or spec.offset != 0.0:
            return f"connection {source} -> {target}: a {source_type} takes no scale or offset"
        return None

    def _missing_ports(self, component: ComponentDescription, ports: list[str]) -> None:
        """One line for every port the template needs that a role FMU lacks, with its own variables."""
        shown = ", ".join(ports[:_LISTED])
        if len(ports) > _LISTED:
            shown += f" (and {len(ports) - _LISTED} more)"
        example = ", ".join(f'{port} = "<variable>"' for port in ports[:3])
        own = self.own.get(component.name, {})
        listed = "; ".join(
            f"{causality}s {_listing(own[causality], ports[0])}"
            for causality in ("input", "output", "parameter")
            if own.get(causality)
        )
        pose = ""
        if component.name == POSE_COMPONENT and set(POSE) & set(ports):
            pose = f" (the run needs the robot pose {', '.join(f'{POSE_COMPONENT}.{a}' for a in POSE)})"
        self.problems.add(
            f"{component.where}.ports",
            f"the FMU ({component.model_name or component.name}) has no variables for the ports "
            f"{shown} that the {TEMPLATE} uses{pose}; map them with ports = {{ {example} }}; the FMU's "
            f"variables: {listed or 'none'}",
        )

    def _endpoint(self, reference: str, where: str, direction: str) -> str | None:
        """`reference` ("component.variable") when it names a port of that direction, else None."""
        name, dot, port = reference.partition(".")
        if not dot or not name or not port:
            self.problems.add(where, f"must be 'component.variable', got '{reference}'")
            return None
        if name in self.broken:
            return None
        if name in self.removed:
            self.problems.add(
                where, f"'{name}' is removed by [system].remove; connect a component of the system"
            )
            return None
        if name not in self.components:
            self.problems.add(
                where,
                f"no component '{name}'{did_you_mean(name, self.components)}; "
                f"components: {_listing(self.components, name)}",
            )
            return None
        component = self.components[name]
        wanted, other = component.outputs, component.inputs
        if direction == "input":
            wanted, other = other, wanted
        if port in wanted or self._text_type(reference, direction) is not None:
            return reference
        if port in other:
            kind = "input" if direction == "output" else "output"
            key = "from" if direction == "output" else "to"
            self.problems.add(
                where,
                f"'{reference}' is an {kind}, and `{key}` takes an {direction} (an {kind} cannot be "
                f"wired to an {kind}){did_you_mean(port, wanted)}; {direction}s of {name}: "
                f"{_listing(wanted, port)}",
            )
            return None
        self.problems.add(
            where,
            f"component '{name}' has no {direction} '{port}'{did_you_mean(port, wanted)}; "
            f"{direction}s: {_listing(wanted, port)}",
        )
        return None

    def _check_unconnected(
        self,
        connections: list[ConnectionDescription],
        attempted: set[str],
        dropped: list[tuple[ConnectionDescription, str]],
    ) -> None:
        """An input that is not connected keeps its start value (or the value it is held at); one
        without a start value must be connected or held, and so must a template input whose
        template connection was dropped (a lost feed, not a choice). One that a failed connection
        meant to feed is reported with that connection. A held input must not be connected too."""
        feeding = {connection.target: connection for connection in connections}
        fed = set(feeding) | attempted
        for component in self.components.values():
            for port in component.held_inputs:
                connection = feeding.get(f"{component.name}.{port}")
                if connection is not None:
                    self.problems.add(
                        f"{component.where}.{port}",
                        f"input '{port}' is held at a value and also connected (from '{connection.source}', "
                        f"{connection.where}); drop one of them",
                    )
        for name, ports in self.unstarted.items():
            component = self.components.get(name)
            if component is None:
                continue
            for port in ports:
                if f"{name}.{port}" in fed or port in component.held_inputs:
                    continue
                self.problems.add(
                    component.where,
                    unstarted_problem(
                        port, f'add [[connections]] to = "{name}.{port}", or hold it with {port} = <value>'
                    ),
                )
        # Template inputs whose template connection was dropped: one line per component and reason.
        unfed: dict[tuple[str, str], list[str]] = {}
        sources: dict[tuple[str, str], list[str]] = {}
        for connection, reason in dropped:
            name, _, port = connection.target.partition(".")
            component = self.components.get(name)
            if component is None or name in self.replacing or connection.target in fed:
                continue  # removed, or an added component's input (reported above), or fed
            if port in component.held_inputs:
                continue
            unfed.setdefault((name, reason), []).append(port)
            sources.setdefault((name, reason), []).append(connection.source)
        for (name, reason), ports in unfed.items():
            component = self.components[name]
            ports = list(dict.fromkeys(ports))
            shown, source = _first(ports), _first(dict.fromkeys(sources[name, reason]))
            several = len(ports) > 1
            if component.kind == "planner":
                remedy = "set [planner] replan = false (the replanning planner reads them), or connect them"
            elif component.kind == "fmu":
                remedy = (
                    f'add [[connections]] to = "{name}.{ports[0]}"{" (and the rest)" if several else ""}, '
                    f"or hold {'each' if several else 'it'} at a value in {component.where} "
                    f"({ports[0]} = <value>)"
                )
            else:
                remedy = f'add [[connections]] to = "{name}.{ports[0]}"{" (and the rest)" if several else ""}'
            self.problems.add(
                component.where,
                f"input{'s' if several else ''} {shown} of {name} {'are' if several else 'is'} "
                "not connected: "
                f"the template's connection{'s' if several else ''} into {'them' if several else 'it'} "
                f"{'were' if several else 'was'} dropped (from {source}: {reason}); {remedy}",
            )

    def _check_loops(self, connections: list[ConnectionDescription], handling: str) -> list[str] | None:
        """The algebraic loop (ports), if any; a problem when `handling` is "error"."""
        feedthrough = {name: component.feedthrough for name, component in self.components.items()}
        loop = _algebraic_loop(((c.source, c.target) for c in connections), feedthrough)
        if loop is None or handling != "error":
            return loop
        names = list(dict.fromkeys(reference.split(".", 1)[0] for reference in loop))
        links = set(zip(loop, loop[1:], strict=False))
        declared = [c.where for c in connections if (c.source, c.target) in links and c.where != TEMPLATE]
        self.problems.add(
            declared[0] if declared else TEMPLATE,
            f"algebraic loop through components {', '.join(names)}: {' -> '.join(loop)} (each output "
            "depends directly on the input before it; an FMU output without declared dependencies "
            "depends on every input): break it with a component whose output is a state, or use "
            '[simulation] algebraic_loops = "delay" (or master = "jacobi") to step the loop with its '
            "inputs from the previous communication point",
        )
        return loop


@dataclass(frozen=True)
class _FmuInterface:
    """What describing a system reads of an FMU component: its ports through a port map."""

    model_description: object  # fmpy's, shared and read-only (`cosim.fmi.description`)
    fmi_version: int
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]
    feedthrough: dict[str, tuple[str, ...]]  # output port -> input ports it depends on directly
    unstarted: tuple[str, ...] = ()  # input ports (numbers and text) whose variable has no start value
    text: dict[str, tuple[str, str]] = field(default_factory=dict)  # String/Binary parameter or input
    # port -> (causality, FMI type)
    text_outputs: dict[str, str] = field(default_factory=dict)  # String/Binary output port -> FMI type


# The interfaces of the last few FMU components described, keyed by everything `FmuComponent` reads
# to make them: the file's path and version (modification time and size, as its description cache),
# the component's name, the port map and the unpacked-size limit. A sweep describes the same FMUs
# once per run in each worker process (each read opens the archive and makes every port).
_INTERFACES: dict[tuple, _FmuInterface] = {}
_INTERFACES_KEPT = 32


def _fmu_interface(path: Path, name: str, port_map: dict, max_size: int) -> _FmuInterface:
    """The interface of `FmuComponent(path, name, port_map=port_map, max_unpacked_size=max_size)`;
    `CosimError` as it raises (never remembered)."""
    from cosim.fmi.layout import fmu_layout

    try:
        status = Path(path).stat()
    except OSError:
        status = None  # fmu_layout says what is wrong
    key = None
    if status is not None:
        mapping = tuple((port, m["name"], m["scale"]) for port, m in port_map.items())
        key = (str(Path(path).resolve()), status.st_mtime_ns, status.st_size, name, mapping, max_size)
        if key in _INTERFACES:
            return _INTERFACES[key]
    layout = fmu_layout(path, name, port_map, max_size)
    inputs = tuple(p.name for p in layout.inputs)
    # As `Component` completes it: the declared dependencies, then every other output on all inputs.
    feedthrough = dict(layout.feedthrough)
    for port in layout.outputs:
        feedthrough.setdefault(port.name, inputs)
    interface = _FmuInterface(
        layout.model_description,
        layout.fmi_version,
        inputs,
        tuple(p.name for p in layout.outputs),
        tuple(p.name for p in layout.parameters),
        feedthrough,
        unstarted_inputs(layout),
        {
            port.name: (causality, port.fmi_type)
            for causality in ("parameter", "input")
            for port in layout.text.get(causality, ())
        },
        {port.name: port.fmi_type for port in layout.text.get("output", ())},
    )
    if key is not None:
        if len(_INTERFACES) >= _INTERFACES_KEPT:
            _INTERFACES.pop(next(iter(_INTERFACES)))
        _INTERFACES[key] = interface
    return interface


# `_variables` of the last few descriptions (fmpy's, shared and read-only: `cosim.fmi.description`),
# each kept with its description: a fleet describes the same four FMUs for every robot.
_VARIABLES: dict[int, tuple] = {}


def _variables(description) -> tuple[dict, dict[str, list[str]], set[str]]:
    """An FMU description's variables by name, their names by causality, and the outputs that
    declare their dependencies (all read-only)."""
    known = _VARIABLES.get(id(description))
    if known is not None and known[0] is description:
        return known[1:]
    variables = {variable.name: variable for variable in description.modelVariables}
    own: dict[str, list[str]] = {}
    for variable in description.modelVariables:
        own.setdefault(variable.causality, []).append(variable.name)
    declared = {u.variable.name for u in description.outputs if u.dependencies is not None}
    if len(_VARIABLES) >= _INTERFACES_KEPT:
        _VARIABLES.pop(next(iter(_VARIABLES)))
    _VARIABLES[id(description)] = (description, variables, own, declared)
    return variables, own, declared


def _algebraic_loop(pairs: Iterable[tuple[str, str]], feedthrough: dict) -> list[str] | None:
    """`find_algebraic_loop(pairs, feedthrough)` (which remembers the last few graphs: a sweep's
    worker describes the same system for every run, and building it checks the same graph again)."""
    return find_algebraic_loop(pairs, feedthrough)


def _value_problem(variable, value: float, given) -> str | None:
    """Whether `value` (what the FMU receives) suits the variable's type and declared min/max."""
    kind = variable.type
    if kind in ("Integer", "Enumeration", "Int32", "Int64", "Int16", "Int8", "UInt8", "UInt16", "UInt32"):
        kind = "integer"
    elif kind == "Boolean":
        if value not in (0.0, 1.0):
            return f"must be true or false, got {given}"
        return None
    if isinstance(given, bool):  # TOML true/false where the FMU wants a number
        return f"must be a number (the FMU's {variable.type}), got {str(given).lower()}"
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


def _text_problem(fmi_type: str, variable, value) -> str | None:
    """Whether `value` suits a String (a TOML string) or Binary (a string of hex digits) variable;
    a string given to any other variable is a problem too."""
    if not fmi_type:
        return f"must be a number (the FMU's {variable.type}), got a string"
    if not isinstance(value, str):
        wanted = "text" if fmi_type == "String" else 'hex digits, two a byte (e.g. "0a0b")'
        return f"the FMU's {fmi_type} takes a string of {wanted}, got {str(value).lower()}"
    if fmi_type == "Binary":
        try:
            bytes.fromhex(value)
        except ValueError:
            return (
                f'the FMU\'s Binary takes a string of hex digits, two a byte (e.g. "0a0b"), got {value!r:.40}'
            )
    return None


def _bound(text) -> float | None:
    try:
        bound = float(text)
    except (TypeError, ValueError):
        return None
    return bound if math.isfinite(bound) else None


def _text(bound: float | None) -> str:
    return "-inf" if bound is None else f"{bound:g}"
