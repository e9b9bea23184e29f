"""FMI 1.0, 2.0 and 3.0 co-simulation FMUs as components, through fmpy, with a strict lifecycle.

An `FmuComponent` is made from the FMU's checked description (`cosim.fmi.description`) and its
ports (`cosim.fmi.layout`, with the port map); fmpy loads the binary and runs the lifecycle calls
(instantiate, setup with the parameters, initialise, terminate, free), and the per-step calls are
generated code over the FMU's C functions (`cosim.fmi.codegen`).

Every real output must be finite: after each step (and after initialisation) `get_outputs` raises
`CosimError` naming the output when one is NaN or infinite, since a NaN fed on would pass as a value
(a NaN pose is no position at all). Outputs listed in `nan_outputs` (or `allow_nan`) may be NaN where
the FMU gives NaN a meaning; they must still not be infinite. The project FMUs' documented NaN
outputs (VFH's `steering_dir` when no direction is free, PurePursuit's `goal_distance` without
waypoints: `cosim.fmi.builtin.documented_nan_variables`) are allowed by default. Integer and
Boolean outputs are always finite.

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
import weakref
from collections import deque
from collections.abc import Collection, Mapping
from functools import cache
from pathlib import Path

import fmpy
import numpy as np
from fmpy.fmi1 import FMU1Slave
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim.core.component import Component, NativeStep, Port, State, closest_names
from cosim.errors import CosimError, SimulationEnded
from cosim.fmi import exit_guard
from cosim.fmi.archive import unpack_instance
from cosim.fmi.codegen import FMI_TYPE_NAMES, TransferGroup, native_step, step_functions, transfer_groups
from cosim.fmi.description import file_identity, fmi1_variable_step, kept_unpacked
from cosim.fmi.layout import fmu_layout, start_value
from cosim.fmi.text import TextTransfer, check_text
from cosim.fmi.types import C_TYPES, KINDS, TRANSFER_TYPES, WIDE, check_integer, exact_as_float

_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")


def functions_bound_once(fmpy_class: type) -> type:
    """fmpy's class `fmpy_class` (same name: fmpy picks the FMI version by it), whose instances bind
    the FMI functions of their library exactly as fmpy's `_loadFunctions` does (argument names and
    types, result type, read off the Python wrappers' signatures), reading those signatures once per
    class and model identifier (an FMI 1.0 function's name carries it) rather than per instance:
    `inspect` over every member took ~1.5 ms an instance, 200 instances in a fleet of 50 robots."""
    bindings: dict[str, list[tuple[str, str, list[str], tuple, object]]] = {}

    def _loadFunctions(self) -> None:  # noqa: N802 - fmpy's name
        known = bindings.get(self.modelIdentifier)
        if known is None:  # fmpy binds them; what it set is what every later instance gets
            fmpy_class._loadFunctions(self)
            bindings[self.modelIdentifier] = [
                (name, f.__name__, list(f.argnames), f.argtypes, f.restype)
                for name, f in self._functions.items()
            ]
            return
        dll = self.dll
        for name, symbol, argnames, argtypes, restype in known:
            function = getattr(dll, symbol)
            function.argnames = list(argnames)
            function.argtypes = argtypes
            function.restype = restype
            self._functions[name] = function

    return type(
        fmpy_class.__name__, (fmpy_class,), {"_loadFunctions": _loadFunctions, "__module__": __name__}
    )


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
        self._release_files = None  # gives the folder back (`cosim.fmi.archive.unpack_instance`)
        self._fatal = False
        self._fmu_state: ctypes.c_void_p | None = None  # kept by `save_state`, freed with the instance
        self.log_messages: deque[str] = deque(maxlen=20)

    # fmpy's class of an instance, by FMI version (`cosim.fmi.model_exchange` has its own).
    _FMPY_CLASSES = {
        version: functions_bound_once(c) for version, c in ((1, FMU1Slave), (2, FMU2Slave), (3, FMU3Slave))
    }

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
        if not ports:  # (most FMUs: asked once per connection)
            return None
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
        return self._variables[port].variable.name

    def _checked_outputs(self) -> tuple[list[int], list[int]]:
        """Slots of the real outputs that must be finite, and of those that may only be NaN."""
        real = [i for i, port in enumerate(self.outputs) if port.type == "real"]
        finite = [i for i in real if self.outputs[i].name not in self.nan_outputs]
        return finite, [i for i in real if self.outputs[i].name in self.nan_outputs]

    def _groups(self, ports: list[Port], only: set[int] | None = None) -> list[TransferGroup]:
        """Per FMI transfer type, the ports (at slots `only`, when given) one call moves."""
        return transfer_groups(ports, self._variables, self._elements, self.fmi_version, only)

    def restrict_push(self, slots) -> None:
        """From now on `push_inputs` sends only the inputs at `slots` (port order): the others keep
        the values last sent (FMI inputs hold their values), e.g. a plan fixed for the whole run."""
        self._input_groups = self._groups(self.inputs, set(slots))
        self._compile_fast_path()
        if self.state is State.STEPPING:
            self._install_fast_path()

    def _compile_fast_path(self) -> None:
        """Generate specialised `push_inputs`, `do_step`, `get_outputs` for this FMU
        (`cosim.fmi.codegen`); `_remove_fast_path` puts the checked class methods back when the
        instance leaves the stepping state."""
        self._compiled = step_functions(self)

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
        interface = self._interface()
        shareable = interface is not None and interface.canBeInstantiatedOnlyOncePerProcess is False
        try:
            kept = kept_unpacked(self.path) if shareable else None
            self._unzip_dir, self._release_files = unpack_instance(
                self.path, _needed_at_run_time, f"navcosim-{self.name}-", shareable, kept
            )
        except Exception as error:
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
        start = start_value(variable.start, fmi_type, key)
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
        variable = self._variables[ports[0].name].variable
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
        """C-level stepping for the compiled kernel (`cosim.fmi.codegen.native_step`)."""
        return native_step(self)

    def can_vary_step(self) -> bool:
        """canHandleVariableCommunicationStepSize of the co-simulation interface (a Model Exchange
        FMU's solver takes any step; fmpy does not read FMI 1.0's Capabilities: read here)."""
        interface = self._interface()
        if interface is not self.model_description.coSimulation:
            return True
        if self.fmi_version == 1:
            return fmi1_variable_step(str(self.path.resolve()), *file_identity(self.path))
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
        type_name = FMI_TYPE_NAMES[self.fmi_version][kind]
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
            self._release_files()  # (a folder shared with other instances goes with the last)
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
