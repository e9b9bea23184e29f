"""Run a scenario: build, plan, step the master, record every signal to MCAP, decide the outcome.

The data flows scenario -> system -> run loop -> recording -> log. `run_scenario(scenario, out_path)`
builds the system (`cosim.navigation.build`), initialises every component, and only then creates
the log (`cosim.record.system_run.open_recorder`), so bad input never leaves a log behind. The run
(`_RobotRun`) is the base run of any system (`cosim.record.system_run.SystemRun`: header, text
signals, clock, how a loop ends) plus the robot's loop, topics and outcome. The loop stops when the
goal is reached, on a collision, at the stop time, on SIGINT/SIGTERM, or when an FMU fails.

What goes into the log, and when, is the recording's (`cosim.record`): the per-step topics in
`cosim.record.steps` (signals, /odom /tf /pose, /scan, /cmd_vel, /obstacles); here only the
header: metadata `navcosim`, `fmu/<role>`, `outcome`; attachments `scenario.toml` and the map
file(s); `/map`, `/map_inflated`, `/goal`, `/obstacles` and the first `/plan` at t = 0; then `/plan`
at each replan (stamped with the start of the planner step that made it) and `/goal` for each goal
given during the run.

The loop: the FMUs step in the compiled kernel (`Master.run_blocks`, `cosim.core.kernel`), which
keeps their buffers after each step, sweeps a noise-free lidar itself, steps the replanning
planner by its C step (`PlannerComponent.kernel_step`) while no replan can follow, and hands the
Python components (a noisy lidar; the planner where a replan may follow; every planner step in a
run that polls goals) back where they are due; their rows are kept too (`python_rows`), so a
block goes on through their steps, up to 1000 steps. It ends at the end of a step in which one
stepped when that step has something to do (a new plan, no path, a goal poll: `cut_after_python`),
before a Python component's step or a sweep while a topic awaits its first message or when a
signal came (`end_before_python`; once every topic had its first message the sweep returns only
when a signal came, seen on `cosim.core.interrupt.signal_socket`, or the watch needs a new
circle: `KernelTables.poll_on_signals`), and after any step whose position may end the run (not
finite, near the goal, or outside the circle that the true obstacles cannot reach: `SafeCircle`).
Each block goes to the recording (`cosim.record.replay`): recorded and checked from its rows
(`cosim.record.blocks`: the positions of all its steps through `OutcomeMonitor.check_positions`,
the rows turned into messages with NumPy every few chunk windows), or, when the rows cannot describe
it, replayed step by step through `finish_step`, as the Python loop's per-step callback does. Either
way the log and the outcome are the same bytes and numbers, and the run ends at the same step.
Hooks: `finish_step(k)` once per step (Python loop, blocks replayed step by step), `finish_checks`
(goal poll, new plan) after a step's position check in both, `on_block` once per block (kernel;
interrupts are noticed there, at most one block late), `SafeCircle.watch` before each kernel call
(it re-reads the monitor's goal). A system the kernel cannot step (Jacobi mode with Python
components) and NAVCOSIM_LOOP=python use the master's Python loop with the per-step callback.

End of a run: a normal end, an interrupt (outcome reason "interrupted") and an FMU failure
(reason "fmu_failed": an error status, a crash, exit() or hang of an FMU in a child process, a NaN
output; metadata `outcome.failure` holds the message) all finalise the log at its path, readable
up to the last completed step. Any other error after the log was created finalises it and renames
it `<name>.failed.mcap`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from cosim import release_collector
from cosim.core import interrupt
from cosim.core.master import Master
from cosim.core.timebase import NS_PER_S
from cosim.errors import PATH_LIMIT, CosimError, shorten
from cosim.fmi import exit_guard
from cosim.navigation.build import BuiltRun, build_run
from cosim.navigation.outcome import Outcome, OutcomeMonitor, SafeCircle, outcome_metadata
from cosim.record.blocks import BlockRecording
from cosim.record.logfile import is_regular_file
from cosim.record.replay import BlockReplay
from cosim.record.steps import StepRecording
from cosim.record.system_run import (
    SystemRun,
    close_quietly,
    initialize_or_close,
    open_recorder,
    run_guarded,
    scenario_attachments,
    update_bar,
    writing_failed,
)
from cosim.scenario.load import Scenario
from cosim.world.imu import Imu


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


def _write_header(built: BuiltRun, steps: SystemRun) -> None:
    """Metadata, attachments and the once-only topics at t = 0."""
    scenario, recorder = built.scenario, steps.recorder
    x, y, theta = scenario.start
    details = {
        "start": f"{x},{y},{theta}",
        "goal": f"{scenario.goal[0]},{scenario.goal[1]}",
        "goal_tolerance": str(scenario.goal_tolerance),
        "macro_step": str(scenario.macro_step),
        "stop_time": str(scenario.stop_time),
        "overrides": " ".join(scenario.overrides),
        "master": scenario.master,
        "topics": ",".join(f"{topic}={name}" for topic, name in scenario.topics.items()),
    }
    attachments = scenario_attachments(scenario.text, scenario.map_file)
    components = built.system.components.values()
    steps.write_header(scenario.name, details, components, scenario.fmu_labels, attachments)
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
    trace: bool | None = None,
) -> RunResult:
    """Run `scenario`, logging to `out_path` (default: `[output].log`). Raises `CosimError` on bad input.
    `sink` (`cosim.record.live.Sink`, e.g. the live view) also gets everything the log gets.
    `goals` (`cosim.record.live.GoalSource`, e.g. the live view's /goal_pose) gives new goals during
    the run (`_goal_poll`). `trace`: keep what the default plot draws in memory (`RunResult.trace`;
    default: when the scenario's [output].plot asks for a plot); without it the run's memory does
    not grow with simulated time.

    An existing `out_path` is refused unless `force`; a default name that is taken gets a numbered
    suffix (`cosim.record.logfile`). SIGINT/SIGTERM before the log exists raise
    `cosim.core.interrupt.Interrupted` (nothing written); after, they stop the run at the next step
    with outcome "interrupted" and a finalised log.
    """
    if out_path is not None and not force and is_regular_file(Path(out_path)):
        # Checked again, race-free, when the log is created; here to fail before the build.
        raise CosimError(f"{shorten(out_path, PATH_LIMIT)}: already exists; give --force to overwrite it")
    with interrupt.catching_signals():
        keep = scenario.plot if trace is None else trace
        return _build_and_run(scenario, out_path, force, progress, flush_interval, sink, goals, keep)


def _build_and_run(
    scenario: Scenario,
    out_path,
    force: bool,
    progress: bool,
    flush_interval: float,
    sink=None,
    goals=None,
    trace: bool = True,
) -> RunResult:
    built = build_run(scenario)
    master = Master(built.system, parameters=built.parameters, stop_time=scenario.stop_time)
    initialize_or_close(master, scenario.source)
    with interrupt.deferred():
        try:
            recorder = open_recorder(
                out_path,
                force,
                scenario.name,
                scenario.log_pattern,
                flush_interval=flush_interval,
                sink=sink,
                topics=scenario.topics,
                trace=trace,
            )
            log_path = recorder.path
        except BaseException:
            close_quietly(master)
            raise
        try:
            return _RobotRun(built, master, recorder, progress, goals).run()
        except OSError as error:
            # The log could not be written (no space, I/O error): what reached the file stays.
            close_quietly(master, recorder)
            raise CosimError(writing_failed(error, log_path)) from None
        except BaseException:
            # Neither a normal end, an interrupt nor an FMU failure: keep the log, but marked.
            close_quietly(master, recorder, {"reached": "false", "reason": "error"})
            if is_regular_file(log_path):
                log_path.replace(log_path.with_suffix(".failed.mcap"))
            raise


class _RobotRun(SystemRun):
    """One robot run, from the header to the finalised log: the base run (`SystemRun`: the
    recorder, the text signals, the clock and progress bar, how a run's loop ends) plus the robot's
    loop: the master steps (the compiled kernel's blocks, or the Python loop), the recording writes
    each step (`StepRecording`, `BlockRecording`), the outcome monitor judges it, the planner's new
    plans and the goals given during the run are taken between steps, and `finish` ends the run
    whatever ended it."""

    def __init__(self, built: BuiltRun, master: Master, recorder, progress: bool, goals=None):
        super().__init__(master, recorder)
        scenario = built.scenario
        system = built.system
        self.built, self.goals = built, goals
        # The robot's side first: the outcome, the replanning planner, the goals given during the run.
        self.monitor = OutcomeMonitor(
            built.world, scenario.goal, scenario.goal_tolerance, scenario.vehicle_radius, scenario.start
        )
        planner = built.planner
        self.planner = planner if planner is not None and not planner.constant_outputs else None
        self.plan_version = self.planner.plan_version if self.planner is not None else 0
        # New goals during the run (the live view's /goal_pose), polled at the planner's rate.
        self.goal_poll = None
        if goals is not None:
            self.goal_poll = _goal_poll(
                goals, built, self.monitor, recorder, lambda: self.recording.current_pose()
            )
        self.goal_steps = system.period_steps(planner) if self.goal_poll is not None and planner else 1
        if self.goal_poll is not None and self.planner is not None:
            # A goal polled after a planner step may replan at once: every step of the planner is
            # Python's, so the kernel's block ends after it (`cut_after_python`).
            self.planner.kernel_steps = False
        # Then the recording: the signal channels, the header, the first records.
        sensors = () if scenario.imu is None else (Imu(scenario.imu, scenario.macro_step),)
        self.recording = StepRecording(
            system, master, recorder, built.description.observed, scenario, sensors
        )
        _write_header(built, self)
        self.begin()
        self.recording.write_constant(master.start_time_ns)
        self.recording.write_pose(0)
        if scenario.bumper:
            recorder.write_bool("/bumper", 0, False)
        # Build (or load) the C kernels that would first run inside the loop, so the real-time factor
        # measures the simulation, not a first run's compilation.
        self.monitor.world.distance(*scenario.start[:2])
        self.tables = None
        if _use_kernel():
            self.tables = master.kernel_tables(record=True, python_rows=True, scalar_rows=True)
        if self.tables is not None:
            self.tables.warm_up()
        self.start_clock(scenario.stop_time if progress else None)
        self.start_ns = master.start_time_ns
        self.h_ns = system.macro_step_ns
        self.reason: str | None = None  # why the loop stopped
        self.replay: BlockReplay | None = None
        self.signal: str | None = None  # a signal taken at a kernel hand-back, for `stop`
        self.settled = False  # every topic had its first message (`BlockRecording.settled`)

    def finish_step(self, k: int) -> str | None:
        """Record what step k produced and check the outcome; why the run ends after it, or None."""
        recording, monitor = self.recording, self.monitor
        t_ns = self.start_ns + k * self.h_ns
        recording.after_step(k, t_ns, self.h_ns)
        mode = recording.mode
        if mode is not None and k % mode.period == 0:
            monitor.check_mode(mode.mode.value(), mode.period_s)
        end_ns = min(t_ns + self.h_ns, self.master.stop_time_ns)  # a last step cut short ends at the stop
        x, y, _ = recording.pose
        reason = monitor.check_position(end_ns / NS_PER_S, x.value(), y.value())
        return self.finish_checks(k, reason)

    def finish_checks(self, k: int, reason: str | None, before_write=None) -> str | None:
        """The end of step k after its position check: a new goal, a new plan (`before_write()`
        first when either may write to the log); why the run ends after it, or None."""
        t_ns = self.start_ns + k * self.h_ns
        if self.goal_poll is not None and reason is None and k % self.goal_steps == 0:
            if before_write is not None:
                before_write()
            self.goal_poll(t_ns, self.h_ns)
        planner = self.planner
        if planner is not None:
            if planner.plan_version != self.plan_version:
                if before_write is not None:
                    before_write()
                self.plan_version = planner.plan_version
                self.recorder.write_path(t_ns, planner.result.path)  # the plan made in step k
            self.monitor.outcome.replans = len(planner.replans)
            if reason is None and planner.no_path is not None:
                self.monitor.outcome.no_path = planner.no_path
                reason = "no_path"
        return reason

    def stop(self, reason: str | None, poll_signal: bool, sim_time: float) -> bool:
        """After a step (Python loop) or a block (kernel): whether the run ends, and why."""
        if reason is None and poll_signal:
            signal, self.signal = self.signal or interrupt.take(), None
            if signal is not None:
                reason = "interrupted"
        self.show_progress(sim_time)
        if reason is not None:
            self.reason = reason
            return True
        return False

    def after_step(self, master: Master) -> bool:
        """The Python loop's per-step callback."""
        return self.stop(self.finish_step(master.step_index - 1), True, master.time)

    def on_block(self, first: int, end: int, histories, clean: bool) -> bool:
        """The kernel's per-block callback."""
        return self.stop(self.replay.replay(first, end, histories, clean), clean, self.master.time)

    def end_before_python(self, k: int) -> bool:
        """Whether a kernel block ends before the Python components of step k (a block goes on
        through them otherwise): when a signal came, so the run stops where it always did, and
        while a topic has yet to get its first message (as `cut_after_python`: the planner's C
        step hands no step back to be cut after)."""
        if self.signal is None:
            self.signal = interrupt.take()
        if self.signal is not None:
            return True
        if not self.settled:  # (once settled, always: a topic's channel stays)
            self.settled = self.replay.fast.settled
            if self.settled:  # from now on only a signal ends a block here: the kernel sees it come
                self.tables.poll_on_signals(interrupt.signal_socket())
        return not self.settled

    def cut_after_python(self, k: int) -> bool:
        """Whether a kernel block ends after step k, in which a Python component stepped: when the
        step's end has something to do (a new plan to write, a planner that found no path, a goal
        to poll for), and while a topic has yet to get its first message (`BlockRecording.settled`)."""
        planner = self.planner
        return (
            self.goal_poll is not None
            or not self.replay.fast.settled
            or (
                planner is not None
                and (planner.plan_version != self.plan_version or planner.no_path is not None)
            )
        )

    def loop(self) -> None:
        """Step to the stop time, or until the run ends: the kernel's blocks, or the Python loop."""
        master = self.master
        total_steps = master.steps_to_stop  # the last one ends at the stop time
        if self.tables is None:
            master.run(total_steps, self.after_step)
            return
        built = self.built
        observed = built.description.observed
        radius = built.scenario.vehicle_radius
        watch = SafeCircle(built.system, master, self.tables, self.monitor, observed.pose[:2], radius)
        polled = self.goal_steps if self.goal_poll is not None else 0
        fast = BlockRecording(
            built.system, master, self.recording, observed, self.monitor, self.finish_checks, polled
        )
        self.replay = BlockReplay(master, self.finish_step, fast)
        master.run_blocks(
            total_steps,
            self.tables,
            self.on_block,
            block=watch.block,
            before_block=watch.watch,
            cut_after_python=self.cut_after_python,
            end_before_python=self.end_before_python,
        )

    def run(self) -> RunResult:
        master = self.master

        def describe(error: CosimError) -> str:
            return str(error) if " at t = " in str(error) else f"{error} (at t = {master.time:.3f} s)"

        exit_guard.add_hook(self.fmu_exited)
        try:
            end = run_guarded(self.loop, describe)
        finally:
            exit_guard.remove_hook(self.fmu_exited)
            self.flush()  # the steps recorded but not yet handed to the log
        if end.ended is not None:
            self.reason = "fmu_terminated"  # the run ends cleanly; the outcome rules judge it
        elif end.interrupted:
            self.reason = "interrupted"
        result = self.finish(end.failure, end.ended)
        if self.tables is not None:  # the loop is over: its record buffer may serve the next run
            self.replay = None
            self.tables.release()
        return result

    def flush(self) -> None:
        """Hand the steps the block recording holds to the log."""
        if self.replay is not None and self.replay.fast is not None:
            self.replay.fast.flush()

    def finish(self, failure: str | None, ended: str | None, free: bool = True) -> RunResult:
        """The end of the run: the last pose, the outcome, the log finalised (`free`: and the
        system closed)."""
        master, recorder, recording, monitor, bar = (
            self.master,
            self.recorder,
            self.recording,
            self.monitor,
            self.bar,
        )
        scenario = self.built.scenario
        wall_time = self.wall_time
        end_ns = master.time_ns
        # The pose at end_ns is the vehicle's after the last completed step (after a failure too; the
        # after_step of that step wrote it already when end_ns is on the pose grid). A pose that turned
        # NaN in the failed step is not logged.
        if master.step_index % recording.pose_steps != 0 and all(
            map(math.isfinite, recording.current_pose())
        ):
            recording.write_pose(end_ns)
        if scenario.bumper and monitor.outcome.reason == "collision":  # the footprint touched at end_ns
            recorder.write_bool("/bumper", end_ns, True)
        self.end_steps()
        reason = "fmu_failed" if failure else self.reason or "stop_time"
        outcome = monitor.finish(end_ns / NS_PER_S, reason)
        if bar is not None:
            update_bar(bar, master.time, wall_time, self.last_update)
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
        if free:
            failure = self.close_master(failure, lambda error: f"terminating the system failed: {error}")
        for name, record in getattr(self.goals, "acknowledged", tuple)():  # the live view's last commands
            recorder.add_metadata(name, record)
        recorder.close(metadata)
        return RunResult(outcome, recorder.path, master.step_index, wall_time, failure, recorder.trace, ended)

    def fmu_exited(self, message: str) -> str:
        """An FMU in this process called exit() (`cosim.fmi.exit_guard`): finalise the log as for a
        failed FMU (the FMUs are not freed: the process ends inside one of them)."""
        if self.master.deliver_pending is not None:  # the kernel's steps before the one under way
            self.master.deliver_pending()
        self.flush()
        failure = f"{message} (after t = {self.master.time:.3f} s)"
        self.finish(failure, None, free=False)
        return f"{failure}; log (up to the failure): {self.recorder.path}"


def _goal_poll(goals, built: BuiltRun, monitor: OutcomeMonitor, recorder, pose):
    """`poll(t_ns, h_ns)`, called after a planner step that started at t_ns: takes the newest goal
    `goals` holds (`take()` -> (x, y) [m] or None) and, unless the robot would not fit there (the
    true obstacles, as the live view shows them) or the planner finds no path to it, makes it the
    goal: the planner replans from the current pose (its new plan goes on /plan as any replan's),
    the outcome monitor judges the new goal (reaching it ends the run), and /goal gets it. A goal
    refused is `goals.report(text)`-ed; the old goal stays and the run goes on. What
    `goals.acknowledged()` returns, if it has it ((name, record) pairs: the live view's commands),
    goes into the log as metadata. `pose()`: the robot's pose (x, y [m], theta [rad]) now."""
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
            why = planner.set_goal(x, y, t, pose())
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
