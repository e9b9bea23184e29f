"""One compiled stepping kernel for every system: FMUs stepped by C calls, Python components handed back.

`cosim.core.fast_loop.compile_loop` generates a loop per system (addresses and connections baked
into the source), which numba cannot cache: each process pays about a second of compilation. This
kernel is written once and reads the system from tables of integers and floats (C function and
buffer addresses, connection and transfer tables), so numba compiles it once per machine
(`cache=True`) and a run only fills the tables (`cosim.core.fast_loop.KernelTables`).

The kernel steps the components of the master's plan in Gauss-Seidel (or Jacobi) order with the
Python loop's arithmetic (`value * scale + offset`, the same integer time base), so both give
bit-identical values. A component the kernel cannot step (a Python component, an FMU in a child
process) is handed back: the kernel returns at that component of that step, the master steps it
in Python, and the kernel resumes with the next component. It can also keep each FMU's buffers
after each of its steps (`record`) and watch a position: it returns after the first step whose
(x, y) is not finite, inside a circle (the goal zone) or outside another (the zone known free of
collisions), so a caller that checks those steps exactly never sees the loop run past one.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

# Return codes of `step_kernel` (first element of the result).
DONE, HAND_BACK, WATCH, FAILED = 0, 1, 2, 3
# Columns of the component table.
(
    C_KIND, C_PERIOD, C_VERSION, C_HANDLE, C_STEP, C_FLAGS, C_LAST_TIME, C_LINK_FIRST, C_LINK_COUNT,
    C_SET_FIRST, C_SET_COUNT, C_GET_FIRST, C_GET_COUNT, C_CHECK_FIRST, C_CHECK_COUNT,
    C_IN_ADDRESS, C_IN_COUNT, C_OUT_ADDRESS, C_OUT_COUNT, C_RECORD, C_RECORD_OFFSET,
) = range(21)  # fmt: skip
COMPONENT_COLUMNS = 21
KIND_IDLE, KIND_NATIVE, KIND_PYTHON = 0, 1, 2  # never stepped (constant outputs), by C calls, by Python
# Columns of the transfer-group table.
G_KIND, G_FUNCTION, G_REFERENCES, G_REFERENCE_COUNT, G_VALUE_COUNT, G_VALUES, G_DIRECT = range(7)
G_SLOT_FIRST, G_SLOT_COUNT = 7, 8
GROUP_COLUMNS = 9
KIND_REAL, KIND_INTEGER, KIND_BOOLEAN = 0, 1, 2
# Failure calls (as `NativeStep.fail`): 0 set, 1 doStep, 2 get, 3 asked to terminate, 4 not finite.


def _address_type():
    return ir.IntType(64)


def _pointer(builder, address, element):
    return builder.inttoptr(address, element.as_pointer())


@intrinsic
def _load_f64(typingctx, address):
    def codegen(context, builder, signature, args):
        return builder.load(_pointer(builder, args[0], ir.DoubleType()))

    return types.float64(types.int64), codegen


@intrinsic
def _store_f64(typingctx, address, value):
    def codegen(context, builder, signature, args):
        builder.store(args[1], _pointer(builder, args[0], ir.DoubleType()))
        return context.get_dummy_value()

    return types.none(types.int64, types.float64), codegen


@intrinsic
def _load_i32(typingctx, address):
    def codegen(context, builder, signature, args):
        value = builder.load(_pointer(builder, args[0], ir.IntType(32)))
        return builder.sext(value, ir.IntType(64))

    return types.int64(types.int64), codegen


@intrinsic
def _store_i32(typingctx, address, value):
    def codegen(context, builder, signature, args):
        builder.store(builder.trunc(args[1], ir.IntType(32)), _pointer(builder, args[0], ir.IntType(32)))
        return context.get_dummy_value()

    return types.none(types.int64, types.int64), codegen


@intrinsic
def _load_u8(typingctx, address):
    def codegen(context, builder, signature, args):
        value = builder.load(_pointer(builder, args[0], ir.IntType(8)))
        return builder.zext(value, ir.IntType(64))

    return types.int64(types.int64), codegen


@intrinsic
def _store_u8(typingctx, address, value):
    def codegen(context, builder, signature, args):
        builder.store(builder.trunc(args[1], ir.IntType(8)), _pointer(builder, args[0], ir.IntType(8)))
        return context.get_dummy_value()

    return types.none(types.int64, types.int64), codegen


@intrinsic
def _call_transfer(typingctx, function, handle, references, count, values, value_count, version):
    """fmi2Set/Get<T>(handle, refs, count, values) or fmi3Set/Get<T>(..., values, value_count).
    Pointers and size_t are passed as 64-bit integers (the same registers in the C convention)."""

    def codegen(context, builder, signature, args):
        i64, i32 = ir.IntType(64), ir.IntType(32)
        function_, handle_, references_, count_, values_, value_count_, version_ = args
        two = ir.FunctionType(i32, [i64, i64, i64, i64])
        three = ir.FunctionType(i32, [i64, i64, i64, i64, i64])
        is_two = builder.icmp_signed("==", version_, ir.Constant(i64, 2))
        with builder.if_else(is_two) as (then, otherwise):
            with then:
                first = builder.call(
                    _pointer(builder, function_, two), [handle_, references_, count_, values_]
                )
                then_block = builder.block
            with otherwise:
                second = builder.call(
                    _pointer(builder, function_, three), [handle_, references_, count_, values_, value_count_]
                )
                otherwise_block = builder.block
        status = builder.phi(i32)
        status.add_incoming(first, then_block)
        status.add_incoming(second, otherwise_block)
        return builder.sext(status, i64)

    signature = types.int64(
        types.int64, types.int64, types.int64, types.int64, types.int64, types.int64, types.int64
    )
    return signature, codegen


@intrinsic
def _call_step(typingctx, function, handle, t, h, flags, last_time, version):
    """fmi2DoStep(handle, t, h, fmi2True) or fmi3DoStep(handle, t, h, true, &flags[0..2], &last)."""

    def codegen(context, builder, signature, args):
        i64, i32, double = ir.IntType(64), ir.IntType(32), ir.DoubleType()
        function_, handle_, t_, h_, flags_, last_, version_ = args
        two = ir.FunctionType(i32, [i64, double, double, i32])
        # A C bool argument: passed zero-extended in a 32-bit register.
        three = ir.FunctionType(i32, [i64, double, double, i32, i64, i64, i64, i64])
        one = ir.Constant(i32, 1)
        is_two = builder.icmp_signed("==", version_, ir.Constant(i64, 2))
        with builder.if_else(is_two) as (then, otherwise):
            with then:
                first = builder.call(_pointer(builder, function_, two), [handle_, t_, h_, one])
                then_block = builder.block
            with otherwise:
                flag1 = builder.add(flags_, ir.Constant(i64, 1))
                flag2 = builder.add(flags_, ir.Constant(i64, 2))
                second = builder.call(
                    _pointer(builder, function_, three), [handle_, t_, h_, one, flags_, flag1, flag2, last_]
                )
                otherwise_block = builder.block
        status = builder.phi(i32)
        status.add_incoming(first, then_block)
        status.add_incoming(second, otherwise_block)
        return builder.sext(status, i64)

    signature = types.int64(
        types.int64, types.int64, types.float64, types.float64, types.int64, types.int64, types.int64
    )
    return signature, codegen


@numba.njit(cache=True)
def _gather(components, i, link_addresses, link_numbers):
    first = components[i, C_LINK_FIRST]
    for j in range(first, first + components[i, C_LINK_COUNT]):
        value = _load_f64(link_addresses[j, 0])
        kind = link_addresses[j, 2]
        if kind == 1:
            value = value * link_numbers[j, 0]
        elif kind == 2:
            value = value * link_numbers[j, 0] + link_numbers[j, 1]
        _store_f64(link_addresses[j, 1], value)


@numba.njit(cache=True)
def _set(components, i, groups, slot_addresses, slot_scales):
    """Copy the inputs into the FMI value arrays (converting), then call the setters; status or 0."""
    handle, version = components[i, C_HANDLE], components[i, C_VERSION]
    first = components[i, C_SET_FIRST]
    for g in range(first, first + components[i, C_SET_COUNT]):
        kind, values = groups[g, G_KIND], groups[g, G_VALUES]
        if groups[g, G_DIRECT] == 0:
            first_slot = groups[g, G_SLOT_FIRST]
            for position in range(groups[g, G_SLOT_COUNT]):
                s = first_slot + position
                value = _load_f64(slot_addresses[s])
                if slot_scales[s] != 1.0:
                    value = value * slot_scales[s]
                if kind == KIND_REAL:
                    _store_f64(values + 8 * position, value)
                elif kind == KIND_INTEGER:
                    _store_i32(values + 4 * position, np.int64(np.rint(value)))
                elif version == 2:
                    _store_i32(values + 4 * position, 1 if value != 0.0 else 0)
                else:
                    _store_u8(values + position, 1 if value != 0.0 else 0)
        status = _call_transfer(
            groups[g, G_FUNCTION], handle, groups[g, G_REFERENCES], groups[g, G_REFERENCE_COUNT],
            values, groups[g, G_VALUE_COUNT], version,
        )  # fmt: skip
        if status > 1:
            return status, kind
    return 0, 0


@numba.njit(cache=True)
def _get(components, i, groups, slot_addresses, slot_scales):
    handle, version = components[i, C_HANDLE], components[i, C_VERSION]
    first = components[i, C_GET_FIRST]
    for g in range(first, first + components[i, C_GET_COUNT]):
        kind, values = groups[g, G_KIND], groups[g, G_VALUES]
        status = _call_transfer(
            groups[g, G_FUNCTION], handle, groups[g, G_REFERENCES], groups[g, G_REFERENCE_COUNT],
            values, groups[g, G_VALUE_COUNT], version,
        )  # fmt: skip
        if status > 1:
            return status, kind
        if groups[g, G_DIRECT] == 0:
            first_slot = groups[g, G_SLOT_FIRST]
            for position in range(groups[g, G_SLOT_COUNT]):
                s = first_slot + position
                if kind == KIND_REAL:
                    value = _load_f64(values + 8 * position)
                elif kind == KIND_INTEGER or version == 2:
                    value = float(_load_i32(values + 4 * position))
                else:
                    value = float(_load_u8(values + position))
                if slot_scales[s] != 1.0:
                    value = value * slot_scales[s]
                _store_f64(slot_addresses[s], value)
    return 0, 0


@numba.njit(cache=True)
def _check(components, i, checks):
    """Slot of the first output that is NaN or infinite (`checks[:, 1]` == 1: infinite only), or -1."""
    first = components[i, C_CHECK_FIRST]
    for c in range(first, first + components[i, C_CHECK_COUNT]):
        value = _load_f64(checks[c, 0])
        if checks[c, 1] == 0:
            if value - value != 0.0:  # NaN exactly when value is NaN or infinite
                return checks[c, 2]
        elif abs(value) == np.inf:
            return checks[c, 2]
    return -1


@numba.njit(cache=True)
def _record(components, i, history, rows):
    if components[i, C_RECORD] == 0:
        return
    n_in, n_out = components[i, C_IN_COUNT], components[i, C_OUT_COUNT]
    base = components[i, C_RECORD_OFFSET] + rows[i] * (n_in + n_out)
    inputs, outputs = components[i, C_IN_ADDRESS], components[i, C_OUT_ADDRESS]
    for j in range(n_in):
        history[base + j] = _load_f64(inputs + 8 * j)
    for j in range(n_out):
        history[base + n_in + j] = _load_f64(outputs + 8 * j)
    rows[i] += 1


@numba.njit(cache=True)
def _advance_native(components, i, t, h):
    """doStep, the terminate flag, get: (call, status) of a failure or (-1, 0)."""
    status = _call_step(
        components[i, C_STEP], components[i, C_HANDLE], t, h, components[i, C_FLAGS],
        components[i, C_LAST_TIME], components[i, C_VERSION],
    )  # fmt: skip
    if status > 1:
        return 1, status
    if components[i, C_VERSION] == 3 and _load_u8(components[i, C_FLAGS] + 1) != 0:
        return 3, 0
    return -1, 0


@numba.njit(cache=True)
def step_kernel(
    first_step, steps, first_position, start_ns, h_ns, jacobi,
    components, step_sizes, link_addresses, link_numbers, groups, slot_addresses, slot_scales,
    checks, history, rows, watch_addresses, watch_numbers,
):  # fmt: skip
    """Step from component `first_position` of step `first_step` up to the end of step
    `first_step + steps - 1`. Returns (code, step, position, component, call, status, kind):
    DONE (all steps ran; step = the next one), HAND_BACK (component `position` of step `step`
    needs Python), WATCH (the position after step `step - 1` is to be checked), FAILED (component
    `component` failed at step `step`: `call`, `status`, `kind` of the set/get group)."""
    n = components.shape[0]
    k = first_step
    position = first_position
    end = first_step + steps
    watching = watch_addresses[0] != 0
    while k < end:
        t = (start_ns + k * h_ns) / 1e9
        if jacobi:
            for i in range(n):
                if components[i, C_KIND] != KIND_IDLE and k % components[i, C_PERIOD] == 0:
                    if components[i, C_KIND] == KIND_PYTHON:
                        return HAND_BACK, k, i, i, 0, 0, 0
                    _gather(components, i, link_addresses, link_numbers)
                    status, kind = _set(components, i, groups, slot_addresses, slot_scales)
                    if status > 1:
                        return FAILED, k, i, i, 0, status, kind
            for i in range(n):
                if components[i, C_KIND] == KIND_NATIVE and k % components[i, C_PERIOD] == 0:
                    call, status = _advance_native(components, i, t, step_sizes[i])
                    if call >= 0:
                        return FAILED, k, i, i, call, status, 0
                    status, kind = _get(components, i, groups, slot_addresses, slot_scales)
                    if status > 1:
                        return FAILED, k, i, i, 2, status, kind
                    slot = _check(components, i, checks)
                    if slot >= 0:
                        return FAILED, k, i, i, 4, slot, 0
                    _record(components, i, history, rows)
        else:
            while position < n:
                i = position
                if components[i, C_KIND] != KIND_IDLE and k % components[i, C_PERIOD] == 0:
                    if components[i, C_KIND] == KIND_PYTHON:
                        return HAND_BACK, k, i, i, 0, 0, 0
                    _gather(components, i, link_addresses, link_numbers)
                    status, kind = _set(components, i, groups, slot_addresses, slot_scales)
                    if status > 1:
                        return FAILED, k, i, i, 0, status, kind
                    call, status = _advance_native(components, i, t, step_sizes[i])
                    if call >= 0:
                        return FAILED, k, i, i, call, status, 0
                    status, kind = _get(components, i, groups, slot_addresses, slot_scales)
                    if status > 1:
                        return FAILED, k, i, i, 2, status, kind
                    slot = _check(components, i, checks)
                    if slot >= 0:
                        return FAILED, k, i, i, 4, slot, 0
                    _record(components, i, history, rows)
                position += 1
        position = 0
        k += 1
        if watching:
            x = _load_f64(watch_addresses[1])
            y = _load_f64(watch_addresses[2])
            if x - x != 0.0 or y - y != 0.0:
                return WATCH, k, 0, -1, 0, 0, 0
            dx, dy = x - watch_numbers[0], y - watch_numbers[1]
            if dx * dx + dy * dy <= watch_numbers[2]:
                return WATCH, k, 0, -1, 0, 0, 0
            dx, dy = x - watch_numbers[3], y - watch_numbers[4]
            if dx * dx + dy * dy >= watch_numbers[5]:
                return WATCH, k, 0, -1, 0, 0, 0
    return DONE, k, 0, -1, 0, 0, 0


def warm_up() -> None:
    """Compile `step_kernel` (or load it from numba's cache) without a system: a call of no steps on
    empty tables, with the argument types every run uses. For a build or install step that fills
    the cache, so a first run does not compile it."""
    empty = np.zeros((0, COMPONENT_COLUMNS), dtype=np.int64)
    step_kernel(
        0, 0, 0, 0, 1, False, empty, np.zeros(0), np.zeros((0, 3), dtype=np.int64), np.zeros((0, 2)),
        np.zeros((0, GROUP_COLUMNS), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0),
        np.zeros((0, 3), dtype=np.int64), np.zeros(1), np.zeros(0, dtype=np.int64),
        np.zeros(3, dtype=np.int64), np.zeros(6),
    )  # fmt: skip
