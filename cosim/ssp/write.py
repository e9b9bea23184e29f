"""Writing an SSP 1.0 archive: SystemStructure.ssd, one .ssv parameter set, the FMUs in resources/.

`write_ssp` takes a flat system in the reader's terms (`SspComponent`, `SspConnection` of
`cosim.ssp.read`: FMU variable names, FMU-level values) and writes what `open_ssp` reads
back to the same system, and what any SSP 1.0 tool reads: every FMU as `resources/<name>.fmu`,
its connectors (the variables that connections use, typed from its modelDescription.xml), the
connections with a `LinearTransformation` where factor or offset is not the identity, the stop
time in `DefaultExperiment`, and the macro step, master algorithm and component periods in
navcosim's annotations (SSP 1.0 has no place for them).

Every value is written twice, with the same number: in `resources/parameters.ssv` bound at the
root system with hierarchical names (`vehicle.x0`), and in an inline parameter set bound at its
own component with the variable's own name (`x0`), which is what libcosim and ecos read (they
ignore a system's bindings). All component sets carry the system's name, the name by which ecos
selects a parameter set (`EcosSimulation.init(0.0, "<name>")`). Both bindings give the same value,
so the SSP rule that a binding higher in the hierarchy wins changes nothing.

Every unit that a connector names is defined in `<ssd:Units>` with its SI exponents
(`ssc:BaseUnit` kg m s A K mol cd rad, factor, offset), as the FMU's own UnitDefinitions give
them; a unit the FMU does not define is left off its connector rather than guessed. A connection
between connectors of different units says suppressUnitConversion="true": navcosim passes values
as they are (its factor and offset), where SSP would convert between the units first. The SSD and
every parameter set are checked against the normative schemas before the archive is written.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from functools import cache
from pathlib import Path

from cosim.errors import CosimError
from cosim.ssp import schema
from cosim.ssp.experiment import SIMULATION_ANNOTATION
from cosim.ssp.read import COMPONENT_ANNOTATION, SSD_NAME, SspComponent, SspConnection
from cosim.ssp.schema import tag

PARAMETERS = "resources/parameters.ssv"
_SSC_TYPES = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer"}
_SSC_TYPES |= {"Enumeration": "Integer", "Boolean": "Boolean"}
_KINDS = {"input": "input", "output": "output", "parameter": "parameter", "structuralParameter": "parameter"}
_BASE_UNIT = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")  # SI exponents, FMI's and SSP's order


def _annotation(parent: ET.Element, prefix: str, kind: str) -> ET.Element:
    """An `Annotations/Annotation type=kind` block under `parent`; returns the Annotation."""
    block = ET.SubElement(parent, tag(f"{prefix}:Annotations"))
    return ET.SubElement(block, tag("ssc:Annotation"), type=kind)


def _value_element(parent: ET.Element, variable, value: float) -> None:
    kind = _SSC_TYPES.get(variable.type)
    if kind is None:
        raise CosimError(f"variable '{variable.name}' of type {variable.type} cannot be written to an SSV")
    if kind == "Real":
        ET.SubElement(parent, tag("ssv:Real"), value=repr(float(value)))
    elif kind == "Integer":
        ET.SubElement(parent, tag("ssv:Integer"), value=str(int(value)))
    else:
        ET.SubElement(parent, tag("ssv:Boolean"), value="true" if value else "false")


def parameter_set(name: str, components: list[SspComponent], prefixed: bool = True) -> ET.Element:
    """The ssv:ParameterSet `name` of the components' parameters and held input values, named
    `component.variable` (`prefixed`, for a binding at the system) or by the variable alone."""
    root = ET.Element(tag("ssv:ParameterSet"), version="1.0", name=name)
    parameters = ET.SubElement(root, tag("ssv:Parameters"))
    for component in components:
        for variable_name, value in {**component.parameters, **component.inputs}.items():
            name = f"{component.name}.{variable_name}" if prefixed else variable_name
            parameter = ET.SubElement(parameters, tag("ssv:Parameter"), name=name)
            _value_element(parameter, component.variables[variable_name], value)
    return root


@cache
def _unit_definitions(fmu: Path) -> dict[str, tuple]:
    """Unit name -> its BaseUnit (kg, m, s, A, K, mol, cd, rad, factor, offset) in the FMU's
    modelDescription.xml; a unit without a BaseUnit is all zeros, factor 1, offset 0 (FMI's defaults)."""
    import fmpy

    definitions = {}
    for unit in fmpy.read_model_description(str(fmu)).unitDefinitions:
        base = unit.baseUnit
        exponents = tuple(int(getattr(base, key, 0) or 0) if base else 0 for key in _BASE_UNIT)
        factor = float(base.factor) if base and base.factor is not None else 1.0
        offset = float(base.offset) if base and base.offset is not None else 0.0
        definitions[unit.name] = (*exponents, factor, offset)
    return definitions


def _unit_of(variable) -> str | None:
    return getattr(variable, "unit", None) or getattr(getattr(variable, "declaredType", None), "unit", None)


def _units(root: ET.Element, used: dict[str, tuple]) -> None:
    """`<ssd:Units>` defining every unit of `used` (name -> BaseUnit) under `root`."""
    if not used:
        return
    units = ET.SubElement(root, tag("ssd:Units"))
    for name, definition in sorted(used.items()):
        unit = ET.SubElement(units, tag("ssc:Unit"), name=name)
        attributes = {key: str(value) for key, value in zip(_BASE_UNIT, definition[:8], strict=True) if value}
        if definition[-2] != 1.0:
            attributes["factor"] = repr(definition[-2])
        if definition[-1] != 0.0:
            attributes["offset"] = repr(definition[-1])
        ET.SubElement(unit, tag("ssc:BaseUnit"), **attributes)


def system_structure(
    name: str,
    components: list[SspComponent],
    connections: list[SspConnection],
    stop_time: float,
    macro_step: float,
    master: str,
    annotation: tuple[str, ET.Element] | None = None,
) -> ET.Element:
    """The SystemStructureDescription element; `annotation` = (type, content) at the SSD level."""
    root = ET.Element(tag("ssd:SystemStructureDescription"), version="1.0", name=name)
    root.set("generationTool", "navcosim")
    system = ET.SubElement(root, tag("ssd:System"), name=name)
    units: dict[str, tuple] = {}
    connector_units: dict[str, str] = {}  # "component.variable" -> the unit its connector names
    bindings = ET.SubElement(system, tag("ssd:ParameterBindings"))
    ET.SubElement(bindings, tag("ssd:ParameterBinding"), source=PARAMETERS)
    used: dict[str, list[str]] = {c.name: [] for c in components}
    for connection in connections:
        for end in (connection.source, connection.target):
            component, _, variable = end.partition(".")
            if variable not in used[component]:
                used[component].append(variable)
    elements = ET.SubElement(system, tag("ssd:Elements"))
    for component in components:
        element = ET.SubElement(
            elements, tag("ssd:Component"), name=component.name, source=f"resources/{component.name}.fmu"
        )
        element.set("implementation", "CoSimulation")
        if used[component.name]:
            connectors = ET.SubElement(element, tag("ssd:Connectors"))
            for variable_name in used[component.name]:
                variable = component.variables[variable_name]
                connector = ET.SubElement(
                    connectors, tag("ssd:Connector"), name=variable_name, kind=_KINDS[variable.causality]
                )
                kind = _SSC_TYPES.get(variable.type, "Real")
                unit = _unit_of(variable) if kind == "Real" else None
                definition = _unit_definitions(Path(component.fmu)).get(unit) if unit else None
                if definition is not None:
                    if units.setdefault(unit, definition) != definition:
                        raise CosimError(
                            f"unit '{unit}' of {component.name}.{variable_name} is defined otherwise by "
                            "another FMU of the system; SSP has one definition per name"
                        )
                attributes = {"unit": unit} if definition is not None else {}
                if definition is not None:
                    connector_units[f"{component.name}.{variable_name}"] = unit
                ET.SubElement(connector, tag(f"ssc:{kind}"), **attributes)
        if component.parameters or component.inputs:
            # The component's own binding, bare names: libcosim and ecos read only these.
            binding = ET.SubElement(
                ET.SubElement(element, tag("ssd:ParameterBindings")), tag("ssd:ParameterBinding")
            )
            values = ET.SubElement(binding, tag("ssd:ParameterValues"))
            values.append(parameter_set(name, [component], prefixed=False))
        if component.period:
            content = _annotation(element, "ssd", COMPONENT_ANNOTATION)
            ET.SubElement(content, tag("nc:Component"), period=repr(component.period))
    if connections:
        wires = ET.SubElement(system, tag("ssd:Connections"))
        for connection in connections:
            start_element, _, start_connector = connection.source.partition(".")
            end_element, _, end_connector = connection.target.partition(".")
            wire = ET.SubElement(
                wires,
                tag("ssd:Connection"),
                startElement=start_element,
                startConnector=start_connector,
                endElement=end_element,
                endConnector=end_connector,
            )
            ends = connector_units.get(connection.source), connector_units.get(connection.target)
            if None not in ends and ends[0] != ends[1]:
                # navcosim connects values as they are (target = factor * source + offset); SSP
                # would convert between the units first.
                wire.set("suppressUnitConversion", "true")
            if connection.factor != 1.0 or connection.offset != 0.0:
                ET.SubElement(
                    wire,
                    tag("ssc:LinearTransformation"),
                    factor=repr(connection.factor),
                    offset=repr(connection.offset),
                )
    _units(root, units)
    experiment = ET.SubElement(root, tag("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(stop_time))
    simulation = _annotation(experiment, "ssd", SIMULATION_ANNOTATION)
    ET.SubElement(simulation, tag("nc:Simulation"), macroStep=repr(macro_step), master=master)
    if annotation is not None:
        kind, content = annotation
        _annotation(root, "ssd", kind).append(content)
    return root


def write_ssp(
    out: Path,
    ssd: ET.Element,
    ssv: ET.Element,
    components: list[SspComponent],
    resources: dict[str, bytes] | None = None,
) -> Path:
    """Validate the SSD and SSV and write the archive `out` with the FMUs and other `resources`."""
    schema.validate(ssd, "ssd", f"{out}: {SSD_NAME} (as written)")
    schema.validate(ssv, "ssv", f"{out}: {PARAMETERS} (as written)")
    for inline in ssd.iter(tag("ssv:ParameterSet")):
        schema.validate(inline, "ssv", f"{out}: {SSD_NAME}: inline parameter set (as written)")
    out = Path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr(SSD_NAME, schema.to_bytes(ssd))
            archive.writestr(PARAMETERS, schema.to_bytes(ssv))
            for component in components:
                archive.write(component.fmu, f"resources/{component.name}.fmu")
            for name, data in (resources or {}).items():
                archive.writestr(name, data)
    except OSError as error:
        raise CosimError(f"{out}: cannot write the SSP ({error.strerror or error})") from None
    return out
