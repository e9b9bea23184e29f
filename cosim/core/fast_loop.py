"""A compiled stepping loop for systems made only of FMUs (the `Master.run` fast path).

Python-side ctypes calls cost about a microsecond each (more on a loaded machine), and an FMU step
needs three of them. When every component is an `FmuComponent` whose inputs and outputs are all
unscaled reals, and nothing observes the individual steps, the master hands the loop to a
function generated for this system and compiled with numba: it calls the FMUs' C functions by
address and copies the connections (with their scale and offset) between the same buffers the
Python path uses, with the same order, periods and arithmetic, so both paths give bit-identical
results. Compilation costs about a second, so the master uses it only for long runs.

`KernelTables` fills the tables of `cosim.core.kernel.step_kernel`, the compiled loop written
once (cached by numba, no per-process compile) that `Master.run_blocks` runs: any FMU whose
`native_step()` describes its calls (integer, boolean and scaled ports included), with the Python
components handed back where they are due.
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
    return None if any(step is None or not step.plain for step in steps) else steps


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


class KernelTables:
    """The tables `cosim.core.kernel.step_kernel` reads for one master plan (see there).

    `plan` is the master's [(component, period, gather)] in step order; `skip` names components
    that are never stepped (constant outputs), whose connections are not copied again either.
    A component whose `native_step()` is None is handed back to Python where it is due.
    """

    def __init__(self, plan, system, skip: set[str], record: bool, block: int) -> None:
        from cosim.core import kernel as K

        n = len(plan)
        components = np.zeros((n, K.COMPONENT_COLUMNS), dtype=np.int64)
        step_sizes = np.zeros(n)
        links, link_numbers, groups, slots, scales, checks = [], [], [], [], [], []
        self.native: list[NativeStep | None] = []
        record_offset = 0
        fed: dict[str, list] = {}
        for connection in system.connections:
            fed.setdefault(connection.target_component, []).append(connection)
        self.record_shapes: list[tuple[int, int] | None] = []
        for i, (component, period, _) in enumerate(plan):
            native = component.native_step()
            self.native.append(native)
            row = components[i]
            row[K.C_PERIOD] = period
            step_sizes[i] = period * system.macro_step_ns / 1e9
            if component.name in skip:
                row[K.C_KIND] = K.KIND_IDLE
                self.record_shapes.append(None)
                continue
            row[K.C_KIND] = K.KIND_NATIVE if native is not None else K.KIND_PYTHON
            row[K.C_IN_ADDRESS] = ctypes.addressof(component.input_cbuffer)
            row[K.C_IN_COUNT] = len(component.inputs)
            row[K.C_OUT_ADDRESS] = ctypes.addressof(component.output_cbuffer)
            row[K.C_OUT_COUNT] = len(component.outputs)
            row[K.C_LINK_FIRST] = len(links)
            for connection in fed.get(component.name, ()):
                if connection.source_component in skip:
                    continue
                producer, source = system.resolve(connection.source, "output")
                _, target = system.resolve(connection.target, "input")
                kind = 0 if connection.is_plain else (1 if connection.offset == 0.0 else 2)
                links.append(
                    (
                        ctypes.addressof(producer.output_cbuffer) + 8 * source,
                        ctypes.addressof(component.input_cbuffer) + 8 * target,
                        kind,
                    )
                )
                link_numbers.append((connection.scale, connection.offset))
            row[K.C_LINK_COUNT] = len(links) - row[K.C_LINK_FIRST]
            if native is None:
                self.record_shapes.append(None)
                continue
            row[K.C_VERSION] = native.fmi_version
            row[K.C_HANDLE] = native.handle
            row[K.C_STEP] = native.do_step
            row[K.C_FLAGS] = native.step_flags.ctypes.data if native.fmi_version == 3 else 0
            row[K.C_LAST_TIME] = native.last_successful_time
            for direction, first_column, count_column in (
                ("set", K.C_SET_FIRST, K.C_SET_COUNT),
                ("get", K.C_GET_FIRST, K.C_GET_COUNT),
            ):
                row[first_column] = len(groups)
                buffer = component.input_cbuffer if direction == "set" else component.output_cbuffer
                for call in native.groups:
                    if call[0] != direction:
                        continue
                    (
                        _,
                        kind,
                        function,
                        refs,
                        ref_count,
                        value_count,
                        values,
                        direct,
                        call_slots,
                        call_scales,
                    ) = call
                    groups.append(
                        (
                            {"real": K.KIND_REAL, "integer": K.KIND_INTEGER, "boolean": K.KIND_BOOLEAN}[kind],
                            function, refs, ref_count, value_count, values, int(direct),
                            len(slots), len(call_slots),
                        )
                    )  # fmt: skip
                    slots += [ctypes.addressof(buffer) + 8 * slot for slot in call_slots]
                    scales += list(call_scales)
                row[count_column] = len(groups) - row[first_column]
            row[K.C_CHECK_FIRST] = len(checks)
            output_base = ctypes.addressof(component.output_cbuffer)
            checks += [(output_base + 8 * slot, 0, slot) for slot in native.finite_outputs]
            checks += [(output_base + 8 * slot, 1, slot) for slot in native.nan_outputs]
            row[K.C_CHECK_COUNT] = len(checks) - row[K.C_CHECK_FIRST]
            if record:
                width = len(component.inputs) + len(component.outputs)
                capacity = block // period + 2
                row[K.C_RECORD] = 1
                row[K.C_RECORD_OFFSET] = record_offset
                self.record_shapes.append((record_offset, capacity, width))
                record_offset += capacity * width
            else:
                self.record_shapes.append(None)
        self.components = components
        self.step_sizes = step_sizes
        self.link_addresses = np.array(links, dtype=np.int64).reshape(-1, 3)
        self.link_numbers = np.array(link_numbers, dtype=np.float64).reshape(-1, 2)
        self.groups = np.array(groups, dtype=np.int64).reshape(-1, K.GROUP_COLUMNS)
        self.slot_addresses = np.array(slots, dtype=np.int64)
        self.slot_scales = np.array(scales, dtype=np.float64)
        self.checks = np.array(checks, dtype=np.int64).reshape(-1, 3)
        self.history = np.zeros(max(1, record_offset))
        self.rows = np.zeros(n, dtype=np.int64)
        self._blocks: list[np.ndarray | None] | None = None
        self.watch_addresses = np.zeros(3, dtype=np.int64)
        self.watch_numbers = np.zeros(6)
        # What the tables point into stays alive with them.
        self._keep = [component for component, _, _ in plan]

    def histories(self) -> list[np.ndarray | None]:
        """Per component, its rows so far as a (rows, inputs + outputs) view, None when not recorded."""
        if self._blocks is None:
            self._blocks = []
            for shape in self.record_shapes:
                if shape is None:
                    self._blocks.append(None)
                    continue
                offset, capacity, width = shape
                self._blocks.append(self.history[offset : offset + capacity * width].reshape(capacity, width))
        rows = self.rows.tolist()
        return [None if block is None else block[: rows[i]] for i, block in enumerate(self._blocks)]

    def warm_up(self) -> None:
        """Compile the kernel, or load it from numba's cache (a call of no steps)."""
        self.run(0, 0, 0, 0, 1, False)

    def run(self, first_step: int, steps: int, position: int, start_ns: int, h_ns: int, jacobi: bool):
        from cosim.core.kernel import step_kernel

        return step_kernel(
            first_step, steps, position, start_ns, h_ns, jacobi, self.components, self.step_sizes,
            self.link_addresses, self.link_numbers, self.groups, self.slot_addresses, self.slot_scales,
            self.checks, self.history, self.rows, self.watch_addresses, self.watch_numbers,
        )  # fmt: skip
