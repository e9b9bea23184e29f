"""Run a scenario: build, plan, step the master, record every signal to MCAP, decide the outcome.

`run_scenario(scenario, out_path)` builds the system (`cosim.navigation.build`), initialises every
component, and only then creates the log, so bad input never leaves a log behind. The loop stops
when the goal is reached, on a collision, at the stop time, on SIGINT/SIGTERM, or when an FMU fails.

Log contents and rates (t = simulated time, integer nanoseconds):
- `/signals/<component>`: every scalar input and output of the component, each time it steps
  (its rate), each value stamped at the time it holds: the record at t has the inputs applied at
  t and the outputs at t (the first record the initial outputs), and a last record at the end
  has the final outputs (`cosim.record.recorder`). Array ports (waypoints, ranges, angles) are
  on `/plan` and `/scan` instead; with [output].signal_arrays array outputs are recorded too (a
  component whose outputs never change, the planner, once at t = 0).
- `/odom`, `/tf`, `/pose`: the robot pose (the description's `Observed.pose`, the vehicle's x, y,
  theta) at t = 0 and every 1/pose_rate s ([output].pose_rate, default 50 Hz), and at the end of
  the run; twist = the commanded v and omega (`Observed.command`, the mixer's).
- `/scan`: every lidar step; `/cmd_vel`: every mixer step (v, omega of the mixer).
- `/obstacles`: at t = 0, and at every lidar step at which a moving obstacle has moved (the poses
  that scan saw).
- `/plan`: at t = 0 and at each replan (stamped with the start of the planner step that made it).
- `/map`, `/map_inflated`, `/goal`: once at t = 0.
- metadata `navcosim`, `fmu/<role>`, `outcome`; attachments `scenario.toml` and the map file(s).

The loop: the FMUs step in the compiled kernel (`Master.run_blocks`, `cosim.core.kernel`), which keeps
their buffers after each step and hands the Python components (lidar, planner) back where they are
due. After each block of steps (cut before every Python component's step, at the end of a step in
which one stepped when that step has something to write (a new plan, no path, a goal poll; else the
block goes on), and after any step whose position may end the run: not finite, near the goal, or
outside a circle that the true obstacles cannot reach) `_BlockRecording` takes the block's rows:
the positions of all its steps go through `OutcomeMonitor.check_positions` (the arithmetic of the
per-step check, step by step), and the rows are collected over blocks and turned into their
messages with NumPy every few chunk windows (`Recorder.hold_steps`: the bytes of writing them one at
a time). A block the rows cannot describe (a topic's first message, a Python component due after
the block's first step) is replayed step by step: `_KernelBlocks.replay_steps` sets the buffers to
each step's values in turn and calls `finish_step` (recording, mode, outcome, planner) for it, as
the Python loop's per-step callback does. Either way the log and the outcome are the same bytes and
numbers, and the run ends at the same step. Hooks: `finish_step(k)` runs once per step (Python
loop, blocks replayed step by step), `finish_checks` (goal poll, new plan) after a step's position
check in both, `on_block` once per block (kernel; interrupts are noticed there, at most one block
late), `_KernelBlocks.watch` before each kernel call (it re-reads the monitor's goal). A system the
kernel cannot step (Jacobi mode with Python components) and NAVCOSIM_LOOP=python use the master's
Python loop with the per-step callback.

End of a run: a normal end, an interrupt (outcome reason "interrupted") and an FMU failure
(reason "fmu_failed": an error status, a crash, exit() or hang of an FMU in a child process, a NaN
output; metadata `outcome.failure` holds the message) all finalise the log at its path, readable
up to the last completed step. Any other error after the log was created finalises it and renames
it `<name>.failed.mcap`.
"""

from __future__ import annotations

import ctypes
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim import release_collector
from cosim.core import interrupt
from cosim.core.master import Master
from cosim.core.timebase import NS_PER_S, due_from
from cosim.errors import PATH_LIMIT, CosimError, SimulationEnded, shorten
from cosim.fmi import exit_guard
from cosim.navigation.build import BuiltRun, build_run
from cosim.navigation.outcome import Outcome, OutcomeMonitor, outcome_metadata
from cosim.record.logfile import (
    claim_default_log,
    claim_log,
    default_log_path,
    is_regular_file,
    navcosim_version,
)
from cosim.record.text_signals import TextRecording
from cosim.scenario.load import Scenario
from cosim.world.shapes import moves

PROGRESS_INTERVAL = 0.1  # [s] wall time between progress-bar updates


@dataclass
class RunResult:
    outcome: Outcome
    log_path: Path | None
    steps: int
    wall_time: float  # [s]
    failure: str | None = None  # message of a failed FMU
    trace: object | None = None  # the recorder's `RunTrace`: what the default plot draws
    ended: str | None = None  # which FMU asked to end the run, and when (reason fmu_terminated)

    @property
    def exit_code(self) -> int:
        """0 goal reached, 1 not reached (stop time, collision, interrupt), 2 failed FMU."""
        if self.failure is not None:
            return 2
        return 0 if self.outcome.reached else 1

    @property
    def real_time_factor(self) -> float:
        return self.outcome.time / self.wall_time if self.wall_time > 0 else math.inf


def _output(system, reference: str) -> tuple[np.ndarray, int]:
    """(output buffer, slot) of an observed "component.port"."""
    component, index = system.resolve(reference, "output")
    return component.output_buffer, index


class _Recording:
    """What the loop records at each step; index arrays are resolved once.

    Components and ports are the system's own; what is read besides the signals (the robot pose,
    the commanded velocity, the scan) comes from the description's `Observed`, by name.
    """

    def __init__(self, built: BuiltRun, master: Master, recorder) -> None:
        self.recorder = recorder
        self.stop_ns = master.stop_time_ns  # a last step cut short ends there, and so does its pose
        system = built.system
        self.entries = []
        self.entry_ports = []  # per entry: (component, scalar input slots, output slots)
        self.constant = []  # (channel, record) of components whose outputs never change: once, at t = 0
        arrays = built.scenario.signal_arrays
        for component in master.order:
            # Array ports are on /plan and /scan; with [output].signal_arrays the array outputs are
            # recorded too (array inputs never: each is fed by an array output).
            inputs = [i for i, p in enumerate(component.inputs) if not p.is_array_element]
            outputs = [i for i, p in enumerate(component.outputs) if arrays or not p.is_array_element]
            names = [component.inputs[i].name for i in inputs] + [component.outputs[i].name for i in outputs]
            if not names:
                continue
            ports = [component.inputs[i] for i in inputs] + [component.outputs[i] for i in outputs]
            units = [port.unit for port in ports]
            if component.constant_outputs:
                channel = recorder.signal_channel(component.name, names, units=units)
                self.constant.append((channel, component, inputs, outputs))
                continue
            channel = recorder.signal_channel(
                component.name,
                names,
                units=units,
                inputs=len(inputs),
                initial=np.concatenate((component.input_buffer[inputs], component.output_buffer[outputs])),
                period_ns=system.period_steps(component) * system.macro_step_ns,
            )
            # One record = the scalar inputs then the outputs. Where the scalar inputs are one run of
            # slots (all ports, or the scalars before the arrays), the record is two views of the
            # buffers made once: no gather per step.
            first, second = (
                _run_view(component.input_buffer, inputs),
                _run_view(component.output_buffer, outputs),
            )
            if first is not None and second is not None:
                self.entries.append((system.period_steps(component), channel, first, second, None))
                self.entry_ports.append((component, inputs, outputs))
                continue
            values = np.empty(len(names))  # the record, gathered; reused, no allocation per step
            gather = (
                component.input_buffer,
                np.array(inputs, dtype=np.intp),
                values[: len(inputs)],
                component.output_buffer,
                np.array(outputs, dtype=np.intp),
                values[len(inputs) :],
            )
            self.entries.append((system.period_steps(component), channel, values, None, gather))
            self.entry_ports.append((component, inputs, outputs))
        observed = built.description.observed
        (self.pose_x, self.x), (self.pose_y, self.y), (self.pose_theta, self.theta) = (
            _output(system, reference) for reference in observed.pose
        )
        self.command = None
        if observed.command is not None:
            (v_buffer, v), (omega_buffer, omega) = (_output(system, r) for r in observed.command)
            steps = system.period_steps(system.component(observed.command[0].split(".")[0]))
            self.command = (steps, v_buffer, v, omega_buffer, omega)
        self.mode = None
        if observed.mode is not None:
            buffer, index = _output(system, observed.mode)
            steps = system.period_steps(system.component(observed.mode.split(".")[0]))
            self.mode = (steps, steps * system.macro_step, buffer, index)
        self.scan = None
        if observed.scan is not None:
            source = observed.scan
            lidar = system.component(source.component)
            ranges_index = [i for i, p in enumerate(lidar.outputs) if p.array_name == "ranges"]
            ranges = _run_view(lidar.output_buffer, ranges_index)
            gather = None if ranges is not None else np.array(ranges_index, dtype=np.intp)
            angles = np.array(source.angles, dtype=float)
            angles.flags.writeable = False  # fixed for the run: the recorder keeps its /scan layout
            # Range limits [m] and scan_time [s] (the lidar's period) of /scan.
            limits = (source.range_min, source.range_max, system.period_steps(lidar) * system.macro_step)
            self.scan = (system.period_steps(lidar), lidar.output_buffer, ranges, gather, angles, limits)
        self.pose_steps = max(1, round(1.0 / (built.scenario.pose_rate * built.scenario.macro_step)))
        self.obstacles = built.scenario.obstacles
        self.moving = [obstacle.motion for obstacle in self.obstacles if moves(obstacle)]
        self.obstacle_offsets = tuple((0.0, 0.0) for _ in self.moving)  # as written at t = 0
        # Moved obstacles go out with the scans (the poses each scan saw), else at the pose rate.
        self.obstacle_steps = self.scan[0] if self.scan is not None else self.pose_steps

    def write_constant(self, t_ns: int) -> None:
        """The records of the components whose outputs are fixed for the run (the plan)."""
        for channel, component, inputs, outputs in self.constant:
            record = np.concatenate((component.input_buffer[inputs], component.output_buffer[outputs]))
            self.recorder.write_signals(channel, t_ns, record)

    def pose(self) -> tuple[float, float, float]:
        # .item: a Python float without a NumPy scalar
        return self.pose_x.item(self.x), self.pose_y.item(self.y), self.pose_theta.item(self.theta)

    def write_pose(self, t_ns: int) -> None:
        x, y, theta = self.pose()
        v = omega = math.nan
        if self.command is not None:
            _, v_buffer, index_v, omega_buffer, index_omega = self.command
            v, omega = v_buffer.item(index_v), omega_buffer.item(index_omega)
        self.recorder.write_pose(t_ns, x, y, theta, v, omega)

    def write_moved_obstacles(self, t_ns: int) -> None:
        """/obstacles at the poses the lidar saw at t_ns, when any obstacle moved since the last one."""
        t = t_ns / NS_PER_S
        offsets = tuple(motion.offset(t) for motion in self.moving)
        if offsets != self.obstacle_offsets:
            self.obstacle_offsets = offsets
            self.recorder.write_obstacles(t_ns, [obstacle.at(t) for obstacle in self.obstacles])

    def after_step(self, k: int, t_ns: int, h_ns: int) -> None:
        """Record what step k (starting at t_ns) produced."""
        hold = self.recorder.hold_signals
        for period, channel, first, second, gather in self.entries:
            if period == 1 or k % period == 0:
                if gather is not None:
                    inputs, input_index, input_part, outputs, output_index, output_part = gather
                    # mode="clip": with the default "raise" NumPy buffers `out` (a copy per call).
                    np.take(inputs, input_index, out=input_part, mode="clip")
                    np.take(outputs, output_index, out=output_part, mode="clip")
                hold(channel, t_ns, first, second)
        recorder = self.recorder
        scan = self.scan
        if scan is not None and k % scan[0] == 0:
            _, buffer, ranges, gather, angles, limits = scan
            recorder.write_scan(t_ns, angles, ranges if gather is None else buffer[gather], *limits)
        if self.moving and k % self.obstacle_steps == 0:
            self.write_moved_obstacles(t_ns)
        command = self.command
        if command is not None and k % command[0] == 0:
            _, v_buffer, index_v, omega_buffer, index_omega = command
            recorder.write_cmd_vel(t_ns, v_buffer.item(index_v), omega_buffer.item(index_omega))
        if (k + 1) % self.pose_steps == 0:
            self.write_pose(min(t_ns + h_ns, self.stop_ns))


def _run_view(buffer: np.ndarray, slots: list[int]) -> np.ndarray | None:
    """A view of `buffer[slots]` when the slots are consecutive (it follows the buffer), else None."""
    if slots and slots != list(range(slots[0], slots[0] + len(slots))):
        return None
    return buffer[slots[0] : slots[0] + len(slots)] if slots else buffer[:0]


def _write_header(built: BuiltRun, master: Master, recorder) -> None:
    """Metadata, attachments and the once-only topics at t = 0."""
    scenario = built.scenario
    x, y, theta = scenario.start
    recorder.add_metadata(
        "navcosim",
        {
            "scenario_name": scenario.name,
            "navcosim_version": navcosim_version(),
            "start": f"{x},{y},{theta}",
            "goal": f"{scenario.goal[0]},{scenario.goal[1]}",
            "goal_tolerance": str(scenario.goal_tolerance),
            "macro_step": str(scenario.macro_step),
            "stop_time": str(scenario.stop_time),
            "overrides": " ".join(scenario.overrides),
            "master": scenario.master,
            "topics": ",".join(f"{topic}={name}" for topic, name in scenario.topics.items()),
        },
    )
    for name, component in built.system.components.items():
        description = component.describe()
        if description:
            if name in scenario.fmu_labels:
                description["fmu"] = scenario.fmu_labels[name]
            recorder.add_metadata(f"fmu/{name}", description)
    recorder.add_unconnected_inputs(built.system)
    recorder.add_attachment("scenario.toml", "application/toml", scenario.text.encode())
    map_file = scenario.map_file
    recorder.add_attachment(map_file.name, "application/octet-stream", map_file.read_bytes())
    if map_file.suffix in (".yaml", ".yml"):
        for line in map_file.read_text().splitlines():
            key, _, value = line.partition(":")
            image = map_file.parent / value.strip().strip("'\"")
            if key.strip() == "image" and image.is_file():
                recorder.add_attachment(image.name, "image/x-portable-graymap", image.read_bytes())
    recorder.write_grid(0, built.grid, "/map")
    recorder.write_grid(0, built.inflated, "/map_inflated")
    if built.plan is not None:
        recorder.write_path(0, built.plan.path)
    recorder.write_obstacles(0, [obstacle.at(0.0) for obstacle in scenario.obstacles])
    recorder.write_goal(0, scenario.goal[0], scenario.goal[1], None)
    release_collector()  # the loop starts: the collector is on again (`cosim.hold_collector`)


def run_scenario(
    scenario: Scenario,
    out_path: Path | None = None,
    progress: bool = False,
    flush_interval: float = 0.5,
    sink=None,
    force: bool = False,
    goals=None,
) -> RunResult:
    """Run `scenario`, logging to `out_path` (default: `[output].log`). Raises `CosimError` on bad input.
    `sink` (`cosim.record.live.Sink`, e.g. the live view) also gets everything the log gets.
    `goals` (`cosim.record.live.GoalSource`, e.g. the live view's /goal_pose) gives new goals during
    the run (`_goal_poll`).

    An existing `out_path` is refused unless `force`; a default name that is taken gets a numbered
    suffix (`cosim.record.logfile`). SIGINT/SIGTERM before the log exists raise
    `cosim.core.interrupt.Interrupted` (nothing written); after, they stop the run at the next step
    with outcome "interrupted" and a finalised log.
    """
    if out_path is not None and not force and is_regular_file(Path(out_path)):
        # Checked again, race-free, when the log is created; here to fail before the build.
        raise CosimError(f"{shorten(out_path, PATH_LIMIT)}: already exists; give --force to overwrite it")
    with interrupt.catching_signals():
        return _build_and_run(scenario, out_path, force, progress, flush_interval, sink, goals)


def _build_and_run(
    scenario: Scenario, out_path, force: bool, progress: bool, flush_interval: float, sink=None, goals=None
) -> RunResult:
    from cosim.record.recorder import Recorder

    built = build_run(scenario)
    master = Master(built.system, parameters=built.parameters, stop_time=scenario.stop_time)
    try:
        master.initialize()
    except CosimError as error:
        _close_quietly(master)
        raise CosimError(f"{scenario.source}: initialising the system failed: {error}") from None
    except BaseException:
        _close_quietly(master)
        raise
    with interrupt.deferred():
        try:
            if out_path is not None:
                log_path, stream = Path(out_path), claim_log(Path(out_path), force)
            else:
                log_path, stream = claim_default_log(default_log_path(scenario.log_pattern, scenario.name))
            recorder = Recorder(
                log_path, flush_interval=flush_interval, sink=sink, topics=scenario.topics, stream=stream
            )
        except BaseException:
            _close_quietly(master)
            raise
        try:
            return _run(built, master, recorder, log_path, progress, goals)
        except OSError as error:
            # The log could not be written (no space, I/O error): what reached the file stays.
            _close_quietly(master, recorder)
            where = shorten(error.filename or log_path, PATH_LIMIT)
            raise CosimError(f"{where}: writing the log failed ({error.strerror or error})") from None
        except BaseException:
            # Neither a normal end, an interrupt nor an FMU failure: keep the log, but marked.
            _close_quietly(master, recorder, {"reached": "false", "reason": "error"})
            if is_regular_file(log_path):
                log_path.replace(log_path.with_suffix(".failed.mcap"))
            raise


def _close_quietly(master: Master, recorder=None, outcome: dict[str, str] | None = None) -> None:
    """Close what a run opened, on its way out with an error that matters more than theirs."""
    try:
        master.close()
    except CosimError:
        pass
    if recorder is not None:
        try:
            recorder.close(outcome)
        except (OSError, CosimError):
            pass


def _run(built: BuiltRun, master: Master, recorder, log_path: Path, progress: bool, goals=None) -> RunResult:
    scenario = built.scenario
    system = built.system
    recording = _Recording(built, master, recorder)
    monitor = OutcomeMonitor(
        built.world, scenario.goal, scenario.goal_tolerance, scenario.vehicle_radius, scenario.start
    )
    _write_header(built, master, recorder)
    text = TextRecording(recorder, system)
    recording.write_constant(master.start_time_ns)
    recording.write_pose(0)
    h_ns = system.macro_step_ns
    total_steps = master.steps_to_stop  # the last one ends at the stop time
    # Build (or load) the C kernels that would first run inside the loop, so the real-time factor
    # measures the simulation, not a first run's compilation.
    monitor.world.distance(*scenario.start[:2])
    tables = master.kernel_tables(record=True) if _use_kernel() else None
    if tables is not None:
        tables.warm_up()
    bar = progress_bar(scenario.stop_time) if progress else None
    wall_start = time.perf_counter()
    last_update = [wall_start, 0.0]
    state = {"reason": None}

    start_ns = master.start_time_ns
    take_signal = interrupt.take
    x_item, y_item, index_x, index_y = recording.pose_x.item, recording.pose_y.item, recording.x, recording.y
    mode_steps, mode_period, mode_buffer, mode_index = recording.mode or (0, 0.0, None, 0)

    planner = built.planner if built.planner is not None and not built.planner.constant_outputs else None
    plan_version = [planner.plan_version if planner is not None else 0]
    # New goals during the run (the live view's /goal_pose), polled at the planner's rate.
    goal_poll = _goal_poll(goals, built, monitor, recorder, recording) if goals is not None else None
    goal_steps = system.period_steps(built.planner) if goal_poll is not None and built.planner else 1

    def finish_step(k: int) -> str | None:
        """Record what step k produced and check the outcome; why the run ends after it, or None."""
        t_ns = start_ns + k * h_ns
        recording.after_step(k, t_ns, h_ns)
        if mode_steps and k % mode_steps == 0:
            monitor.check_mode(mode_buffer.item(mode_index), mode_period)
        end_ns = min(t_ns + h_ns, master.stop_time_ns)  # (a last step cut short ends at the stop time)
        reason = monitor.check_position(end_ns / NS_PER_S, x_item(index_x), y_item(index_y))
        return finish_checks(k, reason)

    def finish_checks(k: int, reason: str | None, before_write=None) -> str | None:
        """The end of step k after its position check: a new goal, a new plan (`before_write()`
        first when either may write to the log); why the run ends after it, or None."""
        t_ns = start_ns + k * h_ns
        if goal_poll is not None and reason is None and k % goal_steps == 0:
            if before_write is not None:
                before_write()
            goal_poll(t_ns, h_ns)
        if planner is not None:
            if planner.plan_version != plan_version[0]:
                if before_write is not None:
                    before_write()
                plan_version[0] = planner.plan_version
                recorder.write_path(t_ns, planner.result.path)  # the plan made in step k
            monitor.outcome.replans = len(planner.replans)
            if reason is None and planner.no_path is not None:
                monitor.outcome.no_path = planner.no_path
                reason = "no_path"
        return reason

    def show_progress(sim_time: float) -> None:
        now = time.perf_counter()
        if now - last_update[0] >= PROGRESS_INTERVAL:
            update_bar(bar, sim_time, now - wall_start, last_update)
            last_update[0] = now

    def stop(reason: str | None, poll_signal: bool, sim_time: float) -> bool:
        """After a step (Python loop) or a block (kernel): whether the run ends, and why."""
        if reason is None and poll_signal and take_signal() is not None:
            reason = "interrupted"
        if bar is not None:
            show_progress(sim_time)
        if reason is not None:
            state["reason"] = reason
            return True
        return False

    def after_step(current: Master) -> bool:
        return stop(finish_step(current.step_index - 1), True, current.time)

    failure = None
    ended = None  # an FMU's request to end the run (FMI terminateSimulation / fmi2Terminated)
    blocks = None

    def finish(failure: str | None, ended: str | None, free: bool = True) -> RunResult:
        """The end of the run: the last pose, the outcome, the log finalised (`free`: and the
        system closed)."""
        wall_time = time.perf_counter() - wall_start
        end_ns = master.time_ns
        # The pose at end_ns is the vehicle's after the last completed step (after a failure too; the
        # after_step of that step wrote it already when end_ns is on the pose grid). A pose that turned
        # NaN in the failed step is not logged.
        if master.step_index % recording.pose_steps != 0 and all(map(math.isfinite, recording.pose())):
            recording.write_pose(end_ns)
        text.finish(end_ns)
        recorder.end_steps(end_ns)
        reason = "fmu_failed" if failure else state["reason"] or "stop_time"
        outcome = monitor.finish(end_ns / NS_PER_S, reason)
        if bar is not None:
            update_bar(bar, master.time, wall_time, last_update)
            # The run is over whatever its reason (goal reached early, collision, interrupt): the bar
            # ends full, at the time the run ended, instead of vanishing part-way.
            bar.total = bar.n
            bar.refresh()
            bar.close()
        metadata = outcome_metadata(outcome)
        if tuple(monitor.goal) != tuple(scenario.goal[:2]):
            metadata["goal"] = f"{monitor.goal[0]},{monitor.goal[1]}"  # the last goal given during the run
        if failure:
            metadata["failure"] = failure
        if ended:
            metadata["ended_by"] = ended
        try:
            if free:
                master.close()
        except CosimError as error:
            failure = failure or f"terminating the system failed: {error}"
        for name, record in getattr(goals, "acknowledged", tuple)():  # the live view's last commands
            recorder.add_metadata(name, record)
        recorder.close(metadata)
        return RunResult(outcome, log_path, master.step_index, wall_time, failure, recorder.trace, ended)

    def fmu_exited(message: str) -> str:
        """An FMU in this process called exit() (`cosim.fmi.exit_guard`): finalise the log as for a
        failed FMU (the FMUs are not freed: the process ends inside one of them)."""
        if blocks is not None and blocks.fast is not None:
            blocks.fast.flush()
        failure = f"{message} (after t = {master.time:.3f} s)"
        finish(failure, None, free=False)
        return f"{failure}; log (up to the failure): {log_path}"

    exit_guard.add_hook(fmu_exited)
    try:
        if tables is None:
            master.run(total_steps, after_step)
        else:
            polled = goal_steps if goal_poll is not None else 0
            blocks = _KernelBlocks(built, master, tables, monitor, finish_step)
            blocks.fast = _BlockRecording(built, master, recording, monitor, finish_checks, polled)

            def on_block(first: int, end: int, histories, clean: bool) -> bool:
                return stop(blocks.replay(first, end, histories, clean), clean, master.time)

            def cut_after_python(k: int) -> bool:
                # The block may go on past step k unless step k's end has something to do: a new
                # plan to write, a planner that found no path, a goal to poll for.
                return goal_poll is not None or (
                    planner is not None
                    and (planner.plan_version != plan_version[0] or planner.no_path is not None)
                )

            master.run_blocks(
                total_steps,
                tables,
                on_block,
                block=blocks.block,
                before_block=blocks.watch,
                cut_after_python=cut_after_python,
            )
    except SimulationEnded as request:  # the run ends cleanly; the outcome rules judge it
        state["reason"] = "fmu_terminated"
        ended = str(request)
    except CosimError as error:
        failure = str(error) if " at t = " in str(error) else f"{error} (at t = {master.time:.3f} s)"
    except interrupt.Interrupted:  # a signal while an FMU in a child process did not answer
        take_signal()
        state["reason"] = "interrupted"
    finally:
        exit_guard.remove_hook(fmu_exited)
        if blocks is not None and blocks.fast is not None:
            blocks.fast.flush()  # the steps recorded but not yet handed to the log
    return finish(failure, ended)


def _goal_poll(goals, built: BuiltRun, monitor: OutcomeMonitor, recorder, recording: _Recording):
    """`poll(t_ns, h_ns)`, called after a planner step that started at t_ns: takes the newest goal
    `goals` holds (`take()` -> (x, y) [m] or None) and, unless the robot would not fit there (the
    true obstacles, as the live view shows them) or the planner finds no path to it, makes it the
    goal: the planner replans from the current pose (its new plan goes on /plan as any replan's),
    the outcome monitor judges the new goal (reaching it ends the run), and /goal gets it. A goal
    refused is `goals.report(text)`-ed; the old goal stays and the run goes on. What
    `goals.acknowledged()` returns, if it has it ((name, record) pairs: the live view's commands),
    goes into the log as metadata."""
    planner = built.planner
    radius = built.scenario.vehicle_radius
    acknowledged = getattr(goals, "acknowledged", None)  # the live view's commands, for the log

    def poll(t_ns: int, h_ns: int) -> None:
        take_goal(t_ns, h_ns)
        for name, record in acknowledged() if acknowledged is not None else ():
            recorder.add_metadata(name, record)

    def take_goal(t_ns: int, h_ns: int) -> None:
        goal = goals.take()
        if goal is None:
            return
        x, y = float(goal[0]), float(goal[1])
        t = (t_ns + h_ns) / NS_PER_S
        why = None
        if not (math.isfinite(x) and math.isfinite(y)):
            why = "not a finite position"
        elif planner is None:
            why = "the scenario has no planner"
        elif _world_at(built.world, t).distance(x, y) < radius:
            why = f"in an obstacle or off the map (the vehicle's {radius:g} m radius does not fit)"
        else:
            why = planner.set_goal(x, y, t, recording.pose())
        if why is not None:
            old = monitor.goal
            goals.report(
                f"/goal_pose ({x:.2f}, {y:.2f}) m at t = {t:.2f} s refused: {why}; "
                f"the goal stays ({old[0]:.2f}, {old[1]:.2f}) m"
            )
            return
        monitor.goal = (x, y)
        recorder.write_goal(t_ns, x, y, None)
        goals.report(f"/goal_pose ({x:.2f}, {y:.2f}) m at t = {t:.2f} s: new goal, replanned", warning=False)

    return poll


def _world_at(world, t: float):
    """The true world with its moving obstacles at time t [s]."""
    if getattr(world, "moving", False):
        world.at(t)
    return world


def _use_kernel() -> bool:
    """Whether the run steps its FMUs in the compiled kernel (`Master.run_blocks`); both ways give
    the same log. NAVCOSIM_LOOP=python forces the Python loop (tests compare the two)."""
    import os

    return os.environ.get("NAVCOSIM_LOOP", "kernel") != "python"


class _KernelBlocks:
    """The run loop's side of `Master.run_blocks`: the watched position and the replay of blocks.

    The kernel returns after any step whose position may end the run: not finite, within the
    goal tolerance (plus a margin), or outside a circle around the last checked position that
    the true obstacles cannot reach within the block (the world's distance there, minus the
    vehicle's radius, minus what moving obstacles can cover in a block, minus a margin). So the
    exact checks of `OutcomeMonitor.check_position`, replayed here for every step from the rows
    the kernel kept, can only end the run at the last step of a block, where the kernel stopped.
    """

    def __init__(self, built: BuiltRun, master: Master, tables, monitor, finish_step) -> None:
        scenario = built.scenario
        system = built.system
        self.master = master
        self.monitor = monitor
        self.finish_step = finish_step
        self.tables = tables
        self.components = [component for component, _, _ in master._plan]
        self.periods = [period for _, period, _ in master._plan]
        observed = built.description.observed
        (vehicle_x, x), (vehicle_y, y) = (system.resolve(r, "output") for r in observed.pose[:2])
        self.pose = (vehicle_x.output_buffer, x, vehicle_y.output_buffer, y)
        tables.watch_addresses[:] = (
            1,
            ctypes.addressof(vehicle_x.output_cbuffer) + 8 * x,
            ctypes.addressof(vehicle_y.output_cbuffer) + 8 * y,
        )
        self.radius = scenario.vehicle_radius
        self.world = monitor.world
        self.speed = getattr(self.world, "max_speed", 0.0)
        self.moving = bool(getattr(self.world, "moving", False))
        # Moving obstacles: short blocks, so the reach of the obstacles in one block stays small.
        self.block = 50 if self.speed > 0.0 else 1000
        self.fast: _BlockRecording | None = None  # recording and checks from the rows, when set
        self.h = system.macro_step
        self.anchor: tuple[float, float] | None = None
        # Per component: period, its scalar inputs (a view of the buffer; array inputs are not
        # recorded), where they sit in a row, its outputs, and both as they were after the last
        # step replayed (at first: after initialisation).
        self.parts = []
        for component, period in zip(self.components, self.periods, strict=True):
            slots = [i for i, port in enumerate(component.inputs) if not port.is_array_element]
            if not slots:
                where = slice(0, 0)
            elif slots == list(range(slots[0], slots[-1] + 1)):
                where = slice(slots[0], slots[-1] + 1)
            else:  # scalars between arrays: the whole buffer
                where = slice(0, len(component.inputs))
            inputs = component.input_buffer[where]
            outputs = component.output_buffer
            self.parts.append((period, inputs, where, outputs, inputs.copy(), outputs.copy()))

    def watch(self) -> None:
        """Before a kernel call: the circle around the current position known free of collisions."""
        buffer_x, x, buffer_y, y = self.pose
        x, y = buffer_x.item(x), buffer_y.item(y)
        numbers = self.tables.watch_numbers
        # The goal as the monitor has it now (a hook may move it between blocks).
        goal, tolerance = self.monitor.goal, self.monitor.tolerance
        reach = tolerance + 1e-6 * (1.0 + tolerance)
        numbers[:3] = (goal[0], goal[1], reach * reach)
        if not self.moving and self.anchor is not None:
            # A static world: the circle stays valid; a new one only when half of it is used up.
            anchor_x, anchor_y = self.anchor
            dx, dy = x - anchor_x, y - anchor_y
            if 4.0 * (dx * dx + dy * dy) < numbers[5]:
                return
        self.anchor = (x, y)
        if not (math.isfinite(x) and math.isfinite(y)):
            numbers[3:] = (0.0, 0.0, -1.0)  # every step is checked
            return
        if self.moving:
            self.world.at(self.master.time)
        distance = self.world.lower_bound(x, y)
        if distance - self.radius < 1.0:
            distance = self.world.distance(x, y)
        drift = self.speed * (self.block + 1) * self.h
        free = distance - self.radius - drift - 1e-6 * (1.0 + distance)
        numbers[3:] = (x, y, free * free if free > 0.0 else -1.0)

    def replay(self, first: int, end: int, histories, clean: bool) -> str | None:
        """Steps [first, end): recorded and checked from their rows (`_BlockRecording`), or, for a
        block that needs it, step by step (`replay_steps`)."""
        fast = self.fast
        if fast is None:
            return self.replay_steps(first, end, histories, clean)
        if fast.accepts(first, end, histories):
            return fast.block(first, end, histories, clean)
        if not fast.usable:
            return self.replay_steps(first, end, histories, clean)
        fast.flush()
        rows = {}
        for i, part in enumerate(self.parts):
            if i in fast.buffers:
                _, _, where, outputs, held_inputs, held_outputs = part
                row = fast.held(i)
                held_inputs[:] = row[where]
                held_outputs[:] = row[len(row) - len(outputs) :]
                rows[i] = row
        try:
            return self.replay_steps(first, end, histories, clean)
        finally:
            for i, row in rows.items():
                _, _, where, outputs, held_inputs, held_outputs = self.parts[i]
                row[where] = held_inputs
                row[len(row) - len(outputs) :] = held_outputs

    def replay_steps(self, first: int, end: int, histories, clean: bool) -> str | None:
        """Steps [first, end) as the Python loop's callback sees them: each recorded component's
        buffers (its scalar inputs and its outputs, what the recording reads) are set to what they
        held after each step (its rows, held between its steps), then put back as they are now."""
        live = []
        views = []
        for i, history in enumerate(histories):
            if history is None:
                continue
            period, inputs, row_inputs, outputs, held_inputs, held_outputs = self.parts[i]
            live.append((inputs.copy(), outputs.copy(), i))
            inputs[:] = held_inputs
            outputs[:] = held_outputs
            if len(history):
                # Rows of the block as two 2-D views: the scalar inputs, the outputs.
                input_rows = history[:, row_inputs]
                output_rows = history[:, history.shape[1] - len(outputs) :]
                views.append((period, due_from(first, period), input_rows, output_rows, inputs, outputs))
        reason = None
        try:
            for k in range(first, end):
                for period, first_k, input_rows, output_rows, inputs, outputs in views:
                    if period == 1:
                        inputs[:] = input_rows[k - first_k]
                        outputs[:] = output_rows[k - first_k]
                    elif k % period == 0:
                        j = (k - first_k) // period
                        inputs[:] = input_rows[j]
                        outputs[:] = output_rows[j]
                reason = self.finish_step(k)
                if reason is not None:
                    if k != end - 1 or not clean:
                        raise RuntimeError(
                            f"the compiled loop ran past step {k}, where the run ends ({reason})"
                        )
                    break
        finally:
            for live_inputs, live_outputs, i in live:
                _, inputs, _, outputs, held_inputs, held_outputs = self.parts[i]
                held_inputs[:] = inputs
                held_outputs[:] = outputs
                inputs[:] = live_inputs
                outputs[:] = live_outputs
        return reason


class _BlockRecording:
    """The kernel path's recording and checks, a block of steps at a time (`_KernelBlocks.replay`).

    Within a block only the kernel's components step (a component stepped by Python steps at most
    in the block's first step, and its live buffers hold that step's values to the block's end), so
    what the Python loop's `finish_step` does step by step can be done over the block's rows: the
    positions are checked in one call of `OutcomeMonitor.check_positions` (the same arithmetic,
    step by step, in Python floats), and the rows are copied into buffers that collect the steps of
    several blocks. `flush()` turns
    those steps into their messages with NumPy (signal records, /odom /tf /pose at the pose rate,
    /cmd_vel and the mixer's mode at the mixer's rate; scans and moved obstacles were made at their
    steps) and hands them to `Recorder.hold_steps`, which writes the bytes of the per-step path.
    Steps are flushed every `WINDOWS` chunk windows of simulated time or the recorder's
    `flush_interval` of wall time, whichever comes first (every window with a live view), before
    anything else is written (a new plan, a goal), when the buffers are full, and at the end of the
    run. A block the rows cannot describe (a component stepped by Python due after its first
    step, a topic's first message) is flushed and replayed step by step (`_KernelBlocks`).
    """

    STEPS = 2048  # steps collected at most between two flushes
    WINDOWS = 2  # chunk windows collected at most between two flushes (1 with a live view): 4 s

    def __init__(
        self, built: BuiltRun, master: Master, recording: _Recording, monitor, finish_checks, polled
    ):
        system = built.system
        self.system = system
        self.recording = recording
        self.recorder = recording.recorder
        self.monitor = monitor
        self.finish_checks = finish_checks
        self.polled = polled  # period [steps] of the goal poll, 0 without
        self.components = [component for component, _, _ in master._plan]
        self.periods = [period for _, period, _ in master._plan]
        self.index = {component.name: i for i, component in enumerate(self.components)}
        self.start_ns = master.start_time_ns
        self.h_ns = system.macro_step_ns
        self.window_ns = self.recorder.window_ns
        self.observed = built.description.observed
        self.ready = False
        self.usable = True
        self.first = self.end = None  # steps collected, not yet flushed: [first, end)
        self.handed = time.monotonic()  # [s] wall clock of the last flush
        self.buffers: dict[int, np.ndarray] = {}
        from cosim.record.rosmsg import twist_cdr

        self.twist = twist_cdr

    def _setup(self, histories) -> None:
        """On the first block: which components have rows, the buffers, the message layout."""
        self.ready = True
        recorded = [history is not None for history in histories]
        system, recording = self.system, self.recording
        self.python = [  # stepped by Python: (plan index, period)
            (i, self.periods[i])
            for i, component in enumerate(self.components)
            if not recorded[i] and not component.constant_outputs
        ]

        def where(reference):
            component, slot = system.resolve(reference, "output")
            i = self.index[component.name]
            return i, len(component.inputs) + slot

        observed = self.observed
        needed = (
            list(observed.pose) + list(observed.command or ()) + ([observed.mode] if observed.mode else [])
        )
        if not all(recorded[where(reference)[0]] for reference in needed):
            self.usable = False
            return
        if recording.scan is not None:
            lidar = self.index[observed.scan.component]
            if recorded[lidar]:  # ranges inside the rows: replayed step by step
                self.usable = False
                return
        self.pose_columns = [where(reference) for reference in observed.pose]
        self.command_columns = (
            [where(reference) for reference in observed.command] if observed.command else None
        )
        self.mode_column = where(observed.mode) if observed.mode else None
        # Rows collected: per recorded component, row 0 the last row before the collected steps.
        self.buffers = {}
        for i, component in enumerate(self.components):
            if recorded[i]:
                rows = np.empty(
                    (self.STEPS // self.periods[i] + 3, len(component.inputs) + len(component.outputs))
                )
                rows[0, : len(component.inputs)] = component.input_buffer
                rows[0, len(component.inputs) :] = component.output_buffer
                self.buffers[i] = rows
        self.counts = dict.fromkeys(self.buffers, 0)
        # Per signal record of a step: (slot in the step's order, channel, plan index, columns of a
        # row or None for a component stepped by Python (its record taken from the live buffers)).
        self.entries = []
        for slot, (entry, (component, inputs, outputs)) in enumerate(
            zip(recording.entries, recording.entry_ports, strict=True)
        ):
            i = self.index[component.name]
            columns = None
            if recorded[i]:
                n_in = len(component.inputs)
                columns = np.array(list(inputs) + [n_in + slot_ for slot_ in outputs], dtype=np.intp)
                if np.array_equal(columns, np.arange(n_in + len(component.outputs))):
                    columns = slice(None)
            self.entries.append((slot, entry[1], i, columns, entry))
        slots = len(self.entries)
        self.scan_slot, self.obstacle_slot, self.command_slot, self.pose_slot = (
            slots,
            slots + 1,
            slots + 2,
            slots + 3,
        )
        self.slots = slots + 6
        self.flush_at = 0  # [ns] flush once a step starting at or after it is collected
        self.live = {
            slot: [] for slot, _, i, columns, _ in self.entries if columns is None
        }  # slot -> (k, row)
        # Entries of components stepped by Python: (their records, period, the entry).
        self.live_entries = [
            (self.live[slot], self.periods[i], entry)
            for slot, _, i, columns, entry in self.entries
            if columns is None
        ]
        self.others = []  # (key, t_ns, (topic, payload))

    def accepts(self, first: int, end: int, histories) -> bool:
        """Whether the block [first, end) can be recorded from its rows (else: step by step)."""
        if not self.ready:
            self._setup(histories)
        if not self.usable:
            return False
        # A component stepped by Python steps at most in the block's first step (`run_blocks`
        # ends a block before it is due, and after its step unless `cut_after_python` lets the
        # block go on); its buffers hold that step's values to the end of the block.
        for _, period in self.python:
            if due_from(first + 1, period) < end:
                return False
        if self.polled and due_from(first, self.polled) < end - 1:
            return False
        recording, recorder = self.recording, self.recorder
        if recording.scan is not None:
            period = recording.scan[0]
            if due_from(first + 1, period) < end:
                return False  # a scan after the first step: its ranges are not held
            if not recorder.has_channel("/scan") and first % period == 0:
                return False
        if recording.command is not None and not recorder.has_channel("/cmd_vel"):
            if due_from(first, recording.command[0]) < end:
                return False
        return True

    def block(self, first: int, end: int, histories, clean: bool) -> str | None:
        """Record and check the steps [first, end) from their rows; why the run ends, or None."""
        if self.first is not None and end - self.first > self.STEPS:
            self.flush()
        if self.first is None:
            self.first = first
            if self.window_ns:
                windows = self.WINDOWS if self.recorder.batching else 1
                self.flush_at = (
                    (self.start_ns + first * self.h_ns) // self.window_ns + windows
                ) * self.window_ns
        start_ns, h_ns = self.start_ns, self.h_ns
        before = dict(self.counts)
        for i, rows in self.buffers.items():
            history = histories[i]
            n = len(history)
            if n:
                at = self.counts[i] + 1
                rows[at : at + n] = history
                self.counts[i] += n
        self.end = end
        last = end - 1
        t_last = start_ns + last * h_ns
        # Records of components stepped by Python: due at most at the first step, from live buffers.
        for taken, period, entry in self.live_entries:
            if first % period == 0:
                _, _, first_view, second, gather = entry
                if gather is not None:
                    inputs, input_index, input_part, outputs, output_index, output_part = gather
                    np.take(inputs, input_index, out=input_part, mode="clip")
                    np.take(outputs, output_index, out=output_part, mode="clip")
                    row = first_view.copy()
                else:
                    row = np.concatenate((first_view, second))
                taken.append((first, row))
        recording, recorder = self.recording, self.recorder
        scan = recording.scan
        if scan is not None and first % scan[0] == 0:
            _, buffer, ranges, gather, angles, limits = scan
            t_first = start_ns + first * h_ns
            payload = recorder.scan_payload(
                t_first, angles, ranges if gather is None else buffer[gather], *limits
            )
            self.others.append((first * self.slots + self.scan_slot, t_first, ("/scan", payload)))
        if recording.moving:
            steps = recording.obstacle_steps
            for k in range(due_from(first, steps), end, steps):
                t_ns = start_ns + k * h_ns
                t = t_ns / NS_PER_S
                offsets = tuple(motion.offset(t) for motion in recording.moving)
                if offsets != recording.obstacle_offsets:
                    recording.obstacle_offsets = offsets
                    payload = recorder.obstacles_payload(
                        t_ns, [obstacle.at(t) for obstacle in recording.obstacles]
                    )
                    self.others.append((k * self.slots + self.obstacle_slot, t_ns, ("/obstacles", payload)))
        # The positions after each step, as the monitor checks them.
        (i, column_x), (j, column_y) = self.pose_columns[:2]
        xs = self._values(i, column_x, first, end, before[i])
        ys = self._values(j, column_y, first, end, before[j])
        stop_ns = self.recording.stop_ns
        times = [min(start_ns + (k + 1) * h_ns, stop_ns) / NS_PER_S for k in range(first, end)]
        index, reason = self.monitor.check_positions(times, xs, ys)
        if reason is not None and (index != end - first - 1 or not clean):
            raise RuntimeError(
                f"the compiled loop ran past step {first + index}, where the run ends ({reason})"
            )
        reason = self.finish_checks(last, reason, self.flush)
        if reason is not None or (self.window_ns and t_last >= self.flush_at):
            self.flush()
        elif time.monotonic() - self.handed >= self.recorder.flush_interval:
            self.flush()  # a killed run loses no more wall time of steps than the recorder's flushes
        return reason

    def _values(self, i: int, column: int, first: int, end: int, before: int) -> list[float]:
        """Column `column` of component i after each step in [first, end) (held between its steps)."""
        rows = self.buffers[i]
        period = self.periods[i]
        if period == 1:
            return rows[before + 1 : before + 1 + end - first, column].tolist()
        due = due_from(first, period)
        at = before + 1 + (np.arange(first, end) - due) // period
        return rows[at, column].tolist()

    def _latest(self, i: int, steps: np.ndarray) -> np.ndarray:
        """Row index (in the collected rows of component i) of its values after each of `steps`."""
        period = self.periods[i]
        due = due_from(self.first, period)
        return (steps - due) // period + 1

    def flush(self) -> None:
        """Hand the collected steps to the recorder (and the modes to the monitor)."""
        if self.first is None:
            return
        first, end = self.first, self.end
        start_ns, h_ns, slots = self.start_ns, self.h_ns, self.slots
        recording = self.recording
        signals = []
        for slot, channel, i, columns, _ in self.entries:
            if columns is None:
                taken = self.live[slot]
                if not taken:
                    continue
                steps = np.array([k for k, _ in taken], dtype=np.int64)
                rows = np.array([row for _, row in taken])
                taken.clear()
            else:
                period = self.periods[i]
                n = self.counts[i]
                due = due_from(first, period)
                steps = due + period * np.arange(n, dtype=np.int64)
                rows = self.buffers[i][1 : n + 1]
                rows = rows[:, columns] if not isinstance(columns, slice) else rows
            signals.append((channel, steps * slots + slot, start_ns + steps * h_ns, rows))
        others = self.others
        if recording.command is not None:
            period = recording.command[0]
            steps = np.arange(due_from(first, period), end, period, dtype=np.int64)
            if len(steps):
                (i, column_v), (j, column_omega) = self.command_columns
                v = self.buffers[i][self._latest(i, steps), column_v].tolist()
                omega = self.buffers[j][self._latest(j, steps), column_omega].tolist()
                twist = self.twist
                for k, t_ns, a, b in zip(
                    (steps * slots + self.command_slot).tolist(),
                    (start_ns + steps * h_ns).tolist(),
                    v,
                    omega,
                    strict=True,
                ):
                    others.append((k, t_ns, ("/cmd_vel", twist(a, b))))
        if self.mode_column is not None:
            period, mode_period, _, _ = recording.mode
            steps = np.arange(due_from(first, period), end, period, dtype=np.int64)
            i, column = self.mode_column
            for mode in self.buffers[i][self._latest(i, steps), column].tolist():
                self.monitor.check_mode(mode, mode_period)
        poses = None
        every = recording.pose_steps
        steps = np.arange(due_from(first + 1, every) - 1, end, every, dtype=np.int64)
        if len(steps):
            values = np.empty((len(steps), 5))
            for column, (i, where_) in enumerate(self.pose_columns):
                values[:, column] = self.buffers[i][self._latest(i, steps), where_]
            if self.command_columns is None:
                values[:, 3:] = math.nan
            else:
                for column, (i, where_) in enumerate(self.command_columns, start=3):
                    values[:, column] = self.buffers[i][self._latest(i, steps), where_]
            ends = np.minimum(start_ns + (steps + 1) * h_ns, self.recording.stop_ns)
            poses = (steps * slots + self.pose_slot, ends, values)
        other = None
        if others:
            other = (
                np.array([key for key, _, _ in others], dtype=np.int64),
                np.array([t for _, t, _ in others], dtype=np.int64),
                [message for _, _, message in others],
            )
        self.others = []
        for i, rows in self.buffers.items():
            rows[0] = rows[self.counts[i]]
            self.counts[i] = 0
        self.first = self.end = None
        self.handed = time.monotonic()
        self.recorder.hold_steps(signals, poses, other)

    def held(self, i: int) -> np.ndarray:
        """Component i's row after the last step handed over (flushed)."""
        return self.buffers[i][0]


def progress_bar(stop_time: float):
    """The run's progress bar on stderr (tqdm, erased at the end), counting simulated seconds up to
    `stop_time` [s]; `update_bar` moves it."""
    from tqdm import tqdm

    return tqdm(
        total=round(stop_time, 3),
        unit="s",
        desc="simulated",
        leave=False,
        dynamic_ncols=True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s [{elapsed}{postfix}]",
    )


def update_bar(bar, sim_time: float, wall: float, last_update: list) -> None:
    """Move `bar` to `sim_time` [s] simulated in `wall` [s] of wall time; `last_update[1]` holds
    the simulated time it showed last."""
    bar.update(round(sim_time - last_update[1], 3))
    last_update[1] = sim_time
    if wall > 0:
        bar.set_postfix_str(f"{sim_time / wall:.0f}x real time", refresh=False)
