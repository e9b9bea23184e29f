"""Reading an SSP 1.0 or 2.0 archive as one flat system of FMU components.

An SSP is a zip archive with `SystemStructure.ssd` at its root and the files that it references
(FMUs, .ssv parameter sets) beside it, usually under `resources/`. `open_ssp(path)` unpacks it,
checks the SSD and every parameter set against the normative schemas of its SSP version
(`cosim.ssp.schema`) and returns an `SspSystem`: the FMU components (a component inside nested
systems is named by its path with `_` for the dots, `follower.car` -> `follower_car`), the
connections between FMU variables, the parameter and start values, and the experiment. Every
error is one `CosimError` line naming the archive, the file and the element; an FMU is named by
its archive member (`resources/X.fmu`), never by the folder it was unpacked to.

Semantics, as SSP 1.0 and 2.0 define them:
- Connections join connectors of a system and of its direct elements; the data flows from an
  output (or a system's own input) to an input (or a system's own output), whatever the order of
  start and end. A connection end without `startElement`/`endElement`, or with it empty (as
  OMSimulator writes), is a connector of the system itself. Chains through the connectors of
  nested systems are followed to the FMU output
  that feeds each FMU input, composing the linear transformations (factor, offset) on the way.
  A system connector that nothing feeds but a parameter binding gives a value, passes that value
  on as a constant (start value of an input, value of a parameter).
- Parameter bindings (a .ssv file, `source`, or an inline `ssv:ParameterSet`, with an optional
  `prefix`) set parameters and the start values of inputs. A system's binding names variables
  hierarchically (`car.wheelbase` inside the system holding `car`). Later bindings override
  earlier ones of the same element; a binding higher in the hierarchy overrides lower ones. Names
  that match no variable are ignored, as the standard says. Values of every numeric SSP type
  (Real, Integer, Boolean, Enumeration; SSP 2.0's Float32/64, Int8..UInt64) are passed as numbers.
- Units: a connection between connectors whose type elements name different units (`<ssc:Real
  unit="mm"/>`) converts the value between them as SSP says, before its LinearTransformation,
  by the `ssd:Units` definitions (SI value = factor * value + offset); units of different SI base
  exponents, or a unit `ssd:Units` does not define, are an error naming both ends, unless the
  connection says suppressUnitConversion="true". A connector that names no unit is not checked.
- Time: `DefaultExperiment` gives startTime and stopTime; the macro step comes from navcosim's,
  the OSP or the OMS annotation, or the FMUs' own step sizes (`cosim.ssp.experiment`), and
  `SspSystem.macro_step_source` says which. A component's period comes from
  `<ssc:Annotation type="org.navcosim.component"><nc:Component period="0.05"/>`.

Components: an FMU runs as co-simulation, or as model exchange (integrated between communication
points by CVode, `cosim.fmi.model_exchange`) when the component says implementation="ModelExchange"
or says "any" (the default) of an FMU without co-simulation.

Not supported (an error, not a silent change of meaning): referenced SSDs/SSPs as components,
ScheduledExecution, signal dictionaries, parameter mappings (.ssm), mapping transformations,
connections that carry a calculated parameter, String, Binary and array values, unit conversion
of parameter values.

An archive is untrusted input: `open_ssp` extracts nothing from one with too many entries or too
large (`cosim.fmi.archive.unpack_problem`) or with a member outside it; an SSD may nest
`MAX_SYSTEM_DEPTH` systems and names of `MAX_NAME_LENGTH` characters, every source must be a path
inside the archive; each limit is a one-line error.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from cosim.core.component import closest_names
from cosim.errors import CosimError, shorten
from cosim.fmi.archive import DEFAULT_MAX_UNPACKED_SIZE, MIB, unpack_problem
from cosim.ssp import schema
from cosim.ssp.experiment import fmu_default_step, read_experiment
from cosim.ssp.schema import annotations_of, local_name, number, tag

SSD_NAME = "SystemStructure.ssd"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
COMPONENT_ANNOTATION = "org.navcosim.component"
_SOURCES = ("output", "calculatedParameter")  # kinds that give a value, seen from outside an element
_CAUSALITY_KINDS = {"input": "input", "output": "output", "parameter": "parameter"}
_CAUSALITY_KINDS |= {"structuralParameter": "parameter", "calculatedParameter": "calculatedParameter"}
_CAUSALITY_KINDS |= {"local": "local"}  # SSP 2.0's connector kind for an FMU's local variable
_REALS = ("Real", "Float64", "Float32")
_INTEGERS = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
# An archive is untrusted input: bounds on what its SSD may nest and name.
MAX_SYSTEM_DEPTH = 20  # systems inside systems below the root system
MAX_NAME_LENGTH = 200  # characters of an element's or connector's name, and of a component's
_BASE_UNIT = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")  # ssc:BaseUnit's SI exponents
DEFAULT_TIMEOUT = 10.0  # [s] longest FMI call of an FMU in a child process, as a scenario's default


@dataclass
class SspComponent:
    """One FMU of the system.

    name: the component's name in the navcosim System (an identifier);
    path: its hierarchical SSP name ("follower.car");
    fmu: the FMU file inside the unpacked archive;
    parameters: FMU parameter -> value; inputs: FMU input -> start value;
    period: [s] between its steps, 0 = every macro step;
    interface: how it runs, "cs" (co-simulation) or "me" (model exchange, `cosim.fmi.model_exchange`
    with its default solver, CVode);
    member: the FMU's archive member ("resources/X.fmu"), as messages and logs name it;
    default_step: [s] the FMU's own DefaultExperiment stepSize, None when it gives none;
    project: True when the file is byte for byte the project's own build of that FMU.
    """

    name: str
    path: str
    fmu: Path
    parameters: dict[str, float] = field(default_factory=dict)
    inputs: dict[str, float] = field(default_factory=dict)
    period: float = 0.0
    variables: dict = field(default_factory=dict, repr=False)  # FMU variable name -> fmpy variable
    member: str = ""
    default_step: float | None = None
    interface: str = "cs"  # "cs" co-simulation, "me" model exchange (integrated by CVode)
    project: bool = False  # its bytes are the project's own build of its model (`is_project_fmu`)


@dataclass(frozen=True)
class SspConnection:
    """FMU output -> FMU input ("component.variable"); target = factor * source + offset."""

    source: str
    target: str
    factor: float = 1.0
    offset: float = 0.0


@dataclass
class SspSystem:
    """A flattened SSP: what `cosim run X.ssp` builds and runs."""

    source: str  # the archive, as errors name it
    name: str  # the SSD's name
    directory: Path  # the unpacked archive
    components: list[SspComponent]
    connections: list[SspConnection]
    start_time: float
    stop_time: float | None  # [s] from DefaultExperiment
    macro_step: float | None  # [s] from an annotation or the FMUs (see the module docstring)
    master: str | None
    annotations: dict[str, ET.Element]  # SSD-level annotations by type: their content element
    ssd_text: bytes = b""
    macro_step_source: str = ""  # where macro_step comes from, as the run summary says it
    version: str = "1.0"  # the SSD's SSP version ('1.0' or '2.0')

    def component(self, name: str) -> SspComponent:
        for component in self.components:
            if component.name == name:
                return component
        raise CosimError(f"{self.source}: no component '{name}'")

    def members(self, text: str) -> str:
        """`text` with every path into the unpacked archive written as the archive member."""
        return archive_members(self.directory, text)


def archive_members(directory: Path, text: str) -> str:
    """`text` with the unpacked archive's folder `directory/` taken off the paths into it, so that
    they read as archive members (`resources/X.fmu`): what the user knows, and the same in every run."""
    for folder in {str(directory), str(directory.resolve())}:
        text = text.replace(folder.rstrip("/") + "/", "")
    return text


def max_unpacked_size(overrides: dict[str, object]) -> int:
    """[bytes] what the archive (and each FMU in it) may unpack to: `simulation.fmu_max_size` MiB
    of a run's overrides (`cosim.ssp.run.parse_overrides`), else the default 1 GiB."""
    if "fmu_max_size" in overrides:
        return round(float(overrides["fmu_max_size"]) * MIB)
    return DEFAULT_MAX_UNPACKED_SIZE


@contextmanager
def open_ssp(path: str | Path, max_unpacked_size: int | None = None) -> Iterator[SspSystem]:
    """Unpack the archive `path` into a temporary folder, read it, and delete the folder on exit.

    Nothing is extracted from an archive with more entries than `cosim.fmi.archive.MAX_ENTRIES`
    or whose entries declare more than `max_unpacked_size` bytes in all (default 1 GiB, as an FMU),
    nor from one with a member that points outside it."""
    path = Path(path)
    source = shorten(path, 200)
    if not path.is_file():
        raise CosimError(f"{source}: no such SSP file")
    if not zipfile.is_zipfile(path):
        raise CosimError(f"{source}: not a zip archive (an SSP is a zip with {SSD_NAME} at its root)")
    try:
        with zipfile.ZipFile(path) as archive:
            _check_members(archive, source, max_unpacked_size)
            directory = Path(tempfile.mkdtemp(prefix="navcosim-ssp-"))
            try:
                archive.extractall(directory)
            except BaseException:
                shutil.rmtree(directory, ignore_errors=True)
                raise
    except (zipfile.BadZipFile, OSError) as error:
        raise CosimError(f"{source}: cannot unpack: {error}") from None
    try:
        yield read_ssd(directory, source, max_unpacked_size)
    finally:
        shutil.rmtree(directory, ignore_errors=True)


def _check_members(archive: zipfile.ZipFile, source: str, max_unpacked_size: int | None) -> None:
    """What `open_ssp` checks before it extracts anything (`CosimError` naming `source`)."""
    names = archive.namelist()
    if SSD_NAME not in names:
        raise CosimError(f"{source}: the archive has no {SSD_NAME} at its root")
    problem = unpack_problem(archive, max_unpacked_size)
    if problem is not None:
        hint = "; raise the limit with --set simulation.fmu_max_size=MIB if you trust it"
        hint = hint if problem.startswith("would") else ""
        raise CosimError(f"{source}: the SSP archive {problem}; not extracted{hint}")
    for name in names:
        member = PurePosixPath(name.replace("\\", "/"))
        if member.is_absolute() or ".." in member.parts:
            raise CosimError(f"{source}: archive member '{shorten(name)}' points outside the archive")


def read_ssd(directory: Path, source: str, max_unpacked_size: int | None = None) -> SspSystem:
    """Read `directory/SystemStructure.ssd` (an unpacked SSP); errors name `source`; each FMU may
    unpack to `max_unpacked_size` bytes (default 1 GiB)."""
    ssd_path = directory / SSD_NAME
    data = ssd_path.read_bytes()
    where = f"{source}: {SSD_NAME}"
    root = schema.parse(data, "ssd", where)
    reader = _Reader(directory, source, where)
    reader.units = _unit_definitions(root)
    reader.max_unpacked_size = max_unpacked_size
    system = root.find(tag("ssd:System"))
    reader.system(system, ())
    components = reader.finish()
    start_time, stop_time, macro_step, master, source_of_step = read_experiment(root, components, where)
    return SspSystem(
        source=source,
        name=root.get("name", ""),
        directory=directory,
        components=components,
        connections=reader.connections,
        start_time=start_time,
        stop_time=stop_time,
        macro_step=macro_step,
        master=master,
        annotations=annotations_of(root),
        ssd_text=data,
        macro_step_source=source_of_step,
        version=schema.version_of(root),
    )


def component_name(path: tuple[str, ...]) -> str:
    """The navcosim component name of an element path: joined by '_', other characters '_'."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", "_".join(path))
    return f"_{name}" if name[:1].isdigit() else name


@dataclass
class _Node:
    """A connector of a component or a system (`owner` = the element's path)."""

    owner: tuple[str, ...]
    name: str
    kind: str
    is_system: bool
    unit: str | None = None  # the unit its type element (ssc:Real) names


class _Reader:
    """Walks the system hierarchy, collecting components, connector nodes, edges and bindings."""

    def __init__(self, directory: Path, source: str, where: str) -> None:
        self.directory = directory
        self.source = source
        self.where = where
        self.components: dict[tuple[str, ...], SspComponent] = {}
        self.systems: set[tuple[str, ...]] = set()
        self.nodes: dict[tuple[tuple[str, ...], str], _Node] = {}
        self.incoming: dict[tuple, tuple[tuple, float, float, str]] = {}  # sink -> (source, f, o, what)
        self.bindings: list[tuple[int, int, str, str, str, str | None, str]] = []
        self.connections: list[SspConnection] = []
        self.units: dict[str, tuple] = {}  # ssd:Units: name -> (SI exponents, factor, offset)
        self.max_unpacked_size: int | None = None  # [bytes] of each FMU (None: the default)

    # ---- hierarchy ---------------------------------------------------------------------------

    def system(self, element: ET.Element, path: tuple[str, ...]) -> None:
        if len(path) > MAX_SYSTEM_DEPTH:
            raise CosimError(
                f"{self.where}: {_where(path)}: systems nest more than {MAX_SYSTEM_DEPTH} deep "
                f"(the limit of navcosim)"
            )
        self.systems.add(path)
        self._connectors(element, path, True)
        self._bindings(element, path)
        elements = element.find(tag("ssd:Elements"))
        names: set[str] = set()
        for child in list(elements) if elements is not None else []:
            name = child.get("name", "")
            self._check_name(name, f"{_where(path)}: element")
            if name in names:
                raise CosimError(f"{self.where}: system '{_dotted(path)}' has two elements named '{name}'")
            names.add(name)
            if child.tag == tag("ssd:Component"):
                self.component(child, path + (name,))
            elif child.tag == tag("ssd:System"):
                self.system(child, path + (name,))
            else:
                raise CosimError(
                    f"{self.where}: {_where(path + (name,))}: {local_name(child.tag)} is not supported"
                )
        for connection in element.iterfind(f"{tag('ssd:Connections')}/{tag('ssd:Connection')}"):
            self._connection(connection, path)
        if element.find(tag("ssd:SignalDictionaries")) is not None:
            raise CosimError(f"{self.where}: {_where(path)}: signal dictionaries are not supported")

    def component(self, element: ET.Element, path: tuple[str, ...]) -> None:
        where = f"{self.where}: {_where(path)}"
        kind = element.get("type", FMU_TYPE)
        if kind != FMU_TYPE:
            raise CosimError(f"{where}: component type '{kind}' is not supported (only FMUs, {FMU_TYPE})")
        implementation = element.get("implementation", "any")
        if implementation == "ScheduledExecution":
            raise CosimError(f"{where}: implementation 'ScheduledExecution' is not supported")
        member = element.get("source", "")
        fmu_path = self._resource(member, where)
        member = PurePosixPath(member).as_posix()
        name = component_name(path)
        if len(name) > MAX_NAME_LENGTH:
            raise CosimError(
                f"{where}: its component name '{shorten(name, 60)}' ({len(name)} characters, the element "
                f"path joined by '_') is longer than {MAX_NAME_LENGTH} characters"
            )
        try:
            interface = _interface(fmu_path, implementation)
            fmu = component_class(interface)(fmu_path, name, max_unpacked_size=self.max_unpacked_size)
        except CosimError as error:
            raise CosimError(f"{where}: {archive_members(self.directory, str(error))}") from None
        variables = {v.name: v for v in fmu.model_description.modelVariables}
        period = 0.0
        annotation = annotations_of(element).get(COMPONENT_ANNOTATION)
        if annotation is not None and annotation.get("period") is not None:
            period = number(annotation, "period", where)
        self.components[path] = SspComponent(
            name,
            _dotted(path),
            fmu_path,
            period=period,
            variables=variables,
            member=member,
            default_step=fmu_default_step(fmu.model_description),
            interface=interface,
            project=is_project_fmu(fmu_path, fmu.model_description, fmu.fmi_version),
        )
        for connector in self._connectors(element, path, False):
            variable = variables.get(connector.get("name"))
            if variable is None:
                raise CosimError(
                    f"{where}: connector '{connector.get('name')}' is not a variable of {member}; "
                    f"variables: {closest_names(connector.get('name'), variables)}"
                )
            expected = _CAUSALITY_KINDS.get(variable.causality)
            if connector.get("kind") == "unspecified" and expected is not None:
                # SSP 2.0: the flow is not given here; the FMU's causality gives it.
                self.nodes[(path, variable.name)].kind = expected
            elif connector.get("kind") != expected:
                raise CosimError(
                    f"{where}: connector '{variable.name}' has kind '{connector.get('kind')}' but the FMU "
                    f"variable's causality is '{variable.causality}'"
                )
        self._bindings(element, path)

    def _connectors(self, element: ET.Element, path: tuple[str, ...], is_system: bool) -> list[ET.Element]:
        connectors = element.findall(f"{tag('ssd:Connectors')}/{tag('ssd:Connector')}")
        for connector in connectors:
            name, kind = connector.get("name", ""), connector.get("kind", "")
            self._check_name(name, f"{_where(path)}: connector")
            if (path, name) in self.nodes:
                raise CosimError(f"{self.where}: {_where(path)}: connector '{name}' declared twice")
            if kind == "inout":
                raise CosimError(
                    f"{self.where}: {_where(path)}: connector '{name}': kind 'inout' is not supported"
                )
            types = [child for child in connector if child.get("unit")]
            unit = types[0].get("unit") if types else None
            self.nodes[(path, name)] = _Node(path, name, kind, is_system, unit)
        return connectors

    def _check_name(self, name: str, what: str) -> None:
        if len(name) > MAX_NAME_LENGTH:
            raise CosimError(
                f"{self.where}: {what} name '{shorten(name, 60)}' is {len(name):,} characters long, "
                f"more than {MAX_NAME_LENGTH}"
            )

    def _resource(self, uri: str, where: str) -> Path:
        relative = PurePosixPath(uri)
        if not uri or uri.startswith("#") or "://" in uri or relative.is_absolute() or ".." in relative.parts:
            raise CosimError(f"{where}: source '{uri}' must be a relative path inside the archive")
        path = self.directory / relative
        if not path.is_file():
            raise CosimError(f"{where}: source '{uri}' is not in the archive")
        return path

    # ---- connections -------------------------------------------------------------------------

    def _endpoint(self, system: tuple[str, ...], element: str | None, connector: str, where: str):
        owner = system if element is None else system + (element,)
        if element is not None and owner not in self.components and owner not in self.systems:
            raise CosimError(f"{where}: no element '{element}' in {_where(system)}")
        node = self.nodes.get((owner, connector))
        if node is None:
            known = [name for (path, name) in self.nodes if path == owner]
            raise CosimError(
                f"{where}: {_where(owner)} has no connector '{connector}'; "
                f"connectors: {closest_names(connector, known) or 'none'}"
            )
        # Seen from inside its own system, a system's input gives a value and its output takes one.
        gives = node.kind in _SOURCES if element is not None else node.kind in ("input", "parameter")
        return (owner, connector), node, gives

    def _connection(self, element: ET.Element, system: tuple[str, ...]) -> None:
        # An empty element name (OMSimulator's way) names the system's own connector, as no name does.
        start = (element.get("startElement") or None, element.get("startConnector"))
        end = (element.get("endElement") or None, element.get("endConnector"))
        what = f"{_dotted(system + ((start[0],) if start[0] else ()) + (start[1],))} -> " + _dotted(
            system + ((end[0],) if end[0] else ()) + (end[1],)
        )
        where = f"{self.where}: connection {what}"
        first, first_node, first_gives = self._endpoint(system, *start, where)
        second, second_node, second_gives = self._endpoint(system, *end, where)
        if first_gives == second_gives:
            side = "give" if first_gives else "take"
            kinds = f"{first_node.kind}, {second_node.kind}"
            raise CosimError(f"{where}: both connectors {side} a value (kinds {kinds})")
        source, sink = (first, second) if first_gives else (second, first)
        if "calculatedParameter" in (first_node.kind, second_node.kind):
            raise CosimError(f"{where}: connections of calculated parameters are not supported")
        factor, offset = 1.0, 0.0
        for child in element:
            if child.tag == tag("ssc:LinearTransformation"):
                factor = float(child.get("factor", 1.0))
                offset = float(child.get("offset", 0.0))
            elif child.tag.endswith("MappingTransformation"):
                raise CosimError(f"{where}: {local_name(child.tag)} is not supported")
        suppress = (element.get("suppressUnitConversion") or "false").strip() in ("true", "1")
        conversion = None if suppress else self._conversion(source, sink, where)
        if conversion is not None:
            # SSP: the source value is converted to the target's unit first, then transformed.
            factor, offset = factor * conversion[0], factor * conversion[1] + offset
        if sink in self.incoming:
            raise CosimError(f"{where}: {_dotted(sink[0] + (sink[1],))} is already connected")
        self.incoming[sink] = (source, factor, offset, where)

    def _conversion(self, source: tuple, sink: tuple, where: str) -> tuple[float, float] | None:
        """(factor, offset) that convert a value in the unit of connector `source` to the unit of
        `sink` (SSP's automatic unit conversion), None when they agree or one of them has no unit;
        `CosimError` naming both ends when the units do not convert into each other."""
        units = self.nodes[source].unit, self.nodes[sink].unit
        if None in units or units[0] == units[1]:
            return None
        pairs = zip(units, (source, sink), strict=True)
        ends = [f"'{unit}' at {_dotted(key[0] + (key[1],))}" for unit, key in pairs]
        definitions = [self.units.get(unit) for unit in units]
        for unit, definition in zip(units, definitions, strict=True):
            if definition is None:
                raise CosimError(
                    f"{where}: units differ ({ends[0]}, {ends[1]}) and '{unit}' is not defined in "
                    'ssd:Units, so they cannot be converted (or say suppressUnitConversion="true")'
                )
        (exponents, f_source, o_source), (target_exponents, f_target, o_target) = definitions
        if exponents != target_exponents:
            raise CosimError(
                f"{where}: units do not agree: {ends[0]} and {ends[1]} have different SI base units "
                '(or say suppressUnitConversion="true" on the connection)'
            )
        # SI value = factor * value + offset, for either unit.
        return f_source / f_target, (o_source - o_target) / f_target

    # ---- parameter bindings ------------------------------------------------------------------

    def _bindings(self, element: ET.Element, path: tuple[str, ...]) -> None:
        where = f"{self.where}: {_where(path)}"
        for order, binding in enumerate(
            element.iterfind(f"{tag('ssd:ParameterBindings')}/{tag('ssd:ParameterBinding')}")
        ):
            kind = binding.get("type", PARAMETER_SET_TYPE)
            if kind != PARAMETER_SET_TYPE:
                raise CosimError(f"{where}: parameter binding type '{kind}' is not supported")
            if binding.find(tag("ssd:ParameterMapping")) is not None:
                raise CosimError(f"{where}: parameter mappings (.ssm) are not supported")
            prefix = binding.get("prefix", "")
            uri = binding.get("source")
            if uri is not None:
                if binding.get("sourceBase", "SSD") != "SSD":
                    raise CosimError(f"{where}: parameter binding sourceBase 'component' is not supported")
                file_where = f"{self.source}: {uri}"
                parameter_set = schema.parse(self._resource(uri, where).read_bytes(), "ssv", file_where)
            else:
                values = binding.find(tag("ssd:ParameterValues"))
                parameter_set = values.find(tag("ssv:ParameterSet")) if values is not None else None
                file_where = f"{where}: inline parameter set"
                if parameter_set is None:
                    raise CosimError(f"{where}: parameter binding without source or inline ssv:ParameterSet")
                schema.validate(parameter_set, "ssv", file_where)
            for parameter in parameter_set.iterfind(f"{tag('ssv:Parameters')}/{tag('ssv:Parameter')}"):
                value = list(parameter)[0]
                name = path + tuple((prefix + parameter.get("name", "")).split("."))
                text = value.get("value")
                if text is None:  # SSP 2.0: the values as ssv:Value children
                    text = " ".join(item.get("value", "") for item in value.iterfind(tag("ssv:Value")))
                entry = (-len(path), order, _dotted(name), local_name(value.tag), text)
                self.bindings.append(entry + (value.get("unit"), file_where))

    def _apply_bindings(self) -> dict[tuple, float]:
        """Apply every binding, deepest first (higher levels override); returns system connector values."""
        system_values: dict[tuple, float] = {}
        for _, _, name, kind, text, unit, where in sorted(self.bindings, key=lambda b: (b[0], b[1])):
            target = self._resolve(name)
            if target is None:
                continue  # the standard: names that match no variable are ignored
            if target[0] == "system":
                system_values[target[1]] = _value(kind, text, None, f"{where}: parameter '{name}'")
                continue
            component, variable = target[1], target[2]
            fmu_variable = component.variables[variable]
            value = _value(kind, text, fmu_variable, f"{where}: parameter '{name}'")
            _check_unit(unit, fmu_variable, f"{where}: parameter '{name}'")
            causality = fmu_variable.causality
            if causality in ("parameter", "structuralParameter"):
                component.parameters[variable] = value
            elif causality == "input":
                component.inputs[variable] = value
            else:
                raise CosimError(
                    f"{where}: parameter '{name}': {component.path}.{variable} has causality '{causality}'; "
                    "only parameters and inputs can be given values"
                )
        return system_values

    def _resolve(self, name: str):
        """A hierarchical name -> ("component", SspComponent, variable) or ("system", node key)."""
        parts = tuple(name.split("."))
        for split in range(len(parts) - 1, -1, -1):
            owner, rest = parts[:split], ".".join(parts[split:])
            if owner in self.components and rest in self.components[owner].variables:
                return "component", self.components[owner], rest
            if owner in self.systems and (owner, rest) in self.nodes:
                return "system", (owner, rest)
        return None

    # ---- flattening --------------------------------------------------------------------------

    def finish(self) -> list[SspComponent]:
        """Apply the bindings and follow every FMU input back to its FMU output (or constant)."""
        system_values = self._apply_bindings()
        names: dict[str, str] = {}
        for component in self.components.values():
            if component.name in names:
                raise CosimError(
                    f"{self.where}: elements '{names[component.name]}' and '{component.path}' both become "
                    f"component '{component.name}'; rename one"
                )
            names[component.name] = component.path
        for key, node in self.nodes.items():
            if node.is_system or node.kind not in ("input", "parameter") or key not in self.incoming:
                continue
            component = self.components[node.owner]
            factor, offset, current, seen = 1.0, 0.0, key, {key}
            while current in self.incoming:
                source, f, o, where = self.incoming[current]
                factor, offset = factor * f, factor * o + offset
                if source in seen:
                    raise CosimError(f"{where}: the connection chain loops through system connectors")
                seen.add(source)
                current = source
            origin = self.nodes[current]
            if not origin.is_system:
                if node.kind == "parameter":
                    raise CosimError(f"{where}: a parameter can only be fed a constant, not an output")
                producer = self.components[origin.owner]
                source_name, target_name = f"{producer.name}.{origin.name}", f"{component.name}.{node.name}"
                self.connections.append(SspConnection(source_name, target_name, factor, offset))
            elif current in system_values:
                value = factor * system_values[current] + offset
                target = component.parameters if node.kind == "parameter" else component.inputs
                target[node.name] = value
        return list(self.components.values())


def _interface(fmu: Path, implementation: str) -> str:
    """The interface to run: "me" for implementation="ModelExchange", and for "any" of an FMU
    without co-simulation; else "cs"."""
    if implementation == "ModelExchange":
        return "me"
    if implementation == "CoSimulation":
        return "cs"
    import fmpy

    try:
        description = fmpy.read_model_description(str(fmu), validate=False)
    except Exception:
        return "cs"  # the component reports what is wrong with the FMU
    return "me" if description.coSimulation is None and description.modelExchange is not None else "cs"


def is_project_fmu(path: Path, description, fmi_version: int) -> bool:
    """True when the FMU file `path` is byte for byte the project's own build of its model (one of
    `cosim.fmi.builtin`'s FMUs, as `cosim ssp export` packs them): code that navcosim ships, which
    "auto" isolation runs in-process as a scenario runs its project FMUs."""
    from cosim.fmi.builtin import GENERATION_TOOL, builtin_fmu, known_names

    name = getattr(description, "modelName", "")
    tool = getattr(description, "generationTool", "") or ""
    if not tool.startswith(GENERATION_TOOL) or fmi_version not in (2, 3) or name not in known_names():
        return False
    try:
        own = builtin_fmu(name, fmi_version)
        if own.stat().st_size != path.stat().st_size:
            return False
        return own.read_bytes() == path.read_bytes()
    except (CosimError, OSError):
        return False


def component_class(interface: str):
    """The component class of an interface: `FmuComponent` ("cs") or `ModelExchangeComponent` ("me")."""
    if interface == "me":
        from cosim.fmi.model_exchange import ModelExchangeComponent

        return ModelExchangeComponent
    from cosim.fmi.component import FmuComponent

    return FmuComponent


def _value(kind: str, text: str | None, variable, where: str) -> float:
    """A parameter value as the float navcosim passes (Booleans 0/1, enumerations their integer);
    `text` is the value attribute, or the ssv:Value children's values joined by a space (SSP 2.0)."""
    if kind in ("String", "Binary"):
        raise CosimError(
            f"{where}: {kind} values are not supported (navcosim sets numbers: Real, Float32/64, "
            "Integer, Int8..UInt64, Boolean, Enumeration)"
        )
    if text is None or len(text.split()) != 1:
        raise CosimError(f"{where}: one value expected, got {text!r} (array values are not supported)")
    if kind in _REALS:
        return float(text)
    if kind in _INTEGERS:
        return float(int(text))
    if kind == "Boolean":
        return 1.0 if text.strip() in ("true", "1") else 0.0
    if kind == "Enumeration":
        items = getattr(getattr(variable, "declaredType", None), "items", None) or []
        for item in items:
            if item.name == text:
                return float(item.value)
        known = ", ".join(item.name for item in items) or "none"
        raise CosimError(f"{where}: '{text}' is not an item of the variable's enumeration ({known})")
    raise CosimError(
        f"{where}: {kind} values are not supported (navcosim sets Real, Integer, Boolean, Enumeration)"
    )


def _check_unit(unit: str | None, variable, where: str) -> None:
    if not unit:
        return
    declared = getattr(variable, "unit", None)
    declared = declared or getattr(getattr(variable, "declaredType", None), "unit", None)
    if declared and declared != unit:
        raise CosimError(
            f"{where}: unit '{unit}' differs from the variable's '{declared}' (no unit conversion)"
        )


def _unit_definitions(root: ET.Element) -> dict[str, tuple]:
    """The SSD's `ssd:Units`: name -> (SI exponents kg..rad, factor, offset) of its ssc:BaseUnit."""
    definitions: dict[str, tuple] = {}
    units = root.find(tag("ssd:Units"))
    for unit in units.iterfind(tag("ssc:Unit")) if units is not None else ():
        base = unit.find(tag("ssc:BaseUnit"))
        base = base if base is not None else ET.Element("none")
        exponents = tuple(int(base.get(name, 0)) for name in _BASE_UNIT)
        definitions[unit.get("name", "")] = (
            exponents,
            float(base.get("factor", 1.0)),
            float(base.get("offset", 0.0)),
        )
    return definitions


def _component(spec: SspComponent, isolation: str, timeout: float, max_unpacked_size: int | None):
    """The component of one FMU, in a child process (`isolation` "process") or in this one."""
    options = {"period": spec.period, "max_unpacked_size": max_unpacked_size}
    if isolation == "process":
        from cosim.fmi.isolated import IsolatedFmuComponent

        integration = (
            {"solver": "cvode", "tolerance": None, "max_step": None} if spec.interface == "me" else None
        )
        return IsolatedFmuComponent(spec.fmu, spec.name, timeout=timeout, integration=integration, **options)
    return component_class(spec.interface)(spec.fmu, spec.name, **options)


def _dotted(path: tuple[str, ...]) -> str:
    return ".".join(path)


def _where(path: tuple[str, ...]) -> str:
    return f"element '{_dotted(path)}'" if path else "the root system"


def _check_starts(ssp: SspSystem, system) -> None:
    """An input that no connection feeds keeps its start value: one without (neither in the FMU nor
    bound by the SSP) is a `CosimError` naming it."""
    from cosim.fmi.layout import fmu_layout
    from cosim.scenario.params import unstarted_inputs, unstarted_problem

    fed = {connection.target for connection in (*system.connections, *system.text_connections)}
    for spec in ssp.components:
        for port in unstarted_inputs(fmu_layout(spec.fmu, spec.name)):
            if f"{spec.name}.{port}" not in fed and port not in spec.inputs:
                where = f"{ssp.source}: {_where(tuple(spec.path.split('.')))}"
                raise CosimError(f"{where}: {unstarted_problem(port, 'connect it or bind its start value')}")


def build_system(
    ssp: SspSystem,
    macro_step: float,
    master: str = "gauss-seidel",
    isolation: str = "auto",
    timeout: float = DEFAULT_TIMEOUT,
    max_unpacked_size: int | None = None,
):
    """A `System` of the SSP's FMU components and connections, and the parameters for `Master`.

    Each FMU runs where `isolation` says, as a scenario's `[simulation] fmu_isolation`: "process"
    in a child process (`cosim.fmi.isolated`, each FMI call limited to `timeout` seconds), "none"
    in this process, "auto" in-process for the project's own FMUs (`SspComponent.project`) and in
    a child process for any other. Each FMU may unpack to `max_unpacked_size` bytes (default 1 GiB).
    Input start values from parameter bindings are staged in the components' input buffers, which
    `Master.initialize` sends before initialising each FMU (connected inputs are then overwritten).
    """
    from cosim.core.system import System

    system = System(macro_step, master)
    parameters: dict[str, dict[str, float]] = {}
    for spec in ssp.components:
        where = f"{ssp.source}: {_where(tuple(spec.path.split('.')))}"
        where_run = isolation if isolation != "auto" else ("none" if spec.project else "process")
        try:
            component = _component(spec, where_run, timeout, max_unpacked_size)
            for name, value in spec.inputs.items():
                component.input_buffer[component.input_index[name]] = value
            system.add(component)
            system.period_steps(component)
        except CosimError as error:
            raise CosimError(f"{where}: {ssp.members(str(error))}") from None
        parameters[spec.name] = dict(spec.parameters)
    for connection in ssp.connections:
        try:
            system.connect(connection.source, connection.target, connection.factor, connection.offset)
        except CosimError as error:
            message = str(error)  # the master's own messages may already name the connection
            if not message.startswith("connection "):
                message = f"connection {connection.source} -> {connection.target}: {message}"
            raise CosimError(f"{ssp.source}: {message}") from None
    _check_starts(ssp, system)
    try:
        system.order()  # an algebraic loop runs delayed (`System.loops`, the default "delay")
    except CosimError as error:
        raise CosimError(f"{ssp.source}: {error}") from None
    return system, parameters
