"""FMI 1.0, 2.0 and 3.0 co-simulation FMUs as components, through fmpy, with a strict lifecycle.

fmpy loads the binary and runs the lifecycle calls; the per-step calls (set inputs, do step, get
outputs) go straight to the FMU's C functions with value references resolved once and values in
preallocated ctypes arrays: one batched call per FMI type, about 4x faster than fmpy's methods,
which convert lists and check types on every call.

Port mapping lets any FMU fill a role: `port_map = {"v": "u_speed", "omega": {"name": "yawRate",
"scale": -1}}` exposes FMU variable `u_speed` as port `v` and `yawRate` as port `omega`. The scale
multiplies in the direction of the data flow: FMU input = scale * port value, port output =
scale * FMU output, FMU parameter = scale * given value. FMU variables not named in the map keep
their own names (unless a mapped port already uses the name). Several ports may name one variable:
an output then fills each of them, and an input receives the value of the port set last (its
position in the FMU's input order); this lets an FMU with fewer ports than a role (a
fault-injection FMU, say) fill it. Supported variable types: FMI 2.0 Real, Integer, Enumeration,
Boolean; FMI 3.0 Float32, Float64, Int8..UInt64, Enumeration (moved as Int64), Boolean, scalars and
arrays (`cosim.fmi.types`). An array sized by a tunable structural parameter has the size of the
parameter's start value (the parameter keeps it).

An FMI 3.0 array variable of fixed size appears as one port per element, named as FMI 2.0's
structured scalars (`ranges[3]`, `waypoints[12,1]`; row-major), so a system connects the FMI 2.0
and the FMI 3.0 build of a model alike. The transfer is native: one fmi3Get/fmi3Set call moves all
variables of a type, each array as one value reference with all its elements (a 720-beam scan is
one reference, not 720). An array is always sent whole; the port map renames scalars only.

Every real output must be finite: after each step (and after initialisation) `get_outputs` raises
`CosimError` naming the output when one is NaN or infinite, since a NaN fed on would pass as a value
(a NaN pose is no position at all). Outputs listed in `nan_outputs` (or `allow_nan`) may be NaN where
the FMU gives NaN a meaning; they must still not be infinite. The project FMUs' documented NaN
outputs (VFH's `steering_dir` when no direction is free, PurePursuit's `goal_distance` without
waypoints: `cosim.fmi.builtin.documented_nan_variables`) are allowed by default. Integer and
Boolean outputs are always finite.

The archive's total uncompressed size is checked before anything is extracted
(`cosim.fmi.archive`; default limit 1 GiB, `max_unpacked_size` raises it).

fmpy behaviour owned here: each instance is extracted into its own directory (static state inside
a shared library is not shared between instances), all but sources/ and documentation/; the working
directory is restored after a failed load; status Discard, Error and Fatal become `CosimError`
naming the component, the model and the time. After Error the instance is only freed; after Fatal
nothing more is called (the standard forbids it), and `free()` just forgets the instance.
"""

from __future__ import annotations

import ctypes
import math
import os
import shutil
import tempfile
import weakref
import zipfile
from collections import deque
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import fmpy
import numpy as np
from fmpy.fmi1 import FMU1Slave
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.model_description import ModelVariable

from cosim.core.component import Component, NativeStep, Port, State, check_unique_ports, closest_names
from cosim.errors import CosimError, SimulationEnded
from cosim.fmi import exit_guard
from cosim.fmi.archive import check_unpacked_size
from cosim.fmi.builtin import documented_nan_variables
from cosim.fmi.text import TEXT_TYPES, TextPort, TextTransfer, check_text, text_start
from cosim.fmi.types import C_TYPES, KINDS, TRANSFER_TYPES, WIDE, check_integer, exact_as_float, transfer_type

_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
# Transfer types as the compiled kernel's group kinds (`cosim.core.kernel.KINDS`).
_KERNEL_TYPES = {1: {"Real": "real", "Integer": "integer"}}  # FMI 1.0 Booleans are chars: Python moves them
_KERNEL_TYPES[2] = {"Real": "real", "Integer": "integer", "Boolean": "boolean"}
_KERNEL_TYPES[3] = {"Float64": "real", "Int32": "integer", "Boolean": "boolean"}
_KERNEL_TYPES[3] |= {name: name.lower() for name in TRANSFER_TYPES[3] if name not in _KERNEL_TYPES[3]}
_FMI_TYPE_NAMES = {
    version: {kind: name for name, kind in names.items()} for version, names in _KERNEL_TYPES.items()
}


@cache
def _fmi1_variable_step(path: str, mtime_ns: int, size: int) -> bool:
    """canHandleVariableCommunicationStepSize of an FMI 1.0 co-simulation FMU (its Capabilities
    element under Implementation/CoSimulation_StandAlone or CoSimulation_Tool)."""
    from xml.etree import ElementTree

    with zipfile.ZipFile(path) as archive:
        root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    capabilities = root.find("Implementation/*/Capabilities")
    return capabilities is not None and capabilities.get("canHandleVariableCommunicationStepSize") in {
        "true",
        "1",
    }


def _file_identity(path: Path) -> tuple[int, int]:
    status = path.stat()
    return status.st_mtime_ns, status.st_size


@cache
def _parsed_description(path: str, mtime_ns: int, size: int):
    """fmpy's parse of an FMU's modelDescription.xml, once per file version: describing a system and
    then building it reads every FMU twice, and a 2000-variable description takes ~25 ms to parse.
    A project FMU's parse is also kept on disk beside it (`_kept_description`). Callers treat the
    result as read-only."""
    kept = _kept_description(Path(path))
    if kept is not None:
        description = _read_kept(kept, path)
        if description is not None:
            return description
    description = fmpy.read_model_description(path)
    if kept is not None:
        _keep(kept, path, description)
    return description


_KEPT_FORMAT = b"navcosim fmpy description 2"


def _kept_description(path: Path) -> Path | None:
    """Where the parse of `path` is kept: beside a project FMU in the FMU build cache
    (`cosim.fmi.builtin`, a folder navcosim writes and whose binaries it runs anyway), else nowhere
    (a user's FMU is parsed each time: nothing is written next to it). Unpickling fmpy's objects
    takes a fifth of parsing the XML again (`_KeptVariable`; and no lxml import, no schema
    validation: the file was validated when it was parsed)."""
    from cosim.fmi.builtin import default_cache_dir

    try:
        cache = default_cache_dir().resolve()
    except OSError:
        return None
    if path.parent != cache and path.parent != cache / "fmi3":
        return None
    return path.with_name(f".{path.stem}.description.pickle")


def _kept_key(path: str) -> bytes:
    """What the kept parse must have been made from: this file (time, size, inode) and fmpy version."""
    status = os.stat(path)
    version = getattr(fmpy, "__version__", "")
    return b" ".join(
        [_KEPT_FORMAT, version.encode(), *(str(n).encode() for n in (status.st_mtime_ns, status.st_size))]
        + [str(status.st_ino).encode()]
    )


def _read_kept(kept: Path, path: str):
    """The kept parse of `path`, or None (none, another file version, another fmpy, unreadable)."""
    import pickle

    try:
        with open(kept, "rb") as stream:
            if stream.readline().rstrip(b"\n") != _kept_key(path):
                return None
            return pickle.load(stream)
    except Exception:  # noqa: BLE001 - whatever is wrong with the kept copy, the FMU is parsed again
        return None


def _keep(kept: Path, path: str, description) -> None:
    """Keep the parse beside the FMU (written aside and renamed: readers never see half of it); a
    failure only means the next run parses again."""
    import io
    import pickle

    partial = kept.with_name(f"{kept.name}.{os.getpid()}")
    try:
        payload = io.BytesIO()
        _kept_pickler(payload, protocol=pickle.HIGHEST_PROTOCOL).dump(description)
        partial.write_bytes(_kept_key(path) + b"\n" + payload.getvalue())
        os.replace(partial, kept)
    except Exception:  # noqa: BLE001 - not kept; nothing else changes
        partial.unlink(missing_ok=True)


def _read_description(path: Path, max_unpacked_size: int | None = None):
    """Check the archive and return fmpy's model description; one-line `CosimError` otherwise."""
    if not path.is_file():
        raise CosimError(f"FMU '{path}' not found")
    if not zipfile.is_zipfile(path):
        raise CosimError(f"FMU '{path}' is not a zip archive (corrupt file or not an FMU)")
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            check_unpacked_size(path, archive, max_unpacked_size)
    except (zipfile.BadZipFile, OSError) as error:
        raise CosimError(f"FMU '{path}' cannot be read: {error}") from None
    if "modelDescription.xml" not in names:
        raise CosimError(f"FMU '{path}' has no modelDescription.xml")
    try:
        description = _parsed_description(str(path.resolve()), *_file_identity(path))
    except Exception as error:  # fmpy raises plain Exceptions with multi-line text
        from cosim.fmi.diagnose import dangling_reference  # (and its XML parser) only for a broken FMU

        problem = dangling_reference(path) if isinstance(error, IndexError | KeyError) else None
        first_line = problem or " ".join(str(error).split())[:300]
        raise CosimError(f"FMU '{path}': invalid modelDescription.xml: {first_line}") from None
    version = int(str(description.fmiVersion).split(".")[0])
    if version not in (1, 2, 3):
        raise CosimError(
            f"FMU '{path}' is FMI {description.fmiVersion}; navcosim supports FMI 1.0, 2.0 and 3.0"
        )
    # The binary of the interface a component uses by default: co-simulation when the FMU has it
    # (`cosim.fmi.model_exchange` checks the Model Exchange binary of an FMU run as one).
    interface = description.coSimulation or description.modelExchange
    if interface is None:
        raise CosimError(f"FMU '{path}' (model {description.modelName}) declares no FMI interface")
    platform = fmpy.platform if version < 3 else fmpy.platform_tuple
    binary = f"binaries/{platform}/{interface.modelIdentifier}{fmpy.sharedLibraryExtension}"
    if binary not in names:
        identifier = interface.modelIdentifier
        from cosim.fmi.diagnose import missing_binary

        raise CosimError(missing_binary(path, names, platform, identifier, fmpy.sharedLibraryExtension))
    return description, version


def _parse_port_map(port_map: Mapping[str, object], path: Path) -> dict[str, tuple[str, float]]:
    """port name -> (FMU variable name, scale)."""
    parsed: dict[str, tuple[str, float]] = {}
    for port, target in port_map.items():
        if isinstance(target, str):
            parsed[port] = (target, 1.0)
        elif isinstance(target, Mapping) and isinstance(target.get("name"), str):
            unknown = set(target) - {"name", "scale"}
            scale = target.get("scale", 1.0)
            if unknown or isinstance(scale, bool) or not isinstance(scale, int | float):
                raise CosimError(f"FMU '{path}': port map entry '{port}' must be a name or {{name, scale}}")
            parsed[port] = (target["name"], float(scale))
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
    variables: Mapping[str, tuple[object, float]]  # port name -> (fmpy variable, scale)
    elements: Mapping[str, int]  # element port of an FMI 3.0 array -> row-major index
    feedthrough: Mapping[str, tuple[str, ...]]  # output port -> input ports, as <ModelStructure> declares
    documented_nan: tuple[str, ...]  # output ports of the FMU's documented NaN outputs
    text: Mapping[str, tuple[TextPort, ...]] = field(default_factory=dict)  # causality -> String/Binary


# Checked archives (`_read_description`) and layouts, keyed by the file's resolved path and version
# (modification time and size) and the unpacked-size limit; a layout also by the component's name
# (its error messages) and the parsed port map. A sweep's worker makes the same few FMUs once per
# run; a changed file is another key. Failures are never remembered.
_DESCRIPTIONS: dict[tuple, tuple[object, int]] = {}
_LAYOUTS: dict[tuple, FmuLayout] = {}
_KEPT = 32


def _remember(cache: dict, key: tuple, value):
    if len(cache) >= _KEPT:
        cache.pop(next(iter(cache)))
    cache[key] = value
    return value


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
    port_map = port_map or {}
    try:
        identity: tuple | None = (str(path.resolve()), *_file_identity(path), max_unpacked_size)
    except (OSError, RuntimeError):
        identity = None  # `_read_description` says what is wrong
    if identity is not None and identity in _DESCRIPTIONS:
        description, version = _DESCRIPTIONS[identity]
    else:
        description, version = _read_description(path, max_unpacked_size)
        if identity is not None:
            _remember(_DESCRIPTIONS, identity, (description, version))
    mapping = _parse_port_map(port_map, path)
    key = None if identity is None else (identity, name, tuple(mapping.items()))
    if key is not None and key in _LAYOUTS:
        return _LAYOUTS[key]
    layout = _make_layout(path, name, description, version, mapping)
    return layout if key is None else _remember(_LAYOUTS, key, layout)


def _make_layout(
    path: Path, name: str, description, version: int, mapping: dict[str, tuple[str, float]]
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
    reaches: dict[str, tuple[object, float]] = {}
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
                reaches[port.name] = (variable, 1.0)
                elements[port.name] = element
            continue
        if variable.name not in by_variable and variable.name in mapping:
            continue  # a mapped port already took this name
        start = _start_value(variable.start, fmi_type, f"FMU '{path}' variable '{variable.name}' start")
        for port_name, scale in by_variable.get(variable.name, [(variable.name, 1.0)]):
            ports[causality].append(
                Port(port_name, kind, unit or "", variable.description or "", start * scale, fmi_type)
            )
            reaches[port_name] = (variable, scale)
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
        description,
        version,
        tuple(ports["input"]),
        tuple(ports["output"]),
        tuple(ports["parameter"]),
        reaches,
        elements,
        feedthrough,
        tuple(port for variable in documented for port in ports_of.get(variable, ())),
        {causality: tuple(listed) for causality, listed in text.items()},
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
        start = _start_value(text, fmi_type, f"FMU '{path}' variable '{port_name}' start")
        ports.append(Port(port_name, kind, unit, variable.description or "", start, fmi_type))
    return ports


class FmuComponent(Component):
    """A co-simulation FMU (FMI 1.0, 2.0 or 3.0) as a component.

    Args:
        path: the .fmu file.
        name: component name (role) in the system.
        parameters: default parameter values by port name (overridden by `setup`).
        port_map: port name -> FMU variable name or {"name": ..., "scale": ...}.
        period: seconds between steps (0 = every macro step).
        feedthrough_override: output port -> input ports it depends on directly, overriding the FMU's
            <ModelStructure> (where an output without `dependencies` depends on every input).
        nan_outputs: output ports that may be NaN (not infinite); every other output must be finite.
        max_unpacked_size: refuse an archive whose entries unpack to more bytes (default 1 GiB).
    """

    def __init__(
        self,
        path: str | Path,
        name: str,
        parameters: Mapping[str, float] | None = None,
        port_map: Mapping[str, object] | None = None,
        period: float = 0.0,
        feedthrough_override: Mapping[str, list[str]] | None = None,
        nan_outputs: Collection[str] = (),
        max_unpacked_size: int | None = None,
    ) -> None:
        super().__init__(name, period=period)
        self.path = Path(path)
        layout = fmu_layout(self.path, name, port_map or {}, max_unpacked_size)
        self.model_description, self.fmi_version = layout.model_description, layout.fmi_version
        self._check_interface()
        self.default_parameters = dict(parameters or {})
        self._variables = layout.variables  # port name -> (fmpy variable, scale); shared, read-only
        self._elements = layout.elements  # element port of an FMI 3.0 array -> row-major index
        feedthrough = dict(layout.feedthrough)
        feedthrough.update(feedthrough_override or {})
        self._set_ports(layout.inputs, layout.outputs, layout.parameters, feedthrough)
        self.text_inputs = layout.text.get("input", ())  # String/Binary variables (`cosim.fmi.text`)
        self.text_outputs = layout.text.get("output", ())
        self.text_parameters = layout.text.get("parameter", ())
        self.text_values: dict[str, str | bytes] = {
            p.name: p.start for p in (*self.text_inputs, *self.text_outputs)
        }
        self._text_feeds: dict[str, tuple[Component, str]] = {}  # text input -> (producer, its output)
        self.text_listener = None  # called with t [s] after each step's text values are read
        self._text = None
        self.nan_outputs: frozenset[str] = frozenset()
        self.allow_nan(*nan_outputs, *layout.documented_nan)
        self._step_time: list[float | None] = [None]  # start of the last doStep [s], for messages
        self._plan_transfers()
        self._slave = None
        self._unzip_dir: str | None = None
        self._fatal = False
        self._fmu_state: ctypes.c_void_p | None = None  # kept by `save_state`, freed with the instance
        self.log_messages: deque[str] = deque(maxlen=20)

    # fmpy's class of an instance, by FMI version (`cosim.fmi.model_exchange` has its own).
    _FMPY_CLASSES = {1: FMU1Slave, 2: FMU2Slave, 3: FMU3Slave}

    def _interface(self):
        """The description's element of the interface this component runs (co-simulation)."""
        return self.model_description.coSimulation

    def _check_interface(self) -> None:
        if self._interface() is None:
            raise CosimError(
                f"FMU '{self.path}' (model {self.model_description.modelName}) supports model exchange "
                'only: run it with interface = "me" (and a solver)'
            )

    def text_port(self, name: str, direction: str) -> str | None:
        """The FMI type ("String", "Binary") of text input/output `name`; None if it is none."""
        ports = self.text_inputs if direction == "input" else self.text_outputs
        return next((p.fmi_type for p in ports if p.name == name), None)

    def set_text(self, name: str, value: str | bytes) -> None:
        """Hold text input `name` at `value` (sent at setup, or before the next step)."""
        port = next((p for p in self.text_inputs if p.name == name), None)
        if port is None:
            names = [p.name for p in self.text_inputs]
            raise CosimError(
                f"FMU '{self.name}' has no String or Binary input '{name}'; those: {names or 'none'}"
            )
        self.text_values[name] = check_text(port, value, f"FMU '{self.name}' input '{name}'")

    def feed_text(self, name: str, producer: Component, output: str) -> None:
        """From now on text input `name` takes `producer`'s text output `output` before each step."""
        self._text_feeds[name] = (producer, output)

    def push_text(self) -> None:
        if self.text_inputs:
            self._send_text()

    def _send_text(self) -> None:
        """Send every text input (the fed ones with their producers' latest values)."""
        for name, (producer, output) in self._text_feeds.items():
            self.text_values[name] = producer.text_values[output]
        status = self._text.set(self.text_inputs, [self.text_values[p.name] for p in self.text_inputs])
        if status > 1:
            self._fail(status, "fmiSetString/fmiSetBinary (text inputs)")

    def _read_text(self) -> None:
        status, values = self._text.get(self.text_outputs)
        if status > 1:
            self._fail(status, "fmiGetString/fmiGetBinary (text outputs)")
        self.text_values.update(zip((p.name for p in self.text_outputs), values, strict=True))

    def _plan_transfers(self) -> None:
        """Per FMI type: buffer slots, value references, FMI value array, scales."""
        self._input_groups = self._groups(self.inputs)
        self._output_groups = self._groups(self.outputs)

    def allow_nan(self, *ports: str) -> None:
        """Let these outputs be NaN (not infinite) from now on; before `instantiate()` only."""
        self._require("allow_nan", State.CREATED)
        for port in ports:
            if port not in self.output_index:
                raise CosimError(
                    f"FMU '{self.path}' (component '{self.name}'): '{port}' is not an output, so it "
                    f"cannot be allowed NaN; outputs: {closest_names(port, self.output_index)}"
                )
        self.nan_outputs = self.nan_outputs | frozenset(ports)

    def variable_name(self, port: str) -> str:
        """The FMU variable behind a port (the port's own name unless the port map renames it)."""
        return self._variables[port][0].name

    def _checked_outputs(self) -> tuple[list[int], list[int]]:
        """Slots of the real outputs that must be finite, and of those that may only be NaN."""
        real = [i for i, port in enumerate(self.outputs) if port.type == "real"]
        finite = [i for i in real if self.outputs[i].name not in self.nan_outputs]
        return finite, [i for i in real if self.outputs[i].name in self.nan_outputs]

    def restrict_push(self, slots) -> None:
        """From now on `push_inputs` sends only the inputs at `slots` (port order): the others keep
        the values last sent (FMI inputs hold their values), e.g. a plan fixed for the whole run."""
        self._input_groups = self._groups(self.inputs, set(slots))
        self._compile_fast_path()
        if self.state is State.STEPPING:
            self._install_fast_path()

    def _groups(
        self, ports: list[Port], only: set[int] | None = None
    ) -> list[tuple[str, list[int], object, object, list[float]]]:
        """Per FMI transfer type: (type, buffer slots, value references, FMI value array, scales). An FMI 3.0
        array's element ports are consecutive (in element order), so its reference is listed once,
        at its first element, and its values fill that stretch of the value array."""
        if only is not None:  # an array is transferred whole: a slot of it brings all of them
            arrays = {self._variables[ports[i].name][0].name for i in only if ports[i].name in self._elements}
            only = set(only) | {
                i
                for i, p in enumerate(ports)
                if p.name in self._elements and self._variables[p.name][0].name in arrays
            }
        groups = []
        for kind in TRANSFER_TYPES[self.fmi_version]:
            slots = [i for i, p in enumerate(ports) if p.fmi_type == kind and (only is None or i in only)]
            if slots:
                references = [
                    self._variables[ports[i].name][0].valueReference
                    for i in slots
                    if self._elements.get(ports[i].name, 0) == 0
                ]
                scales = [self._variables[ports[i].name][1] for i in slots]
                values = (C_TYPES[self.fmi_version][kind] * len(slots))()
                groups.append((kind, slots, (ctypes.c_uint32 * len(references))(*references), values, scales))
        return groups

    def _compile_fast_path(self) -> None:
        """Generate specialised `push_inputs`, `do_step`, `get_outputs` for this FMU.

        The functions are generated as straight-line Python with every buffer, value reference
        and C function bound as a constant: a step then costs the C calls plus a few
        element copies, with no loop, lookup or allocation. `_remove_fast_path` puts the checked
        class methods back when the instance leaves the stepping state.
        """
        n = "" if self.fmi_version < 3 else ", {n}"
        names: dict[str, object] = {"fail": self._fail, "np": np, "ib": self.input_cbuffer}
        names.update(
            ob=self.output_cbuffer, obn=self.output_buffer, ibn=self.input_buffer, handle=self._handle
        )
        push, pull = ["def push_inputs():"], ["def get_outputs():"]
        for direction, groups, lines in (
            ("Set", self._input_groups, push),
            ("Get", self._output_groups, pull),
        ):
            for g, (kind, slots, references, values, scales) in enumerate(groups):
                function = f"fmi{self.fmi_version}{direction}{kind}"
                direct = KINDS[kind] == "real" and C_TYPES[self.fmi_version][kind] is ctypes.c_double
                direct = direct and all(scale == 1.0 for scale in scales) and len(groups) == 1
                buffer = self.input_cbuffer if direction == "Set" else self.output_cbuffer
                if direct and slots == list(range(len(slots))):
                    values = buffer  # the FMI call reads/writes the component's buffer itself
                names.update(
                    {f"f{direction}{g}": self._setters[kind] if direction == "Set" else self._getters[kind]}
                )
                names.update({f"r{direction}{g}": references, f"v{direction}{g}": values})
                names[f"vn{direction}{g}"] = np.ctypeslib.as_array(values)
                names[f"s{direction}{g}"] = np.array(slots, dtype=np.intp)
                names[f"k{direction}{g}"] = np.array(scales)
                copies = [] if values is buffer else _copy_lines(direction, g, KINDS[kind], slots, scales)
                if direction == "Get" and kind in WIDE:  # before the copy rounds them
                    below = "" if kind == "UInt64" else f" or vnGet{g}.min() < -exact{kind}"
                    test = f"vnGet{g}.max() > exact{kind}{below}"
                    copies.insert(0, f"    if {test}: inexact(vnGet{g}, sGet{g}, '{kind}')")
                count = len(references)  # FMI 3.0: then the number of values (array elements)
                call = [
                    f"    status = f{direction}{g}(handle, r{direction}{g}, {count}, v{direction}{g}"
                    + n.format(n=len(slots))
                    + ")",
                    f"    if status > 1: fail(status, '{function}')",
                ]
                lines += copies + call if direction == "Set" else call + copies
        push.append("    return None")
        pull += _finite_check_lines(*self._checked_outputs())
        names.update(nonfinite=self._nonfinite_output, zeros=np.zeros(len(self.outputs)), inf=math.inf)
        names.update(exactInt64=np.int64(2**53), exactUInt64=np.uint64(2**53), inexact=self._inexact_output)
        pull.append("    return obn")
        if self.fmi_version < 3:
            step = ["def do_step(t, h):", "    clock[0] = t", "    status = raw(handle, t, h, 1)"]
        else:
            step = ["def do_step(t, h):", "    clock[0] = t", "    status = raw(handle, t, h, True, *flags)"]
        names["clock"] = self._step_time
        step.append("    if status > 1: step_failed(status, t)")
        names["step_failed"] = self._step_failed
        if self.fmi_version == 3:
            step.append("    if step_flags[1]: asked_to_terminate(t)")
            names.update(flags=self._do_step_flags, step_flags=self._step_flags)
            names["asked_to_terminate"] = self._asked_to_terminate
        names["raw"] = self._raw_do_step
        exec("\n".join(push + pull + step), names)  # noqa: S102 - generated from our own templates
        self._compiled = {method: names[method] for method in ("push_inputs", "get_outputs", "do_step")}
        if self.text_inputs or self.text_outputs:  # text beside the numbers (`cosim.fmi.text`)
            self._compiled.update(_with_text(self, self._compiled["do_step"], self._compiled["get_outputs"]))

    def _install_fast_path(self) -> None:
        self.__dict__.update(self._compiled)

    def _remove_fast_path(self) -> None:
        for method in ("push_inputs", "get_outputs", "do_step"):
            self.__dict__.pop(method, None)

    # ---- lifecycle ---------------------------------------------------------------------------

    def _fail(self, status: int, function: str, t: float | None = None) -> None:
        """Raise the `CosimError` for a bad status; Error and Fatal mark the instance failed."""
        if status >= 3:
            self._remove_fast_path()
            self.state = State.FAILED
            self._fatal = self._fatal or status == 4
        when = f" at t = {t:.9g} s" if t is not None else ""
        detail = f": {self.log_messages[-1]}" if self.log_messages else ""
        name = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
        raise CosimError(
            f"FMU '{self.name}' (model {self.model_description.modelName}) returned "
            f"fmi{self.fmi_version}{name} from {function}{when}{detail}"
        )

    def _log(self, *args) -> None:
        # FMI 3.0 passes (environment, status, category, message); FMI 2.0 comes via the dispatcher.
        status, category, message = args[-3:]
        if status >= 1:
            text = message.decode(errors="replace") if isinstance(message, bytes) else str(message)
            self.log_messages.append(" ".join(text.split()))

    def unpack(self) -> None:
        """Extract the archive into the instance's own folder (`instantiate()` does it if not done):
        what the instance can use, its binaries and resources (not sources/ or documentation/)."""
        self._require("unpack", State.CREATED)
        if self._unzip_dir is not None:
            return
        self._unzip_dir = tempfile.mkdtemp(prefix=f"navcosim-{self.name}-")
        try:
            fmpy.extract(str(self.path), unzipdir=self._unzip_dir, include=_needed_at_run_time)
        except Exception as error:
            self._discard_files()
            detail = " ".join(str(error).split())[:300]
            what = f"FMU '{self.path}' (component '{self.name}')"
            raise CosimError(f"{what} cannot be unpacked: {detail}") from None

    def instantiate(self) -> None:
        self._require("instantiate", State.CREATED)
        self.unpack()
        exit_guard.watch(self)  # an exit() inside the FMU from now on ends the run as failed
        description = self.model_description
        work_dir = os.getcwd()
        try:
            slave_class = self._FMPY_CLASSES[self.fmi_version]
            guid = description.guid if self.fmi_version < 3 else description.instantiationToken
            self._slave = slave_class(
                guid=guid,
                unzipDirectory=self._unzip_dir,
                modelIdentifier=self._interface().modelIdentifier,
                instanceName=self.name,
            )
            if self.fmi_version == 1:
                self._slave.instantiate()  # (fmpy's FMI 1.0 callbacks)
            elif self.fmi_version == 2:
                self._slave.instantiate(callbacks=self._fmi2_callbacks())
            else:
                self._slave.instantiate(logMessage=self._log)
        except Exception as error:
            exit_guard.release(self)
            self._discard_files()
            detail = (
                f": {self.log_messages[-1]}" if self.log_messages else f": {' '.join(str(error).split())}"
            )
            raise CosimError(
                f"FMU '{self.path}' (component '{self.name}') failed to instantiate{detail[:300]}"
            ) from None
        finally:
            # fmpy changes into the binary's folder and does not change back when loading fails.
            os.chdir(work_dir)
        self._bind_raw_functions()
        self._compile_fast_path()
        self.state = State.INSTANTIATED

    def _fmi2_callbacks(self):
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
        )

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _fmi2_logger()
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        # The FMU hands componentEnvironment back to the logger: it selects this component.
        callbacks.componentEnvironment = id(self)
        _LOG_TARGETS[id(self)] = weakref.ref(self)
        try:  # fmpy's C proxy formats the variadic message; it keeps one logger process-wide
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(ctypes.byref(callbacks))
        except Exception:
            pass
        self._callbacks = callbacks  # keep the callbacks alive as long as the instance
        return callbacks

    def _bind_raw_functions(self) -> None:
        """Own prototypes of the per-step C functions (fmpy's wrappers allocate on every call)."""
        dll = self._slave.dll
        c_void_p, c_size_t, c_int = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int
        self._handle = self._slave.component
        self._setters, self._getters = {}, {}
        # Only the types the FMU's ports use (an FMI 2.0 Enumeration moves as Integer).
        used = {p.fmi_type for p in (*self.inputs, *self.outputs, *self.parameters)}
        for type_name in (name for name in TRANSFER_TYPES[self.fmi_version] if name in used):
            values = ctypes.POINTER(C_TYPES[self.fmi_version][type_name])
            vrs = ctypes.POINTER(ctypes.c_uint32)
            if self.fmi_version < 3:
                prototype = ctypes.CFUNCTYPE(c_int, c_void_p, vrs, c_size_t, values)
            else:
                prototype = ctypes.CFUNCTYPE(c_int, c_void_p, vrs, c_size_t, values, c_size_t)
            self._setters[type_name] = prototype((self._function(f"Set{type_name}"), dll))
            self._getters[type_name] = prototype((self._function(f"Get{type_name}"), dll))
        if self.text_inputs or self.text_outputs or self.text_parameters:
            self._text = TextTransfer(dll, self.fmi_version, self._handle, self._function)
        self._bind_do_step(dll)

    def _function(self, name: str) -> str:
        """The C symbol of FMI function `name` ("SetReal"): fmi2SetReal, fmi3SetReal; FMI 1.0 prefixes
        the model identifier: <identifier>_fmiSetReal."""
        if self.fmi_version == 1:
            return f"{self._interface().modelIdentifier}_fmi{name}"
        return f"fmi{self.fmi_version}{name}"

    def _bind_do_step(self, dll) -> None:
        c_void_p, c_double, c_int = ctypes.c_void_p, ctypes.c_double, ctypes.c_int
        if self.fmi_version < 3:  # FMI 1.0's last argument (newStep) is an fmiBoolean, a char
            last = c_int if self.fmi_version == 2 else ctypes.c_uint8
            prototype = ctypes.CFUNCTYPE(c_int, c_void_p, c_double, c_double, last)
            self._raw_do_step = prototype((self._function("DoStep"), dll))
            self._do_step_flags = ()
        else:
            flag = ctypes.POINTER(ctypes.c_bool)
            prototype = ctypes.CFUNCTYPE(
                c_int, c_void_p, c_double, c_double, ctypes.c_bool, flag, flag, flag, ctypes.POINTER(c_double)
            )
            self._raw_do_step = prototype(("fmi3DoStep", dll))
            # eventHandlingNeeded, terminateSimulation, earlyReturn: contiguous for the compiled kernel.
            self._step_flags = (ctypes.c_bool * 3)()
            self._last_successful_time = ctypes.c_double()
            first = ctypes.addressof(self._step_flags)
            self._do_step_flags = tuple(ctypes.cast(first + i, flag) for i in range(3)) + (
                ctypes.pointer(self._last_successful_time),
            )

    def _call_lifecycle(self, function: str, *args) -> None:
        try:
            getattr(self._slave, function)(*args)
        except Exception as error:
            status = getattr(error, "status", 3)
            self._fail(int(status), function)

    def setup(self, t0: float, parameters: Mapping[str, float], stop_time: float | None = None) -> None:
        self._require("setup", State.INSTANTIATED)
        self.t0 = float(t0)
        self.stop_time = None if stop_time is None else float(stop_time)
        # The experiment before the values, as libcosim and ecos order them: an FMU may reset its
        # variables to their start values in fmi2SetupExperiment (20-sim's do), and the values set
        # after it must stay. FMI 1.0 and 3.0 take the times when initialisation starts.
        if self.fmi_version == 2:
            self._call_lifecycle("setupExperiment", None, self.t0, self.stop_time)
        values = dict(self.default_parameters)
        values.update(parameters)
        names = [p.name for p in (*self.parameters, *self.text_parameters)]
        kinds = {p.name: p.fmi_type for p in self.parameters}
        arrays: dict[str, dict[int, float]] = {}  # FMI 3.0 array parameter -> given elements
        texts = {p.name: p for p in self.text_parameters}
        given_texts = {}
        for key, value in values.items():
            if key in texts:
                given_texts[key] = check_text(texts[key], value, f"FMU '{self.name}' parameter '{key}'")
                continue
            if key not in kinds:
                raise CosimError(
                    f"FMU '{self.name}' (model {self.model_description.modelName}) has no parameter "
                    f"'{key}'; parameters: {closest_names(key, names) or 'none'}"
                )
            if key in self._elements:
                arrays.setdefault(key.split("[")[0], {})[self._elements[key]] = value
                continue
            variable, scale = self._variables[key]
            if variable.causality == "structuralParameter" and variable.variability == "tunable":
                self._check_structural(key, variable, kinds[key], value)
                continue
            value = value if scale == 1.0 else value * scale  # (a Python int stays exact for an Int64)
            self._set_scalar(kinds[key], variable.valueReference, value, key)
        for array, elements in arrays.items():
            self._set_array_parameter(array, elements)
        if given_texts and self._text.set([texts[k] for k in given_texts], list(given_texts.values())) > 1:
            self._fail(3, "fmiSetString/fmiSetBinary (parameters)")
        if self.text_inputs:
            self._send_text()
        self._initializing = False
        self.state = State.SET_UP

    def _check_structural(self, key: str, variable, fmi_type: str, value: float) -> None:
        """A tunable structural parameter sizes arrays, whose ports were made at its start value: it
        keeps that value (changing it takes FMI 3.0's configuration mode and ports of another size)."""
        start = _start_value(variable.start, fmi_type, key)
        if float(value) != start:
            raise CosimError(
                f"FMU '{self.name}' (model {self.model_description.modelName}): structural parameter "
                f"'{key}' sizes array variables, whose ports navcosim makes at its start value "
                f"{start:g}; it cannot be set to {value:g}"
            )

    def _set_scalar(self, kind: str, reference: int, value: float, name: str) -> None:
        """Set one variable of transfer type `kind` (integers checked against the type's range)."""
        value = self._fmi_value(kind, value, name)
        values = (C_TYPES[self.fmi_version][kind] * 1)(value)
        status = self._setters[kind](
            self._handle, (ctypes.c_uint32 * 1)(reference), 1, values, *self._count(1)
        )
        if status > 1:
            self._fail(status, f"fmi{self.fmi_version}Set{kind} ({name})")

    def _fmi_value(self, kind: str, value: float, name: str):
        """A parameter value as its FMI type takes it."""
        if KINDS[kind] == "integer":
            return check_integer(value, kind, f"FMU '{self.name}': parameter '{name}'")
        if KINDS[kind] == "boolean":
            return value != 0
        return float(value)

    def _set_array_parameter(self, array: str, elements: Mapping[int, float]) -> None:
        """Set FMI 3.0 array parameter `array` whole: the given elements, the others at their start."""
        ports = [p for p in self.parameters if p.name in self._elements and p.name.split("[")[0] == array]
        variable = self._variables[ports[0].name][0]
        kind = ports[0].fmi_type
        numbers = [elements.get(self._elements[p.name], p.start) for p in ports]
        values = (C_TYPES[3][kind] * len(numbers))(*(self._fmi_value(kind, v, array) for v in numbers))
        status = self._setters[kind](
            self._handle, (ctypes.c_uint32 * 1)(variable.valueReference), 1, values, len(numbers)
        )
        if status > 1:
            self._fail(status, f"fmi3Set{kind} ({array})")

    def _count(self, n: int) -> tuple[int, ...]:
        return () if self.fmi_version < 3 else (n,)

    def enter_initialization(self) -> None:
        """Enter initialization mode (FMI 3.0 with the start and stop times); FMI 1.0 has none: its
        inputs pushed before `initialize` are the initial values."""
        self._require("enter_initialization", State.SET_UP)
        if self._initializing:
            return
        if self.fmi_version == 2:
            self._call_lifecycle("enterInitializationMode")
        elif self.fmi_version == 3:
            self._call_lifecycle("enterInitializationMode", None, self.t0, self.stop_time)
        self._initializing = True

    def initialize(self) -> None:
        self._require("initialize", State.SET_UP)
        self.enter_initialization()
        if self.fmi_version == 1:  # no initialization mode: fmiInitializeSlave(tStart, stopDefined, tStop)
            self._call_lifecycle("initialize", self.t0, self.stop_time)
        else:
            self._call_lifecycle("exitInitializationMode")
        self.state = State.STEPPING
        self._install_fast_path()

    def push_inputs(self) -> None:
        self._require("push_inputs", State.INSTANTIATED, State.SET_UP, State.STEPPING)
        self._compiled["push_inputs"]()

    def do_step(self, t: float, h: float) -> None:
        self._require("do_step", State.STEPPING)
        self._compiled["do_step"](t, h)

    def get_outputs(self) -> np.ndarray:
        self._require("get_outputs", State.STEPPING)
        return self._compiled["get_outputs"]()

    def native_step(self) -> NativeStep | None:
        """C-level stepping for the compiled kernel: every get/set call as a group (`NativeStep.groups`)."""

        def address(function) -> int:
            return ctypes.cast(function, ctypes.c_void_p).value

        version = self.fmi_version
        kernel_kinds = _KERNEL_TYPES[version]
        if self._text_feeds or self.text_outputs:
            return None  # text moves in Python (`cosim.fmi.text`)
        if any(group[0] not in kernel_kinds for group in (*self._input_groups, *self._output_groups)):
            return None
        version = 2 if version == 1 else version  # FMI 1.0 calls as FMI 2.0 does (the same C arguments)
        calls = []
        for direction, groups, buffer in (
            ("set", self._input_groups, self.input_cbuffer),
            ("get", self._output_groups, self.output_cbuffer),
        ):
            functions = self._setters if direction == "set" else self._getters
            for fmi_type, slots, refs, values, scales in groups:
                kind = kernel_kinds[fmi_type]
                # As `_compile_fast_path`: a lone unscaled real group over all ports is the buffer.
                direct = kind == "real" and all(scale == 1.0 for scale in scales) and len(groups) == 1
                direct = direct and slots == list(range(len(slots)))
                calls.append(
                    (
                        direction, kind, address(functions[fmi_type]), ctypes.addressof(refs), len(refs),
                        len(slots), ctypes.addressof(buffer if direct else values), direct,
                        tuple(slots), tuple(float(scale) for scale in scales),
                    )
                )  # fmt: skip
        finite_outputs, nan_outputs = self._checked_outputs()
        # The kernel reads an Int64/UInt64 beyond 2^53 as NaN, so the check stops at it.
        finite_outputs += [i for i, port in enumerate(self.outputs) if port.fmi_type in WIDE]
        return NativeStep(
            fmi_version=version,
            handle=self._handle if isinstance(self._handle, int) else self._handle.value,
            do_step=address(self._raw_do_step),
            step_flags=np.ctypeslib.as_array(self._step_flags) if version == 3 else np.zeros(3, bool),
            last_successful_time=ctypes.addressof(self._last_successful_time) if version == 3 else 0,
            fail=self._native_failure,
            groups=tuple(calls),
            finite_outputs=tuple(finite_outputs),
            nan_outputs=tuple(nan_outputs),
        )

    def can_vary_step(self) -> bool:
        """canHandleVariableCommunicationStepSize of the co-simulation interface (a Model Exchange
        FMU's solver takes any step; fmpy does not read FMI 1.0's Capabilities: read here)."""
        interface = self._interface()
        if interface is not self.model_description.coSimulation:
            return True
        if self.fmi_version == 1:
            return _fmi1_variable_step(str(self.path.resolve()), *_file_identity(self.path))
        return bool(interface.canHandleVariableCommunicationStepSize)

    def state_support(self) -> str | None:
        """None when the FMU can get and set its state (canGetAndSetFMUstate, FMI 2.0 and 3.0), else
        why not."""
        model = f"model {self.model_description.modelName}"
        if self.fmi_version == 1:
            return f"{model} is FMI 1.0, which has no FMU state"
        if self._interface() is not self.model_description.coSimulation:
            # The solver's own state (CVode's history) would have to go back with the FMU's.
            return f"{model} runs as Model Exchange, whose solver state is not saved"
        if not self._interface().canGetAndSetFMUstate:
            return f"{model} does not declare canGetAndSetFMUstate"
        return None

    def save_state(self) -> None:
        """fmi2GetFMUstate / fmi3GetFMUState into the one state this component keeps (allocated by
        the FMU at the first call, overwritten in place after that, as FMI allows)."""
        self._require("save_state", State.STEPPING)
        if self._fmu_state is None:
            self._fmu_state = ctypes.c_void_p()
        function = "fmi2GetFMUstate" if self.fmi_version == 2 else "fmi3GetFMUState"
        self._call_state(function, ctypes.byref(self._fmu_state))

    def restore_state(self) -> None:
        """fmi2SetFMUstate / fmi3SetFMUState with the state `save_state` kept."""
        self._require("restore_state", State.STEPPING)
        if self._fmu_state is None:
            raise CosimError(f"FMU '{self.name}': restore_state() before save_state()")
        function = "fmi2SetFMUstate" if self.fmi_version == 2 else "fmi3SetFMUState"
        self._call_state(function, self._fmu_state)

    def _call_state(self, function: str, state) -> None:
        if self.state_support() is not None:
            raise CosimError(f"FMU '{self.name}': {self.state_support()}")
        try:
            getattr(self._slave, function)(self._slave.component, state)
        except Exception as error:  # fmpy's FMICallException carries the status
            self._fail(int(getattr(error, "status", 3)), function, self._step_time[0])

    def _free_state(self) -> None:
        """Free the kept FMU state (before the instance: FMI frees states with it only by accident)."""
        state, self._fmu_state = self._fmu_state, None
        if state is None or not state.value or self._fatal:
            return
        function = "fmi2FreeFMUstate" if self.fmi_version == 2 else "fmi3FreeFMUState"
        try:
            getattr(self._slave, function)(self._slave.component, ctypes.byref(state))
        except Exception:  # a broken FMU must not prevent freeing the instance
            pass

    def _native_failure(self, call: int, status: int, t: float, kind: str = "real") -> None:
        if call == 3:
            self._asked_to_terminate(t)
        if call == 1:
            self._step_failed(status, t)
        if call == 4:
            self._step_time[0] = t
            if self.outputs[status].fmi_type in WIDE:  # read again, to name the value
                self._compiled["get_outputs"]()
            self._nonfinite_output()
        type_name = _FMI_TYPE_NAMES[self.fmi_version][kind]
        function = ("Set" + type_name, "DoStep", "Get" + type_name)[call]
        self._fail(status, f"fmi{self.fmi_version}{function}", t)

    def _nonfinite_output(self) -> None:
        """Raise the `CosimError` naming the first output that is NaN (not allowed) or infinite."""
        for port, value in zip(self.outputs, self.output_buffer.tolist(), strict=True):
            if math.isfinite(value) or math.isnan(value) and port.name in self.nan_outputs:
                continue
            variable = self.variable_name(port.name)
            named = f"'{port.name}'" + (f" (variable '{variable}')" if variable != port.name else "")
            t = self._step_time[0]
            when = "initialisation" if t is None else f"fmi{self.fmi_version}DoStep at t = {t:.9g} s"
            shown = "NaN" if math.isnan(value) else f"{value:+}"
            raise CosimError(
                f"FMU '{self.name}' (model {self.model_description.modelName}) output {named} is "
                f"{shown} after {when} (FMU outputs must be finite; list outputs whose NaN has a "
                "meaning in the component's nan_outputs)"
            )

    def _inexact_output(self, values: np.ndarray, slots: np.ndarray, fmi_type: str) -> None:
        """Raise the `CosimError` naming the first 64-bit integer output a float64 cannot hold."""
        for value, slot in zip(values.tolist(), slots.tolist(), strict=False):
            exact_as_float(value, fmi_type, f"FMU '{self.name}' output '{self.outputs[slot].name}'")

    def _step_failed(self, status: int, t: float) -> None:
        """A doStep status above Warning: Discard with fmi2Terminated true (FMI 2.0) or with
        terminateSimulation set (FMI 3.0) is the FMU's request to end the simulation; anything else
        fails."""
        if self.fmi_version == 3:
            requested = bool(self._step_flags[1])
        else:
            requested = self.fmi_version == 2 and self._fmi2_terminated()
        if status == 2 and requested:
            self._asked_to_terminate(t)
        self._fail(status, f"fmi{self.fmi_version}DoStep", t)

    def _fmi2_terminated(self) -> bool:
        """fmi2GetBooleanStatus(fmi2Terminated): whether the FMU wants the simulation to end."""
        c_int = ctypes.c_int
        prototype = ctypes.CFUNCTYPE(c_int, ctypes.c_void_p, c_int, ctypes.POINTER(c_int))
        try:
            function = prototype(("fmi2GetBooleanStatus", self._slave.dll))
        except AttributeError:
            return False
        terminated = c_int(0)
        fmi2_terminated = 3  # fmi2StatusKind
        status = function(self._handle, fmi2_terminated, ctypes.byref(terminated))
        return status == 0 and terminated.value != 0

    def _asked_to_terminate(self, t: float) -> None:
        raise SimulationEnded(
            f"FMU '{self.name}' (model {self.model_description.modelName}) asked to end "
            f"the simulation in its step from t = {t:.9g} s",
            self.name,
            t,
        )

    def terminate(self) -> None:
        self._require("terminate", State.SET_UP, State.STEPPING)
        self._remove_fast_path()
        self.state = State.TERMINATED
        self._call_lifecycle("terminate")

    def free(self) -> None:
        """Free the instance and unload the binary; after fmi*Fatal only forget them."""
        self._remove_fast_path()
        if self._slave is not None and self.state is not State.FREED:
            self._free_state()
            slave, self._slave = self._slave, None
            if not self._fatal:
                try:
                    slave.freeInstance()
                except Exception:  # a broken FMU must not prevent freeing the others
                    pass
        self.state = State.FREED
        _LOG_TARGETS.pop(id(self), None)
        exit_guard.release(self)
        self._discard_files()

    def _discard_files(self) -> None:
        if self._unzip_dir is not None:
            shutil.rmtree(self._unzip_dir, ignore_errors=True)
            self._unzip_dir = None

    def describe(self) -> dict[str, str]:
        description = self.model_description
        return {
            "fmu": str(self.path),
            "model_name": description.modelName or "",
            "fmi_version": description.fmiVersion or "",
            "guid": (description.guid if self.fmi_version < 3 else description.instantiationToken) or "",
            "generation_tool": description.generationTool or "",
            "generation_date": description.generationDateAndTime or "",
        }


_LOG_TARGETS: dict[int, weakref.ref] = {}


def _with_text(component: FmuComponent, do_step, get_outputs) -> dict:
    """`do_step` that first sends the text inputs, `get_outputs` that also reads the text outputs."""

    started = [None]  # start [s] of the step whose outputs `read` gets next

    def stepped(t: float, h: float) -> None:
        if component.text_inputs:
            component._send_text()
        do_step(t, h)
        started[0] = t

    def read():
        outputs = get_outputs()
        if component.text_outputs:
            component._read_text()
        if started[0] is not None and component.text_listener is not None:
            component.text_listener(started[0])  # a recording (`cosim.record.text_signals`)
        started[0] = None
        return outputs

    return {"do_step": stepped, "get_outputs": read}


def _needed_at_run_time(member: str) -> bool:
    """Whether an instance's directory gets this archive member: all but the FMU's C sources and its
    documentation, which the FMI standard gives the model no use of at run time (its own files are
    in resources/); extracting them was most of the files an instance wrote."""
    return not member.startswith(("sources/", "documentation/"))


@cache
def _fmi2_logger():
    """One FMI 2.0 logger for all instances, dispatching on componentEnvironment."""
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    def dispatch(environment, instance, status, category, message):
        target = _LOG_TARGETS.get(environment or 0)
        component = target() if target is not None else None
        if component is not None:
            component._log(status, category, message)

    return fmi2CallbackLoggerTYPE(dispatch)


def _finite_check_lines(finite: list[int], nan_allowed: list[int]) -> list[str]:
    """Source lines calling `nonfinite()` when an output at a `finite` slot is NaN or infinite, or
    one at a `nan_allowed` slot is infinite. x - x is 0.0 for every finite x and NaN otherwise, so
    one comparison covers a whole sum of such differences."""
    lines = []
    if len(finite) > 10:  # one NumPy dot product beats many element reads
        if finite == list(range(len(finite))) and not nan_allowed:
            lines.append("    if obn.dot(zeros) != 0.0: nonfinite()")
        else:
            lines.append(f"    if obn[{finite!r}].dot(zeros[:{len(finite)}]) != 0.0: nonfinite()")
    elif finite:
        terms = " + ".join(f"((a{slot} := ob[{slot}]) - a{slot})" for slot in finite)
        lines.append(f"    if {terms} != 0.0: nonfinite()")
    lines += [f"    if abs(ob[{slot}]) == inf: nonfinite()" for slot in nan_allowed]
    return lines


def _copy_lines(direction: str, group: int, kind: str, slots: list[int], scales: list[float]) -> list[str]:
    """Source lines copying one type group between a component buffer and its FMI value array."""
    values, array = f"v{direction}{group}", f"vn{direction}{group}"
    if len(slots) > 8:  # one NumPy copy beats many element copies
        scaled = "" if all(scale == 1.0 for scale in scales) else f" * k{direction}{group}"
        if direction == "Get":
            return [f"    obn[s{direction}{group}] = {array}{scaled}"]
        staged = f"ibn[s{direction}{group}]{scaled}"
        convert = {"real": staged, "integer": f"np.rint({staged})", "boolean": f"{staged} != 0.0"}[kind]
        return [f"    {array}[:] = {convert}"]
    lines = []
    for position, (slot, scale) in enumerate(zip(slots, scales, strict=True)):
        factor = "" if scale == 1.0 else f" * {scale!r}"
        if direction == "Get":
            lines.append(f"    ob[{slot}] = {values}[{position}]{factor}")
        else:
            convert = {"real": "{}", "integer": "int(round({}))", "boolean": "{} != 0.0"}[kind]
            lines.append(f"    {values}[{position}] = " + convert.format(f"ib[{slot}]{factor}"))
    return lines


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


def _start_value(start: object, fmi_type: str, what: str) -> float:
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


def _variable_defaults() -> dict[str, object]:
    """fmpy's `ModelVariable` fields and their defaults."""
    import attr

    return {
        a.name: a.default.factory() if isinstance(a.default, attr.Factory) else a.default
        for a in attr.fields(ModelVariable)
    }


class _KeptVariable(ModelVariable):
    """fmpy's `ModelVariable` as a kept description has it: only the fields that differ from the
    defaults are in the instance (a `__dict__`; the defaults are class attributes, which shadow
    fmpy's slots), so unpickling one is a dict update instead of fmpy's forty-odd slot assignments
    (a 2000-variable description: ~3 ms instead of ~13 ms). Read-only like every parsed description
    here: the list defaults are shared."""

    def __getstate__(self) -> dict:
        return dict(self.__dict__)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)


for _name, _default in _variable_defaults().items():
    setattr(_KeptVariable, _name, _default)


def _new_kept_variable() -> _KeptVariable:
    """An empty `_KeptVariable` (unpickling: its state follows)."""
    return object.__new__(_KeptVariable)


def _kept_pickler(stream, protocol: int):
    """A pickler that writes a description's `ModelVariable`s as `_KeptVariable`s."""
    import pickle

    defaults = _variable_defaults()

    class Pickler(pickle.Pickler):
        def reducer_override(self, obj):
            if type(obj) is not ModelVariable:
                return NotImplemented
            state = {}
            for name, default in defaults.items():
                value = getattr(obj, name)
                if value is not default and (type(value) is not type(default) or value != default):
                    state[name] = value
            return _new_kept_variable, (), state

    return Pickler(stream, protocol=protocol)
