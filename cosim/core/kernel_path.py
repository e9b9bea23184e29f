"""The master's kernel block path: a `Master` stepped through the compiled kernel, a block at a time.

`kernel_tables` describes a master's plan to the kernel (`cosim.core.fast_loop.KernelTables`), or
says the kernel cannot run it; `run_blocks` steps through those tables in stretches of steps:
the kernel (`cosim.core.kernel`, C) steps the FMUs and keeps their buffers after each step, returns
where a component that needs Python is due (stepped here, with the Python loop's arithmetic), and
where a watched position needs a look; after each stretch the caller's `on_block` gets the rows.
`Master.run`, `Master.run_recorded` and `Master.run_blocks` use it (`master` below is a
`cosim.core.master.Master`, which imports this module); the Master owns the state (`step_index`,
`failure`, its plan and stop time), this module only the stepping.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from cosim.core import fast_loop
from cosim.core.timebase import NS_PER_S
from cosim.errors import CosimError


def kernel_tables(
    master, record: bool, block: int, python_rows: bool = False, scalar_rows: bool = False
) -> fast_loop.KernelTables | None:
    """The tables of `run_blocks` for `master`'s plan, or None when the kernel cannot run the
    system: no component steps by C calls, Jacobi mode with a component that needs Python, or a
    delayed or iterated algebraic loop (those step in the Python loop). `python_rows`: the
    components that need Python have rows too; `scalar_rows`: rows keep no input array elements
    (`KernelTables`)."""
    plan = master._plan
    skip = {entry.component.name for entry in plan if entry.component.constant_outputs}
    tables = fast_loop.KernelTables(plan, master.system, skip, record, block, python_rows, scalar_rows)
    stepped = [python for python, (c, _, _) in zip(tables.python, plan, strict=True) if c.name not in skip]
    if all(stepped):  # no component steps by C calls
        return None
    if master.system.mode == "jacobi" and any(stepped):
        return None
    if master._previous or master._loop_groups:
        return None  # a delayed or iterated loop steps in Python (`Master._advance`)
    return tables


def all_native_tables(master, record: bool, block: int) -> fast_loop.KernelTables | None:
    """`kernel_tables`, but None also when a component that is stepped needs Python (`Master.run`
    and `Master.run_recorded` hand nothing back)."""
    tables = kernel_tables(master, record, block)
    if tables is not None and any(tables.python):
        return None
    return tables


def raise_failure(master, native, name: str, k: int, call: int, status: int, kind: int) -> None:
    """Raise the error of the kernel's report that component `name` (its native handle `native`)
    failed in call `call` (0, 2: set-up, no time; else at step k's time) with FMI status `status`
    of the function kind `kind`; kept as the master's failure."""
    from cosim.core import kernel

    at = None if call in (0, 2) else (master.start_time_ns + k * master.system.macro_step_ns) / NS_PER_S
    try:
        native.fail(call, status, at, kernel.KINDS[kind])
    except CosimError as error:
        master.failure = error
        raise
    raise CosimError(f"component '{name}' failed at step {k}")


def run_blocks(
    master,
    steps: int,
    tables: fast_loop.KernelTables,
    on_block: Callable[[int, int, list, bool], bool | None] | None = None,
    block: int = 1000,
    before_block: Callable[[], None] | None = None,
    cut_after_python: Callable[[int], bool] | None = None,
    end_before_python: Callable[[int], bool] | None = None,
) -> int:
    """Advance `master` up to `steps` macro steps through the compiled kernel; components that need
    Python are stepped here where they are due. Returns the steps done.

    After each stretch of complete steps [first, end) -- at most `block` steps, cut where a
    Python component is due (before it steps), at the end of a step in which one stepped, and
    after a step whose watched position (`tables.watch_*`) needs a look -- `on_block(first,
    end, histories, clean)` is called: `histories[i]` holds component i's buffers (inputs,
    then outputs) after each of its steps in the stretch when the tables record it, else None.
    `clean` is True when no component has stepped yet in step `end`: then a true return
    stops the run at `end` (the same place as the Python loop's callback would); otherwise
    the return is ignored. `before_block()` is called before each call of the kernel.

    `cut_after_python(k)`, when given, is asked after the Python components of step k have
    stepped: False lets the stretch go on past step k (so Python components step only in the
    first step of a stretch, and hold their buffers to its end); True, or no callable, ends
    the stretch with step k.

    Tables made with `python_rows` (`kernel_tables`) give the Python components rows too,
    written here after each of their steps: then a stretch is not cut where a Python component
    is due (it goes on through their steps, up to `block` steps) unless `end_before_python(k)`,
    asked there, is true (e.g. a signal to notice where the cut would have been); a Python
    component that fails hands the stretch's steps before its own over first. A component the
    kernel steps by one C call (a sweep: the lidar) is such a place too: the kernel returns
    before it (POLL) and steps it when called again.
    """
    most = tables.record_block or block  # recorded: the rows the tables hold
    if not 1 <= block <= most:
        raise CosimError(f"block must be 1 to {max(1, most)} steps, got {block}")
    from cosim.core import kernel

    plan = master._plan
    h_ns, start_ns = master.system.macro_step_ns, master.start_time_ns
    jacobi = master.system.mode == "jacobi"
    tail_from = master._tail_from
    # Periods, whole steps [s], the stepping components and, per position of the plan, the
    # stepping components before it (stepping[: split[position]]; those from it on
    # stepping[split[position] :]): made once per tables (a fleet calls this once per block).
    stretches = tables.stretch_plan(plan, h_ns)
    periods, whole, stepping, split = stretches.periods, stretches.whole, stretches.stepping, stretches.split
    # The recorded components (positions, periods); rows so far in `tables.rows`.
    blocks = tables.row_arrays()
    recorded, recorded_periods = stretches.recorded, stretches.recorded_periods
    rows = tables.rows
    step = tables.run
    # Python components with rows (`python_rows`): their input counts, by plan position.
    python_rows = tables.python_rows
    input_counts = [len(entry.component.inputs) for entry in plan] if python_rows else []
    row_inputs = tables.row_inputs  # the inputs a row keeps (all, or the scalars)
    end = master.step_index + steps
    first = k = master.step_index
    position = 0
    rows[:] = 0
    # Between the calls below only the kernel sets the FMUs' inputs (Python components step here);
    # before them anyone may have (a Python loop, a restored state): each group sends all once
    # (unless the caller holds that nobody did since its last call: `KernelTables.sent_kept`).
    tables.start_run()
    finish_step = False  # a Python component stepped: the kernel ends this step, then returns

    def deliver(first: int, k: int, clean: bool):
        """`on_block` with each recorded component's rows of the steps [first, k); rows of step
        k already taken (components before the kernel's position) are kept for the next stretch."""
        held = rows[recorded]
        p = recorded_periods  # the steps of each in [first, k), at most the rows it has
        counts = np.minimum((k + p - 1) // p - (first + p - 1) // p, held)
        master.step_index = k
        delivered = tables.delivered(counts).copy()
        stop = on_block(first, k, delivered, clean) if on_block is not None else False
        extra = held - counts
        if extra.any():
            for j in np.flatnonzero(extra).tolist():
                history, n = blocks[int(recorded[j])], int(counts[j])
                history[: int(extra[j])] = history[n : int(held[j])].copy()
        rows[recorded] = extra
        return stop

    def deliver_pending() -> None:
        """The rows of the stretch's steps before the one under way, to `on_block` (an FMU that
        ends the process inside the kernel: `cosim.fmi.exit_guard` finalises the log)."""
        under_way = max(first, tables.step_under_way())
        if under_way > first:
            deliver(first, under_way, False)

    master.deliver_pending = deliver_pending
    try:
        while True:
            if k >= end and position == 0:
                break
            if before_block is not None:
                before_block()
            # At most `block` steps a stretch (a stretch of `python_rows` goes on through hand-backs).
            count = 1 if finish_step else min(block - (k - first) if python_rows else block, end - k)
            tail = tail_from is not None and k >= tail_from
            if tail:  # steps cut at the stop time go one at a time, with their step sizes
                count = 1
                for i in stepping:
                    tables.step_sizes[i] = master.step_seconds(k, periods[i])
            elif tail_from is not None:
                count = min(count, tail_from - k)
            code, k, position, failed, call, status, kind = step(k, count, position, start_ns, h_ns, jacobi)
            finish_step = False
            clean = position == 0 or not any(k % periods[i] == 0 for i in stepping[: split[position]])
            master.step_index = k
            # A hand-back with `python_rows` does not end the stretch while step k fits in it.
            going_on = (
                python_rows
                and (code == kernel.HAND_BACK or code == kernel.POLL)
                and k - first < block
                and (end_before_python is None or not end_before_python(k))
            )
            if k > first and not going_on:
                stop = deliver(first, k, clean)
                first = k
                if stop and clean:
                    break
            master.step_index = k
            if code == kernel.FAILED:
                raise_failure(
                    master, tables.native[failed], plan[failed].component.name, k, call, status, kind
                )
            if code == kernel.HAND_BACK:
                # This component, and the next ones due in this step while they need Python too.
                while True:
                    component, period, gather = plan[position]
                    try:
                        if gather is not None:
                            gather()
                            component.push_inputs()
                        cut = tail_from is not None and k >= tail_from
                        h = master.step_seconds(k, period) if cut else whole[position]
                        component.do_step((start_ns + k * h_ns) / NS_PER_S, h)
                        component.get_outputs()
                    except CosimError as error:
                        if python_rows and k > first:  # the steps before this one, as a cut would
                            deliver(first, k, False)
                        master.failure = error
                        raise
                    if python_rows:  # its row: inputs, then outputs, after the step
                        at = rows.item(position)
                        history = blocks[position]
                        kept = row_inputs[position]
                        history[at, kept] = component.input_buffer[kept]
                        history[at, input_counts[position] :] = component.output_buffer
                        rows[position] = at + 1
                    position += 1
                    following = next(
                        (i for i in itertools.islice(stepping, split[position], None) if k % periods[i] == 0),
                        None,
                    )
                    if following is None or not tables.python[following]:
                        break
                    position = following
                finish_step = cut_after_python is None or cut_after_python(k)
    finally:
        master.deliver_pending = None
    return master.step_index - (end - steps)
