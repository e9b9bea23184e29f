"""The master algorithm: runs a `System` (`cosim.core.system`: components, connections, step
order) on the integer time base of `cosim.core.timebase`: initialise, step, close.

Initialisation
--------------
Initialisation follows libcosim and ecos (FMI allows other orders; some FMUs rely on this one):
every component is instantiated, then set up (FMI 2.0: fmi2SetupExperiment with the start and stop
times, then the parameters, so an FMU that resets its variables in setupExperiment keeps the
values), then enters initialisation (FMI 3.0's enterInitializationMode takes the times; FMI 1.0
has no such mode: fmiInitializeSlave takes them when the component initialises). The connected
values are then exchanged in an order where a producer comes before a consumer whose input feeds
one of the consumer's *connected* outputs directly (`System.initialization_order`): a vehicle whose
pose outputs are states initialises before the controllers that read the pose, even though the
controllers' commands feed its (unconnected) velocity outputs. Each component gathers its inputs
from the producers already initialised (other inputs keep their start values), initialises, and
has its outputs read. A component that initialised before a producer of an input that any output
of its depends on directly (`System.initialized_early`: the vehicle's measured velocity on its
commands) then gathers all its connected inputs once more and has its outputs read again, so at
the start time every output reflects its connected inputs (within an algebraic loop, after that
one pass in a fixed order; with `loops="iterate"` the loop's members exchange their connected
values again until they agree to `loop_tolerance`, and the components they feed take them once
more). Jacobi mode uses the same initialisation.

Stop time
---------
A master given a stop time tells every component (`Component.setup`), never steps past it, and
cuts the steps that would end after it: a component due at step k steps by
min(P * h, stop - t_k) (`Master.step_seconds`), so a stop time that is no whole number of macro
steps (or of a component's period) after the start ends with a shorter step, exactly at the stop
time (`Master.steps_to_stop` steps; `time` is then the stop time). An FMU without
canHandleVariableCommunicationStepSize (`Component.can_vary_step`) cannot take that shorter step:
`Master` refuses such a stop time in one line, naming the component and the nearest stop times it
can end at (`cosim fmu simulate` refuses it too). Stepping past the stop time would break the
stop time the FMU was told, and ending at the last whole step before it (fmpy's choice) would end
the run silently early. The compiled kernel takes those
last steps one at a time, with the cut step sizes written into its tables.

Loops
-----
`Master.run` steps in Python (with a per-step callback, or always when `compiled=False`; each
component's inputs copied by its generated gather, `cosim.core.gather`) or, for a
system whose stepped components are all FMUs stepped by C calls and nobody observing the steps,
in the compiled kernel (`cosim.core.kernel`, C, reading tables filled by `cosim.core.fast_loop`);
`Master.run_recorded` likewise, keeping the rows per block. `Master.run_blocks` steps through the
same kernel, handing components that need Python back where they are due, recording the FMUs'
buffers and watching a position; its callback runs per block of steps (the block path itself is
`cosim.core.kernel_path`). All loops give bit-identical values.

Failures
--------
A component that raises `CosimError` while stepping stops the master: `step()`/`run()` re-raise
it, further steps are refused, and `close()` terminates the healthy components and frees all
(a failed FMU is not terminated; freeing it is safe).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping

import numpy as np

from cosim.core import fast_loop, kernel_path
from cosim.core.component import Component, State
from cosim.core.fast_loop import PlanEntry
from cosim.core.gather import make_gather
from cosim.core.loops import MASTER_SIGNALS, LoopLink, LoopSolver, MasterSignals
from cosim.core.system import System
from cosim.core.timebase import NS_PER_S, due_from, seconds_to_ns
from cosim.errors import CosimError

# `run`/`run_recorded` with `compiled=None` step through the kernel from this many steps on: fewer
# do not repay filling its tables (about the cost of 20 Python-loop steps of two FMUs).
COMPILED_MIN_STEPS = 100
# Most steps per call of the compiled kernel (`Master.run_blocks`).
KERNEL_BLOCK = 1000
# `Master.run` without a callback: nobody looks between blocks, so longer ones (about 0.1 s each,
# after which a KeyboardInterrupt gets through).
_RUN_BLOCK = 100_000


def _no_outputs() -> None:
    """`get_outputs` of a loop's entry in the Python loop: its members have read theirs."""


class Master:
    """Runs a `System`: initialise, step (one macro step per call) or run many, close.

    Use as a context manager, or call `close()` in a `finally`.
    """

    def __init__(
        self,
        system: System,
        start_time: float = 0.0,
        parameters: Mapping[str, Mapping[str, float]] | None = None,
        stop_time: float | None = None,
    ) -> None:
        self.system = system
        self.start_time_ns = seconds_to_ns(start_time, "start time")
        # The components are told the stop time, and no step of theirs ends after it (`steps_to_stop`).
        self.stop_time = None if stop_time is None else float(stop_time)
        self.stop_time_ns = None if stop_time is None else seconds_to_ns(stop_time, "stop time")
        if self.stop_time_ns is not None and self.stop_time_ns <= self.start_time_ns:
            raise CosimError(f"stop time {stop_time} s is not after the start time {start_time} s")
        self.parameters = {name: dict(values) for name, values in (parameters or {}).items()}
        for name in self.parameters:
            system.component(name)
        # Algebraic loops iterated within the macro step (`cosim.core.loops`): their members must
        # roll back, and the iteration counts go on /signals/master.
        self._loop_groups = system.loop_groups() if system.loops == "iterate" else []
        self._signals: MasterSignals | None = None
        if self._loop_groups:
            self._check_loop_states()
            known = system.components.get(MASTER_SIGNALS)
            if known is not None and not isinstance(known, MasterSignals):
                raise CosimError(
                    f"a component is named '{MASTER_SIGNALS}', the name of the master's own signals "
                    '(loop_iterations) under simulation.algebraic_loops = "iterate"; rename it'
                )
            self._signals = known or system.add(MasterSignals([]))
        self.order = system.order()
        if self._signals is not None:  # stepped last: it takes the iteration counts of the step
            self.order = [c for c in self.order if c is not self._signals] + [self._signals]
        self.step_index = 0
        self.failure: CosimError | None = None
        # While `run_blocks` runs: hands the rows of the steps before the one under way to its
        # `on_block` (for an FMU that ends the process inside the kernel: `cosim.fmi.exit_guard`).
        self.deliver_pending: Callable[[], None] | None = None
        self._initialized = False
        self._closed = False
        self._kernels: dict[tuple[bool, int], fast_loop.KernelTables | None] = {}
        delayed = system.delayed_links()
        # Loop members' outputs as they were before the step (copied at its start, `_advance`).
        self._previous = {
            producer: np.array(system.components[producer].output_buffer) for producer, _ in delayed
        }
        if delayed:
            loop = " -> ".join(system.algebraic_loop() or [])
            members = ", ".join(system.loop_components())
            print(
                f"note: algebraic loop {loop}: {members} step with their inputs from the previous "
                'communication point (simulation.algebraic_loops = "delay")',
                file=sys.stderr,
            )
        if self._loop_groups:
            loop = " -> ".join(system.algebraic_loop() or [])
            members = ", ".join(system.loop_components())
            print(
                f"note: algebraic loop {loop}: {members} iterate to a fixed point within each macro "
                f'step (simulation.algebraic_loops = "iterate", loop_tolerance = '
                f"{system.loop_tolerance:g}, loop_max_iterations = {system.loop_max_iterations}); "
                "the system steps in the Python master loop, not the compiled kernel",
                file=sys.stderr,
            )
        self._step_now = [0] if self._loop_groups else None  # the step `_advance` is in, for the loops
        self._solvers: list[LoopSolver] = []
        self._plan = [
            PlanEntry(
                component,
                system.period_steps(component),
                make_gather(
                    system,
                    component,
                    delayed={p: self._previous[p] for p, c in delayed if c == component.name} or None,
                ),
            )
            for component in self.order
        ]
        # The Python loop's entries (`_advance`): (period, step [s], gather, push_inputs, do_step,
        # get_outputs), plain tuples because the loop unpacks them on every step.
        self._steppers: list[tuple] = []
        self._check_cut_steps()
        self._tail_from = self._first_short_step()

    def _check_loop_states(self) -> None:
        """Every member of an iterated loop must save and restore its state: one-line error otherwise."""
        for group in self._loop_groups:
            for name in group.members:
                problem = self.system.components[name].state_support()
                if problem is not None:
                    loop = " -> ".join(self.system.algebraic_loop() or group.members)
                    raise CosimError(
                        f'simulation.algebraic_loops = "iterate" rolls back the components of algebraic '
                        f"loop {loop}, but component '{name}' cannot: {problem}; use "
                        'simulation.algebraic_loops = "delay" (inputs from the previous communication point)'
                    )

    def _loop_solvers(self) -> list[LoopSolver]:
        """One `LoopSolver` per iterated loop, with the plan's gathers (after initialisation)."""
        plan = {entry.component.name: entry for entry in self._plan}
        solvers = []
        for group in self._loop_groups:
            members = [plan[component.name] for component in self.order if component.name in group.members]
            links = []
            for c in group.connections:
                producer, output = self.system.resolve(c.source, "output")
                consumer, input_ = self.system.resolve(c.target, "input")
                name = f"{c.source} -> {c.target}"
                links.append(LoopLink(name, producer, output, consumer, input_, c.scale, c.offset))
            label = ", ".join(link.name for link in links)
            solvers.append(
                LoopSolver(
                    f"({label})",
                    members,
                    links,
                    self.system.loop_tolerance,
                    self.system.loop_max_iterations,
                    self.step_seconds,
                )
            )
        return solvers

    def _initial_loop_passes(self, order: list[Component]) -> int:
        """Exchange the loops' connected values until they agree (initialisation, `loops="iterate"`);
        then the components outside the loops take their connected inputs once more (those fed by
        a loop see its settled values). Returns the passes over the loops, the first one included
        (the pass every mode makes: `System.initialized_early`)."""
        solvers = self._loop_solvers()
        members = {name for group in self._loop_groups for name in group.members}
        looped = [(c, make_gather(self.system, c)) for c in order if c.name in members]
        passes = 1
        while True:
            unsettled = [(solver, worst) for solver in solvers if (worst := solver.worst(solver.links))]
            if not unsettled:
                break
            if passes >= self.system.loop_max_iterations:
                solver, worst = unsettled[0]
                raise solver.not_converged(worst, "at initialisation")
            for component, gather in looped:
                if gather is not None:
                    gather()
                    component.push_inputs()
                component.get_outputs()
            passes += 1
        if passes > 1:
            for component in order:
                gather = None if component.name in members else make_gather(self.system, component)
                if gather is not None:
                    gather()
                    component.push_inputs()
                    component.get_outputs()
        return passes

    # ---- time --------------------------------------------------------------------------------

    @property
    def time_ns(self) -> int:
        """Start of the next step (the current simulation time) in integer nanoseconds; the stop
        time after a last step cut short to end there."""
        time_ns = self.start_time_ns + self.step_index * self.system.macro_step_ns
        return time_ns if self.stop_time_ns is None else min(time_ns, self.stop_time_ns)

    @property
    def time(self) -> float:
        """Current simulation time [s], exact up to one float rounding of `time_ns`."""
        return self.time_ns / NS_PER_S

    @property
    def steps_to_stop(self) -> int | None:
        """Macro steps from the start to the stop time (None without one); where the stop time is no
        whole number of macro steps after the start the last is shorter, ending at the stop time."""
        if self.stop_time_ns is None:
            return None
        return -(-(self.stop_time_ns - self.start_time_ns) // self.system.macro_step_ns)

    def _check_cut_steps(self) -> None:
        """`CosimError` when the stop time cuts the last step of a component that cannot take a
        shorter step (module docstring, "Stop time")."""
        if self.stop_time_ns is None:
            return
        span_ns = self.stop_time_ns - self.start_time_ns
        for component, period, _ in self._plan:
            step_ns = period * self.system.macro_step_ns
            if span_ns % step_ns == 0 or component.constant_outputs or component.can_vary_step():
                continue
            whole = span_ns // step_ns
            before, after = ((self.start_time_ns + n * step_ns) / NS_PER_S for n in (whole, whole + 1))
            raise CosimError(
                f"stop time {self.stop_time:g} s is not a whole number of steps of component "
                f"'{component.name}' ({step_ns / NS_PER_S:g} s) after the start time "
                f"{self.start_time_ns / NS_PER_S:g} s, and it cannot take the shorter last step that "
                "would end there (no canHandleVariableCommunicationStepSize); give a stop time of "
                f"{before:g} or {after:g} s"
            )

    def _first_short_step(self) -> int | None:
        """The first step at which a component's step would end after the stop time, so is cut to
        end at it (None: none would). Component of period P due at k passes the stop when
        (k + P) h > stop - start, that is k >= floor((stop - start) / h) - P + 1."""
        if self.stop_time_ns is None:
            return None
        whole = (self.stop_time_ns - self.start_time_ns) // self.system.macro_step_ns
        firsts = [due_from(max(0, whole - entry.period + 1), entry.period) for entry in self._plan]
        return min(firsts, default=None)

    def _check_steps(self, steps: int) -> None:
        if steps < 0:
            raise CosimError(f"number of steps must be >= 0, got {steps}")
        last = self.steps_to_stop
        if last is not None and self.step_index + steps > last:
            raise CosimError(
                f"{steps} steps from t = {self.time:g} s pass the stop time {self.stop_time:g} s "
                f"({last - self.step_index} steps remain)"
            )

    def step_seconds(self, k: int, period: int) -> float:
        """The step [s] of a component of `period` macro steps due at step k: a whole period, or up
        to the stop time when that comes first."""
        h_ns = period * self.system.macro_step_ns
        if self.stop_time_ns is not None:
            h_ns = min(h_ns, self.stop_time_ns - self.start_time_ns - k * self.system.macro_step_ns)
        return h_ns / NS_PER_S

    # ---- lifecycle ---------------------------------------------------------------------------

    def initialize(self) -> None:
        """Instantiate, set up (parameters), and initialise every component (see module doc)."""
        if self._initialized:
            raise CosimError("the master is already initialised")
        t0 = self.start_time_ns / NS_PER_S
        try:
            for component in self.order:
                component.instantiate()
            for component in self.order:
                component.setup(t0, self.parameters.get(component.name, {}), self.stop_time)
            for component in self.order:
                component.enter_initialization()
            ready: set[str] = set()
            order = self.system.initialization_order()
            for component in order:
                gather = make_gather(self.system, component, producers=ready)
                if gather is not None:
                    gather()
                component.push_inputs()
                component.push_text()
                component.initialize()
                component.get_outputs()
                ready.add(component.name)
            for component in self.system.initialized_early(order):
                gather = make_gather(self.system, component)
                if gather is not None:
                    gather()
                component.push_inputs()
                component.push_text()
                component.get_outputs()
            if self._loop_groups:
                self._signals.output_buffer[0] = self._initial_loop_passes(order)
        except BaseException:
            try:
                self.close()
            except CosimError:
                pass  # terminating the others failed too; the error that stopped initialisation is the news
            raise
        self._initialized = True
        self._skip_constant_producers()
        # Bound once, after initialisation installed the components' fast paths.
        h_ns = self.system.macro_step_ns
        self._solvers = self._loop_solvers() if self._loop_groups else []
        if self._signals is not None:
            self._signals.solvers = self._solvers
        solver_of = {member.component.name: solver for solver in self._solvers for member in solver.members}
        placed: set[int] = set()
        self._steppers = []
        for c, period, gather in self._plan:
            solver = solver_of.get(c.name)
            if solver is None:
                if not c.constant_outputs:
                    self._steppers.append(
                        (period, period * h_ns / NS_PER_S, gather, c.push_inputs, c.do_step, c.get_outputs)
                    )
            elif id(solver) not in placed:  # a loop steps as one entry, at its first member's place
                placed.add(id(solver))
                self._steppers.append((1, h_ns / NS_PER_S, None, None, self._loop_step(solver), _no_outputs))

    def _loop_step(self, solver: LoopSolver) -> Callable[[float, float], None]:
        """The `do_step` of a loop's entry in the Python loop: the loop's macro step (`_advance` keeps
        the step number in `_step_now`)."""
        now = self._step_now

        def do_step(t: float, h: float) -> None:
            solver.step(now[0], t)

        return do_step

    def _skip_constant_producers(self) -> None:
        """Components with constant outputs were copied from at initialisation: from now on their
        connections are not copied again, and an FMU consumer pushes only its other inputs."""
        constant = {name for name, c in self.system.components.items() if c.constant_outputs}
        if not constant:
            return
        dynamic = set(self.system.components) - constant
        plan = []
        for component, period, gather in self._plan:
            fed = self.system.links().get(component.name, ())
            if any(link.producer in constant for link in fed):
                gather = make_gather(self.system, component, producers=dynamic)
                static = {link.input for link in fed if link.producer in constant}
                if hasattr(component, "restrict_push"):
                    component.restrict_push([i for i in range(len(component.inputs)) if i not in static])
            plan.append(PlanEntry(component, period, gather))
        self._plan = plan

    def _check_running(self) -> None:
        if self.failure is not None:
            raise CosimError(f"the master stopped after a failure: {self.failure}")
        if not self._initialized or self._closed:
            raise CosimError("the master is not running (call initialize() first; not after close())")

    def step(self) -> None:
        """Advance one macro step, from `time` to `time + macro_step` (or to the stop time)."""
        self._check_running()
        self._check_steps(1)
        self._advance(1)

    def run(
        self,
        steps: int,
        callback: Callable[[Master], bool | None] | None = None,
        compiled: bool | None = None,
    ) -> int:
        """Advance `steps` macro steps; return the number done.

        With `callback`, it is called after every step and a true return stops early. Without
        it the loop has no per-step Python callback, and a system whose stepped components are
        all FMUs stepped by C calls runs in the compiled kernel (`cosim.core.kernel`):
        `compiled=None` chooses it for runs of at least `COMPILED_MIN_STEPS`, True forces it where
        possible, False never.
        """
        self._check_running()
        self._check_steps(steps)
        if callback is None:
            wanted = steps >= COMPILED_MIN_STEPS if compiled is None else compiled
            tables = self._kernel(record=False, block=KERNEL_BLOCK) if wanted else None
            if tables is not None:
                self.run_blocks(steps, tables, block=_RUN_BLOCK)
            else:
                self._advance(steps)
            return steps
        return self._advance(steps, callback)

    def run_recorded(
        self,
        steps: int,
        on_block: Callable[[int, int, list[np.ndarray]], None],
        block: int = 1000,
        compiled: bool | None = None,
    ) -> int:
        """Advance `steps` macro steps, keeping every component's inputs and outputs after each of
        its steps; after each block of at most `block` steps call `on_block(first_step, count,
        histories)`, where `histories[i]` (component i of `order`) has one row per step of that
        component in the block, k = first_step .. first_step + count - 1 with k % period == 0:
        its inputs, then its outputs. Returns the steps done.

        A system whose stepped components are all FMUs stepped by C calls runs the blocks in the
        compiled kernel, which fills the rows itself (`compiled` as in `run`); otherwise the Python
        loop copies them.
        """
        self._check_running()
        self._check_steps(steps)
        if block < 1:
            raise CosimError(f"block must be >= 1 step, got {block}")
        wanted = steps >= COMPILED_MIN_STEPS if compiled is None else compiled
        tables = self._kernel(record=True, block=block) if wanted else None
        if tables is not None:
            # Components never stepped (constant outputs) have no rows, as in the Python loop.
            empty = [np.empty((0, len(c.inputs) + len(c.outputs))) for c, _, _ in self._plan]

            def forward(first: int, end: int, delivered: list, clean: bool) -> None:
                kept = [empty[i] if rows is None else rows for i, rows in enumerate(delivered)]
                on_block(first, end - first, kept)

            # All components are stepped by the kernel: its stretches are the blocks.
            self.run_blocks(steps, tables, forward, block=block)
            return steps
        histories = [
            np.empty((block // period + 1, len(c.inputs) + len(c.outputs))) for c, period, _ in self._plan
        ]
        rows = np.zeros(len(histories), dtype=np.int64)
        done = 0
        while done < steps:
            count = min(block, steps - done)
            first = self.step_index
            rows[:] = 0
            try:
                for k in range(first, first + count):
                    self._advance(1)
                    for i, (component, period, _) in enumerate(self._plan):
                        if not component.constant_outputs and (period == 1 or k % period == 0):
                            row = histories[i][rows[i]]
                            row[: len(component.inputs)] = component.input_buffer
                            row[len(component.inputs) :] = component.output_buffer
                            rows[i] += 1
            finally:
                self._deliver(first, on_block, histories, rows)
            done += count
        return steps

    def kernel_tables(
        self,
        record: bool = False,
        block: int = KERNEL_BLOCK,
        python_rows: bool = False,
        scalar_rows: bool = False,
    ) -> fast_loop.KernelTables | None:
        """The tables of `run_blocks` (`cosim.core.kernel`), or None when the kernel cannot run this
        system: no component steps by C calls, or Jacobi mode with a component that needs Python.
        `python_rows` (with `record`): the components that need Python have rows too, and the
        stretches of `run_blocks` go on through their steps (`cosim.core.kernel_path`).
        `scalar_rows` (with `record`): the rows keep the scalar inputs only, not the elements of
        input arrays (`cosim.core.fast_loop.recorded_inputs`: what a recording reads)."""
        self._check_running()
        return kernel_path.kernel_tables(self, record, block, python_rows, scalar_rows)

    def run_blocks(
        self,
        steps: int,
        tables: fast_loop.KernelTables,
        on_block: Callable[[int, int, list, bool], bool | None] | None = None,
        block: int = KERNEL_BLOCK,
        before_block: Callable[[], None] | None = None,
        cut_after_python: Callable[[int], bool] | None = None,
        end_before_python: Callable[[int], bool] | None = None,
    ) -> int:
        """Advance up to `steps` macro steps through the compiled kernel, handing components that
        need Python back where they are due; `on_block(first, end, histories, clean)` after each
        stretch of steps. Returns the steps done. The arguments and callbacks are those of
        `cosim.core.kernel_path.run_blocks`, which says what they mean."""
        self._check_running()
        self._check_steps(steps)
        return kernel_path.run_blocks(
            self, steps, tables, on_block, block, before_block, cut_after_python, end_before_python
        )

    def _deliver(self, first: int, on_block, histories: list[np.ndarray], rows: np.ndarray) -> None:
        """Hand the rows of the steps that ran (all of them, or up to a failure) to `on_block`."""
        end = self.step_index
        if end <= first:
            return
        # Steps of each component in [first, end): rows of a step cut short by a failure are dropped.
        kept = [
            history[: min(int(n), (end + period - 1) // period - (first + period - 1) // period)]
            for history, n, (_, period, _) in zip(histories, rows, self._plan, strict=True)
        ]
        on_block(first, end - first, kept)

    def _kernel(self, record: bool, block: int) -> fast_loop.KernelTables | None:
        """Tables for `run`/`run_recorded` (kept for the next call), or None when a component that
        is stepped needs Python (or none is stepped by C calls)."""
        key = (record, block)
        if key not in self._kernels:
            self._kernels[key] = kernel_path.all_native_tables(self, record, block)
        return self._kernels[key]

    def _advance(self, steps: int, callback: Callable[[Master], bool | None] | None = None) -> int:
        """Step `steps` times (or until `callback`, called after each step, returns true); return
        the number of steps done. On a failure `step_index` is the step that failed."""
        steppers = self._steppers
        h_ns = self.system.macro_step_ns
        start_ns = self.start_time_ns
        jacobi = self.system.mode == "jacobi"
        tail_from = self._tail_from
        components = self.system.components
        previous = [(copy, components[name].output_buffer) for name, copy in self._previous.items()]
        now = self._step_now
        first = k = self.step_index
        try:
            for k in range(first, first + steps):
                t = (start_ns + k * h_ns) / NS_PER_S
                tail = tail_from is not None and k >= tail_from  # steps cut at the stop time
                for copy, outputs in previous:
                    copy[:] = outputs
                if now is not None:
                    now[0] = k
                if jacobi:
                    due = [entry for entry in steppers if k % entry[0] == 0]
                    for _, _, gather, push, _, _ in due:
                        if gather is not None:
                            gather()
                            push()
                    for period, h, _, _, do_step, get_outputs in due:
                        do_step(t, self.step_seconds(k, period) if tail else h)
                        get_outputs()
                else:
                    for period, h, gather, push, do_step, get_outputs in steppers:
                        if period == 1 or k % period == 0:
                            if gather is not None:
                                gather()
                                push()
                            do_step(t, self.step_seconds(k, period) if tail else h)
                            get_outputs()
                if callback is not None:
                    self.step_index = k + 1
                    if callback(self):
                        return k + 1 - first
        except CosimError as error:
            self.step_index = k
            self.failure = error
            raise
        self.step_index = first + steps
        return steps

    def close(self) -> None:
        """Terminate healthy components and free all; idempotent. Raises the first terminate error."""
        if self._closed:
            return
        self._closed = True
        first_error: CosimError | None = None
        for component in self.order:
            if component.state in (State.SET_UP, State.STEPPING):
                try:
                    component.terminate()
                except CosimError as error:
                    first_error = first_error or error
        for component in self.order:
            component.free()
        if first_error is not None and self.failure is None:
            raise first_error

    def __enter__(self) -> Master:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
