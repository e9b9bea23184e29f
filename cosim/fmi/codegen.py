"""An FMU component's per-step code: the value transfers (`TransferGroup`), the straight-line Python
of `push_inputs`, `do_step` and `get_outputs` (`step_functions`), and the same calls described for
the compiled kernel (`native_step`).

The per-step calls (set inputs, do step, get outputs) go straight to the FMU's C functions with value
references resolved once and values in preallocated ctypes arrays: one batched call per FMI type,
about 4x faster than fmpy's methods, which convert lists and check types on every call. The
transfer is native: one fmi3Get/fmi3Set call moves all variables of a type, each FMI 3.0 array as
one value reference with all its elements (a 720-beam scan is one reference, not 720).

The functions are generated with every buffer, value reference and C function bound as a constant
named for what it is (`fmi2SetReal`, `Real_input_references`, `outputs`), so a step costs the C
calls plus a few element copies, with no loop, lookup or allocation. A generated `push_inputs` of
two inputs, one of them scaled, reads:

    def push_inputs():
        Real_input_values[0] = inputs[0]
        Real_input_values[1] = inputs[1] * -1.0
        status = fmi2SetReal(instance, Real_input_references, 2, Real_input_values)
        if status > 1: fail(status, 'fmi2SetReal')
        return None

Every real output must be finite: `get_outputs` calls `nonfinite()` (the component's error naming
the output) when one is NaN or infinite, except the outputs allowed NaN, which must still not be
infinite. A 64-bit integer output a float64 cannot hold exactly is an error too (`inexact`).
"""

from __future__ import annotations

import ctypes
import functools
import math
from array import array
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass

import numpy as np

from cosim.core.component import Component, NativeStep, Port
from cosim.fmi.layout import MappedVariable
from cosim.fmi.types import C_TYPES, KINDS, TRANSFER_TYPES, WIDE

# Transfer types as the compiled kernel's group kinds (`cosim.core.kernel.KINDS`).
KERNEL_TYPES = {1: {"Real": "real", "Integer": "integer"}}  # FMI 1.0 Booleans are chars: Python moves them
KERNEL_TYPES[2] = {"Real": "real", "Integer": "integer", "Boolean": "boolean"}
KERNEL_TYPES[3] = {"Float64": "real", "Int32": "integer", "Boolean": "boolean"}
KERNEL_TYPES[3] |= {name: name.lower() for name in TRANSFER_TYPES[3] if name not in KERNEL_TYPES[3]}
FMI_TYPE_NAMES = {
    version: {kind: name for name, kind in names.items()} for version, names in KERNEL_TYPES.items()
}


@dataclass(frozen=True)
class TransferGroup:
    """The ports of one FMI transfer type that one get or set call moves."""

    fmi_type: str  # "Real", "Float64", "Int32", ... (`cosim.fmi.types.TRANSFER_TYPES`)
    slots: list[int]  # the ports' places in the component's buffer, in port order
    references: ctypes.Array  # value references (an FMI 3.0 array's once, at its first element)
    values: ctypes.Array  # the FMI value array the call reads or fills, one element per slot
    scales: list[float]  # per slot, in the direction of the data flow


def transfer_groups(
    ports: list[Port],
    variables: Mapping[str, MappedVariable],
    elements: Mapping[str, int],
    fmi_version: int,
    only: Collection[int] | None = None,
) -> list[TransferGroup]:
    """Per FMI transfer type, the ports (those at slots `only`, when given) moved by one call. An FMI
    3.0 array's element ports are consecutive (in element order), so its reference is listed once,
    at its first element, and its values fill that stretch of the value array."""
    if only is not None:  # an array is transferred whole: a slot of it brings all of them
        arrays = {variables[ports[i].name].variable.name for i in only if ports[i].name in elements}
        only = set(only) | {
            i for i, p in enumerate(ports) if p.name in elements and variables[p.name].variable.name in arrays
        }
    by_type: dict[str, list[int]] = {}  # (one pass over the ports: a path follower has 2003 inputs)
    kinds = {p.fmi_type for p in ports} if only is None else ()
    if len(kinds) == 1:  # (the usual FMU: every port of one type)
        by_type[next(iter(kinds))] = list(range(len(ports)))
    else:
        for i, p in enumerate(ports):
            if only is None or i in only:
                if p.fmi_type in by_type:
                    by_type[p.fmi_type].append(i)
                else:
                    by_type[p.fmi_type] = [i]
    groups = []
    for kind in TRANSFER_TYPES[fmi_version]:
        slots = by_type.get(kind)
        if slots:
            mapped = [variables[ports[i].name] for i in slots]
            if elements:
                first = [elements.get(ports[i].name, 0) == 0 for i in slots]
                pairs = zip(mapped, first, strict=True)
                references = [m.variable.valueReference for m, kept in pairs if kept]
            else:  # (no array: every port has its own reference)
                references = [m.variable.valueReference for m in mapped]
            scales = [m.scale for m in mapped]
            values = (C_TYPES[fmi_version][kind] * len(slots))()
            array = _references(references)
            groups.append(TransferGroup(kind, slots, array, values, scales))
    return groups


def _references(references: list[int]) -> ctypes.Array:
    """A ctypes array of the value references, as `(c_uint32 * n)(*references)` makes it; copied from
    an `array("I")` (~10x faster for 2000) where every reference fits in 32 unsigned bits."""
    kind = ctypes.c_uint32 * len(references)
    try:
        packed = array("I", references)
    except (OverflowError, TypeError):
        return kind(*references)
    if packed.itemsize != ctypes.sizeof(ctypes.c_uint32):
        return kind(*references)
    return kind.from_buffer_copy(packed)


def _is_buffer(group: TransferGroup, groups: list[TransferGroup], fmi_version: int) -> bool:
    """Whether the FMI call can read or fill the component's buffer itself: a lone unscaled group of
    doubles over all ports in order."""
    kind = group.fmi_type
    direct = KINDS[kind] == "real" and C_TYPES[fmi_version][kind] is ctypes.c_double
    direct = direct and all(scale == 1.0 for scale in group.scales) and len(groups) == 1
    return direct and group.slots == list(range(len(group.slots)))


def step_functions(component: Component) -> dict[str, Callable]:
    """Generate `push_inputs`, `do_step` and `get_outputs` for an `FmuComponent` whose C functions
    are bound (`FmuComponent._bind_raw_functions`); text inputs and outputs (`cosim.fmi.text`) move
    beside the numbers."""
    version = component.fmi_version
    count_argument = "" if version < 3 else ", {n}"  # FMI 3.0 also takes the number of values
    names: dict[str, object] = {"fail": component._fail, "np": np, "instance": component._handle}
    names.update(inputs=component.input_cbuffer, input_array=component.input_buffer)
    names.update(outputs=component.output_cbuffer, output_array=component.output_buffer)
    push, pull = ["def push_inputs():"], ["def get_outputs():"]
    for io, groups, lines in (
        ("input", component._input_groups, push),
        ("output", component._output_groups, pull),
    ):
        direction = "Set" if io == "input" else "Get"
        functions = component._setters if io == "input" else component._getters
        buffer = component.input_cbuffer if io == "input" else component.output_cbuffer
        for group in groups:
            kind, prefix = group.fmi_type, f"{group.fmi_type}_{io}"
            function = f"fmi{version}{direction}{kind}"
            values = buffer if _is_buffer(group, groups, version) else group.values
            names[function] = functions[kind]
            names[f"{prefix}_references"] = group.references
            names[f"{prefix}_values"] = values
            names[f"{prefix}_value_array"] = np.ctypeslib.as_array(values)
            names[f"{prefix}_slots"] = np.array(group.slots, dtype=np.intp)
            names[f"{prefix}_scales"] = np.array(group.scales)
            scales = group.scales
            copies = [] if values is buffer else _copy_lines(io, prefix, KINDS[kind], group.slots, scales)
            if io == "output" and kind in WIDE:  # before the copy rounds them
                array, largest = f"{prefix}_value_array", f"largest_exact_{kind}"
                below = "" if kind == "UInt64" else f" or {array}.min() < -{largest}"
                report = f"inexact({array}, {prefix}_slots, '{kind}')"
                copies.insert(0, f"    if {array}.max() > {largest}{below}: {report}")
            count = len(group.references)  # FMI 3.0: then the number of values (array elements)
            call = [
                f"    status = {function}(instance, {prefix}_references, {count}, {prefix}_values"
                + count_argument.format(n=len(group.slots))
                + ")",
                f"    if status > 1: fail(status, '{function}')",
            ]
            lines += copies + call if io == "input" else call + copies
    push.append("    return None")
    pull += _finite_check_lines(*component._checked_outputs())
    names.update(nonfinite=component._nonfinite_output, zeros=np.zeros(len(component.outputs)), inf=math.inf)
    names.update(largest_exact_Int64=np.int64(2**53), largest_exact_UInt64=np.uint64(2**53))
    names["inexact"] = component._inexact_output
    pull.append("    return output_array")
    do_step = f"fmi{version}DoStep"
    if version < 3:
        step = ["def do_step(t, h):", "    step_start[0] = t", f"    status = {do_step}(instance, t, h, 1)"]
    else:
        step = ["def do_step(t, h):", "    step_start[0] = t"]
        step.append(f"    status = {do_step}(instance, t, h, True, *do_step_flags)")
    names["step_start"] = component._step_time
    step.append("    if status > 1: step_failed(status, t)")
    names["step_failed"] = component._step_failed
    if version == 3:
        step.append("    if step_flags[1]: asked_to_terminate(t)")  # terminateSimulation
        names.update(do_step_flags=component._do_step_flags, step_flags=component._step_flags)
        names["asked_to_terminate"] = component._asked_to_terminate
    names[do_step] = component._raw_do_step
    exec(_compiled("\n".join(push + pull + step)), names)  # noqa: S102 - generated from our own templates
    compiled = {method: names[method] for method in ("push_inputs", "get_outputs", "do_step")}
    if component.text_inputs or component.text_outputs:  # text beside the numbers (`cosim.fmi.text`)
        compiled.update(_with_text(component, compiled["do_step"], compiled["get_outputs"]))
    return compiled


@functools.lru_cache(maxsize=64)
def _compiled(source: str):
    """`source` compiled (a code object is immutable: every component with the same code shares it;
    a sweep's worker generates the same four FMUs' code for every run)."""
    return compile(source, "<string>", "exec")


def _copy_lines(io: str, prefix: str, kind: str, slots: list[int], scales: list[float]) -> list[str]:
    """Source lines copying one transfer group (`io` "input" or "output", names starting with
    `prefix`) between the component's buffer and its FMI value array."""
    values, array = f"{prefix}_values", f"{prefix}_value_array"
    if len(slots) > 8:  # one NumPy copy beats many element copies
        scaled = "" if all(scale == 1.0 for scale in scales) else f" * {prefix}_scales"
        if io == "output":
            return [f"    output_array[{prefix}_slots] = {array}{scaled}"]
        staged = f"input_array[{prefix}_slots]{scaled}"
        convert = {"real": staged, "integer": f"np.rint({staged})", "boolean": f"{staged} != 0.0"}[kind]
        return [f"    {array}[:] = {convert}"]
    lines = []
    for position, (slot, scale) in enumerate(zip(slots, scales, strict=True)):
        factor = "" if scale == 1.0 else f" * {scale!r}"
        if io == "output":
            lines.append(f"    outputs[{slot}] = {values}[{position}]{factor}")
        else:
            convert = {"real": "{}", "integer": "int(round({}))", "boolean": "{} != 0.0"}[kind]
            lines.append(f"    {values}[{position}] = " + convert.format(f"inputs[{slot}]{factor}"))
    return lines


def _finite_check_lines(finite: list[int], nan_allowed: list[int]) -> list[str]:
    """Source lines calling `nonfinite()` when an output at a `finite` slot is NaN or infinite, or
    one at a `nan_allowed` slot is infinite. x - x is 0.0 for every finite x and NaN otherwise, so
    one comparison covers a whole sum of such differences."""
    lines = []
    if len(finite) > 10:  # one NumPy dot product beats many element reads
        if finite == list(range(len(finite))) and not nan_allowed:
            lines.append("    if output_array.dot(zeros) != 0.0: nonfinite()")
        else:
            lines.append(f"    if output_array[{finite!r}].dot(zeros[:{len(finite)}]) != 0.0: nonfinite()")
    elif finite:
        terms = " + ".join(f"((output{slot} := outputs[{slot}]) - output{slot})" for slot in finite)
        lines.append(f"    if {terms} != 0.0: nonfinite()")
    lines += [f"    if abs(outputs[{slot}]) == inf: nonfinite()" for slot in nan_allowed]
    return lines


def _with_text(component: Component, do_step, get_outputs) -> dict:
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


def native_step(component: Component) -> NativeStep | None:
    """C-level stepping of an `FmuComponent` for the compiled kernel: every get/set call as a group
    (`NativeStep.groups`); None when a transfer needs Python (text, or a type the kernel lacks)."""

    def address(function) -> int:
        return ctypes.cast(function, ctypes.c_void_p).value

    version = component.fmi_version
    kernel_kinds = KERNEL_TYPES[version]
    if component._text_feeds or component.text_outputs:
        return None  # text moves in Python (`cosim.fmi.text`)
    groups = (*component._input_groups, *component._output_groups)
    if any(group.fmi_type not in kernel_kinds for group in groups):
        return None
    calls = []
    for direction, groups, buffer in (
        ("set", component._input_groups, component.input_cbuffer),
        ("get", component._output_groups, component.output_cbuffer),
    ):
        functions = component._setters if direction == "set" else component._getters
        for group in groups:
            kind = kernel_kinds[group.fmi_type]
            # As `step_functions`: a lone unscaled real group over all ports is the buffer.
            direct = kind == "real" and all(scale == 1.0 for scale in group.scales) and len(groups) == 1
            direct = direct and group.slots == list(range(len(group.slots)))
            calls.append(
                (
                    direction, kind, address(functions[group.fmi_type]), ctypes.addressof(group.references),
                    len(group.references), len(group.slots),
                    ctypes.addressof(buffer if direct else group.values), direct,
                    tuple(group.slots), tuple(map(float, group.scales)),
                )
            )  # fmt: skip
    finite_outputs, nan_outputs = component._checked_outputs()
    # The kernel reads an Int64/UInt64 beyond 2^53 as NaN, so the check stops at it.
    finite_outputs += [i for i, port in enumerate(component.outputs) if port.fmi_type in WIDE]
    handle = component._handle
    c_version = 2 if version == 1 else version  # FMI 1.0 calls as FMI 2.0 does (the same C arguments)
    return NativeStep(
        fmi_version=c_version,
        handle=handle if isinstance(handle, int) else handle.value,
        do_step=address(component._raw_do_step),
        step_flags=np.ctypeslib.as_array(component._step_flags) if c_version == 3 else np.zeros(3, bool),
        last_successful_time=ctypes.addressof(component._last_successful_time) if c_version == 3 else 0,
        fail=component._native_failure,
        groups=tuple(calls),
        finite_outputs=tuple(finite_outputs),
        nan_outputs=tuple(nan_outputs),
    )
