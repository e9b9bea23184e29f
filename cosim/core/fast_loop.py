"""The tables of the master's compiled stepping kernel (`cosim.core.kernel`), filled from a plan.

Python-side ctypes calls cost about a microsecond each (more on a loaded machine), and an FMU step
needs three of them. `KernelTables` describes a master plan to the kernel, written once in C: every
FMU whose `native_step()` describes its calls (real, integer, boolean and scaled ports alike) by
the addresses of its FMI functions, instance and value arrays, the connections (with their scale
and offset) as copies between the same buffers the Python loop uses, and the components that need
Python, which the kernel hands back where they are due. `Master.run`, `Master.run_recorded` and
`Master.run_blocks` step through it; it keeps the Python loop's order, periods and arithmetic, so
every loop gives bit-identical results.
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from cosim.core.component import Component, NativeStep


class PlanEntry(NamedTuple):
    """A component as the master steps it (the master's plan, in step order)."""

    component: Component
    period: int  # [macro steps]
    gather: Callable[[], None] | None  # copies its connected inputs (`cosim.core.gather`); None: none


def transfer_expression(value: str, scale: float, offset: float) -> str:
    """Source text of what a connection delivers: `value * scale + offset`, without the no-op terms.

    The master's Python loop (`cosim.core.gather`) and the compiled loop both use it, so they do the
    same floating-point operations and give bit-identical inputs.
    """
    expression = value if scale == 1.0 else f"{value} * {scale!r}"
    return expression if offset == 0.0 else f"{expression} + {offset!r}"


class StretchPlan(NamedTuple):
    """What `cosim.core.kernel_path.run_blocks` reads of a plan and its tables at each call
    (`KernelTables.stretch_plan`)."""

    periods: list[int]  # per plan position [macro steps]
    whole: list[float]  # a component's whole step [s] (`Master.step_seconds` where no step is cut)
    stepping: list[int]  # positions of the components the master steps (not idle)
    # Per position, the stepping components before it are stepping[: split[position]].
    split: list[int]
    recorded: np.ndarray  # positions of the components with rows
    recorded_periods: np.ndarray  # their periods


_DELIVERIES = 16  # row counts whose views `KernelTables.delivered` keeps

RUN_LINK = 3  # a link table row that is a run of plain links (kernel.c's `gather`)
MIN_RUN = 4  # plain links in a row that become one run


# Record buffers (`KernelTables.history`) of tables released after their run, by size, for the next
# tables of that size in this process: a sweep's worker makes the same ~8 MB every run, and a new
# buffer's pages are mapped at their first writes (`warm_up`: ~1.5-6 ms of system time for 8 MB); a
# kept one is mapped already and only zeroed (~0.25 ms). A few kept.
_SPARE: dict[int, np.ndarray] = {}
_SPARE_KEPT = 2
_SPARE_MIN_BYTES = 1 << 20


def _record_buffer(size: int) -> tuple[np.ndarray, bool]:
    """A record buffer of `size` zeros, and whether its pages are mapped (a kept one: `_SPARE`)."""
    spare = _SPARE.pop(size, None)
    if spare is None:
        return np.zeros(size), False
    spare.fill(0.0)
    return spare, True


def _link_plan(system, fed: dict, name: str, skip: set[str]) -> tuple[tuple, tuple, tuple]:
    """The links into component `name` from producers not in `skip`, by port indices: (entries
    (producer, output index, input index, kind), numbers (scale, offset), the fed slots (input
    index, producer)), in the order of their inputs (each input has one link: any order copies the
    same values), with each stretch of at least `MIN_RUN` plain links from one producer to
    consecutive inputs from outputs evenly apart (consecutive, or one column of a row-major array:
    a plan's x or y) made one run (kind `RUN_LINK`; numbers: its length, the outputs' stride): one
    loop in the kernel instead of one link per value, the same values. Worked out once for the
    system's graph (`System._cached`: shared by the systems of one structure), read-only;
    `KernelTables` places it at the buffers."""
    key = ("kernel links", name, frozenset(skip))
    plan = system._cached(key)
    if plan is not None:
        return plan
    chosen = [link for link in fed.get(name, ()) if link.producer not in skip]
    chosen.sort(key=lambda link: link.input)  # (each input has one link: any order copies the same)
    entries, numbers = [], []
    j = 0
    while j < len(chosen):
        connection, producer, source, target = chosen[j]
        end = j + 1
        stride = chosen[j + 1].output - source if j + 1 < len(chosen) else 0
        if connection.is_plain and stride > 0 and chosen[j + 1].producer == producer:
            while end < len(chosen):
                link = chosen[end]
                if not (
                    link.producer == producer
                    and link.connection.is_plain
                    and link.output == source + stride * (end - j)
                    and link.input == target + (end - j)
                ):
                    break
                end += 1
        if end - j >= MIN_RUN:
            entries.append((producer, source, target, RUN_LINK))
            numbers.append((float(end - j), float(stride)))
        else:
            for connection, producer, source, target in chosen[j:end]:
                kind = 0 if connection.is_plain else (1 if connection.offset == 0.0 else 2)
                entries.append((producer, source, target, kind))
                numbers.append((connection.scale, connection.offset))
        j = end
    fed_slots = tuple((link.input, link.producer) for link in chosen)
    return system._keep(key, (tuple(entries), tuple(numbers), fed_slots))


def recorded_inputs(component: Component) -> slice:
    """The inputs of `component` a recording reads from its rows, as one slice of the input
    buffer: its scalar inputs (their run of slots; all inputs when array elements lie between
    them; none without scalars). Array elements are never recorded (`cosim.record.steps`)."""
    slots = [i for i, port in enumerate(component.inputs) if not port.is_array_element]
    if not slots:
        return slice(0, 0)
    if slots == list(range(slots[0], slots[-1] + 1)):
        return slice(slots[0], slots[-1] + 1)
    return slice(0, len(component.inputs))


class KernelTables:
    """The tables `cosim.core.kernel.step_kernel` reads for one master plan (see there).

    `plan` is the master's `PlanEntry`s in step order; `skip` names components
    that are never stepped (constant outputs), whose connections are not copied again either.
    A component whose `native_step()` is None is handed back to Python where it is due, unless
    its `kernel_sweep()` gives (C function address, its argument): then the kernel steps it by
    that call on its first three inputs (the lidar's sweep: `cosim.world.lidar.Lidar`).
    `python_rows` (with `record`): those components have rows too, which `run_blocks` writes
    after their steps, so a stretch of steps goes on through them (see there); one whose
    `kernel_step()` gives (C function address, its state) is stepped by that call, which says
    whether the step needs Python after all (then it is handed back: the replanning planner).
    `scalar_rows` (with `record`): a row keeps only the inputs `recorded_inputs` gives (the scalar
    ones: what a recording reads), not the elements of input arrays (a plan's waypoints, a scan's
    ranges), whose columns are left as they were; `row_inputs[i]` is component i's kept slice.
    """

    def __init__(
        self,
        plan: list[PlanEntry],
        system,
        skip: set[str],
        record: bool,
        block: int,
        python_rows: bool = False,
        scalar_rows: bool = False,
    ) -> None:
        from cosim.core import kernel as K

        n = len(plan)
        self._sent: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # `_change_only`'s
        components = np.zeros((n, K.COMPONENT_COLUMNS), dtype=np.int64)
        step_sizes = np.zeros(n)
        links, link_numbers, groups, slots, scales, checks = [], [], [], [], [], []
        self.native: list[NativeStep | None] = []
        record_offset = 0
        fed = system.links()
        self.record_shapes: list[tuple[int, int] | None] = []
        self.row_inputs = [
            recorded_inputs(component) if scalar_rows else slice(0, len(component.inputs))
            for component, _, _ in plan
        ]
        self.python: list[bool] = []  # whether each component is handed back to Python
        place = {entry.component.name: i for i, entry in enumerate(plan)}
        output_bases: dict[str, int] = {}  # producer -> address of its output buffer
        for i, (component, period, _) in enumerate(plan):
            native = component.native_step()
            self.native.append(native)
            # A component stepped by one C call on its inputs x, y, theta (`Lidar.kernel_sweep`).
            sweep = getattr(component, "kernel_sweep", None)
            sweep = sweep() if native is None and callable(sweep) else None
            self.python.append(native is None and sweep is None and component.name not in skip)
            row = components[i]
            row[K.C_PERIOD] = period
            step_sizes[i] = period * system.macro_step_ns / 1e9
            if component.name in skip:
                row[K.C_KIND] = K.KIND_IDLE
                self.record_shapes.append(None)
                continue
            row[K.C_KIND] = K.KIND_NATIVE if native is not None else K.KIND_PYTHON
            if sweep is not None:
                row[K.C_KIND] = K.KIND_SWEEP
                row[K.C_STEP], row[K.C_HANDLE] = sweep
                # With `python_rows` the kernel returns before it (POLL), where a stretch could end.
                row[K.C_FLAGS] = 1 if record and python_rows else 0
            row[K.C_IN_ADDRESS] = ctypes.addressof(component.input_cbuffer)
            row[K.C_IN_COUNT] = len(component.inputs)
            row[K.C_OUT_ADDRESS] = ctypes.addressof(component.output_cbuffer)
            row[K.C_OUT_COUNT] = len(component.outputs)
            kept = self.row_inputs[i]
            row[K.C_RECORD_IN_FIRST], row[K.C_RECORD_IN_COUNT] = kept.start, kept.stop - kept.start
            row[K.C_LINK_FIRST] = first_link = len(links)
            # The links by port indices, runs made (`_link_plan`, worked out once per graph), here
            # placed at this system's buffers.
            entries, numbers, fed_slots = _link_plan(system, fed, component.name, skip)
            # input slot -> the plan position of the producer the kernel copies it from
            producers = {slot: place[producer_name] for slot, producer_name in fed_slots}
            input_base = ctypes.addressof(component.input_cbuffer)
            for producer_name, source, target, kind in entries:
                output_base = output_bases.get(producer_name)
                if output_base is None:
                    producer = system.components[producer_name]
                    output_base = output_bases[producer_name] = ctypes.addressof(producer.output_cbuffer)
                links.append((output_base + 8 * source, input_base + 8 * target, kind))
            link_numbers += numbers
            row[K.C_LINK_COUNT] = len(links) - first_link
            if sweep is not None:
                record_offset = self._reserve(record, component, period, block, record_offset, row)
                continue
            if native is None:  # rows written by `run_blocks` with python_rows (C_RECORD stays 0)
                # A Python component with a C step (`kernel_step`) that needs Python only at some
                # steps: with python_rows the kernel steps it when it can (and writes those rows).
                kernel_step = getattr(component, "kernel_step", None)
                kernel_step = kernel_step() if record and python_rows and callable(kernel_step) else None
                if kernel_step is not None:
                    row[K.C_STEP], row[K.C_HANDLE] = kernel_step
                    record_offset = self._reserve(True, component, period, block, record_offset, row)
                    continue
                record_offset = self._reserve(record and python_rows, component, period, block, record_offset)
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
                    sent = sent_references = runs = 0
                    if direction == "set" and kind == "real" and ref_count == value_count:
                        sent, sent_references, runs = self._change_only(
                            ref_count, [producers.get(slot, -1) for slot in call_slots]
                        )
                    groups.append(
                        (
                            K.KINDS.index(kind),
                            function, refs, ref_count, value_count, values, int(direct),
                            len(slots), len(call_slots), sent, sent_references, runs,
                        )
                    )  # fmt: skip
                    base = ctypes.addressof(buffer)
                    slots += [base + 8 * slot for slot in call_slots]
                    scales += list(call_scales)
                row[count_column] = len(groups) - row[first_column]
            row[K.C_CHECK_FIRST] = len(checks)
            output_base = ctypes.addressof(component.output_cbuffer)
            checks += [(output_base + 8 * slot, 0, slot) for slot in native.finite_outputs]
            checks += [(output_base + 8 * slot, 1, slot) for slot in native.nan_outputs]
            row[K.C_CHECK_COUNT] = len(checks) - row[K.C_CHECK_FIRST]
            record_offset = self._reserve(record, component, period, block, record_offset, row)
        self.components = components
        self.step_sizes = step_sizes
        self.link_addresses = np.array(links, dtype=np.int64).reshape(-1, 3)
        self.link_numbers = np.array(link_numbers, dtype=np.float64).reshape(-1, 2)
        self.groups = np.array(groups, dtype=np.int64).reshape(-1, K.GROUP_COLUMNS)
        self.slot_addresses = np.array(slots, dtype=np.int64)
        self.slot_scales = np.array(scales, dtype=np.float64)
        self.checks = np.array(checks, dtype=np.int64).reshape(-1, 3)
        self.history, self._mapped = _record_buffer(max(1, record_offset))
        self.record_block = block if record else None  # the most steps per kernel call the rows hold
        self.python_rows = bool(record and python_rows)
        self.rows = np.zeros(n, dtype=np.int64)
        self._blocks: list[np.ndarray | None] | None = None
        self.watch_addresses = np.zeros(3, dtype=np.int64)
        self.watch_numbers = np.zeros(6)
        self.stamps = np.zeros(n + 1, dtype=np.int64)  # kernel calls, steps per component (`_change_only`)
        # `run_blocks` keeps what the change-only groups sent from one of its calls to the next
        # (`forget_sent` only at the first) when its caller holds that between them nothing but this
        # kernel on these tables sets these FMUs' inputs or restores their state (a fleet's loop);
        # False: it forgets at each call.
        self.sent_kept = False
        self._started = False
        self._stretches: tuple | None = None  # `stretch_plan`: (plan, h_ns, the plan)
        self._deliveries: dict[bytes, list] = {}  # `delivered`: rows per component, by row counts
        # What the tables point into stays alive with them.
        self._keep = [entry.component for entry in plan]
        self._kernel = None
        self._released = False

    def poll_on_signals(self, fd: int) -> None:
        """From the next kernel call on, the polled sweeps (which return before each of their
        steps, so `run_blocks` can look for a signal there) return only when socket `fd` holds a
        byte: a signal came (`cosim.core.interrupt.signal_socket`), or when the watched position
        has used half of its free circle (`watch_numbers`: the caller's `before_block` draws a new
        one, as `cosim.navigation.outcome.SafeCircle.watch` does then); fd < 0: nothing changes."""
        from cosim.core import kernel as K

        if fd < 0:
            return
        rows = self.components
        polled = (rows[:, K.C_KIND] == K.KIND_SWEEP) & (rows[:, K.C_FLAGS] == 1)
        rows[polled, K.C_FLAGS] = 2
        rows[polled, K.C_LAST_TIME] = fd

    def forget_sent(self) -> None:
        """The next set of each change-only setter group sends every value (kernel.c's
        `set_changed`): call it whenever something besides the kernel may have set an FMU's inputs
        or restored its state (`run_blocks` does at its start: `start_run`)."""
        for sent, *_ in self._sent:
            sent[0] = 0.0

    def start_run(self) -> None:
        """`run_blocks` starts on these tables: `forget_sent`, unless `sent_kept` and they ran before."""
        if not (self.sent_kept and self._started):
            self.forget_sent()
        self._started = True

    def stretch_plan(self, plan: list[PlanEntry], h_ns: int) -> StretchPlan:
        """What `run_blocks` reads of `plan` and these tables at each call (`StretchPlan`), made once
        (a fleet calls it once per block of 10 steps, with ~300 components)."""
        cached = self._stretches
        if cached is not None and cached[0] is plan and cached[1] == h_ns:
            return cached[2]
        import bisect

        from cosim.core import kernel as K
        from cosim.core.timebase import NS_PER_S

        periods = [entry.period for entry in plan]
        stepping = np.flatnonzero(self.components[: len(periods), K.C_KIND] != K.KIND_IDLE).tolist()
        recorded = [i for i, block in enumerate(self.row_arrays()) if block is not None]
        stretches = StretchPlan(
            periods=periods,
            whole=[period * h_ns / NS_PER_S for period in periods],
            stepping=stepping,
            split=[bisect.bisect_left(stepping, position) for position in range(len(plan) + 1)],
            recorded=np.array(recorded, dtype=np.int64),
            recorded_periods=np.array([periods[i] for i in recorded], dtype=np.int64),
        )
        self._stretches = (plan, h_ns, stretches)
        self._deliveries.clear()
        return stretches

    def delivered(self, counts: np.ndarray) -> list[np.ndarray | None]:
        """Per component, its first rows (`counts`: how many, per recorded component in the order
        of `StretchPlan.recorded`) as a view of its row array, None when not recorded: the same
        list (copy it to keep it) and views for the same counts, which a fleet's blocks repeat."""
        key = counts.tobytes()
        found = self._deliveries.get(key)
        if found is None:
            blocks = self.row_arrays()
            found = [None] * len(blocks)
            for i, n in zip(self._stretches[2].recorded.tolist(), counts.tolist(), strict=True):
                found[i] = blocks[i][:n]
            if len(self._deliveries) >= _DELIVERIES:
                self._deliveries.clear()
            self._deliveries[key] = found
        return found

    def _change_only(self, count: int, producers: list[int]) -> tuple[int, int, int]:
        """The arrays of a setter group of `count` float64 scalars that sends only the values that
        changed since its last set (kernel.c's `set_changed`), `producers` the plan position of the
        component each value is copied from in the kernel (-1: none), made runs of the same
        producer: their addresses, kept alive here."""
        from cosim.core import kernel as K

        sent = np.zeros(1 + 2 * count)
        references = np.zeros(count, dtype=np.uint32)
        starts = [j for j in range(count) if j == 0 or producers[j] != producers[j - 1]]
        runs = np.zeros(1 + K.RUN_COLUMNS * len(starts), dtype=np.int64)
        runs[0] = len(starts)
        table = runs[1:].reshape(-1, K.RUN_COLUMNS)
        table[:, K.RUN_FROM] = starts
        table[:, K.RUN_TO] = starts[1:] + [count]
        table[:, K.RUN_PRODUCER] = [producers[j] for j in starts]
        self._sent.append((sent, references, runs))
        return sent.ctypes.data, references.ctypes.data, runs.ctypes.data

    def _reserve(self, record: bool, component, period: int, block: int, offset: int, row=None) -> int:
        """Room for `component`'s rows (its inputs then outputs, once per step of a block) at
        `offset` of the record buffer when `record`, its shape kept in `record_shapes` (else None);
        `row` given: the kernel writes them there (C_RECORD). Returns the next free offset."""
        if not record:
            self.record_shapes.append(None)
            return offset
        from cosim.core import kernel as K

        width = len(component.inputs) + len(component.outputs)
        capacity = block // period + 2
        if row is not None:
            row[K.C_RECORD] = 1
            row[K.C_RECORD_OFFSET] = offset
        self.record_shapes.append((offset, capacity, width))
        return offset + capacity * width

    def histories(self) -> list[np.ndarray | None]:
        """Per component, its rows so far as a (rows, inputs + outputs) view, None when not recorded."""
        rows = self.rows.tolist()
        return [None if block is None else block[: rows[i]] for i, block in enumerate(self.row_arrays())]

    def row_arrays(self) -> list[np.ndarray | None]:
        """Per component, the whole (capacity, inputs + outputs) array its rows go into (the first
        `rows[i]` hold rows), None when not recorded; the same arrays for the tables' life."""
        if self._blocks is None:
            self._blocks = []
            for shape in self.record_shapes:
                if shape is None:
                    self._blocks.append(None)
                    continue
                offset, capacity, width = shape
                self._blocks.append(self.history[offset : offset + capacity * width].reshape(capacity, width))
        return self._blocks

    def warm_up(self) -> None:
        """Load the kernel (building its library on a machine's first use), bind these tables and
        bring the record buffer's pages in: `np.zeros` leaves them to be mapped at the kernel's
        first writes, ~1 ms a few megabytes (a fleet's: 5.6 MB at N = 50) in its first call (before
        any call: the buffer holds its zeros)."""
        if self._released:
            raise RuntimeError("kernel tables used after `release`")
        if self._kernel is None and not self._mapped:
            self.history.fill(0.0)
        self._bound()

    def release(self) -> None:
        """The run is over: these tables are used no more (the kernel is unbound, `_bound` refuses),
        and their record buffer, when nothing else holds it (no view of it is left: a view holds its
        base array), is kept for the next tables of its size in this process (`_SPARE`)."""
        history = self.history
        self._released = True
        self._kernel = self._blocks = self.history = None
        self._deliveries = {}
        self._stretches = None
        # References: `history` here and getrefcount's argument; any other is a holder still using it.
        if history is not None and sys.getrefcount(history) == 2 and history.nbytes >= _SPARE_MIN_BYTES:
            if len(_SPARE) >= _SPARE_KEPT:
                _SPARE.pop(next(iter(_SPARE)))
            _SPARE[history.size] = history

    def _bound(self):
        if self._released:
            raise RuntimeError("kernel tables used after `release`")
        if self._kernel is None:
            from cosim.core.kernel import Kernel

            self._kernel = Kernel(
                self.components, self.step_sizes, self.link_addresses, self.link_numbers, self.groups,
                self.slot_addresses, self.slot_scales, self.checks, self.history, self.rows,
                self.watch_addresses, self.watch_numbers, self.stamps,
            )  # fmt: skip
        return self._kernel

    def step_under_way(self) -> int:
        """The step the kernel's last call was in when it returned, or is in now (an FMU that
        ends the process inside a call: `cosim.fmi.exit_guard`)."""
        from cosim.core import kernel as K

        return self._bound()._result[K.R_STEP]

    def run(self, first_step: int, steps: int, position: int, start_ns: int, h_ns: int, jacobi: bool):
        """`cosim.core.kernel.step_kernel` on these tables. Change the arrays in place only (the
        kernel holds their addresses): `watch_addresses[:] = ...`, `rows[:] = 0`."""
        return (self._kernel or self._bound())(first_step, steps, position, start_ns, h_ns, jacobi)
