"""Writing an SSP 1.0 archive: SystemStructure.ssd, one .ssv parameter set, the FMUs in resources/.

`write_ssp` takes a flat system in the reader's terms (`SspComponent`, `SspConnection` of
`cosim.ssp.read`: FMU variable names, FMU-level values) and writes what `open_ssp` reads
back to the same system, and what any SSP 1.0 tool reads: every FMU as `resources/<name>.fmu`,
its connectors (the variables that connections use, typed from its modelDescription.xml), the
connections with a `LinearTransformation` where factor or offset is not the identity, every value
in `resources/parameters.ssv` bound at the root system with hierarchical names, the stop time in
`DefaultExperiment`, and the macro step, master algorithm and component periods in navcosim's
annotations (SSP 1.0 has no place for them). Both XML files are checked against the normative
schemas before the archive is written.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from cosim.errors import CosimError
from cosim.ssp import schema
from cosim.ssp.read import (
    COMPONENT_ANNOTATION,
    SIMULATION_ANNOTATION,
    SSD_NAME,
    SspComponent,
    SspConnection,
)
from cosim.ssp.schema import tag

PARAMETERS = "resources/parameters.ssv"
_SSC_TYPES = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer"}
_SSC_TYPES |= {"Enumeration": "Integer", "Boolean": "Boolean"}
_KINDS = {"input": "input", "output": "output", "parameter": "parameter", "structuralParameter": "parameter"}


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


def parameter_set(name: str, components: list[SspComponent]) -> ET.Element:
    """The ssv:ParameterSet of every component's parameters and held input values."""
    root = ET.Element(tag("ssv:ParameterSet"), version="1.0", name=name)
    parameters = ET.SubElement(root, tag("ssv:Parameters"))
    for component in components:
        for variable_name, value in {**component.parameters, **component.inputs}.items():
            name = f"{component.name}.{variable_name}"
            parameter = ET.SubElement(parameters, tag("ssv:Parameter"), name=name)
            _value_element(parameter, component.variables[variable_name], value)
    return root


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
                unit = getattr(variable, "unit", None) if kind == "Real" else None
                ET.SubElement(connector, tag(f"ssc:{kind}"), **({"unit": unit} if unit else {}))
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
            if connection.factor != 1.0 or connection.offset != 0.0:
                ET.SubElement(
                    wire,
                    tag("ssc:LinearTransformation"),
                    factor=repr(connection.factor),
                    offset=repr(connection.offset),
                )
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
