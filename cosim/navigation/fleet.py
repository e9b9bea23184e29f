"""Run a fleet: every robot's system stepped together, robots seeing and touching each other.

`run_fleet(fleet)` builds each robot as the single-robot run builds it (`build_run` with the
robot's description from `cosim.scenario.fleet_compose.describe_fleet`: its lidar has the inputs
`robots_x[j]`, `robots_y[j]`), puts every robot's components into ONE `System` (`fleet_system`:
components `robot1:vehicle`, ..., the robots' own connections, and the links
`robot2:vehicle.x -> robot1:lidar.robots_x[1]` by which the robots see each other) and steps it
with one `Master`, a block of steps at a time. A block is the greatest common divisor of every
robot's lidar and planner periods (10 steps for the template's 10 Hz lidar at 100 Hz), so Python
components step only in a block's first step:

1. the lidars read the vehicles' poses, which are states (no direct dependency on the vehicles'
   inputs), so the master steps every lidar before any vehicle: each scan at t sees every robot
   where it stands at t, whatever the robots' order;
2. the master steps the block (FMUs in the compiled kernel, `Master.run_blocks`; lidars and
   planners in its first step, all in one C call (`_BlockProgram`: the sweeps, the planners' C
   steps `PlannerComponent.kernel_step`) handing back what needs Python), keeping each step's
   rows of every component: every Python component first, then every FMU through the whole block
   in one kernel call
   (`_PythonSteps`), when no FMU a Python component reads or feeds comes before it in the
   master's order (the same values as the kernel handing each back where it is due);
3. then, step by step through the block, the footprints are checked pairwise
   (`cosim.world.fleet.FleetContacts`: exact first contact of circles moving linearly within
   the step), and each robot against the walls and unknown obstacles (`OutcomeMonitor`, exactly
   as for one robot); with on_collision = "continue" (nothing but the robots' own ends ends the
   run) a robot at a time for the block's steps (every robot in a static world in one C call,
   `_FleetJudge`), and the pairs for all of them at once, with the same arithmetic in the same
   order;
4. mission progress: a robot within its goal's tolerance has reached it; after its `dwell` the
   planner is given the next goal (`PlannerComponent.set_goal`, a replan from the current pose)
   at the end of that block (at most one block, 0.1 s, later); after the last goal (times
   `repeat`) the robot has completed and stays where it is (still an obstacle for the others).

With `[fleet] coordination` other than "none", or a robot's `stop`, `FleetCoordination` (in
`cosim.navigation.coordination`) acts before every block: it hands each robot's planner component
the cells its action dependency graph releases (or holds a stopped robot), and a mission's next
goal is a re-solve of all robots' paths instead of a replan.

The run ends when every robot has completed, at the stop time, or at the first collision when
`[fleet] on_collision = "stop"` (robot-robot contact, or a robot hitting a wall or obstacle). With
"continue" every robot-robot contact is reported once when it begins and the run goes on; a
robot that hit a wall or obstacle has failed: it is no longer judged, and at the end of that block
(at most 0.1 s later) it is switched off (`_halt`: its components are no longer stepped), so it
stays where it stands, an obstacle the others' lidars see. (Only the compiled kernel can leave
components out: a fleet it cannot step, Jacobi with Python components, runs such a robot on.)

Deadlock: a robot that has not completed and has come no closer than 0.5 m to its current goal
than its best for `[fleet] deadlock_after` seconds (dwelling at a goal excluded) is deadlocked from
the start of that period; it stays deadlocked unless it makes progress again (then the period
counts anew). The fleet outcome counts robots deadlocked at the end.

A run that ends inside a block ends at that step: the fleet's system has advanced to the block's
end, but nothing after the step is judged or logged. The log (`cosim.navigation.fleet_log`) is the
base run's (`cosim.record.system_run`) with every robot recorded as the single-robot run records
one, under its namespace: `/robot1/signals/<component>`, `/robot1/scan`, `/robot1/cmd_vel`,
`/robot1/odom`, ..., one TF tree `map -> robot1/odom -> robot1/base_link`, goals, plans and the
fleet outcome.
"""

from __future__ import annotations

import ctypes
import functools
import gc
import math
import struct
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim import release_collector
from cosim.core import interrupt
from cosim.core.component import Component
from cosim.core.gather import Snapshot, make_gather
from cosim.core.master import NS_PER_S, Master
from cosim.core.system import System
from cosim.core.timebase import due_from
from cosim.errors import PATH_LIMIT, CosimError, shorten
from cosim.navigation.build import build_run
from cosim.navigation.coordination import FleetCoordination
from cosim.navigation.fleet_log import FleetLog
from cosim.navigation.outcome import MODE_RECOVER, OutcomeMonitor
from cosim.record.blocks import column_runs
from cosim.record.logfile import is_regular_file
from cosim.record.system_run import (
    close_quietly,
    initialize_or_close,
    open_recorder,
    run_guarded,
    writing_failed,
)
from cosim.scenario.fleet import Fleet
from cosim.scenario.fleet_compose import POSE_OF, SEEN_BY, describe_fleet
from cosim.world.fleet import Contact, FleetContacts

PROGRESS = 0.5  # [m] closer to the current goal than the best so far: progress (deadlock rule)
STOPPED_SPEED = 0.01  # [m/s] below this a robot counts as stopped
# From this many plain links from components the kernel steps, a Python component's inputs are
# copied from one snapshot of their outputs in one index copy (`_PythonSteps.make`), not one by one.
_SNAPSHOT_LINKS = 16


@dataclass
class RobotOutcome:
    """One robot's run. status: running, completed, collision (with a wall or obstacle; robot
    contacts are in the fleet's `collisions`), no_path, stop_time (still running at the stop
    time), stopped (still running when the run ended otherwise: the first collision with
    on_collision = "stop", an interrupt)."""

    name: str
    status: str = "running"
    goals_reached: int = 0
    goals: int = 0  # goals of the mission, times repeat
    completion_time: float | None = None  # [s] when the last goal was reached
    distance: float = 0.0  # [m]
    min_clearance_walls: float = math.inf  # [m] footprint to the true map and obstacles
    min_clearance_robots: float = math.inf  # [m] footprint to footprint
    stopped_time: float = 0.0  # [s] slower than STOPPED_SPEED while not completed or dwelling
    recovery_time: float = 0.0  # [s] in the mixer's recover mode
    deadlocked_at: float | None = None  # [s] start of the no-progress period that made it deadlocked
    collision: tuple[float, float, float] | None = None  # (t [s], x, y [m]) of hitting a wall or obstacle


@dataclass
class FleetOutcome:
    robots: list[RobotOutcome]
    collisions: list[Contact] = field(default_factory=list)
    time: float = 0.0  # [s] simulated when the run ended
    reason: str = (
        "running"  # completed, collision, stop_time, all_ended (none still running, not all completed)
    )
    wall_time: float = 0.0  # [s]
    failure: str | None = None  # the message of a failed FMU (reason fmu_failed)
    # [fleet] coordination's planning: method, solves, failures (solves without a plan), planning_time
    # [s of wall]; None without a coordinator
    coordination: dict | None = None

    @property
    def completed(self) -> bool:
        return all(robot.status == "completed" for robot in self.robots)

    @property
    def makespan(self) -> float | None:
        """[s] until the last robot completed (None unless all did)."""
        return max(robot.completion_time for robot in self.robots) if self.completed else None

    @property
    def deadlocks(self) -> list[RobotOutcome]:
        return [
            robot for robot in self.robots if robot.deadlocked_at is not None and robot.status != "completed"
        ]

    @property
    def throughput(self) -> float:
        """Goals reached per hour of simulated time."""
        return (
            sum(robot.goals_reached for robot in self.robots) * 3600.0 / self.time if self.time > 0 else 0.0
        )

    @property
    def exit_code(self) -> int:
        """0 only when every robot completed its goal or mission; 2 when an FMU failed."""
        if self.failure is not None:
            return 2
        return 0 if self.completed else 1


class Progress:
    """The deadlock rule for one robot (module docstring): `update(t, remaining)` with its distance
    [m] to its current goal after the step that ended at t [s] returns the time since which it is
    deadlocked, or None; `restart(t, remaining)` when it gets a new goal (or dwells)."""

    def __init__(self, deadlock_after: float, t: float, remaining: float) -> None:
        self.deadlock_after = deadlock_after
        self.restart(t, remaining)

    def restart(self, t: float, remaining: float) -> None:
        self.best, self.best_time, self.deadlocked_at = remaining, t, None

    def update(self, t: float, remaining: float) -> float | None:
        if remaining < self.best - PROGRESS:
            self.best, self.best_time, self.deadlocked_at = remaining, t, None
        elif self.deadlocked_at is None and t - self.best_time >= self.deadlock_after - 1e-9:
            self.deadlocked_at = self.best_time
        return self.deadlocked_at


class _Robot:
    """One robot of the run: its built components (in the fleet's system), where the fleet's block
    rows hold its pose, command and mode, its mission and its outcome."""

    def __init__(self, robot, built, deadlock_after: float) -> None:
        self.robot = robot
        self.built = built
        system = built.system  # the robot's own system: its components, ports and periods
        vehicle, self.slot_x = system.resolve(f"{POSE_OF}.x", "output")
        _, self.slot_y = system.resolve(f"{POSE_OF}.y", "output")
        self.vehicle_outputs = vehicle.output_buffer
        observed = built.description.observed
        mode = observed.mode if observed else None
        self.mode = system.resolve(mode, "output") if mode else None
        self.theta = system.resolve(f"{POSE_OF}.theta", "output")[1]
        self.commands = (
            [system.resolve(r, "output") for r in observed.command] if observed and observed.command else None
        )
        self.goals = [goal for _ in range(robot.repeat) for goal in robot.mission]
        self.goal_index = 0
        self.dwell_until: float | None = None
        scenario = robot.scenario
        self.monitor = OutcomeMonitor(
            built.world, scenario.goal, scenario.goal_tolerance, scenario.vehicle_radius, scenario.start
        )
        self.outcome = RobotOutcome(robot.name, goals=len(self.goals))
        remaining = math.hypot(scenario.goal[0] - scenario.start[0], scenario.goal[1] - scenario.start[1])
        self.progress = Progress(deadlock_after, 0.0, remaining)
        self.logged_goal = scenario.goal
        self.pending_goal = False
        self.logged_plan = 0
        self.vehicle = vehicle
        self.vehicle_row = -1  # where the fleet's block rows hold the vehicle's, set by `place`
        self.vehicle_period = system.period_steps(vehicle)
        inputs = len(vehicle.inputs)
        self.pose_columns = _columns([inputs + vehicle.output_index[axis] for axis in ("x", "y", "theta")])
        command = [vehicle.input_index.get(port) for port in ("v", "omega")]
        self.command_columns = _columns(command) if None not in command else None
        self.mode_row = None
        if self.mode is not None:
            component, slot = self.mode
            self.mode_row = [component, len(component.inputs) + slot, system.period_steps(component)]
        self.poses = np.empty((0, 3))
        self.commands_now = np.empty((0, 2))
        self.modes = np.empty(0)
        self._last = (np.array(self.pose, dtype=float), np.array(self.command, dtype=float), math.nan)
        self.halted = False  # switched off after hitting a wall or obstacle (`_halt`)

    def place(self, order: list) -> None:
        """Where the fleet system's block rows (components in `order`) hold this robot's."""
        self.vehicle_row = next(i for i, component in enumerate(order) if component is self.vehicle)
        if self.mode_row is not None:
            component = self.mode_row[0]
            self.mode_row[0] = next(i for i, c in enumerate(order) if c is component)

    def take(self, histories: list[np.ndarray], first: int, count: int) -> None:
        """Keep, from the rows of the block of `count` steps from step `first`, for each step the
        pose at its end, the command applied in it and the avoidance mode."""
        if self._last is None:  # after a block taken by `_BlockRows` (arrays of their own)
            self._last = (self.poses[-1], self.commands_now[-1], self.modes[-1])
        last_pose, last_command, last_mode = self._last
        if self.halted:  # not stepped: where it stopped, commanding nothing
            self.poses = np.tile(last_pose, (count, 1))
            self.commands_now = np.zeros((count, 2))
            self.modes = np.full(count, math.nan)
            self._last = (last_pose, np.zeros(2), math.nan)
            return
        vehicle = histories[self.vehicle_row]
        self.poses = _held(vehicle[:, self.pose_columns], first, count, self.vehicle_period, last_pose)
        if self.command_columns is not None:
            self.commands_now = _held(
                vehicle[:, self.command_columns], first, count, self.vehicle_period, last_command
            )
        else:
            self.commands_now = np.full((count, 2), math.nan)
        if self.mode_row is not None:
            row, column, period = self.mode_row
            modes = _held(histories[row][:, column : column + 1], first, count, period, np.array([last_mode]))
            self.modes = modes[:, 0]
        else:
            self.modes = np.full(count, math.nan)
        # Copies: the rows may be views of buffers the next block refills (`_columns`).
        self._last = (self.poses[-1].copy(), self.commands_now[-1].copy(), self.modes[-1])

    @property
    def position(self) -> tuple[float, float]:
        return float(self.vehicle_outputs[self.slot_x]), float(self.vehicle_outputs[self.slot_y])

    @property
    def pose(self) -> tuple[float, float, float]:
        return (*self.position, float(self.vehicle_outputs[self.theta]))

    @property
    def command(self) -> tuple[float, float]:
        if self.commands is None:
            return math.nan, math.nan
        (a, i), (b, j) = self.commands
        return float(a.output_buffer[i]), float(b.output_buffer[j])

    @property
    def judged(self) -> bool:
        return self.outcome.status == "running"


def run_fleet(
    fleet: Fleet,
    trace: list | None = None,
    log_path: Path | None = None,
    *,
    force: bool = False,
    progress: bool = False,
    sink=None,
    goals=None,
) -> FleetOutcome:
    """Run `fleet` (module docstring); `CosimError` on bad input (before anything runs). `trace`,
    when given, gets (t [s], positions (N x 2) [m]) at the start and after every step; `log_path`
    gets the fleet's log (`cosim.navigation.fleet_log`; an existing file only with `force`), with a
    progress bar on stderr when `progress`; `sink` (`cosim.record.live.Sink`, the live view) gets
    everything the log gets, and `goals` (`cosim.record.live.GoalSource`) is answered that a
    fleet takes no goals. A failed FMU or SIGINT/SIGTERM ends the run with reason "fmu_failed"
    (`FleetOutcome.failure`) or "interrupted", the log finalised."""
    if log_path is not None and not force and is_regular_file(Path(log_path)):
        # Checked again, race-free, when the log is created; here to fail before the build.
        raise CosimError(f"{shorten(log_path, PATH_LIMIT)}: already exists; give --force to overwrite it")
    with interrupt.catching_signals():
        with _collector_paused():  # the build (`_collector_paused`)
            described = describe_fleet(fleet)
            robots = [
                _Robot(
                    robot,
                    build_run(robot.scenario, described.robots[robot.name]),
                    fleet.settings.deadlock_after,
                )
                for robot in fleet.robots
            ]
            system, parameters = fleet_system(fleet, described, [each.built for each in robots])
            coordination = FleetCoordination.make(fleet, robots)  # None: "none" and no stops
            master = Master(system, parameters=parameters, stop_time=fleet.first.stop_time)
            initialize_or_close(master, fleet.source)
        release_collector()  # the loop starts: the collector is on again (`cosim.hold_collector`)
        for each in robots:
            each.place(master.order)
        outcome = FleetOutcome([each.outcome for each in robots])
        if log_path is None:
            try:
                _run(fleet, master, robots, trace, None, outcome, coordination)
            finally:
                close_quietly(master)
            return outcome
        with interrupt.deferred():
            try:
                recorder = open_recorder(log_path, force, fleet.name, sink=sink, trace=False)
            except BaseException:
                close_quietly(master)
                raise
            try:
                stop_time = fleet.first.stop_time if progress else None
                log = FleetLog(master, recorder, fleet, robots, stop_time, goals)
                end = run_guarded(
                    lambda: _run(fleet, master, robots, trace, log, outcome, coordination),
                    lambda error: f"{error} (at t = {master.time:.3f} s)",
                )
                if end.failure is not None:
                    outcome.reason, outcome.failure = "fmu_failed", end.failure
                elif end.ended is not None:
                    outcome.reason = "fmu_terminated"
                elif end.interrupted:
                    outcome.reason = "interrupted"
                outcome.failure = log.close_master(
                    outcome.failure, lambda e: f"terminating the system failed: {e}"
                )
                log.close(outcome, round(outcome.time * NS_PER_S))
            except OSError as error:
                close_quietly(master, recorder)
                raise CosimError(writing_failed(error, Path(log_path))) from None
            except BaseException:
                close_quietly(master, recorder)
                raise
        return outcome


def core_name(robot: str, component: str) -> str:
    """A robot's component in the fleet's `System`: `robot1:vehicle`. The core reads a reference
    `component.port` up to its first dot, so the description's `robot1.vehicle` is spelt with a
    colon there (a slash would make FMU temporary folders nested paths)."""
    return f"{robot}:{component}"


@contextmanager
def _collector_paused():
    """No cyclic garbage collection while a fleet is built (each robot described, built, the fleet's
    system made and initialised): ~10^6 objects that live as long as the run (every robot's ports,
    connections, links), which the young-generation collections walked again and again, finding
    almost nothing (~1.5 s of CPU of a 50-robot build, a third of it). Afterwards what was made
    joins the oldest generation at once (`gc.freeze` then `gc.unfreeze`, unless objects are frozen
    already: those stay so) rather than being walked by the young collections once more (~0.3 s),
    and the collector is on again if it was (`cosim run` holds it already: `cosim.hold_collector`)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            if gc.get_freeze_count() == 0:
                gc.freeze()
                gc.unfreeze()
            gc.enable()


def fleet_system(fleet: Fleet, described, builts: list) -> tuple[System, dict]:
    """One `System` of every robot's components (`core_name`), connections and the links between
    robots, and the FMU parameters by component; the components are those `build_run` made."""
    first = fleet.first
    system = System(first.macro_step, first.master, first.algebraic_loops, first.loop_tolerance,
                    first.loop_max_iterations)  # fmt: skip
    parameters: dict[str, dict[str, float]] = {}
    for robot, built in zip(fleet.robots, builts, strict=True):
        system.merge(built.system, core_name(robot.name, ""))  # checked when `build_run` connected them
        for name, values in built.parameters.items():
            parameters[core_name(robot.name, name)] = values
    system.connect_many(
        (link.source.replace(".", ":", 1), link.target.replace(".", ":", 1), link.scale, link.offset)
        for link in described.links
    )
    for component in system.components.values():
        system.period_steps(component)
    return system, parameters


class _PythonSteps:
    """The fleet's components stepped by Python (lidars, planners), stepped here at a block's first
    step (`step`), all of them before the compiled kernel steps the FMUs through the whole block in
    one call: the kernel's tables skip them (as components with constant outputs: the kernel neither
    steps them nor copies their outputs), so after they stepped their outputs are copied into the
    FMUs that read them (`feeds`, the master's arithmetic), and hold to the block's end as the
    kernel would have copied them. The same values as the kernel handing each back where it is due
    (`Master.run_blocks`), in fewer kernel calls, when no FMU a Python component reads or feeds
    comes before it in the master's order (`make`: None otherwise). Gathers, steps and feeds run in
    one C call (`_BlockProgram`) where it can, which hands back the components that need Python."""

    def __init__(
        self, master: Master, steps: list, feeds: list, gathers: dict, snapshot=None, program=None
    ) -> None:
        self.master = master
        self.snapshot = snapshot  # outputs of components not stepped here, read by many links (`make`)
        # (component, period, gather of its inputs or None, its C step or None: `_c_step`), in the
        # master's order.
        self.steps = steps
        self.feeds = feeds  # copy of the Python components' outputs into each FMU that reads them
        self.gathers = gathers  # (consumer, its Python producers or None: all) -> gather, for `make`
        # The same steps and feeds in one C call (`_BlockProgram`), handing back what needs Python;
        # None: every step as above.
        self.program = program

    @classmethod
    def make(cls, master: Master, previous: _PythonSteps | None = None) -> _PythonSteps | None:
        """The fleet's Python components, or None (class docstring); `previous`: those before a
        robot was switched off, whose gathers are kept (a gather per robot component: generating
        them takes a quarter of a second at N = 50)."""
        system = master.system
        if system.mode == "jacobi":  # every component reads the outputs of the step before
            return None
        python = [
            c for c in master.order if type(c).native_step is Component.native_step and not c.constant_outputs
        ]
        if not python:
            return None
        names = {c.name for c in python}
        place = {c.name: i for i, c in enumerate(master.order)}
        links = system.links()
        consumers: dict[str, set[str]] = {}  # FMU -> the Python components it reads
        for consumer, fed in links.items():
            for link in fed:
                if link.producer in names and consumer not in names:
                    if place[consumer] < place[link.producer]:
                        return None  # it reads the Python component's previous output
                    consumers.setdefault(consumer, set()).add(link.producer)
                elif consumer in names and link.producer not in names:
                    if (
                        place[link.producer] < place[consumer]
                        and not system.components[link.producer].constant_outputs
                    ):
                        return None  # the Python component reads its output of the same step
        gathers = {}
        kept = previous.gathers if previous is not None else {}

        def gather(name: str, producers: frozenset | None):
            key = (name, producers)
            if key not in gathers:
                gathers[key] = (
                    kept[key] if key in kept else make_gather(system, system.components[name], producers)
                )
            return gathers[key]

        # Many plain links from components not stepped here (a lidar reading every vehicle): copied
        # from one snapshot of those components' outputs, taken before the block's steps.
        outside: dict[str, list] = {}
        for c in python:
            fed = [link for link in links.get(c.name, ()) if link.producer not in names]
            if len(fed) >= _SNAPSHOT_LINKS and all(link.connection.is_plain for link in fed):
                outside[c.name] = fed
        read = {link.producer for fed in outside.values() for link in fed}
        snapshot = Snapshot([c for c in master.order if c.name in read]) if outside else None

        def step_gather(c):
            if c.name not in outside:
                return gather(c.name, None)
            inside = frozenset(link.producer for link in links[c.name] if link.producer in names)
            from_snapshot = snapshot.gather(c, outside[c.name])
            rest = gather(c.name, inside) if inside else None
            if rest is None:
                return from_snapshot

            def both() -> None:
                from_snapshot()
                rest()

            return both

        steps = [(c, system.period_steps(c), step_gather(c), _c_step(c)) for c in python]
        order = sorted(consumers, key=place.__getitem__)
        feeds = [gather(name, frozenset(consumers[name])) for name in order]
        fed = [
            (system.components[name], [link for link in links[name] if link.producer in consumers[name]])
            for name in order
        ]
        program = _BlockProgram.make(system, [(c, period) for c, period, *_ in steps], fed)
        return cls(master, steps, feeds, gathers, snapshot, program)

    def tables(self, block: int):
        """The kernel's tables without the Python components; None when the kernel cannot step the
        rest alone."""
        return _tables_without(self.master, [component for component, *_ in self.steps], block)

    def step(self, k: int) -> None:
        """Step the Python components due at step k, then copy their outputs to the FMUs."""
        master = self.master
        t = (master.start_time_ns + k * master.system.macro_step_ns) / NS_PER_S
        program = self.program
        if program is not None:
            self._step_program(program, k, t)
            return
        if self.snapshot is not None:  # (none of those components steps before the gathers)
            self.snapshot.take()
        for component, period, gather, c_step in self.steps:
            if k % period:
                continue
            try:
                if gather is not None:
                    gather()
                    component.push_inputs()
                # A planner's C step does the step while it needs no Python (`_c_step`).
                if c_step is None or c_step(t):
                    component.do_step(t, master.step_seconds(k, period))
                component.get_outputs()
            except CosimError as error:
                master.failure = error
                raise
        for feed in self.feeds:
            feed()

    def _step_program(self, program: _BlockProgram, k: int, t: float) -> None:
        """`step` by the C program: each component it hands back is stepped here, as `step` would,
        from where the program stopped (its C step's hand-over: `do_step` goes on; a component
        stepped by Python: all of it), then the program goes on after it."""
        master, steps, snapshot = self.master, self.steps, self.snapshot
        taken = False
        end = len(steps) + 1  # (the feeds: the program's last entry, never handed back)
        i = program.run(0, k, t)
        while i < end:
            component, period, gather, c_step = steps[i]
            try:
                if program.python[i]:
                    if gather is not None:
                        if snapshot is not None and not taken:  # (the producers have not stepped)
                            snapshot.take()
                            taken = True
                        gather()
                        component.push_inputs()
                    if c_step is None or c_step(t):
                        component.do_step(t, master.step_seconds(k, period))
                else:  # gathered, its C step handed over
                    component.do_step(t, master.step_seconds(k, period))
                component.get_outputs()
            except CosimError as error:
                master.failure = error
                raise
            i = program.run(i + 1, k, t)


class _BlockProgram:
    """`_PythonSteps.step` in one C call a block (`fleet_python_block` of fleet.c), the same
    operations in the same order: per component due, its gather as copies from the producers'
    output buffers into its input buffer (the connection's arithmetic), then a lidar swept in C
    (`Lidar.step`: the other robots' circles placed from its inputs; without noise or moving
    obstacles) or a C step (`PlannerComponent.kernel_step`); last the copies into the FMUs that read
    them (`_PythonSteps.feeds`). It hands a component back to Python (`run` returns its index) when
    its C step says so, or before its gather when it has no step in C (`python`: then all of it is
    Python's). The components' push_inputs and get_outputs, which the C steps skip, are those of
    `PythonComponent` (a state check) and the components are stepping: checked by `make`."""

    # The threads of a step (None: one for each CPU this process may use), and the fewest chains
    # (robots) due in a stretch that use more than one. Measured with 2 CPUs under a load of ~5
    # (fleet_fifty's first N robots, unlogged, ms a simulated second, wall / CPU, one thread -> two):
    # N = 5: 5.3 / 5.3 -> 6.5 / 6.5; N = 12: 11.7 / 11.8 -> 12.8 / 13.4; N = 20: 20.3 / 20.1 ->
    # 20.5 / 21.7; N = 50: 52 / 52 -> 48 / 55.6 (the other thread's cold caches and wake-ups).
    threads: int | None = None
    MIN_CHAINS = 20

    def __init__(self, entries: list, copies: list, chains: list[list[int]] | None = None) -> None:
        from cosim.world import kernels

        library = kernels.fleet_library()
        self.function = library.fleet_python_block
        self.steps = (kernels.BlockStepArrays * len(entries))(*entries)
        self.copies = (kernels.BlockCopyArrays * max(1, len(copies)))(*copies)
        self.count = len(entries)
        self.python = [entry.kind == kernels.BLOCK_PYTHON for entry in entries]
        self._steps_address = ctypes.addressof(self.steps)
        self._copies_address = ctypes.addressof(self.copies)
        self.program = None
        threads = self.threads if self.threads is not None else _usable_cpus()
        chains = chains or []
        if threads > 1 and len(chains) >= max(2, self.MIN_CHAINS):
            pool = library.block_pool_new(min(threads, len(chains)) - 1)
            if pool:
                self._threaded(library, kernels, pool, chains)

    def _threaded(self, library, kernels, pool: int, chains: list[list[int]]) -> None:
        """Step by `fleet_python_block_threads` on `pool` (freed with this object)."""
        import weakref

        self._members = np.array([i for chain in chains for i in chain], dtype=np.int64)
        self._firsts = np.cumsum([0, *map(len, chains)]).astype(np.int64)
        self._scratch = np.zeros((2, len(chains)), dtype=np.int64)
        self.program = kernels.BlockProgramArrays(
            steps=self._steps_address, n=self.count, copies=self._copies_address,
            members=self._members.ctypes.data, firsts=self._firsts.ctypes.data, chains=len(chains),
            cursor=self._scratch[0].ctypes.data, due=self._scratch[1].ctypes.data,
            pool=pool, min_chains=self.MIN_CHAINS,
        )  # fmt: skip
        weakref.finalize(self, library.block_pool_free, pool)
        self._program_address = ctypes.addressof(self.program)
        self._threads_function = library.fleet_python_block_threads

    def run(self, start: int, k: int, t: float) -> int:
        """The components from `start` on at step k (t [s]); the index of the first handed back, or
        the number of entries (the components and the feeds) when none is."""
        if self.program is not None:
            return self._threads_function(self._program_address, start, k, t)
        return self.function(self._steps_address, self.count, start, k, t, self._copies_address)

    @classmethod
    def make(cls, system: System, steps: list, fed: list) -> _BlockProgram | None:
        """The program of `steps` ((component, period) in the master's order) and `fed` ((FMU, its
        links from those components) in the order of the feeds); None when it would step no
        component in C, or a gather cannot be copied so (an input written by two links)."""
        from cosim.core.component import PythonComponent, State
        from cosim.world import kernels
        from cosim.world.lidar import Lidar

        links = system.links()
        entries, copies = [], []

        def gathered(consumer: Component, fed_links: list) -> tuple[int, int] | None:
            found = _block_copies(system, consumer, fed_links)
            if found is None:
                return None
            first = len(copies)
            copies.extend(found)
            return first, len(found)

        def plain(c) -> bool:  # push_inputs and get_outputs only check the state
            kind = type(c)
            return (
                c.state is State.STEPPING
                and kind.push_inputs is PythonComponent.push_inputs
                and kind.get_outputs is PythonComponent.get_outputs
            )

        stepped = 0
        chained: dict[str, int] = {}  # the components stepped in C: their entries
        for c, period in steps:
            entry = kernels.BlockStepArrays(period=period, kind=kernels.BLOCK_PYTHON)
            kernel_step = getattr(c, "kernel_step", None)
            found = kernel_step() if callable(kernel_step) else None
            if plain(c) and isinstance(c, Lidar) and _sweeps_in_c(c):
                entry.kind = kernels.BLOCK_LIDAR
                entry.lidar, entry.inputs = c._address, ctypes.addressof(c.input_cbuffer)
                entry.robots = len(c._robot_rows)
                entry.robot_rows = c._robot_rows.ctypes.data if entry.robots else None
            elif plain(c) and found is not None:
                entry.kind = kernels.BLOCK_C_STEP
                entry.c_step, entry.state = found
            if entry.kind != kernels.BLOCK_PYTHON:
                stretch = gathered(c, links.get(c.name, []))
                if stretch is None:
                    return None
                entry.first_copy, entry.copies = stretch
                stepped += 1
                chained[c.name] = len(entries)
            entries.append(entry)
        if not stepped:
            return None
        chains = _chains(chained, links)
        feeds = kernels.BlockStepArrays(period=1, kind=kernels.BLOCK_COPIES, first_copy=len(copies))
        for consumer, fed_links in fed:
            if gathered(consumer, fed_links) is None:
                return None
        feeds.copies = len(copies) - feeds.first_copy
        entries.append(feeds)
        return cls(entries, copies, chains)


def _usable_cpus() -> int:
    """The CPUs this process may run on (its affinity where the system has one)."""
    import os

    getter = getattr(os, "sched_getaffinity", None)
    return len(getter(0)) if getter is not None else os.cpu_count() or 1


def _chains(chained: dict[str, int], links: dict) -> list[list[int]]:
    """`chained`'s entries (component name -> entry) joined into chains, each component with those
    stepped in C whose outputs it reads (either way round: also one after it in the order, whose
    outputs of the last step it reads): the chains share no component and read none of another's
    outputs, so they may step side by side (`fleet_python_block_threads`). Each chain's entries in
    order, the chains by their first."""
    parent = {name: name for name in chained}

    def root(name: str) -> str:
        while parent[name] != name:
            parent[name] = parent[parent[name]]
            name = parent[name]
        return name

    for name in chained:
        for link in links.get(name, ()):
            if link.producer in chained:
                parent[root(link.producer)] = root(name)
    groups: dict[str, list[int]] = {}
    for name, index in chained.items():
        groups.setdefault(root(name), []).append(index)
    return sorted(sorted(group) for group in groups.values())


def _sweeps_in_c(lidar) -> bool:
    """Whether `fleet_python_block` may step this lidar as `Lidar.step` does: that step, its scan
    and placing of the robots are `Lidar`'s own, it draws no noise, no obstacle moves (`world.at`
    does nothing) and its angles are written (they are from `on_initialize` on)."""
    from cosim.core.component import PythonComponent
    from cosim.world.lidar import Lidar

    kind = type(lidar)
    rows = lidar._robot_rows
    return (
        kind.step is Lidar.step
        and kind.scan is Lidar.scan
        and kind._place_robots is Lidar._place_robots
        and kind.do_step is PythonComponent.do_step
        and lidar.angle_noise == 0
        and lidar.range_noise == 0
        and not lidar.world.moving
        and lidar._angles_written
        and rows.flags.c_contiguous
        and rows.flags.writeable
    )


def _block_copies(system: System, consumer: Component, links: list) -> list | None:
    """`_BlockProgram`'s copies for `links` into `consumer` (of `System.links`): each stretch of
    plain links from one producer into consecutive inputs from evenly spaced outputs one copy,
    every other link a copy of its own; None when an input is written twice."""
    from cosim.world import kernels

    targets = [link.input for link in links]
    if len(set(targets)) != len(targets):
        return None
    components = system.components
    target_base = ctypes.addressof(consumer.input_cbuffer)
    copies = []
    run = None  # [producer, first link, stride, count, last output] of the stretch being made
    for link in sorted(links, key=lambda link: link.input):
        if run is not None and link.connection.is_plain:
            producer, first, stride, count, last = run
            if link.producer == producer and link.input == first.input + count:
                if count == 1 or link.output - last == stride:
                    run[2], run[3], run[4] = link.output - last, count + 1, link.output
                    continue
        if run is not None:
            copies.append(_copy(components, target_base, *run[:4]))
            run = None
        if link.connection.is_plain:
            run = [link.producer, link, 0, 1, link.output]
            continue
        scale, offset = link.connection.scale, link.connection.offset
        source = ctypes.addressof(components[link.producer].output_cbuffer) + 8 * link.output
        copies.append(
            kernels.BlockCopyArrays(
                source=source, target=target_base + 8 * link.input, count=1, stride=0,
                multiply=int(scale != 1.0), add=int(offset != 0.0), scale=scale, offset=offset,
            )
        )  # fmt: skip
    if run is not None:
        copies.append(_copy(components, target_base, *run[:4]))
    return copies


def _copy(components: dict, target_base: int, producer: str, first, stride: int, count: int):
    """A plain copy of `count` values from `producer`'s output `first.output` on, `stride` apart,
    into the inputs from `first.input` on."""
    from cosim.world import kernels

    source = ctypes.addressof(components[producer].output_cbuffer) + 8 * first.output
    return kernels.BlockCopyArrays(
        source=source, target=target_base + 8 * first.input, count=count, stride=stride
    )


def _c_step(component):
    """The C step of a Python component (`PlannerComponent.kernel_step`: the scan into the costmap,
    the progress, the triggers), as a call of t [s] that says whether the step needs Python after
    all (then `do_step` goes on from where it stopped, as the compiled kernel hands it back); None
    without one (every step in Python)."""
    kernel_step = getattr(component, "kernel_step", None)
    found = kernel_step() if callable(kernel_step) else None
    if found is None:
        return None
    function, state = found
    call = ctypes.CFUNCTYPE(ctypes.c_int64, ctypes.c_void_p, ctypes.c_double)(function)
    return functools.partial(call, state)


def _advance(
    master: Master,
    robots: list[_Robot],
    count: int,
    tables,
    python: _PythonSteps | None = None,
    rows: _BlockRows | None = None,
    split: _SplitKernel | None = None,
) -> list:
    """Step the fleet's system `count` steps, hand every robot its rows and return them (per
    component of the master's order, its inputs and outputs after each of its steps; None for one
    stepped by Python), valid until the next call (views of the kernel's buffers). `python`: the
    Python components, stepped before the kernel steps the rest (`tables` then without them);
    `rows`: every robot's rows taken at once (`_BlockRows`, of `tables`) where it can; `split`: the
    kernel's block as calls side by side (`_SplitKernel`) where it fits."""
    first = master.step_index
    if rows is not None:
        rows.pose_rows = rows.modes_now = None
    kept: list[list[np.ndarray]] = []
    views = [True]  # the rows kept are the kernel's buffers (one clean stretch), not copies
    if python is not None:
        python.step(first)
    if split is not None and split.fits(first, count):
        if not split.active:  # the one set of tables ran last: the parts send every value first
            for part in split.parts:
                part.forget_sent()
            split.active = True
        histories = split.run(first, count)
        if split.rows is not None:
            split.rows.pose_rows = split.rows.modes_now = None
            if split.rows.take(histories, first, count):
                if rows is not None:
                    rows.pose_rows, rows.modes_now = split.rows.pose_rows, split.rows.modes_now
                return histories
        for each in robots:
            each.take(histories, first, count)
        return histories
    if split is not None and split.active and tables is not None:
        tables.forget_sent()  # the parts ran last
        split.active = False
    if tables is not None:
        # FMUs in the compiled kernel; the lidars and planners (Python) step in the block's first
        # step and hold their outputs to its end (the block is cut only at their periods). The
        # rows are views of the kernel's buffers, which its next call refills: copied only then
        # (a block is mostly one stretch), else valid until the next block's steps; copied at
        # once after a stretch that ended inside a step (not `clean`: the rows of that step
        # already taken are moved to the buffers' start as soon as they are handed over).
        def copy_kept() -> None:
            for part in kept:
                part[:] = [r if r is None or r.base is None else r.copy() for r in part]

        def keep(_first: int, _end: int, delivered: list, clean: bool) -> None:
            views[0] = views[0] and clean
            kept.append(list(delivered) if clean else [None if r is None else r.copy() for r in delivered])

        master.run_blocks(
            count,
            tables,
            keep,
            block=count,
            before_block=copy_kept,
            cut_after_python=lambda _k: False,
        )
    else:
        rows = None
        master.run_recorded(count, lambda _first, _count, delivered: kept.append(delivered), block=count)
    if len(kept) == 1:
        histories = kept[0]
        if rows is not None and views[0] and rows.take(histories, first, count):
            return histories
    else:
        histories = [
            np.concatenate([part[i] for part in kept if part[i] is not None])
            if any(part[i] is not None for part in kept)
            else None
            for i in range(len(kept[0]))
        ]
    for each in robots:
        each.take(histories, first, count)
    return histories


class _BlockRows:
    """Every robot's poses, commands and modes of a block (`_Robot.take`) in one gather from the
    kernel's record buffer (of each set of `tables` that steps robots: `_SplitKernel`'s parts),
    where the robots' vehicles and mode components have their rows, rather than robot by robot: the
    same values, in arrays of their own; a robot switched off (`_halt`) where it stopped,
    commanding nothing, its mode NaN, as `_Robot.take` has it. `take` leaves the robots to
    `_Robot.take` when the block's rows are not one stretch of every step in those buffers."""

    def __init__(self, robots: list[_Robot], tables: list, block: int) -> None:
        self.robots = robots
        stepped = [r for r, each in enumerate(robots) if not each.halted]
        self.vehicle_rows = [robots[r].vehicle_row for r in stepped]
        self.mode_rows = [(robots[r].mode_row[0], robots[r].mode_row[2]) for r in stepped]
        self.halted = [r for r, each in enumerate(robots) if each.halted]
        # per set of tables: its history, its robots and their [step, robot, x y theta v omega] and
        # [step, robot] indices into it
        self.parts = []
        steps = np.arange(block, dtype=np.intp)[:, None]
        for part in tables:
            shapes = part.record_shapes
            mine = [r for r in stepped if shapes[robots[r].vehicle_row] is not None]
            columns = np.zeros((block, len(mine), 5), dtype=np.intp)
            modes = np.zeros((block, len(mine)), dtype=np.intp)
            for at, r in enumerate(mine):
                each = robots[r]
                offset, _, width = shapes[each.vehicle_row]
                taken = [*_column_list(each.pose_columns), *_column_list(each.command_columns)]
                columns[:, at] = offset + steps * width + np.array(taken, dtype=np.intp)
                row, column, period = each.mode_row
                offset, _, width = shapes[row]
                # step j's mode: the row of the component's latest step <= j (`_held`; its first
                # step the block's first, checked by `take`)
                modes[:, at] = offset + (steps[:, 0] // period) * width + column
            if mine:
                self.parts.append((part.history, np.array(mine, dtype=np.intp), columns, modes))
        self.block = block
        self.pose_rows: np.ndarray | None = None  # [step, robot, x y theta v omega] of the last `take`
        self.modes_now: np.ndarray | None = None  # [step, robot] modes of the last `take`

    @classmethod
    def make(cls, robots: list[_Robot], tables: list, block: int) -> _BlockRows | None:
        """None unless every robot still stepped has its vehicle stepped every step and it and its
        mode component rows in one of the kernel's buffers, its command columns its vehicle's."""
        if not tables or any(part is None for part in tables):
            return None
        for each in robots:
            if each.halted:
                continue
            if each.vehicle_period != 1 or each.command_columns is None or each.mode_row is None:
                return None
            found = [part.record_shapes for part in tables if part.record_shapes[each.vehicle_row]]
            if len(found) != 1:
                return None
            shapes = found[0]
            if (
                shapes[each.mode_row[0]] is None
                or shapes[each.vehicle_row][1] < block
                or shapes[each.mode_row[0]][1] < -(-block // each.mode_row[2])
            ):
                return None
        return cls(robots, tables, block)

    def take(self, histories: list, first: int, count: int) -> bool:
        """`_Robot.take` of every robot for the block of `count` steps from step `first` whose rows
        `histories` are, as views of the kernel's buffers (one stretch); False (nothing taken) when
        a robot's vehicle has not `count` rows there, or its mode component does not step in the
        block's first step (its mode before that is the last block's) or has not its rows."""
        if count > self.block or any(len(histories[row]) != count for row in self.vehicle_rows):
            return False
        for row, period in self.mode_rows:
            if first % period or len(histories[row]) != -(-count // period):
                return False
        robots = self.robots
        if len(self.parts) == 1 and not self.halted:
            history, _, columns, modes = self.parts[0]
            rows, modes = history.take(columns[:count]), history.take(modes[:count])
        else:
            rows = np.empty((count, len(robots), 5))
            modes = np.empty((count, len(robots)))
            for history, mine, columns, indices in self.parts:
                rows[:, mine] = history.take(columns[:count])
                modes[:, mine] = history.take(indices[:count])
        for r in self.halted:  # not stepped: where it stopped, commanding nothing
            each = robots[r]
            if each._last is None:
                each._last = (each.poses[-1], each.commands_now[-1], each.modes[-1])
            rows[:, r, :3] = each._last[0]
            rows[:, r, 3:] = 0.0
            modes[:, r] = math.nan
        self.pose_rows, self.modes_now = rows, modes
        for r, each in enumerate(robots):
            each.poses = rows[:, r, :3]
            each.commands_now = rows[:, r, 3:]
            each.modes = modes[:, r]
            each._last = None
        return True


class _SplitKernel:
    """The kernel's block of a fleet's FMUs as `PARTS` calls side by side on the pool of the block
    program's threads (`block_pool_kernels` of fleet.c: each call taken by whichever thread is
    free, so a worker woken late leaves the caller no more to do than alone), each on tables of
    a part of the robots (the other parts' components left out as constant outputs, as the Python
    components are), instead of one call on all: no FMU reads an output of another robot's FMU
    (`make` checks every link), so each FMU is set, stepped and read with the same values in the
    same order as in the one call, its rows the same. Only the project's FMUs (no global state:
    instances apart are independent) step so. The calls run whole blocks of full steps (`fits`);
    a failed FMU raises the error of the first failure in the one call's order (step, then
    position), the other parts' FMUs maybe having stepped further (the run ends there)."""

    PARTS = 4

    def __init__(self, master: Master, parts: list, pool: int, block: int) -> None:
        from cosim.core import kernel
        from cosim.world import kernels

        self.master = master
        self.parts = parts  # the tables of each part
        self.pool = pool
        self.block = block
        self.function = kernels.fleet_library().block_pool_kernels
        address = ctypes.cast(kernel._kernel(), ctypes.c_void_p).value
        bound = [part._bound() for part in parts]
        self.results = [part._result for part in bound]
        self.jobs = (kernels.KernelJobArrays * len(parts))(
            *(
                kernels.KernelJobArrays(
                    function=address,
                    start_ns=master.start_time_ns,
                    h_ns=master.system.macro_step_ns,
                    tables=ctypes.addressof(part._tables),
                    result=ctypes.addressof(part._result),
                )  # fmt: skip
                for part in bound
            )
        )
        self.plans = [part.stretch_plan(master._plan, master.system.macro_step_ns) for part in parts]
        self.active = False  # the last block ran here (else on the one set of tables)
        self.rows: _BlockRows | None = None  # `_BlockRows` of the parts

    @classmethod
    def make(cls, master: Master, robots: list[_Robot], python: _PythonSteps | None, block: int):
        """The split of the robots still stepped into `PARTS` parts (fleet order), or None: without a
        pool of threads (`_BlockProgram`), fewer than `_BlockProgram.MIN_CHAINS` robots, a component
        that is not one of the project's FMUs stepped by the kernel, or a link between two robots'
        FMUs."""
        from cosim.core.component import Component
        from cosim.fmi.builtin import GENERATION_TOOL

        program = python.program if python is not None else None
        if program is None or program.program is None or master.system.mode == "jacobi":
            return None
        stepped = [each for each in robots if not each.halted]
        if len(stepped) < max(2, _BlockProgram.MIN_CHAINS):
            return None
        python_components = [component for component, *_ in python.steps]
        parts = min(cls.PARTS, len(stepped))
        part_of: dict[str, int] = {}
        parts_components: list[list] = [[] for _ in range(parts)]
        for number, each in enumerate(stepped):
            part = number * parts // len(stepped)
            for component in each.built.system.components.values():
                if component.constant_outputs or any(component is c for c in python_components):
                    continue
                if type(component).native_step is Component.native_step:
                    return None  # a component the kernel would hand back
                description = getattr(component, "model_description", None)
                if description is None or not (description.generationTool or "").startswith(GENERATION_TOOL):
                    return None
                part_of[component.name] = part
                parts_components[part].append(component)
        for component in master.order:  # every component the kernel steps is one robot's
            if component.constant_outputs or any(component is c for c in python_components):
                continue
            if component.name not in part_of:
                return None
        for consumer, fed in master.system.links().items():
            for link in fed:
                producer = part_of.get(link.producer)
                if producer is not None and part_of.get(consumer, producer) != producer:
                    return None
        tables_of_parts = []
        for part in range(parts):
            others = [*python_components]
            for other in range(parts):
                if other != part:
                    others += parts_components[other]
            tables = _tables_without(master, others, block)
            if tables is None:
                return None
            tables.sent_kept = True
            tables.warm_up()
            tables_of_parts.append(tables)
        split = cls(master, tables_of_parts, program.program.pool, block)
        split.rows = _BlockRows.make(robots, tables_of_parts, block)
        return split

    def fits(self, first: int, count: int) -> bool:
        """Whether the block of `count` steps from `first` is whole steps of the macro step (none
        cut at the stop time: those go through `Master.run_blocks`)."""
        tail_from = self.master._tail_from
        return 0 < count <= self.block and (tail_from is None or first + count <= tail_from)

    def run(self, first: int, count: int) -> list:
        """Step the block; the rows of every component (as `Master.run_blocks` hands them over)."""
        from cosim.core import kernel

        master = self.master
        master._check_running()
        master._check_steps(count)
        for part in self.parts:
            part.rows[:] = 0
            part.start_run()
        for job in self.jobs:
            job.first_step, job.steps = first, count
        self.function(self.pool, ctypes.addressof(self.jobs), len(self.jobs))
        end = first + count
        results = [tuple(result) for result in self.results]
        if any(result[0] != kernel.DONE or result[1] != end for result in results):
            self._failed(results)
        histories = None
        for part, plan in zip(self.parts, self.plans, strict=True):
            p = plan.recorded_periods
            counts = np.minimum((end + p - 1) // p - (first + p - 1) // p, part.rows[plan.recorded])
            delivered = part.delivered(counts)
            if histories is None:
                histories = list(delivered)
            else:
                histories = [a if a is not None else b for a, b in zip(histories, delivered, strict=True)]
        master.step_index = end
        return histories

    def _failed(self, results: list) -> None:
        """Raise the error of the first failure (step, then position) as `Master.run_blocks` would."""
        from cosim.core import kernel
        from cosim.core.kernel_path import raise_failure

        master = self.master
        failures = [(r[1], r[2], i) for i, r in enumerate(results) if r[0] == kernel.FAILED]
        if not failures:
            raise CosimError(f"the fleet's kernel stopped unexpectedly (codes {[r[0] for r in results]})")
        k, _, i = min(failures)
        code, k, position, failed, call, status, kind = results[i]
        master.step_index = k
        raise_failure(
            master, self.parts[i].native[failed], master._plan[failed].component.name, k, call, status, kind
        )


def _tables_without(master: Master, components: list, block: int):
    """The kernel's tables of the master's components but `components` (left out as constant
    outputs while they are made); None when the kernel cannot step the rest alone."""
    from cosim.core import kernel

    for component in components:
        component.constant_outputs = True
    try:
        tables = master.kernel_tables(record=True, block=block, scalar_rows=True)
    finally:
        for component in components:
            component.constant_outputs = False
    if tables is None or (tables.components[:, kernel.C_KIND] == kernel.KIND_PYTHON).any():
        return None
    return tables


def _column_list(columns) -> list[int]:
    """`_columns`' slice or list as the list of its columns."""
    return list(range(columns.start, columns.stop)) if isinstance(columns, slice) else list(columns)


def _log_plans(log: FleetLog, robots: list[_Robot], t_ns: int) -> None:
    """The plans made in the block that starts at t_ns (stamped t_ns: a planner steps only in a
    block's first step), or at its start (a new mission goal given at the end of the last block)."""
    for each in robots:
        planner = each.built.planner
        if planner is not None and planner.plan_version != each.logged_plan:
            log.write_plan(t_ns, each.robot.name, planner.result.path)
            each.logged_plan = planner.plan_version


def _block_steps(master: Master) -> int:
    """Steps per block: the greatest common divisor of the periods (in steps) of every robot's
    Python components (lidar, planner), so each of their steps, the only ones that read the other
    robots, falls on a block's first step; 1 when a robot has a lidar stepped every step."""
    periods = [
        master.system.period_steps(component)
        for component in master.order
        if component.name.partition(":")[2] in (SEEN_BY, "planner") and not component.constant_outputs
    ]
    return math.gcd(*periods) if periods else 1


def _run(
    fleet: Fleet,
    master: Master,
    robots: list[_Robot],
    trace: list | None,
    log: FleetLog | None,
    outcome: FleetOutcome,
    coordination: FleetCoordination | None = None,
) -> None:
    """Step the fleet to its end (module docstring), filling `outcome` as it goes; `coordination`
    releases each robot's cells before every block (`cosim.navigation.coordination`)."""
    settings = fleet.settings
    contacts = FleetContacts([each.robot.name for each in robots], [each.robot.radius for each in robots])
    h_ns = robots[0].built.system.macro_step_ns
    steps = master.steps_to_stop
    stop_ns = master.stop_time_ns
    positions = np.array([each.position for each in robots])
    contacts.start(positions)
    if trace is not None:
        trace.append((0.0, positions))
    pose_steps = max(1, round(1.0 / (fleet.first.pose_rate * fleet.first.macro_step)))
    for each in robots:  # the first plan: in the log's header
        if each.built.planner is not None:
            each.logged_plan = each.built.planner.plan_version
    if log is not None:
        log.write_poses(0, [(*each.pose, *each.command) for each in robots])
    block = _block_steps(master)
    stop_on_collision = settings.on_collision == "stop"
    tables, python = _tables(master, block)
    if tables is not None:  # between the blocks' kernel calls nothing else sets the FMUs' inputs
        tables.sent_kept = True
        _warm_up(master, tables)
    if log is not None and steps > 0:  # the channels the first block registers, now, in its order
        log.steps.register_step_channels(0, min(block, steps))  # (the loop starts at k = 0)
    block_rows = _BlockRows.make(robots, [tables], block)
    split = _SplitKernel.make(master, robots, python, block) if tables is not None else None
    judge = _FleetJudge.make(robots) if not stop_on_collision else None
    if coordination is not None:  # the released cells (and halts) for the first block
        coordination.before_block(0.0)
    wall_start = time.perf_counter()
    reason = None
    k = 0
    last_pose_step = 0
    try:
        while k < steps and reason is None:
            count = min(block, steps - k)
            histories = _advance(master, robots, count, tables, python, block_rows, split)
            # [step, robot, x y theta v omega] when `_BlockRows` took them
            taken = block_rows.pose_rows if block_rows is not None else None
            if log is not None:
                _log_plans(log, robots, k * h_ns)
            poses = []  # the poses logged in the block: (step, t_ns, per robot x, y, theta, v, omega)
            pose_rows = None
            ends_ns = [(k + i + 1) * h_ns for i in range(count)]
            if stop_ns is not None:
                ends_ns = [min(end_ns, stop_ns) for end_ns in ends_ns]
            ends = [end_ns / NS_PER_S for end_ns in ends_ns]
            starts = [(k + i) * h_ns / NS_PER_S for i in range(count)]
            lengths = [end - start for start, end in zip(starts, ends, strict=True)]
            last = count - 1
            if taken is not None:
                stacked = taken[:, :, :2].copy()  # step, robot, x y
            else:
                stacked = np.stack([each.poses[:, :2] for each in robots], axis=1)
            # Nothing ends the run but the robots' own ends: judged a robot at a time.
            if not stop_on_collision:
                if judge is not None:
                    modes = block_rows.modes_now if taken is not None else None
                    ended = judge.block(robots, ends, lengths, positions, stacked, modes)
                else:
                    ended = [_judge_block(each, ends, lengths, positions[r]) for r, each in enumerate(robots)]
                if all(not each.judged for each in robots):  # ends with the step in which the last one ended
                    last = max((step for step in ended if step is not None), default=0)
                    stacked = stacked[: last + 1]
            if not stop_on_collision:  # every step up to the last is checked: all at once
                began_in = contacts.steps(starts, lengths, np.concatenate((positions[None], stacked)))
            for i in range(last + 1):
                t_next, end_ns = ends[i], ends_ns[i]
                after = stacked[i]
                began = (
                    began_in[i]
                    if not stop_on_collision
                    else contacts.step(starts[i], lengths[i], positions, after)
                )
                outcome.collisions += began
                if stop_on_collision:
                    for k_robot, each in enumerate(robots):
                        _judge(each, t_next, lengths[i], positions[k_robot], after[k_robot], i)
                positions = after
                outcome.time = t_next
                if trace is not None:
                    trace.append((t_next, after))
                if log is not None and (k + i + 1) % pose_steps == 0:
                    if pose_rows is None and taken is not None:
                        pose_rows = taken
                    elif pose_rows is None:  # per step, robot: x, y, theta, v, omega
                        pose_rows = np.concatenate(
                            (
                                np.stack([each.poses for each in robots], axis=1),
                                np.stack([each.commands_now for each in robots], axis=1),
                            ),
                            axis=2,
                        )
                    poses.append((k + i, end_ns, pose_rows[i]))
                    last_pose_step = k + i + 1
                if stop_on_collision and (
                    began or any(each.outcome.status == "collision" for each in robots)
                ):
                    reason = "collision"
                elif (stop_on_collision or i == last) and all(not each.judged for each in robots):
                    reason = "completed" if outcome.completed else "all_ended"
                if reason is not None:
                    break
            if log is not None:
                log.block(k, k + i + 1, histories, poses)
            k += i + 1
            if reason is None and interrupt.take() is not None:
                reason = "interrupted"
            if tables is not None and reason is None:
                if any(each.outcome.status == "collision" and not each.halted for each in robots):
                    tables, python = _halt(master, robots, log, block, python)
                    if tables is not None:
                        tables.sent_kept = True
                    block_rows = _BlockRows.make(robots, [tables], block)
                    split = _SplitKernel.make(master, robots, python, block) if tables is not None else None
            for each in robots:  # a new mission goal: given at the end of the block
                if each.pending_goal and each.judged:
                    _next_goal(each, outcome.time, coordination)
                each.pending_goal = False
                if log is not None and each.monitor.goal != each.logged_goal:
                    log.write_goal(round(outcome.time * NS_PER_S), each.robot.name, *each.monitor.goal)
                    each.logged_goal = each.monitor.goal
            if coordination is not None and reason is None:
                coordination.before_block(outcome.time)  # cells released, halts, re-solves
    finally:  # the numbers judged in C back in the robots' outcomes
        if judge is not None:
            judge.release_all(robots)
    if log is not None and last_pose_step != k:  # the pose at the end (step i of the last block)
        log.write_poses(
            round(outcome.time * NS_PER_S), [(*each.poses[i], *each.commands_now[i]) for each in robots]
        )
    reason = reason or "stop_time"
    for k_robot, each in enumerate(robots):
        each.outcome.min_clearance_walls = each.monitor.outcome.min_clearance
        each.outcome.min_clearance_robots = float(contacts.min_clearance[k_robot])
        if each.outcome.status == "running":
            each.outcome.status = "stop_time" if reason == "stop_time" else "stopped"
    outcome.reason = reason
    outcome.wall_time = time.perf_counter() - wall_start
    coordinator = coordination.coordinator if coordination is not None else None
    if coordinator is not None:
        outcome.coordination = {
            "method": coordinator.method,
            "solves": coordinator.solves,
            "failures": coordinator.failures,
            "planning_time": coordinator.solve_time,
        }


def _warm_up(master: Master, tables) -> None:
    """What the kernel's first block would make or bring in first, before the loop: the kernel
    bound, its record buffer's pages mapped (`KernelTables.warm_up`), the plan of its stretches
    (`KernelTables.stretch_plan`): ~3 ms of the first block at N = 50."""
    tables.warm_up()
    tables.stretch_plan(master._plan, master.system.macro_step_ns)


def _halt(master: Master, robots: list[_Robot], log: FleetLog | None, block: int, python=None):
    """Switch off every robot that hit a wall or obstacle ([fleet] on_collision = "continue"): its
    components are no longer stepped (the master steps no component with constant outputs), so it
    stays where it stands, its pose still seen by the others' lidars. Returns the kernel's tables
    for the robots still stepped, and their Python components (`_tables`)."""
    for each in robots:
        if each.outcome.status == "collision" and not each.halted:
            each.halted = True
            for component in each.built.system.components.values():
                component.constant_outputs = True
            if log is not None:
                log.steps.halt(each.robot.name)
    return _tables(master, block, python)


def _tables(master: Master, block: int, previous: _PythonSteps | None = None) -> tuple:
    """The kernel's tables for a block and the Python components stepped apart from it
    (`_PythonSteps`; `previous`: those until now), or the tables with every component (the kernel
    handing the Python ones back) and None, or (None, None) when the kernel cannot step the fleet."""
    python = _PythonSteps.make(master, previous)
    tables = python.tables(block) if python is not None else None
    if tables is None:
        return master.kernel_tables(record=True, block=block, scalar_rows=True), None
    return tables, python


def _columns(columns: list[int]) -> list[int] | slice:
    """Columns of a component's block rows: a slice when they are consecutive (a view of the
    rows, no copy: nothing writes into a robot's poses or commands), else the list."""
    runs = column_runs(columns)
    return runs[0] if len(runs) == 1 else columns


def _held(rows: np.ndarray, first: int, count: int, period: int, last: np.ndarray) -> np.ndarray:
    """Per step k = first .. first + count - 1, the row of the component's latest step <= k (its
    rows are those of the steps k % period == 0; before its first step in the block, `last`)."""
    if period == 1:
        return rows
    lead = due_from(first, period) - first  # the steps before its first in the block
    out = rows[_held_rows(lead, count, period)] if len(rows) else np.empty((count, len(last)))
    out[:lead] = last
    return out


@functools.lru_cache(maxsize=256)
def _held_rows(lead: int, count: int, period: int) -> np.ndarray:
    """`_held`'s row per step (row j holds from step lead + j period on; 0 before), the same for
    every robot and block of the same phase: made once (read-only)."""
    rows = np.maximum((np.arange(count) - lead) // period, 0)
    rows.setflags(write=False)
    return rows


def _judge(each: _Robot, t: float, h: float, before, after, step: int = 0) -> None:
    """One robot after the step that ended at t: distance, clearance, mode, mission, deadlock."""
    result = each.outcome
    if not each.judged:
        return
    moved = math.hypot(after[0] - before[0], after[1] - before[1])
    result.distance += moved
    if each.modes[step] == MODE_RECOVER:
        result.recovery_time += h
    monitor = each.monitor
    _, why = monitor.check_positions((t,), (float(after[0]),), (float(after[1]),))
    if why == "collision":
        result.status = "collision"
        result.collision = (t, float(after[0]), float(after[1]))
        return
    if each.pending_goal:  # at a goal, the next one given at the block's end
        return
    dwelling = each.dwell_until is not None
    if moved < STOPPED_SPEED * h and not dwelling:
        result.stopped_time += h
    if dwelling:
        if t + 1e-9 < each.dwell_until:
            return
        each.dwell_until = None
        each.pending_goal = True
        return
    if why == "goal_reached":
        monitor.outcome.reason, monitor.outcome.reached = "running", False
        result.goals_reached += 1
        goal = each.goals[each.goal_index]
        each.goal_index += 1
        if each.goal_index == len(each.goals):
            result.status = "completed"
            result.completion_time = t
            result.deadlocked_at = None
            return
        result.deadlocked_at = None
        if goal.dwell > 0:
            each.dwell_until = t + goal.dwell
            return
        each.pending_goal = True
        return
    goal = each.goals[each.goal_index]
    result.deadlocked_at = each.progress.update(t, math.hypot(goal.x - after[0], goal.y - after[1]))


def _judge_block(each: _Robot, ends: list[float], lengths: list[float], start, done=None) -> int | None:
    """`_judge` for every step of the block whose steps end at `ends` [s] and last `lengths` [s],
    the robot at `start` (x, y) [m] before the first; returns the step in which it stopped being
    judged, None when it did not. The steps up to the next goal reached or collision are checked
    in one `OutcomeMonitor.check_positions` call, with the same arithmetic, in the same order, as
    step by step; a robot dwelling or waiting for its next goal is judged step by step. `done`:
    (event, why, moved, x, y) of `_FleetJudge`, which judged the steps before `event` and the
    distance and recovery time of `event` (moved in it, to x, y) in C: why is "goal_reached" or
    "collision" there, or None when step `event` is left to this function."""
    if not each.judged:
        return None
    result, monitor, progress = each.outcome, each.monitor, each.progress
    xs, ys = each.poses[:, 0].tolist(), each.poses[:, 1].tolist()
    modes = each.modes.tolist()
    bx, by = float(start[0]), float(start[1])
    count = len(ends)
    i = 0
    while i < count:
        goal = each.goals[each.goal_index]
        if done is not None:
            event, why, moved, bx, by = done
            done = None
            if why is None:
                i = event
                continue
        elif each.pending_goal or each.dwell_until is not None:
            _judge(each, ends[i], lengths[i], (bx, by), (xs[i], ys[i]), i)
            bx, by = xs[i], ys[i]
            if not each.judged:
                return i
            i += 1
            continue
        else:
            index, why = monitor.check_positions(ends[i:], xs[i:], ys[i:])
            event = i + index  # the step that reached a goal or collided (count: none)
            for j in range(i, min(event + 1, count)):
                x, y, h = xs[j], ys[j], lengths[j]
                moved = math.hypot(x - bx, y - by)
                bx, by = x, y
                result.distance += moved
                if modes[j] == MODE_RECOVER:
                    result.recovery_time += h
                if j == event:
                    break
                if moved < STOPPED_SPEED * h:
                    result.stopped_time += h
                result.deadlocked_at = progress.update(ends[j], math.hypot(goal.x - x, goal.y - y))
            if why is None:
                return None
        t, x, y = ends[event], xs[event], ys[event]
        if why == "collision":
            result.status = "collision"
            result.collision = (t, x, y)
            return event
        if moved < STOPPED_SPEED * lengths[event]:  # reached a goal (neither dwelling nor waiting)
            result.stopped_time += lengths[event]
        monitor.outcome.reason, monitor.outcome.reached = "running", False
        result.goals_reached += 1
        each.goal_index += 1
        result.deadlocked_at = None
        if each.goal_index == len(each.goals):
            result.status = "completed"
            result.completion_time = t
            return event
        if goal.dwell > 0:
            each.dwell_until = t + goal.dwell
        else:
            each.pending_goal = True
        i = event + 1
    return None


class _FleetJudge:
    """`_judge_block` of every robot in one C call a block (`fleet_judge` of fleet.c: the same
    operations in the same order), for the robots whose checks are compiled (a static world:
    `OutcomeMonitor`'s `_CompiledChecks`) and that neither dwell nor wait for their next goal.
    Such a robot's numbers (its outcome's distance, stopped and recovery times, deadlock; its
    `Progress`; its monitor's state) are kept in its C struct from block to block (`hold`) and come
    back to Python (`release`) when it reaches a goal, collides, or reaches a step its checks leave
    to Python, where `_judge_block` goes on; and for every robot at the end of the run
    (`release_all`, before anything reads them). `_judge_block` judges the other robots."""

    # The Judge fields from `active` to `time` (`hold`), and from `last_x` to `reason` (`release`).
    _HOLD = struct.Struct("=q13d")
    _RELEASE = struct.Struct("=17d2q")

    def __init__(self, robots: list[_Robot]) -> None:
        from cosim.world import kernels

        self.kernels = kernels
        self.function = kernels.fleet_library().fleet_judge
        self.judges = (kernels.JudgeArrays * len(robots))()
        self.address = ctypes.addressof(self.judges)
        size = ctypes.sizeof(kernels.JudgeArrays)
        self.hold_at = [r * size + kernels.JudgeArrays.active.offset for r in range(len(robots))]
        self.release_at = [r * size + kernels.JudgeArrays.last_x.offset for r in range(len(robots))]
        self.compiled = [each.monitor._compiled for each in robots]
        self.held = [False] * len(robots)
        self.ended = np.zeros(len(robots), dtype=np.int64)
        for judge, compiled in zip(self.judges, self.compiled, strict=True):
            if compiled is not None:
                judge.monitor = compiled.address
            judge.stopped_speed, judge.progress, judge.recover = STOPPED_SPEED, PROGRESS, MODE_RECOVER

    @classmethod
    def make(cls, robots: list[_Robot]) -> _FleetJudge | None:
        """The judge of `robots`, or None when none has compiled checks."""
        if all(each.monitor._compiled is None for each in robots):
            return None
        return cls(robots)

    def hold(self, r: int, each: _Robot) -> None:
        """Robot r's numbers into its struct: judged in C from now on."""
        result, progress, monitor = each.outcome, each.progress, each.monitor
        goal = each.goals[each.goal_index]
        nan = math.nan
        self._HOLD.pack_into(
            self.judges, self.hold_at[r], 1, nan, nan, result.distance, result.recovery_time,
            result.stopped_time, nan if result.deadlocked_at is None else result.deadlocked_at,
            progress.best, progress.best_time,
            nan if progress.deadlocked_at is None else progress.deadlocked_at,
            progress.deadlock_after, goal.x, goal.y, monitor.outcome.time,
        )  # fmt: skip
        self.compiled[r].put(monitor)
        self.held[r] = True

    def release(self, r: int, each: _Robot) -> tuple[float, float, float, int, int]:
        """Robot r's numbers back from its struct (judged in Python from now on); returns the
        position after the last step judged, the distance moved in the last, its step and why
        the judging ended there (CHECK_*)."""
        result, progress, monitor = each.outcome, each.progress, each.monitor
        (x, y, result.distance, result.recovery_time, result.stopped_time, dead, progress.best,
         progress.best_time, progress_dead, _, _, _, monitor.outcome.time, _, _, _, moved, event,
         code) = self._RELEASE.unpack_from(self.judges, self.release_at[r])  # fmt: skip
        result.deadlocked_at = None if dead != dead else dead
        progress.deadlocked_at = None if progress_dead != progress_dead else progress_dead
        self.compiled[r].get(monitor)
        self.judges[r].active = 0
        self.held[r] = False
        return x, y, moved, event, code

    def release_all(self, robots: list[_Robot]) -> None:
        for r, each in enumerate(robots):
            if self.held[r]:
                self.release(r, each)

    def block(self, robots: list[_Robot], ends: list[float], lengths: list[float], starts: np.ndarray,
              positions: np.ndarray, modes: np.ndarray | None = None) -> list[int | None]:  # fmt: skip
        """`_judge_block` of every robot (`starts`: N x 2 before the block's first step,
        `positions`: steps x N x 2 after each; `modes`: steps x N, the robots' `modes` side by side,
        when at hand); per robot the step in which it stopped being judged."""
        count = len(ends)
        held, compiled = self.held, self.compiled
        for r, each in enumerate(robots):
            wanted = (
                compiled[r] is not None
                and each.outcome.status == "running"
                and not each.pending_goal
                and each.dwell_until is None
                and count <= compiled[r].capacity
            )
            if wanted != held[r]:
                if wanted:
                    self.hold(r, each)
                else:
                    self.release(r, each)
        ended: list[int | None] = [None] * len(robots)
        python = [r for r in range(len(robots)) if not held[r]]
        if len(python) < len(robots):
            if modes is None:
                modes = np.stack([each.modes for each in robots], axis=1)
            starts = np.ascontiguousarray(starts, dtype=np.float64)
            times, steps = np.array(ends), np.array(lengths)
            events = self.function(
                self.address, len(robots), starts.ctypes.data, positions.ctypes.data, modes.ctypes.data,
                times.ctypes.data, steps.ctypes.data, count, self.ended.ctypes.data,
            )  # fmt: skip
            kernels = self.kernels
            for r in self.ended[:events].tolist():
                each = robots[r]
                x, y, moved, event, code = self.release(r, each)
                why = None
                if code != kernels.CHECK_PYTHON:
                    why = each.monitor._compiled.ended(each.monitor, event, code, count)
                ended[r] = _judge_block(each, ends, lengths, starts[r], (event, why, moved, x, y))
        for r in python:
            ended[r] = _judge_block(robots[r], ends, lengths, starts[r])
        return ended


def _next_goal(each: _Robot, t: float, coordination: FleetCoordination | None = None) -> None:
    """Give the planner the robot's next goal (a replan from where it stands; coordinated: the
    coordinator re-solves before the next block)."""
    goal = each.goals[each.goal_index]
    x, y, theta = (float(value) for value in each.poses[-1])
    planner = each.built.planner
    if coordination is not None and coordination.coordinator is not None:
        why = None
    else:
        why = planner.set_goal(goal.x, goal.y, t, (x, y, theta)) if planner is not None else "no planner"
    if why is not None:
        each.outcome.status = "no_path"
        return
    each.monitor.goal = (goal.x, goal.y)
    each.monitor.tolerance = goal.tolerance
    each.progress.restart(t, math.hypot(goal.x - x, goal.y - y))


def format_fleet(fleet: Fleet, outcome: FleetOutcome) -> str:
    """The summary table: a row per robot and the fleet's line."""
    rows = [
        ("robot", "status", "goals", "time [s]", "distance [m]", "clearance walls [m]",
         "clearance robots [m]", "stopped [s]", "recovery [s]", "deadlocked")
    ]  # fmt: skip
    for robot in outcome.robots:
        rows.append(
            (
                robot.name, robot.status, f"{robot.goals_reached}/{robot.goals}",
                "-" if robot.completion_time is None else f"{robot.completion_time:.2f}",
                f"{robot.distance:.2f}", f"{robot.min_clearance_walls:.3f}",
                f"{robot.min_clearance_robots:.3f}",
                f"{robot.stopped_time:.2f}", f"{robot.recovery_time:.2f}",
                "-" if robot.deadlocked_at is None else f"since {robot.deadlocked_at:.2f} s",
            )
        )  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [
        "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip() for row in rows
    ]
    makespan = outcome.makespan
    lines.append(
        f"fleet: {outcome.reason} at t = {outcome.time:.2f} s; makespan "
        f"{'-' if makespan is None else f'{makespan:.2f} s'}; throughput {outcome.throughput:.1f} goals/h; "
        f"collisions {len(outcome.collisions)}; deadlocks {len(outcome.deadlocks)}; "
        f"wall {outcome.wall_time:.2f} s"
    )
    if outcome.coordination is not None:
        c = outcome.coordination
        lines.append(
            f"coordination: {c['method']}: {c['solves']} solves ({c['failures']} without a plan), "
            f"{c['planning_time']:.2f} s of wall time planning"
        )
    lines += [f"  collision: {contact.describe()}" for contact in outcome.collisions]
    lines += [
        f"  collision: {robot.name} hits a wall or obstacle at t = {robot.collision[0]:.3f} s at "
        f"({robot.collision[1]:.3f}, {robot.collision[2]:.3f})"
        for robot in outcome.robots
        if robot.collision is not None
    ]
    return "\n".join(lines)


def run_fleet_command(args, fleet: Fleet, plot=None, sink=None) -> int:
    """`cosim run FLEET.toml`: run, print the fleet summary; exit 0 only when every robot completed
    (2 when an FMU failed). `plot(log_path)`, when given, draws the PNG beside the log once it is
    written (the plot is a later stage, `cosim.logs`: the CLI hands it in); `sink` (the live view,
    `--realtime`) gets everything the log gets."""
    import sys

    from cosim.record.logfile import default_log_path

    path = Path(args.out if args.out is not None else default_log_path(fleet.first.log_pattern, fleet.name))
    live = getattr(args, "live", False)
    outcome = run_fleet(
        fleet,
        log_path=path,
        force=args.force,
        progress=not args.quiet,
        sink=sink,
        goals=sink if live else None,
    )
    if not args.quiet:
        print(format_fleet(fleet, outcome))
        print(f"log: {path}", file=sys.stdout)
    if outcome.failure is not None:
        print(f"cosim: error: {outcome.failure}; log (up to the failure): {path}", file=sys.stderr)
        return outcome.exit_code
    if plot is not None:
        plot(path)
    return outcome.exit_code
