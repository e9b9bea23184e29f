"""`cosim ssp export SCENARIO --out X.ssp`, and running such an archive as the scenario it came from.

The archive holds the scenario's whole system:
- the FMU components as `resources/<component>.fmu` (the files that the scenario runs), their
  parameters (as the run sets them, derived ones included) in `resources/parameters.ssv` and in
  each component's own binding, the units, the connections between FMUs, the stop time, macro
  step, master and periods (`cosim.ssp.write`); any SSP 1.0 tool runs this FMU part;
- the parts that are not FMUs (planner, lidar, world, outcome settings) as resources, the scenario
  TOML `resources/navcosim/scenario.toml` as written and its map files beside it, described by the
  SSD-level annotation `org.navcosim.scenario`:
  `<nc:Scenario name=... scenario="resources/navcosim/scenario.toml">` with one `nc:Python` per
  Python component (planner, lidar), one `nc:Resource` per map file, and `nc:Set` overrides that
  re-point file names into the archive, keep each FMU's isolation as the scenario had it (its
  project FMUs in-process, on the compiled kernel) and repeat the `--set` overrides of the export.

`cosim run X.ssp` on such an archive rebuilds the navigation system: the scenario from the TOML
(the non-FMU parts), the FMUs from the SSD's components and their parameters from the SSV. The
system it builds is checked against the SSD (same components, periods and connections), so an SSD
edited into something the scenario does not describe is an error rather than silently ignored.
The run is the scenario's run: `cosim log diff` of both logs at tolerance 0 finds no difference.

The archive is untrusted input: every file the scenario names (the TOML, its map and the map's
image, the FMUs) must lie inside the archive; the log goes where the command line says (or the
default `logs/` name), never where the archive's `[output] log` says; an FMU that the archive says
to run in-process runs in a child process unless it is the project's own build
(`cosim.ssp.read.is_project_fmu`) or the command line says `simulation.fmu_isolation`; and the
archive cannot raise the limits of the run above the command line's or the defaults
(`simulation.fmu_timeout`, `fmu_max_size`, `max_steps`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

from cosim.errors import CosimError, shorten
from cosim.fmi.archive import MIB
from cosim.scenario.load import DEFAULT_LOG_PATTERN, Scenario, parse_scenario
from cosim.ssp.read import DEFAULT_TIMEOUT, SspComponent, SspConnection, SspSystem, max_unpacked_size
from cosim.ssp.schema import tag

SCENARIO_ANNOTATION = "org.navcosim.scenario"
SCENARIO_DIR = "resources/navcosim"


def _port_of(scenario: Scenario, name: str, port: str) -> tuple[str, float]:
    """(FMU variable, scale) of a component's port."""
    spec = scenario.components.get(name)
    mapping = spec.ports.get(port) if spec is not None else None
    return (mapping.variable, mapping.scale) if mapping is not None else (port, 1.0)


def flat_system(built) -> tuple[list[SspComponent], list[SspConnection]]:
    """The FMU part of a built run in SSP terms: FMU variables and FMU-level values.

    Ports map to FMU variables with a scale (FMU input = scale * port value, output port =
    scale * FMU output, FMU parameter = scale * value), so a connection `target = k * source + c`
    between ports is `target_var = (t k s) source_var + t c` between variables.
    """
    from cosim.fmi.component import FmuComponent
    from cosim.fmi.isolated import IsolatedFmuComponent

    scenario = built.scenario
    components: list[SspComponent] = []
    for name, component in built.system.components.items():
        if not isinstance(component, FmuComponent | IsolatedFmuComponent):
            continue
        variables = {v.name: v for v in component.model_description.modelVariables}
        # Parameters, and the inputs the scenario holds at a value (start values of the inputs).
        values: tuple[dict, dict] = ({}, {})
        held = built.description.components[name].held_inputs
        for target, given in zip(values, (built.parameters.get(name, {}), held), strict=True):
            for port, value in given.items():
                variable, scale = _port_of(scenario, name, port)
                target[variable] = value * scale
                if target[variable] / scale != value:
                    raise CosimError(
                        f"{scenario.source}: [{name}].{port}: {value!r} times the port scale {scale!r} does "
                        "not divide back exactly; the exported SSP would not reproduce the run"
                    )
        components.append(SspComponent(name, name, component.path, *values, component.period, variables))
    return components, fmu_connections(scenario, built.system.connections, {c.name for c in components})


def fmu_connections(scenario: Scenario, connections, fmus: set[str]) -> list[SspConnection]:
    """The connections between the FMUs `fmus` (of a built `System` or a `SystemDescription`: both
    have source, target, scale, offset) between FMU variables, port scales folded in."""
    found = []
    for connection in connections:
        if connection.source_component not in fmus or connection.target_component not in fmus:
            continue  # a Python component's connection: the template makes it again
        source, source_scale = _port_of(scenario, *connection.source.split(".", 1))
        target, target_scale = _port_of(scenario, *connection.target.split(".", 1))
        factor = target_scale * connection.scale * source_scale
        found.append(
            SspConnection(
                f"{connection.source_component}.{source}",
                f"{connection.target_component}.{target}",
                factor,
                target_scale * connection.offset,
            )
        )
    return found


def _map_files(scenario: Scenario) -> list[Path]:
    """The known map and, for a ROS map .yaml, its image (both must sit in one folder)."""
    files = [scenario.map_file]
    if scenario.map_file.suffix in (".yaml", ".yml"):
        for line in scenario.map_file.read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "image":
                image = (scenario.map_file.parent / value.strip().strip("'\"")).resolve()
                if image.parent != scenario.map_file.parent:
                    raise CosimError(
                        f"{scenario.map_file}: image '{value.strip()}' must sit beside the .yaml "
                        "to be exported"
                    )
                files.append(image)
    return files


def export_scenario(scenario: Scenario, out: Path) -> Path:
    """Write the SSP of `scenario` to `out` (see the module docstring); `CosimError` on bad input."""
    from cosim.navigation.build import build_run
    from cosim.ssp.write import parameter_set, system_structure, write_ssp

    built = build_run(scenario)
    components, connections = flat_system(built)
    content = ET.Element(tag("nc:Scenario"), name=scenario.name, scenario=f"{SCENARIO_DIR}/scenario.toml")
    sets = [f'map.file="{scenario.map_file.name}"']
    for component in components:
        spec = scenario.components[component.name]
        # A [components.NAME] may carry a role's name: it replaces that role.
        section = f"components.{component.name}" if spec.added else component.name
        if not spec.is_builtin:
            sets.append(f'{section}.fmu="../{component.name}.fmu"')
        # Where the scenario ran the FMU: in the archive every FMU is given by path, which alone
        # would put the project's own FMUs in a child process (off the compiled kernel).
        sets.append(f'{section}.isolation="{scenario.isolation(spec)}"')
    for name in built.system.components:
        if name not in {component.name for component in components}:
            ET.SubElement(content, tag("nc:Python"), name=name, kind=name)
    resources = {f"{SCENARIO_DIR}/scenario.toml": scenario.text.encode()}
    for path in _map_files(scenario):
        resources[f"{SCENARIO_DIR}/{path.name}"] = path.read_bytes()
        ET.SubElement(content, tag("nc:Resource"), path=f"{SCENARIO_DIR}/{path.name}")
    for override in sets + list(scenario.overrides):
        ET.SubElement(content, tag("nc:Set"), value=override)
    ssd = system_structure(
        scenario.name,
        components,
        connections,
        scenario.stop_time,
        scenario.macro_step,
        scenario.master,
        (SCENARIO_ANNOTATION, content),
    )
    ssv = parameter_set(scenario.name, components)
    return write_ssp(Path(out), ssd, ssv, components, resources)


def scenario_of(ssp: SspSystem, simulation: dict[str, object]) -> Scenario:
    """The scenario an exported SSP describes, with the FMUs and parameters of its SSD and SSV."""
    from cosim.scenario.limits import MAX_STEPS
    from cosim.world.distance import check_start_goal

    content = ssp.annotations[SCENARIO_ANNOTATION]
    where = f"{ssp.source}: SystemStructure.ssd: annotation {SCENARIO_ANNOTATION}"
    uri = content.get("scenario")
    toml = _inside(ssp, uri) if uri else None
    if content.tag != tag("nc:Scenario") or toml is None or not toml.is_file():
        raise CosimError(
            f"{where}: needs an nc:Scenario whose scenario attribute names a file in the archive"
            + (f" (got '{shorten(uri)}')" if uri else "")
        )
    if float(simulation.get("start_time", 0.0)) != 0.0:
        raise CosimError(
            f"{ssp.source}: a navcosim scenario starts at t = 0; simulation.start_time is not allowed"
        )
    overrides = [element.get("value", "") for element in content.iterfind(tag("nc:Set"))]
    if "max_steps" not in simulation:  # the archive's own max_steps cannot raise the default
        overrides.append(f"simulation.max_steps={MAX_STEPS}")
    overrides += [f"simulation.{key}={value}" for key, value in simulation.items()]
    try:
        text = toml.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise CosimError(f"{ssp.source}: {uri}: cannot read the scenario ({error})") from None
    scenario = parse_scenario(text, f"{ssp.source}: {uri}", toml.parent, overrides)
    files = [scenario.map_file]
    if _inside(ssp, scenario.map_file) is not None:
        try:
            files = _map_files(scenario)  # and a ROS map's image, which must sit beside it
        except CosimError:
            raise CosimError(
                f"{ssp.source}: {uri}: the image of the map '{scenario.map_file.name}' is not beside it in "
                "the archive; an archive's scenario may name only files inside it"
            ) from None
        except (OSError, UnicodeDecodeError):
            pass  # the map's own reader says what is wrong with it
    for path in files:
        if _inside(ssp, path) is None:
            raise CosimError(
                f"{ssp.source}: {uri}: the map file '{shorten(path)}' is not in the archive; an "
                "archive's scenario may name only files inside it"
            )
    limits = {"log_pattern": DEFAULT_LOG_PATTERN}  # the archive's [output] log is not followed
    if "fmu_timeout" not in simulation:
        limits["fmu_timeout"] = min(scenario.fmu_timeout, DEFAULT_TIMEOUT)
    limits["fmu_max_size"] = min(scenario.fmu_max_size, max_unpacked_size(simulation) / MIB)
    scenario = replace(scenario, **limits)
    check_start_goal(scenario)
    components = dict(scenario.components)
    labels = {name: ssp.component(name).member for name in scenario.components}
    for name, spec in scenario.components.items():
        component = ssp.component(name)
        parameters = {}
        for variable, value in {**component.parameters, **component.inputs}.items():
            ports = [port for port in spec.ports if spec.ports[port].variable == variable]
            port = ports[0] if ports else variable
            parameters[port] = value / _port_of(scenario, name, port)[1]
        isolation = spec.isolation
        if "fmu_isolation" in simulation:  # the command line decides for every FMU
            isolation = "none" if simulation["fmu_isolation"] == "auto" and component.project else None
        elif scenario.isolation(spec) == "none" and not component.project:
            isolation = "process"  # the archive says in-process, but this is not the project's FMU
        components[name] = replace(spec, fmu=str(component.fmu), parameters=parameters, isolation=isolation)
    return replace(scenario, components=components, fmu_labels=labels)


def _inside(ssp: SspSystem, name: str | Path) -> Path | None:
    """The file `name` (relative to the unpacked archive, or absolute) when it lies inside the
    archive, symbolic links resolved; None when it does not."""
    text = str(name)
    if "\0" in text:
        return None
    root = ssp.directory.resolve()
    path = (root / text).resolve()
    return path if path.is_relative_to(root) else None


def _check_against_ssd(ssp: SspSystem, scenario: Scenario) -> None:
    """The scenario's FMU part must be the SSD's: same components, periods and connections (from
    its description: building the run here too would plan and load it twice)."""
    from cosim.scenario.compose import describe_system

    description = describe_system(scenario)
    ours = [(c.name, c.period) for c in description.components.values() if c.kind == "fmu"]
    connections = fmu_connections(scenario, description.connections, {name for name, _ in ours})
    where = f"{ssp.source}: SystemStructure.ssd"
    theirs = [(c.name, c.period) for c in ssp.components]
    if sorted(ours) != sorted(theirs):
        raise CosimError(f"{where}: components and periods {theirs} differ from the scenario's {ours}")
    if sorted(map(_key, connections)) != sorted(map(_key, ssp.connections)):
        missing = sorted(set(map(_key, connections)) - set(map(_key, ssp.connections)))
        extra = sorted(set(map(_key, ssp.connections)) - set(map(_key, connections)))
        raise CosimError(
            f"{where}: the connections differ from the scenario's (edit {SCENARIO_DIR}/scenario.toml "
            f"instead): missing {missing[:3]}, not in the scenario {extra[:3]}"
        )


def _key(connection: SspConnection) -> tuple:
    return (connection.source, connection.target, connection.factor, connection.offset)


def run_exported(
    ssp: SspSystem, simulation: dict[str, object], out_path: Path | None, progress: bool, force: bool = False
):
    """Run an exported SSP as its scenario; returns (scenario, `cosim.navigation.run.RunResult`)."""
    from cosim.navigation.run import run_scenario

    scenario = scenario_of(ssp, simulation)
    _check_against_ssd(ssp, scenario)
    # The caller draws its PNG from the log, so no in-memory trace is kept (memory flat in time).
    result = run_scenario(scenario, out_path, progress=progress, force=force, trace=False)
    if result.failure is not None and not result.failure.startswith(f"{ssp.source}:"):
        result.failure = f"{ssp.source}: {result.failure}"  # as every SSP error line (the log keeps its own)
    return scenario, result
