"""A compiled stepping loop for systems made only of FMUs (the `Master.run` fast path).

Python-side ctypes calls cost about a microsecond each (more on a loaded machine), and an FMU step
needs three of them. When every component is an `FmuComponent` whose inputs and outputs are all
unscaled reals, and nothing observes the individual steps, the master hands the loop to a
function generated for this system and compiled with numba: it calls the FMUs' C functions by
address and copies the connections (with their scale and offset) between the same buffers the
Python path uses, with the same order, periods and arithmetic, so both paths give bit-identical
results. Compilation costs about a second, so the master uses it only for long runs.
"""

from __future__ import annotations

import ctypes

import numpy as np

from cosim.core.component import Component, NativeStep

_U64 = ctypes.c_uint64
# Pointers are passed as 64-bit addresses: the same registers as a pointer in the C calling convention.
_PROTOTYPES = {
    "transfer2": ctypes.CFUNCTYPE(ctypes.c_int, _U64, _U64, ctypes.c_size_t, _U64),
    "transfer3": ctypes.CFUNCTYPE(ctypes.c_int, _U64, _U64, ctypes.c_size_t, _U64, ctypes.c_size_t),
    "step2": ctypes.CFUNCTYPE(ctypes.c_int, _U64, ctypes.c_double, ctypes.c_double, ctypes.c_int),
    "step3": ctypes.CFUNCTYPE(
        ctypes.c_int, _U64, ctypes.c_double, ctypes.c_double, ctypes.c_bool, _U64, _U64, _U64, _U64
    ),
}


def transfer_expression(value: str, scale: float, offset: float) -> str:
    """Source text of what a connection delivers: `value * scale + offset`, without the no-op terms.

    The master's Python loop (`cosim.core.master`) and the compiled loop both use it, so they do the
    same floating-point operations and give bit-identical inputs.
    """
    expression = value if scale == 1.0 else f"{value} * {scale!r}"
    return expression if offset == 0.0 else f"{expression} + {offset!r}"


def native_steps(order: list[Component]) -> list[NativeStep] | None:
    """Every component's C-level step, or None when any of them needs Python to step."""
    steps = [component.native_step() for component in order]
    return None if any(step is None for step in steps) else steps


def _count(version: int, n: int) -> str:
    """FMI 3.0 get/set functions take the number of values as an extra argument."""
    return "" if version == 2 else f", {n}"


def compile_loop(
    plan: list[tuple[Component, int, object]],
    system,
    start_time_ns: int,
    native: list[NativeStep],
    record: bool = False,
):
    """Generate and compile `loop(first_step, steps) -> (next_step, component, call, status)`.

    With `record`, it is `loop(first_step, steps, histories, rows)`: after each step of component
    i (index in `plan`, the master's step order) its inputs then outputs are copied into row `rows[i]` of
    `histories[i]` (float64, at least as many rows as its steps in the call), and `rows[i]` counts up.

    `component` is -1 when all steps ran; otherwise the index (in `plan`) of the FMU whose
    call (0 set, 1 step, 2 get) returned `status` > Warning at step `next_step`, or (call 3) that
    asked to terminate the simulation, or (call 4) whose output at slot `status` is not finite.
    """
    import numba

    names: dict[str, object] = {}
    arguments = ", ".join(f"in{i}, out{i}, flag{i}" for i in range(len(plan)))
    if record:
        arguments += ", rows, " + ", ".join(f"history{i}" for i in range(len(plan)))
    lines = [f"def loop(first_step, steps, {arguments}):"]
    lines += ["    for k in range(first_step, first_step + steps):"]
    lines += [f"        t = ({start_time_ns} + k * {system.macro_step_ns}) / 1e9"]
    index = {component.name: i for i, (component, _, _) in enumerate(plan)}
    jacobi = system.mode == "jacobi"
    gathers, steps = [], []
    for i, (component, period, _) in enumerate(plan):
        c = native[i]
        due = "        if True:" if period == 1 else f"        if k % {period} == 0:"
        gather = []
        for connection in system.connections:
            if connection.target_component == component.name:
                producer, source = system.resolve(connection.source, "output")
                _, target = system.resolve(connection.target, "input")
                value = transfer_expression(
                    f"out{index[producer.name]}[{source}]", connection.scale, connection.offset
                )
                gather.append(f"            in{i}[{target}] = {value}")
        version, handle = c.fmi_version, c.handle
        if component.inputs:
            names[f"set{i}"] = _PROTOTYPES[f"transfer{version}"](c.set_real)
            references = c.input_references
            count = c.input_reference_count if c.input_reference_count >= 0 else len(component.inputs)
            gather += [
                f"            status = set{i}({handle}, {references}, {count}, "
                f"{c.input_values}{_count(version, len(component.inputs))})",
                f"            if status > 1: return k, {i}, 0, status",
            ]
        h = period * system.macro_step_ns / 1e9
        names[f"step{i}"] = _PROTOTYPES[f"step{version}"](c.do_step)
        if version == 2:
            step = [f"            status = step{i}({handle}, t, {h!r}, 1)"]
        else:
            first = c.step_flags.ctypes.data
            flags = f"{first}, {first + 1}, {first + 2}, {c.last_successful_time}"
            step = [f"            status = step{i}({handle}, t, {h!r}, True, {flags})"]
        step.append(f"            if status > 1: return k, {i}, 1, status")
        if version == 3:  # terminateSimulation is the second flag
            step.append(f"            if flag{i}[1]: return k, {i}, 3, 0")
        if component.outputs:
            names[f"get{i}"] = _PROTOTYPES[f"transfer{version}"](c.get_real)
            references = c.output_references
            count = c.output_reference_count if c.output_reference_count >= 0 else len(component.outputs)
            step += [
                f"            status = get{i}({handle}, {references}, {count}, "
                f"{c.output_values}{_count(version, len(component.outputs))})",
                f"            if status > 1: return k, {i}, 2, status",
            ]
            # x - x is NaN exactly when x is NaN or infinite.
            step += [
                f"            if out{i}[{j}] - out{i}[{j}] != 0.0: return k, {i}, 4, {j}"
                for j in c.finite_outputs
            ]
            step += [
                f"            if abs(out{i}[{j}]) == np.inf: return k, {i}, 4, {j}" for j in c.nan_outputs
            ]
        if record:
            count, outputs = len(component.inputs), len(component.outputs)
            step += [
                f"            row = rows[{i}]",
                f"            for j in range({count}): history{i}[row, j] = in{i}[j]",
                f"            for j in range({outputs}): history{i}[row, {count} + j] = out{i}[j]",
                f"            rows[{i}] = row + 1",
            ]
        if jacobi:
            gathers += [due] + (gather or ["            pass"])
            steps += [due] + step
        else:
            lines += [due] + gather + step
    lines += gathers + steps
    lines += ["    return first_step + steps, -1, 0, 0"]
    names["np"] = np
    exec("\n".join(lines), names)  # noqa: S102 - generated from our own templates
    compiled = numba.njit(names["loop"])
    buffers = []
    for (component, _, _), c in zip(plan, native, strict=True):
        buffers += [component.input_buffer, component.output_buffer, c.step_flags]

    if record:

        def run_recording(
            first_step: int, count: int, rows: np.ndarray, histories
        ) -> tuple[int, int, int, int]:
            return compiled(np.int64(first_step), np.int64(count), *buffers, rows, *histories)

        return run_recording

    def run(first_step: int, count: int) -> tuple[int, int, int, int]:
        return compiled(np.int64(first_step), np.int64(count), *buffers)

    return run
