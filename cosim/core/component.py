"""One interface for every part of a co-simulation: FMUs and Python components alike.

A `Component` has named, typed ports (inputs, outputs, parameters), a period (how often the
master steps it), declared direct dependencies of outputs on inputs (`feedthrough`, used to
order the components and to detect algebraic loops) and a strict lifecycle:

    instantiate() -> setup(t0, parameters) -> [set_inputs] -> initialize()
        -> { set_inputs / do_step / get_outputs }* -> terminate() -> free()

Every value that crosses a component's boundary is a float64 in one of two preallocated buffers:
`input_buffer` (one slot per input, in port order) and `output_buffer` (one slot per output).
Integer and Boolean ports carry their value as a float (0.0/1.0 for Booleans); FMU components
convert at the FMI call. The master writes connected inputs straight into `input_buffer` and then
calls `push_inputs()` (one batched call per FMI type for an FMU), so a step costs no allocation.

Array-valued signals are flattened into scalar ports named like `ranges[3]` or
`waypoints[12,1]` (1-based indices, as FMI's structured naming convention). `Port.array_name`
and `Port.array_index` tell them apart from plain scalars, so a logger can publish arrays on
their own topics.
"""

from __future__ import annotations

import ctypes
import enum
import functools
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from cosim.errors import CosimError

PORT_TYPES = ("real", "integer", "boolean")
_ARRAY_ELEMENT = re.compile(r"^(?P<base>.+)\[(?P<index>\d+(?:\s*,\s*\d+)*)\]$")


@dataclass(frozen=True)
class NativeStep:
    """How the compiled kernel (`cosim.core.kernel`) steps a component by C calls alone.

    Addresses are plain integers (C pointers). `fmi_version` selects the calling convention of the
    FMI get/set/doStep functions. `groups` lists every get/set call of a step: (direction "set" or
    "get", kind "real"/"integer"/"boolean", function, value references, reference count, value
    count, FMI value array, direct (the array is the component's buffer), buffer slots, scales); the
    kinds beyond those three are `cosim.core.kernel.KINDS`.
    `fail(call, status, t, kind)` raises the component's `CosimError` for a call (0 set, 1 doStep,
    2 get, 3 asked to terminate, 4 an output not finite: `status` is its slot) that the kernel
    stopped at. After each get the kernel checks that the outputs at `finite_outputs` are finite
    and those at `nan_outputs` are not infinite.
    """

    fmi_version: int
    handle: int
    do_step: int
    step_flags: np.ndarray  # FMI 3.0: eventHandlingNeeded, terminateSimulation, earlyReturn
    last_successful_time: int  # FMI 3.0: address of the double doStep writes
    fail: Callable[..., None]
    groups: tuple = ()
    finite_outputs: tuple[int, ...] = ()
    nan_outputs: tuple[int, ...] = ()


@dataclass(frozen=True, init=False)
class Port:
    """A scalar port: name, FMI-like type (`real`, `integer`, `boolean`), unit, start value, and
    for an FMU's port the FMI type that moves it (`fmi_type`: "Float32", "Int64", ...; see
    `cosim.fmi.types`; "" for other components' ports)."""

    name: str
    type: str = "real"
    unit: str = ""
    description: str = ""
    start: float = 0.0
    fmi_type: str = ""
    array_name: str | None = field(default=None, init=False, compare=False)
    array_index: tuple[int, ...] | None = field(default=None, init=False, compare=False)
    # True for ports such as `ranges[3]` that are one element of an array signal (an attribute,
    # not a property: a run's set-up reads it for each of ~10,000 ports).
    is_array_element: bool = field(default=False, init=False, compare=False, repr=False)

    def __init__(
        self,
        name: str,
        type: str = "real",
        unit: str = "",
        description: str = "",
        start: float = 0.0,
        fmi_type: str = "",
    ) -> None:
        # Written out (not generated) because a run makes ~10,000 ports: the generated __init__ of a
        # frozen dataclass sets each field through object.__setattr__ and parsed every name anew.
        if type not in PORT_TYPES:
            raise CosimError(f"port '{name}': type '{type}' is not one of {', '.join(PORT_TYPES)}")
        array_name, array_index = _array_element(name) if name[-1:] == "]" else (None, None)
        self.__dict__.update(
            name=name,
            type=type,
            unit=unit,
            description=description,
            start=start,
            fmi_type=fmi_type,
            array_name=array_name,
            array_index=array_index,
            is_array_element=array_name is not None,
        )


@functools.lru_cache(maxsize=1 << 16)
def _array_element(name: str) -> tuple[str | None, tuple[int, ...] | None]:
    """(`ranges`, (3,)) of an array element port's name `ranges[3]`; (None, None) of any other."""
    match = _ARRAY_ELEMENT.match(name)
    if match is None:
        return None, None
    return match["base"], tuple(int(part) for part in match["index"].split(","))


def array_ports(base: str, count: int, columns: int = 0, unit: str = "", start: float = np.nan) -> list[Port]:
    """Ports `base[1]..base[count]`, or `base[k,c]` for c = 1..columns (row-major), NaN start."""
    return list(_array_ports(base, count, columns, unit, start))


@functools.lru_cache(maxsize=64)
def _array_ports(base: str, count: int, columns: int, unit: str, start: float) -> tuple[Port, ...]:
    """`array_ports`, made once per argument set (ports are read-only; describing and building a
    system made a planner's 2000 waypoint ports four times)."""
    if columns:
        indices = [(row, col) for row in range(1, count + 1) for col in range(1, columns + 1)]
        names = [f"{base}[{row},{col}]" for row, col in indices]
    else:
        indices = [(row,) for row in range(1, count + 1)]
        names = [f"{base}[{row}]" for row in range(1, count + 1)]
    if not base:
        return tuple(Port(name, unit=unit, start=start) for name in names)
    ports = []
    for name, index in zip(names, indices, strict=True):  # the element known: no parsing of its name
        port = object.__new__(Port)
        port.__dict__.update(
            name=name, type="real", unit=unit, description="", start=start, fmi_type="",
            array_name=base, array_index=index, is_array_element=True,
        )  # fmt: skip
        ports.append(port)
    return tuple(ports)


def check_unique_ports(component: str, kind: str, ports: Iterable[Port]) -> None:
    """`CosimError` when two of a component's `kind` ports ("input", "output", "parameter") share a name."""
    names = [port.name for port in ports]
    if len(set(names)) != len(names):
        duplicate = next(n for n in names if names.count(n) > 1)
        raise CosimError(f"component '{component}': {kind} '{duplicate}' declared twice")


def closest_names(name: str, candidates: Iterable[str], limit: int = 12) -> str:
    """The candidates as a comma-separated list, closest to `name` first (for error messages)."""
    import difflib  # only for an error message: not imported by a run that has none

    candidates = list(candidates)
    close = difflib.get_close_matches(name, candidates, n=limit, cutoff=0.0)
    rest = [c for c in candidates if c not in close]
    listed = close + rest[: max(0, limit - len(close))]
    more = len(candidates) - len(listed)
    return ", ".join(listed) + (f" (and {more} more)" if more > 0 else "")


class State(enum.IntEnum):
    """Lifecycle states; a method called in the wrong state raises `CosimError`."""

    CREATED = 0
    INSTANTIATED = 1
    SET_UP = 2
    STEPPING = 3
    TERMINATED = 4
    FREED = 5
    FAILED = 6  # returned an error: terminate() is skipped, free() stays safe


class Component(ABC):
    """Abstract component. Subclasses fill `inputs`, `outputs`, `parameters` before `instantiate`.

    Attributes:
        name: unique name in the system (a role name such as `vehicle`).
        inputs, outputs, parameters: ordered `Port` lists.
        period: seconds between steps; 0 = every macro step. Must be a multiple of the macro step.
        feedthrough: output name -> names of the inputs it depends on directly (at the same
            instant). An output missing from the dict depends on all inputs. Read-only: outputs
            with the same dependencies share one list (a path follower's 7 outputs on its 2003
            inputs, a planner's 2000 waypoints on one input).
        input_buffer, output_buffer: float64 arrays, one slot per input/output port.
    """

    # True when the outputs never change after initialize() (a plan fixed for the run): the master
    # then copies its connections once, at initialisation, and does not step it.
    constant_outputs: bool = False

    def __init__(
        self,
        name: str,
        inputs: Sequence[Port] = (),
        outputs: Sequence[Port] = (),
        parameters: Sequence[Port] = (),
        period: float = 0.0,
        feedthrough: Mapping[str, Sequence[str]] | None = None,
    ) -> None:
        if not name or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise CosimError(f"component name '{name}' must be an identifier (letters, digits, _)")
        if period < 0:
            raise CosimError(f"component '{name}': period {period} s must be >= 0")
        self.name = name
        self.period = float(period)
        self.state = State.CREATED
        self._set_ports(inputs, outputs, parameters, feedthrough)

    # ---- ports and buffers -------------------------------------------------------------------

    def _set_ports(
        self,
        inputs: Sequence[Port],
        outputs: Sequence[Port],
        parameters: Sequence[Port],
        feedthrough: Mapping[str, Sequence[str]] | None,
    ) -> None:
        """Declare the ports and allocate the buffers (ctypes memory with NumPy views)."""
        self.inputs = list(inputs)
        self.outputs = list(outputs)
        self.parameters = list(parameters)
        for kind, ports in (("input", self.inputs), ("output", self.outputs), ("parameter", self.parameters)):
            check_unique_ports(self.name, kind, ports)
        self.input_index = {p.name: i for i, p in enumerate(self.inputs)}
        self.output_index = {p.name: i for i, p in enumerate(self.outputs)}
        # ctypes arrays let the master copy single values fast; the NumPy views serve bulk copies.
        self.input_cbuffer = (ctypes.c_double * max(1, len(self.inputs)))()
        self.output_cbuffer = (ctypes.c_double * max(1, len(self.outputs)))()
        self.input_buffer = np.ctypeslib.as_array(self.input_cbuffer)[: len(self.inputs)]
        self.output_buffer = np.ctypeslib.as_array(self.output_cbuffer)[: len(self.outputs)]
        self.input_buffer[:] = [p.start for p in self.inputs]
        self.output_buffer[:] = [p.start for p in self.outputs]
        self.feedthrough = self._check_feedthrough(feedthrough or {})

    def _check_feedthrough(self, feedthrough: Mapping[str, Sequence[str]]) -> dict[str, list[str]]:
        """Complete the dependency dict: outputs not listed depend on every input."""
        complete: dict[str, list[str]] = {}
        inputs = self.input_index.keys()
        checked: dict[int, list[str]] = {}  # id of a dependency sequence given -> its checked list
        for output, depends in feedthrough.items():
            if output not in self.output_index:
                raise CosimError(f"component '{self.name}': feedthrough names unknown output '{output}'")
            listed = checked.get(id(depends))
            if listed is None:  # (outputs often share one sequence: a path follower's name 2000 inputs)
                listed = checked[id(depends)] = list(depends)
                if not inputs >= set(listed):
                    name = next(name for name in listed if name not in inputs)
                    raise CosimError(
                        f"component '{self.name}': output '{output}' depends on unknown input '{name}'"
                    )
            complete[output] = listed
        every_input = [p.name for p in self.inputs]
        for port in self.outputs:
            if port.name not in complete:
                complete[port.name] = every_input
        return complete

    def port(self, name: str) -> tuple[str, int]:
        """('input' | 'output', index) of a port; `CosimError` listing the ports when unknown."""
        if name in self.output_index:
            return "output", self.output_index[name]
        if name in self.input_index:
            return "input", self.input_index[name]
        known = [p.name for p in self.outputs] + [p.name for p in self.inputs]
        raise CosimError(f"component '{self.name}' has no port '{name}'; ports: {closest_names(name, known)}")

    def signal_names(self) -> list[str]:
        """Names of every scalar input then output, the order of `signal_values()`."""
        return [p.name for p in self.inputs] + [p.name for p in self.outputs]

    def signal_values(self) -> np.ndarray:
        """Current input then output values (a new array; callers may keep it)."""
        return np.concatenate((self.input_buffer, self.output_buffer))

    # ---- lifecycle ---------------------------------------------------------------------------

    def _require(self, method: str, *states: State) -> None:
        if self.state not in states:
            allowed = " or ".join(s.name.lower() for s in states)
            raise CosimError(
                f"component '{self.name}': {method}() called in state {self.state.name.lower()}, "
                f"needs {allowed}"
            )

    @abstractmethod
    def instantiate(self) -> None:
        """Create the model instance (load an FMU's binary)."""

    @abstractmethod
    def setup(self, t0: float, parameters: Mapping[str, float], stop_time: float | None = None) -> None:
        """Set up the experiment (start time t0 [s]; the stop time [s], None when open), then apply
        parameter values (by name)."""

    def enter_initialization(self) -> None:
        """Enter initialisation (an FMU's initialization mode): inputs pushed from now on until
        `initialize` are the initial values. A component without such a mode does nothing."""
        return None

    @abstractmethod
    def initialize(self) -> None:
        """End initialisation (entering it first if need be): outputs become valid for t0 from the
        pushed inputs."""

    @abstractmethod
    def push_inputs(self) -> None:
        """Send every staged `input_buffer` value to the model (one batched call per FMI type)."""

    def set_inputs(self, index: np.ndarray | Sequence[int], values: np.ndarray | Sequence[float]) -> None:
        """Stage `values` at input slots `index` (port order) and send all inputs to the model."""
        self.input_buffer[np.asarray(index, dtype=np.intp)] = values
        self.push_inputs()

    @abstractmethod
    def do_step(self, t: float, h: float) -> None:
        """Advance from t to t + h [s] using the inputs last pushed."""

    @abstractmethod
    def get_outputs(self) -> np.ndarray:
        """Read all outputs into `output_buffer` and return it (the same array every call)."""

    @abstractmethod
    def terminate(self) -> None:
        """End the simulation (skipped for a failed component)."""

    @abstractmethod
    def free(self) -> None:
        """Release the instance. Safe in every state, and safe to call twice."""

    def native_step(self) -> NativeStep | None:
        """The C-level step of this component, or None when it needs Python to step (the default)."""
        return None

    def can_vary_step(self) -> bool:
        """Whether the component takes steps shorter than its period (a last step cut at the stop
        time); an FMU says so with canHandleVariableCommunicationStepSize. Default: it can."""
        return True

    # ---- state (what `[simulation] algebraic_loops = "iterate"` rolls a step back with) ---------

    def state_support(self) -> str | None:
        """None when the component can keep its state and go back to it (`save_state`,
        `restore_state`); otherwise why not, a phrase for a message. The default: it cannot."""
        return "it cannot save and restore its state"

    def save_state(self) -> None:
        """Keep the component's current state (while stepping); a second call replaces the first."""
        raise CosimError(f"component '{self.name}': {self.state_support()}")

    def restore_state(self) -> None:
        """Go back to the state `save_state` kept (the output buffer keeps its values until the next
        `get_outputs`)."""
        raise CosimError(f"component '{self.name}': {self.state_support()}")

    def text_port(self, name: str, direction: str) -> str | None:
        """The type ("String", "Binary") of a text input or output outside the float buffers (an
        FMU's: `cosim.fmi.text`); None for every other name (the default: a component has none)."""
        return None

    def feed_text(self, name: str, producer: Component, output: str) -> None:
        """Take text input `name` from `producer`'s text output `output` before each step."""
        raise CosimError(f"component '{self.name}' has no text input '{name}'")

    def push_text(self) -> None:
        """Send the text inputs now, the fed ones with their producers' current values (the master
        calls it at initialisation; while stepping they go before each step). Default: none."""
        return None

    def describe(self) -> dict[str, str]:
        """Facts for a log's metadata (FMU GUID, generating tool...); empty for plain components."""
        return {}

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} ({self.state.name.lower()})>"


class PythonComponent(Component):
    """Base of components written in Python (planner, lidar, user code).

    Subclasses declare ports in `__init__` and override `step(t, h)`, which reads
    `self.input_buffer` and writes `self.output_buffer`. Optional hooks: `on_setup(t0,
    parameters)` (parameters arrive already checked against the declared ones, as floats) and
    `on_initialize()` (compute initial outputs from the staged inputs; default: `step(t0, 0)` is
    not called, outputs keep their start values).
    """

    def instantiate(self) -> None:
        self._require("instantiate", State.CREATED)
        self.state = State.INSTANTIATED

    def setup(self, t0: float, parameters: Mapping[str, float], stop_time: float | None = None) -> None:
        self._require("setup", State.INSTANTIATED)
        known = {p.name for p in self.parameters}
        for key in parameters:
            if key not in known:
                raise CosimError(
                    f"component '{self.name}' has no parameter '{key}'; parameters: "
                    f"{closest_names(key, [p.name for p in self.parameters]) or 'none'}"
                )
        values = {p.name: p.start for p in self.parameters}
        values.update(parameters)
        self.t0 = float(t0)
        self.on_setup(self.t0, values)
        self.state = State.SET_UP

    def initialize(self) -> None:
        self._require("initialize", State.SET_UP)
        self.on_initialize()
        self.state = State.STEPPING

    def push_inputs(self) -> None:
        self._require("push_inputs", State.INSTANTIATED, State.SET_UP, State.STEPPING)

    def do_step(self, t: float, h: float) -> None:
        if self.state is not State.STEPPING:
            self._require("do_step", State.STEPPING)
        self.step(t, h)

    def get_outputs(self) -> np.ndarray:
        if self.state is State.FREED:
            self._require("get_outputs", State.SET_UP, State.STEPPING, State.TERMINATED)
        return self.output_buffer

    def terminate(self) -> None:
        self._require("terminate", State.STEPPING, State.SET_UP)
        self.state = State.TERMINATED

    def free(self) -> None:
        self.state = State.FREED

    def on_setup(self, t0: float, parameters: Mapping[str, float]) -> None:
        """Hook: receive parameters [declared units] and the start time [s]."""

    def on_initialize(self) -> None:
        """Hook: set initial outputs from `input_buffer`."""

    @abstractmethod
    def step(self, t: float, h: float) -> None:
        """Advance from t by h [s]: read `input_buffer`, write `output_buffer`."""
