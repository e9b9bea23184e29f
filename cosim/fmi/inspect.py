"""What is inside an FMU (FMI 2.0 or 3.0) and whether it is valid: the logic of `cosim fmu info/validate`."""

from __future__ import annotations

import ctypes
import math
import os
import platform
import re
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import fmpy
import fmpy.model_description as fmpy_description
import fmpy.validation as fmpy_validation
from fmpy.validation import validate_fmu

from cosim.errors import CosimError
from cosim.fmi.builtin import builtin_fmu, known_names

FMPY_HEADERS = Path(fmpy.__file__).parent / "c-code"
_ELEMENT = re.compile(r"^(?P<base>.+)\[(?P<indices>\d+(?:,\d+)*)\]$")


@dataclass
class VariableRow:
    """One row of the variable table; an array of scalars `a[i,j]` collapses into one row."""

    name: str
    causality: str
    variability: str
    type: str
    unit: str
    start: str
    description: str


def resolve(file_or_name: str, fmi_version: int = 2) -> Path:
    """An FMU file path, or the built FMU of a project FMU name in FMI `fmi_version`."""
    path = Path(file_or_name)
    if path.exists():
        return path
    if file_or_name in known_names():
        return builtin_fmu(file_or_name, fmi_version)
    raise CosimError(f"{file_or_name}: no such file and not a project FMU ({', '.join(known_names())})")


def read_description(path: Path):
    """fmpy's ModelDescription of `path`; one-line CosimError for anything that is not an FMU."""
    if path.is_dir():
        raise CosimError(f"{path}: is a directory, not an .fmu file")
    if not zipfile.is_zipfile(path):
        raise CosimError(f"{path}: not an FMU (not a zip archive)")
    with zipfile.ZipFile(path) as archive:
        if "modelDescription.xml" not in archive.namelist():
            raise CosimError(f"{path}: not an FMU (no modelDescription.xml)")
    try:
        return fmpy.read_model_description(str(path), validate=False)
    except Exception as error:  # fmpy raises many types for a malformed description
        raise CosimError(f"{path}: unreadable modelDescription.xml ({error})") from None


def _unit(variable) -> str:
    if getattr(variable, "unit", None):
        return variable.unit
    declared = getattr(variable, "declaredType", None)
    return getattr(declared, "unit", None) or ""


def _start(variable) -> str:
    start = variable.start
    if start is None:
        return ""
    text = str(start)
    return text if len(text) <= 24 else text[:21] + "..."


def _dimension_sizes(variable, description) -> list[int | None]:
    """Each dimension's size: its start, or the start of the structural parameter it names (None
    when neither gives a number)."""
    by_reference = {v.valueReference: v for v in description.modelVariables}
    sizes: list[int | None] = []
    for dimension in getattr(variable, "dimensions", None) or []:
        size = dimension.start
        if size is None and dimension.valueReference is not None:
            size = getattr(by_reference.get(dimension.valueReference), "start", None)
        try:
            sizes.append(int(size))
        except (TypeError, ValueError):
            sizes.append(None)
    return sizes


def _array_row(variable, description, row: VariableRow) -> VariableRow:
    """An FMI 3.0 array variable: its shape in the name, one start when all elements share it."""
    sizes = _dimension_sizes(variable, description)
    row.name = variable.name + "".join(f"[{size if size is not None else '?'}]" for size in sizes)
    starts = str(variable.start).split() if variable.start is not None else []
    row.start = starts[0] if len(set(starts)) == 1 else ("(varies)" if starts else "")
    count = math.prod(size or 0 for size in sizes)
    row.description = f"array of {count} elements; {row.description}".rstrip("; ")
    return row


def variable_rows(description) -> list[VariableRow]:
    """The variable table: scalars as they are, FMI 3.0 arrays with their shape, FMI 2.0 arrays of
    scalars summarised with their index ranges."""
    rows: list[VariableRow] = []
    groups: dict[str, tuple[VariableRow, list[list[int]], set[tuple[str, str]]]] = {}
    first_name: dict[str, str] = {}
    for variable in description.modelVariables:
        row = VariableRow(
            name=variable.name,
            causality=variable.causality or "",
            variability=variable.variability or "",
            type=variable.type,
            unit=_unit(variable),
            start=_start(variable),
            description=variable.description or "",
        )
        if getattr(variable, "dimensions", None):
            rows.append(_array_row(variable, description, row))
            continue
        match = _ELEMENT.match(variable.name)
        if match is None:
            rows.append(row)
            continue
        indices = [int(i) for i in match["indices"].split(",")]
        # Elements of one array differ in one or more indices: group by the base name and rank.
        key = f"{match['base']}/{len(indices)}/{row.causality}"
        if key not in groups:
            groups[key] = (row, [], set())
            first_name[key] = variable.name
            rows.append(row)
        _, seen, texts = groups[key]
        seen.append(indices)
        texts.add((row.start, row.description))
    for key, (row, seen, texts) in groups.items():
        base = key.split("/")[0]
        ranges = []
        for axis in zip(*seen, strict=True):
            low, high = min(axis), max(axis)
            ranges.append(str(low) if low == high else f"{low}..{high}")
        row.name = f"{base}[{','.join(ranges)}]"
        starts, descriptions = {start for start, _ in texts}, {text for _, text in texts}
        row.start = row.start if len(starts) == 1 else "(varies)"
        example = "" if len(descriptions) == 1 else f"e.g. {first_name[key]}: "
        row.description = f"{len(seen)} elements; {example}{row.description}"
    return rows


def format_info(path: Path) -> str:
    """The text of `cosim fmu info`."""
    description = read_description(path)
    kinds = [
        k for k in ("coSimulation", "modelExchange", "scheduledExecution") if getattr(description, k, None)
    ]
    lines = [
        f"file:            {path}",
        f"FMI version:     {description.fmiVersion}",
        f"model name:      {description.modelName}",
        f"GUID:            {description.guid}",
        f"generation tool: {description.generationTool or ''}",
        f"interfaces:      {', '.join(kinds)}",
        f"description:     {description.description or ''}",
        "",
    ]
    header = VariableRow("name", "causality", "variability", "type", "unit", "start", "description")
    rows = [header, *variable_rows(description)]
    fields = ("name", "causality", "variability", "type", "unit", "start")
    widths = {f: max(len(getattr(r, f)) for r in rows) for f in fields}
    for row in rows:
        cells = [getattr(row, f).ljust(widths[f]) for f in fields]
        lines.append("  ".join([*cells, row.description]).rstrip())
    return "\n".join(lines)


def _platform_binaries(fmi_version: str) -> tuple[str, str]:
    """(binaries folder, library suffix) of this machine for an FMI major version."""
    machine = platform.machine().lower()
    system = {"Linux": "linux", "Darwin": "darwin", "Windows": "win"}.get(
        platform.system(), platform.system()
    )
    suffix = {"linux": ".so", "darwin": ".dylib", "win": ".dll"}.get(system, ".so")
    if fmi_version.startswith("3"):
        arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
        system3 = {"win": "windows"}.get(system, system)
        return f"{arch}-{system3}", suffix
    bits = "64" if sys.maxsize > 2**32 else "32"
    return f"{system}{bits}", suffix


def required_functions(fmi_version: str, interfaces: tuple[str, ...] = ("cs", "me")) -> list[str]:
    """The FMI API functions an FMU's binary must export for `interfaces` ("cs", "me"), read from
    the standard headers fmpy ships. FMI 3.0 requires every function of the API, of interface types
    the FMU does not support too (they may just return fmi3Error); FMI 2.0 requires the common
    functions and those of each interface the FMU declares, so a co-simulation-only FMU need not
    export fmi2GetDerivatives. FMI 1.0 is not checked (its names carry the model identifier)."""
    major = fmi_version[0]
    header = FMPY_HEADERS / f"fmi{major}Functions.h"
    if major not in "23" or not header.is_file():
        return []
    text = header.read_text()
    if major == "2":
        # The header's export block: "Common Functions", then the Model Exchange functions, then
        # the Co-Simulation ones (the banners also stand above the type definitions: take the last).
        common = text.rindex("Common Functions")
        exchange = text.rindex("Functions for FMI2 for Model Exchange")
        cosimulation = text.rindex("Functions for FMI2 for Co-Simulation")
        parts = [text[common:exchange]]
        parts += [text[exchange:cosimulation]] if "me" in interfaces else []
        parts += [text[cosimulation:]] if "cs" in interfaces else []
        text = "".join(parts)
    return sorted(set(re.findall(rf"FMI{major}_Export\s+fmi{major}\w+TYPE\s+(fmi{major}\w+)\s*;", text)))


def _binary_problems(path: Path, description) -> list[str]:
    folder, suffix = _platform_binaries(description.fmiVersion)
    interfaces: dict[str, set[str]] = {}  # model identifier -> the interfaces its binary serves
    for interface, kind in (
        ("cs", description.coSimulation),
        ("me", description.modelExchange),
        ("se", getattr(description, "scheduledExecution", None)),
    ):
        if kind is not None:
            interfaces.setdefault(kind.modelIdentifier, set()).add(interface)
    identifiers = interfaces
    problems = []
    with zipfile.ZipFile(path) as archive, tempfile.TemporaryDirectory() as temp:
        names = set(archive.namelist())
        for identifier in sorted(identifiers):
            member = f"binaries/{folder}/{identifier}{suffix}"
            if member not in names:
                problems.append(f"no binary for this platform: {member} is missing")
                continue
            library_path = archive.extract(member, temp)
            cwd = os.getcwd()
            try:
                library = ctypes.CDLL(library_path, mode=os.RTLD_NOW | os.RTLD_LOCAL)
            except OSError as error:
                problems.append(f"{member} does not load: {error}")
                continue
            finally:
                os.chdir(cwd)
            missing = [
                name
                for name in required_functions(description.fmiVersion, tuple(interfaces[identifier]))
                if not hasattr(library, name)
            ]
            if missing:
                problems.append(
                    f"{member} does not export {len(missing)} FMI functions: {', '.join(missing)}"
                )
    return problems


def fmpy_problems(path: Path) -> list[str]:
    """fmpy's `validate_fmu` checks, with its structured-name check run once per name shape.

    fmpy parses every structured variable name with an Earley parser (~45 ms a name, 90 s for
    2000 waypoint inputs). Replacing each digit run by "1" keeps a name's membership in the
    grammar (digits only ever appear as a digit class), so one representative per shape gives
    the same verdict.
    """
    if not hasattr(fmpy_validation, "_validate_variable_names"):
        return list(validate_fmu(str(path)))
    problems = []
    with zipfile.ZipFile(path) as archive:
        problems += [f'The file path "{n}" contains a backslash.' for n in archive.namelist() if "\\" in n]
    try:
        description = fmpy.read_model_description(str(path), validate=True, validate_model_structure=True)
    except fmpy_description.ValidationError as error:
        return problems + list(error.problems)
    except Exception as error:  # fmpy's own validate_fmu reports any failure as a problem
        return problems + [str(error)]
    shapes = {re.sub(r"[0-9]+", "1", v.name): v for v in description.modelVariables}
    representatives = SimpleNamespace(
        variableNamingConvention=description.variableNamingConvention, modelVariables=list(shapes.values())
    )
    return problems + fmpy_validation._validate_variable_names(representatives)


_INTEGER_TYPES = {"Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}


def array_problems(description) -> list[str]:
    """FMI 3.0 array variables that fmpy's validation lets through: a Dimension without a size (no
    start, no valueReference), a Dimension naming something other than an integer structural
    parameter or constant, and start values that do not fill the array (one value, or one per
    element, each a number of the variable's type)."""
    if not str(description.fmiVersion).startswith("3"):
        return []
    by_reference = {v.valueReference: v for v in description.modelVariables}
    problems = []
    for variable in description.modelVariables:
        dimensions = getattr(variable, "dimensions", None) or []
        if not dimensions:
            continue
        label = f"array variable {variable.name!r}"
        for number, dimension in enumerate(dimensions, start=1):
            if dimension.start is None and dimension.valueReference is None:
                problems.append(f"{label}: Dimension {number} has neither start nor valueReference")
            elif dimension.start is None:
                size = by_reference.get(dimension.valueReference)
                if (
                    size is None
                    or size.type not in _INTEGER_TYPES
                    or size.causality
                    not in (
                        "structuralParameter",
                        "calculatedParameter",
                    )
                    and size.variability != "constant"
                ):
                    problems.append(
                        f"{label}: Dimension {number} refers to value reference {dimension.valueReference}, "
                        "which is not an integer structural parameter or constant"
                    )
            elif int(dimension.start) < 0:
                problems.append(f"{label}: Dimension {number} has a negative size {dimension.start}")
        sizes = _dimension_sizes(variable, description)
        if variable.start is None or None in sizes:
            continue
        starts = str(variable.start).split()
        count = math.prod(sizes)
        if len(starts) not in (1, count):
            problems.append(f"{label}: {len(starts)} start values for {count} elements (give 1 or {count})")
        parse = float if variable.type in ("Float32", "Float64") else int
        if variable.type in ("Float32", "Float64") or variable.type in _INTEGER_TYPES:
            bad = []
            for text in starts:
                try:
                    parse(text)
                except ValueError:
                    bad.append(text)
            if bad:
                problems.append(f"{label}: start value {bad[0]!r} is not a {variable.type}")
    return problems


def archive_problems(path: Path) -> list[str]:
    """What `cosim run` refuses in the zip itself: more than the default unpacked-size limit (a
    zip bomb), and members that would land outside the extraction folder (absolute names or `..`
    parts: a zip slip)."""
    from cosim.fmi.archive import DEFAULT_MAX_UNPACKED_SIZE, mib, unpacked_size

    problems = []
    try:
        with zipfile.ZipFile(path) as archive:
            total = unpacked_size(archive)
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError):
        return []  # not an archive at all: read_description says so, as for `cosim run` (exit 2)
    if total > DEFAULT_MAX_UNPACKED_SIZE:
        problems.append(
            f"unpacks to {mib(total)}, more than the default limit of "
            f"{mib(DEFAULT_MAX_UNPACKED_SIZE)} ([simulation] fmu_max_size)"
        )
    escaping = [
        name for name in names if name.startswith(("/", "\\")) or ".." in name.replace("\\", "/").split("/")
    ]
    if escaping:
        problems.append(
            f"member '{escaping[0]}' would be extracted outside the FMU's folder ({len(escaping)} such)"
        )
    return problems


def validate(path: Path) -> list[str]:
    """Problems of the FMU at `path`: the archive's own (size, member paths), fmpy's validation,
    FMI 3.0 array checks, binary and exported-symbol checks."""
    problems = archive_problems(path)
    if problems:  # nothing is extracted from such an archive, as `cosim run` extracts nothing
        return problems
    description = read_description(path)
    return fmpy_problems(path) + array_problems(description) + _binary_problems(path, description)
