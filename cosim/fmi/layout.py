"""An FMU's ports as a component has them (`FmuLayout`): which variables become inputs, outputs and
parameters, under which names, and what each port reaches in the FMU.

Port mapping lets any FMU fill a role: `port_map = {"v": "u_speed", "omega": {"name": "yawRate",
"scale": -1}}` exposes FMU variable `u_speed` as port `v` and `yawRate` as port `omega`. The scale
multiplies in the direction of the data flow: FMU input = scale * port value, port output =
scale * FMU output, FMU parameter = scale * given value. FMU variables not named in the map keep
their own names (unless a mapped port already uses the name). Several ports may name one variable:
an output then fills each of them, and an input receives the value of the port set last (its
position in the FMU's input order); this lets an FMU with fewer ports than a role (a
fault-injection FMU, say) fill it. Supported variable types: FMI 2.0 Real, Integer, Enumeration,
Boolean; FMI 3.0 Float32, Float64, Int8..UInt64, Enumeration (moved as Int64), Boolean, scalars and
arrays (`cosim.fmi.types`); String and Binary variables are text ports (`cosim.fmi.text`). An array
sized by a tunable structural parameter has the size of the parameter's start value (the parameter
keeps it).

An FMI 3.0 array variable of fixed size appears as one port per element, named as FMI 2.0's
structured scalars (`ranges[3]`, `waypoints[12,1]`; row-major), so a system connects the FMI 2.0
and the FMI 3.0 build of a model alike. An array is always sent whole; the port map renames
scalars only.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cosim.core.component import Port, check_unique_ports, closest_names
from cosim.errors import CosimError
from cosim.fmi import builtin as builtin_module
from cosim.fmi import text as text_module
from cosim.fmi import types as types_module
from cosim.fmi.builtin import documented_nan_variables
from cosim.fmi.description import _kept_description, _kept_key, checked_description, file_key, remember
from cosim.fmi.text import TEXT_TYPES, TextPort, text_start
from cosim.fmi.types import KINDS, WIDE, exact_as_float, transfer_type


class MappedVariable(NamedTuple):
    """What a port reaches in the FMU: the variable (fmpy's, or its name in a port map) and the
    scale in the direction of the data flow."""

    variable: object
    scale: float


def _parse_port_map(port_map: Mapping[str, object], path: Path) -> dict[str, MappedVariable]:
    """port name -> (FMU variable name, scale)."""
    parsed: dict[str, MappedVariable] = {}
    for port, target in port_map.items():
        if isinstance(target, str):
            parsed[port] = MappedVariable(target, 1.0)
        elif isinstance(target, Mapping) and isinstance(target.get("name"), str):
            unknown = set(target) - {"name", "scale"}
            scale = target.get("scale", 1.0)
            if unknown or isinstance(scale, bool) or not isinstance(scale, int | float):
                raise CosimError(f"FMU '{path}': port map entry '{port}' must be a name or {{name, scale}}")
            parsed[port] = MappedVariable(target["name"], float(scale))
        else:
            raise CosimError(f"FMU '{path}': port map entry '{port}' must be a name or {{name, scale}}")
    return parsed


@dataclass(frozen=True)
class FmuLayout:
    """What `FmuComponent` makes of one FMU file version through a port map: its ports, what each
    one reaches in the FMU, and the declared dependencies (`fmu_layout`). Shared by every component
    made from the same file, name, port map and size limit in this process (describing a system and
    then building it made each FMU's thousands of ports twice); read-only."""

    model_description: object  # fmpy's
    fmi_version: int
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    parameters: tuple[Port, ...]
    variables: Mapping[str, MappedVariable]  # port name -> (fmpy variable, scale)
    elements: Mapping[str, int]  # element port of an FMI 3.0 array -> row-major index
    feedthrough: Mapping[str, tuple[str, ...]]  # output port -> input ports, as <ModelStructure> declares
    documented_nan: tuple[str, ...]  # output ports of the FMU's documented NaN outputs
    text: Mapping[str, tuple[TextPort, ...]] = field(default_factory=dict)  # causality -> String/Binary


# Layouts, keyed by the file version and size limit (`cosim.fmi.description.file_key`), the
# component's name (its error messages) and the parsed port map. Failures are never remembered.
_LAYOUTS: dict[tuple, FmuLayout] = {}


def fmu_layout(
    path: str | Path,
    name: str,
    port_map: Mapping[str, object] | None = None,
    max_unpacked_size: int | None = None,
) -> FmuLayout:
    """The ports `FmuComponent(path, name, port_map=..., max_unpacked_size=...)` has, without making
    the component (a system description needs no more); the same `CosimError` otherwise (the
    archive's problems before the port map's). Made once per file version in a process."""
    path = Path(path)
    identity = file_key(path, max_unpacked_size)
    description, version = checked_description(path, max_unpacked_size, identity)
    mapping = _parse_port_map(port_map or {}, path)
    key = None if identity is None else (identity, name, tuple(mapping.items()))
    if key is not None and key in _LAYOUTS:
        return _LAYOUTS[key]
    kept = None if identity is None else _kept_layout(path, mapping)
    layout = _read_kept_layout(kept, description) if kept is not None else None
    if layout is None:
        layout = _make_layout(path, name, description, version, mapping)
        if kept is not None:
            _keep_layout(kept, layout)
    return layout if key is None else remember(_LAYOUTS, key, layout)


# A project FMU's layout is also kept on disk beside its kept description (`cosim.fmi.description`),
# one file per port map, for the next process: reading it back takes half of making ~3,500 ports
# again. It holds the layout without the description: the description and its variables are written
# as references (their positions), resolved against the description the process has read. Its first
# line says what it was made from: the FMU file (`_kept_key`: time, size, inode, fmpy's version), the
# port map, and the code that makes a layout (these modules' times and sizes), so an edit to either
# makes it another key.
_KEPT_LAYOUT_FORMAT = b"navcosim layout 1"
_LAYOUT_CODE = tuple(
    Path(module.__file__)
    for module in (
        sys.modules[__name__],
        sys.modules[Port.__module__],
        text_module,
        types_module,
        builtin_module,
    )
)


def _kept_layout(path: Path, mapping: dict[str, MappedVariable]) -> tuple[Path, bytes] | None:
    """Where the layout of `path` through `mapping` is kept and the key it must have been kept under;
    None for an FMU whose description is not kept (a user's: nothing is written next to it)."""
    kept = _kept_description(path)
    if kept is None:
        return None
    try:
        code = [f"{status.st_mtime_ns} {status.st_size}" for status in map(os.stat, _LAYOUT_CODE)]
        source = _kept_key(str(path))
    except OSError:
        return None
    digest = hashlib.sha256(repr(tuple(mapping.items())).encode()).hexdigest()[:20]
    key = b" ".join([_KEPT_LAYOUT_FORMAT, source, digest.encode(), " ".join(code).encode()])
    return kept.with_name(f".{path.stem}.layout-{digest}.pickle"), key


def _read_kept_layout(kept: tuple[Path, bytes], description) -> FmuLayout | None:
    """The kept layout, its references resolved against `description`; None when there is none for
    this key or it cannot be read (then it is made again)."""
    import pickle

    path, key = kept
    try:
        with open(path, "rb") as stream:
            if stream.readline().rstrip(b"\n") != key:
                return None
            unpickler = pickle.Unpickler(stream)
            # A reference is a variable's position, or -1 for the description (the last item here):
            # looked up by the list itself, no Python call per port.
            unpickler.persistent_load = [*description.modelVariables, description].__getitem__
            layout = unpickler.load()
    except Exception:  # noqa: BLE001 - whatever is wrong with the kept copy, the layout is made again
        return None
    return layout if isinstance(layout, FmuLayout) else None


def _keep_layout(kept: tuple[Path, bytes], layout: FmuLayout) -> None:
    """Write the layout beside the FMU (aside, then renamed: a reader never sees half of it); a failure
    only means the next process makes it again."""
    import io
    import pickle

    path, key = kept
    description = layout.model_description
    position = {id(variable): number for number, variable in enumerate(description.modelVariables)}

    class Pickler(pickle.Pickler):
        def persistent_id(self, obj):
            if obj is description:
                return -1
            return position.get(id(obj))  # (ids of live objects: only the variables are in it)

    partial = path.with_name(f"{path.name}.{os.getpid()}")
    try:
        payload = io.BytesIO()
        Pickler(payload, protocol=pickle.HIGHEST_PROTOCOL).dump(layout)
        partial.write_bytes(key + b"\n" + payload.getvalue())
        os.replace(partial, path)
    except Exception:  # noqa: BLE001 - not kept; nothing else changes
        partial.unlink(missing_ok=True)


def _make_layout(
    path: Path, name: str, description, version: int, mapping: dict[str, MappedVariable]
) -> FmuLayout:
    variables = {v.name: v for v in description.modelVariables}
    for port, (variable, _) in mapping.items():
        if variable not in variables:
            raise CosimError(
                f"FMU '{path}' (component '{name}') has no variable '{variable}' "
                f"(mapped to port '{port}'); variables: {closest_names(variable, variables)}"
            )
    by_variable: dict[str, list[tuple[str, float]]] = {}
    for port, (variable, scale) in mapping.items():
        by_variable.setdefault(variable, []).append((port, scale))
    reaches: dict[str, MappedVariable] = {}
    elements: dict[str, int] = {}
    ports: dict[str, list[Port]] = {"input": [], "output": [], "parameter": []}
    text: dict[str, list[TextPort]] = {"input": [], "output": [], "parameter": []}
    for variable in description.modelVariables:
        causality = variable.causality if variable.causality != "structuralParameter" else "parameter"
        if variable.type in TEXT_TYPES and causality in text and not getattr(variable, "dimensions", None):
            port = TextPort(
                variable.name,
                variable.type,
                variable.valueReference,
                text_start(variable),
                variable.description or "",
            )
            text[causality].append(port)
            continue
        kind = KINDS.get(variable.type)
        if causality not in ports or kind is None:
            continue
        fmi_type = transfer_type(version, variable.type)
        unit = getattr(variable, "unit", None) or getattr(
            getattr(variable, "declaredType", None), "unit", None
        )
        if getattr(variable, "dimensions", None):
            shape = _array_shape(variable, description)
            if shape is None:
                continue  # a dimension without a size (inspect.py reports such a description)
            if variable.name in by_variable:
                raise CosimError(
                    f"FMU '{path}' (component '{name}'): port map entry "
                    f"'{by_variable[variable.name][0][0]}' names array variable '{variable.name}'; "
                    "only scalar variables can be mapped"
                )
            made = _array_ports(path, name, variable, fmi_type, unit or "", shape, mapping)
            ports[causality] += made
            for element, port in enumerate(made):
                reaches[port.name] = MappedVariable(variable, 1.0)
                elements[port.name] = element
            continue
        if variable.name not in by_variable and variable.name in mapping:
            continue  # a mapped port already took this name
        start = start_value(variable.start, fmi_type, f"FMU '{path}' variable '{variable.name}' start")
        for port_name, scale in by_variable.get(variable.name, [(variable.name, 1.0)]):
            ports[causality].append(
                Port(port_name, kind, unit or "", variable.description or "", start * scale, fmi_type)
            )
            reaches[port_name] = MappedVariable(variable, scale)
    for causality, declared in ports.items():  # as `Component` checks them: here, so describing finds it
        check_unique_ports(name, causality, declared)
    ports_of: dict[str, list[str]] = {}
    for port, (variable, _) in reaches.items():
        ports_of.setdefault(variable.name, []).append(port)
    feedthrough = {}
    for unknown in description.outputs:
        if unknown.dependencies is not None and unknown.variable.name in ports_of:
            depends = tuple(
                port
                for d in unknown.dependencies
                if d.causality == "input" and d.name in ports_of
                for port in ports_of[d.name]
            )
            for port in ports_of[unknown.variable.name]:
                feedthrough[port] = depends
    documented = documented_nan_variables(description)
    return FmuLayout(
        model_description=description,
        fmi_version=version,
        inputs=tuple(ports["input"]),
        outputs=tuple(ports["output"]),
        parameters=tuple(ports["parameter"]),
        variables=reaches,
        elements=elements,
        feedthrough=feedthrough,
        documented_nan=tuple(port for variable in documented for port in ports_of.get(variable, ())),
        text={causality: tuple(listed) for causality, listed in text.items()},
    )


def _array_ports(path: Path, name: str, variable, fmi_type: str, unit: str, shape, mapping) -> list[Port]:
    """One port per element of FMI 3.0 array `variable` (transfer type `fmi_type`), named `name[i]` /
    `name[i,j]`."""
    kind = KINDS[fmi_type]
    starts = str(variable.start).split() if variable.start not in (None, "") else []
    ports = []
    for element, index in enumerate(np.ndindex(*shape)):
        port_name = f"{variable.name}[{','.join(str(i + 1) for i in index)}]"
        if port_name in mapping:
            raise CosimError(
                f"FMU '{path}' (component '{name}'): mapped port '{port_name}' "
                f"is also an element of array variable '{variable.name}'"
            )
        text = starts[element if len(starts) > 1 else 0] if starts else None
        start = start_value(text, fmi_type, f"FMU '{path}' variable '{port_name}' start")
        ports.append(Port(port_name, kind, unit, variable.description or "", start, fmi_type))
    return ports


def _array_shape(variable, description) -> tuple[int, ...] | None:
    """The shape of an FMI 3.0 array variable: each dimension's start, or the start of the
    structural parameter that sizes it (a tunable one too: the ports keep the size the FMU starts
    with, which `FmuComponent.setup` holds it to); None when a dimension's size is unknown."""
    by_reference = {v.valueReference: v for v in description.modelVariables}
    shape = []
    for dimension in variable.dimensions:
        size = dimension.start
        if size is None:
            parameter = by_reference.get(dimension.valueReference)
            if parameter is None or parameter.start in (None, ""):
                return None
            size = parameter.start
        shape.append(int(size))
    return tuple(shape)


def start_value(start: object, fmi_type: str, what: str) -> float:
    """A variable's start attribute (of transfer type `fmi_type`) as a float (NaN when absent); a
    64-bit integer start a float64 cannot hold is a `CosimError` naming `what`."""
    kind = KINDS[fmi_type]
    if start is None or start == "":
        return float("nan") if kind == "real" else 0.0
    text = str(start).strip().split()[0]
    if kind == "boolean":
        return 1.0 if text.lower() in ("true", "1") else 0.0
    if fmi_type in WIDE:
        try:
            return exact_as_float(int(text), fmi_type, what)
        except ValueError:
            pass
    try:
        return float(text)
    except ValueError:
        return float("nan")
