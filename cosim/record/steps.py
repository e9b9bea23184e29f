"""What a robot run records at each step, and where each value is read: the per-step recording.

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
- a pose sensor's topic (`/imu`): at every end of a step on its grid (t = n / rate, n >= 1, up
  to the stop time), its message for the pose then (`PoseSensor`).

`StepRecording.after_step(k, ...)` writes what step k produced, one step at a time (the Python
loop, and the kernel's blocks replayed step by step: `cosim.record.replay`); `cosim.record.blocks`
writes the same messages from a block's rows. Components and ports are the system's own; what is
read besides the signals (pose, command, mode, scan) comes from the description's `Observed`, by
name, resolved once into the named records below.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np

from cosim.core.timebase import NS_PER_S, due_from
from cosim.world.shapes import moves


class Gather(NamedTuple):
    """A record whose ports are not one run of slots: gathered into `values` at each step."""

    inputs: np.ndarray  # the component's input buffer
    input_index: np.ndarray  # slots of the recorded inputs
    input_part: np.ndarray  # where they go in the record (a view of `values`)
    outputs: np.ndarray  # the component's output buffer
    output_index: np.ndarray
    output_part: np.ndarray

    def take(self) -> None:
        """Gather the current values into the record."""
        # mode="clip": with the default "raise" NumPy buffers `out` (a copy per call).
        np.take(self.inputs, self.input_index, out=self.input_part, mode="clip")
        np.take(self.outputs, self.output_index, out=self.output_part, mode="clip")


class SignalEntry(NamedTuple):
    """One component's `/signals/<component>` record: the scalar inputs, then the outputs."""

    period: int  # [steps] the component's
    channel: int
    first: np.ndarray  # the record (gathered), or a view of the inputs
    second: np.ndarray | None  # a view of the outputs; None when gathered
    gather: Gather | None
    component: object  # the `Component`
    inputs: list[int]  # slots of the recorded inputs
    outputs: list[int]  # slots of the recorded outputs

    def record(self) -> np.ndarray:
        """A copy of the record as the buffers hold it now."""
        if self.gather is not None:
            self.gather.take()
            return self.first.copy()
        return np.concatenate((self.first, self.second))


class ConstantEntry(NamedTuple):
    """A component whose outputs never change (the planner): its record once, at t = 0."""

    channel: int
    component: object
    inputs: list[int]
    outputs: list[int]


class PoseSensor(Protocol):
    """A sensor that reads the robot's pose on its own grid (`cosim.world.imu.Imu`): its topic (of
    the topic table), its period [macro steps], the pose at the start, and its message for the pose
    at each sample, in time order (it may keep state between samples)."""

    topic: str
    steps: int

    def start(self, t_ns: int, x: float, y: float, theta: float) -> None:
        """The pose [m, m, rad] at the start t_ns [ns] (no message)."""

    def sample(self, t_ns: int, x: float, y: float, theta: float) -> bytes:
        """The CDR payload of the message at t_ns [ns] for the pose [m, m, rad] then."""


class Reading(NamedTuple):
    """Where one observed output is read: a component's output buffer and the slot in it."""

    buffer: np.ndarray
    slot: int

    def value(self) -> float:
        return self.buffer.item(self.slot)  # .item: a Python float without a NumPy scalar


class CommandPorts(NamedTuple):
    """The commanded velocities (/cmd_vel, the twist of /odom), read at the commanding component's
    steps."""

    period: int  # [steps]
    v: Reading  # [m/s]
    omega: Reading  # [rad/s]


class ModePort(NamedTuple):
    """The avoidance mode the outcome counts, read at its component's steps."""

    period: int  # [steps]
    period_s: float  # [s]
    mode: Reading


class ScanPorts(NamedTuple):
    """The lidar's ranges for /scan, and the scan's fixed layout."""

    period: int  # [steps] the lidar's
    buffer: np.ndarray  # the lidar's output buffer
    ranges: np.ndarray | None  # a view of the ranges in it, or None: gathered through `gather`
    gather: np.ndarray | None
    angles: np.ndarray  # [rad] fixed for the run: the recorder keeps its /scan layout
    range_min: float  # [m]
    range_max: float  # [m]
    scan_time: float  # [s] the lidar's period

    def current(self) -> np.ndarray:
        return self.ranges if self.gather is None else self.buffer[self.gather]


def reading(component, slot: int) -> Reading:
    """Where output `slot` of `component` is read."""
    return Reading(component.output_buffer, slot)


def run_view(buffer: np.ndarray, slots: list[int]) -> np.ndarray | None:
    """A view of `buffer[slots]` when the slots are consecutive (it follows the buffer), else None."""
    if slots and slots != list(range(slots[0], slots[0] + len(slots))):
        return None
    return buffer[slots[0] : slots[0] + len(slots)] if slots else buffer[:0]


class StepRecording:
    """What the loop records at each step; index arrays are resolved once (module docstring).

    `system`, `master` (its step order and stop time), `recorder`, `observed` (the description's
    `Observed`) and `scenario` (signal_arrays, pose_rate, macro_step, obstacles) of the run;
    `sensors`: the pose sensors the run records; `order`: the components recorded, in the master's
    step order (default: all of `master.order`; a fleet's robot: its own).
    """

    def __init__(
        self,
        system,
        master,
        recorder,
        observed,
        scenario,
        sensors: tuple[PoseSensor, ...] = (),
        order: list | None = None,
    ):
        self.recorder = recorder
        self.sensors = tuple(sensors)
        self.stop_ns = master.stop_time_ns  # a last step cut short ends there, and so does its pose
        # What the recording asks of the system, asked once: each component's period [steps], where
        # each observed output is read, the lidar.
        periods = {component.name: system.period_steps(component) for component in system.components.values()}
        found = {reference: system.resolve(reference, "output") for _, reference in observed.references()}
        lidar = system.component(observed.scan.component) if observed.scan is not None else None
        h = system.macro_step  # [s]
        self.entries: list[SignalEntry] = []
        self.constant: list[ConstantEntry] = []
        arrays = scenario.signal_arrays
        for component in master.order if order is None else order:
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
                self.constant.append(ConstantEntry(channel, component, inputs, outputs))
                continue
            period = periods[component.name]
            channel = recorder.signal_channel(
                component.name,
                names,
                units=units,
                inputs=len(inputs),
                initial=np.concatenate((component.input_buffer[inputs], component.output_buffer[outputs])),
                period_ns=period * system.macro_step_ns,
            )
            # Where the scalar inputs are one run of slots (all ports, or the scalars before the
            # arrays), the record is two views of the buffers made once: no gather per step.
            first = run_view(component.input_buffer, inputs)
            second = run_view(component.output_buffer, outputs)
            gather = None
            if first is None or second is None:
                first, second = np.empty(len(names)), None  # the record, reused: no allocation per step
                gather = Gather(
                    component.input_buffer,
                    np.array(inputs, dtype=np.intp),
                    first[: len(inputs)],
                    component.output_buffer,
                    np.array(outputs, dtype=np.intp),
                    first[len(inputs) :],
                )
            self.entries.append(
                SignalEntry(period, channel, first, second, gather, component, inputs, outputs)
            )
        self.pose = tuple(reading(*found[reference]) for reference in observed.pose)  # x, y, theta
        for sensor in self.sensors:
            sensor.start(master.start_time_ns, *self.current_pose())
        self.command = None
        if observed.command is not None:
            v, omega = (reading(*found[reference]) for reference in observed.command)
            commanding = found[observed.command[0]][0]
            self.command = CommandPorts(periods[commanding.name], v, omega)
        self.mode = None
        if observed.mode is not None:
            component, _ = found[observed.mode]
            steps = periods[component.name]
            self.mode = ModePort(steps, steps * h, reading(*found[observed.mode]))
        self.scan = None
        if lidar is not None:
            source = observed.scan
            ranges_index = [i for i, p in enumerate(lidar.outputs) if p.array_name == "ranges"]
            ranges = run_view(lidar.output_buffer, ranges_index)
            angles = np.array(source.angles, dtype=float)
            angles.flags.writeable = False
            period = periods[lidar.name]
            self.scan = ScanPorts(
                period,
                lidar.output_buffer,
                ranges,
                None if ranges is not None else np.array(ranges_index, dtype=np.intp),
                angles,
                source.range_min,
                source.range_max,
                period * h,
            )
        self.pose_steps = max(1, round(1.0 / (scenario.pose_rate * scenario.macro_step)))
        self.obstacles = scenario.obstacles
        self.moving = [obstacle.motion for obstacle in self.obstacles if moves(obstacle)]
        self.obstacle_offsets = tuple((0.0, 0.0) for _ in self.moving)  # as written at t = 0
        # Moved obstacles go out with the scans (the poses each scan saw), else at the pose rate.
        self.obstacle_steps = self.scan.period if self.scan is not None else self.pose_steps

    def write_constant(self, t_ns: int) -> None:
        """The records of the components whose outputs are fixed for the run (the plan)."""
        for channel, component, inputs, outputs in self.constant:
            record = np.concatenate((component.input_buffer[inputs], component.output_buffer[outputs]))
            self.recorder.write_signals(channel, t_ns, record)

    def current_pose(self) -> tuple[float, float, float]:
        """x [m], y [m], theta [rad] of the robot as the buffers hold them now."""
        x, y, theta = self.pose
        return x.value(), y.value(), theta.value()

    def write_pose(self, t_ns: int) -> None:
        x, y, theta = self.current_pose()
        v = omega = math.nan
        if self.command is not None:
            v, omega = self.command.v.value(), self.command.omega.value()
        self.recorder.write_pose(t_ns, x, y, theta, v, omega)

    def moved_obstacles(self, t_ns: int) -> list | None:
        """The obstacles at t_ns when any moved since the last time they were taken, else None."""
        t = t_ns / NS_PER_S
        offsets = tuple(motion.offset(t) for motion in self.moving)
        if offsets == self.obstacle_offsets:
            return None
        self.obstacle_offsets = offsets
        return [obstacle.at(t) for obstacle in self.obstacles]

    def obstacle_payloads(self, first: int, end: int, start_ns: int, h_ns: int):
        """(k, t_ns, /obstacles payload) for each step k of first .. end - 1 at which the moving
        obstacles are due (every `obstacle_steps`) and have moved since they were last taken."""
        if not self.moving:
            return
        steps = self.obstacle_steps
        for k in range(due_from(first, steps), end, steps):
            t_ns = start_ns + k * h_ns
            obstacles = self.moved_obstacles(t_ns)
            if obstacles is not None:
                yield k, t_ns, self.recorder.obstacles_payload(t_ns, obstacles)

    def after_step(self, k: int, t_ns: int, h_ns: int) -> None:
        """Record what step k (starting at t_ns) produced."""
        hold = self.recorder.hold_signals
        for entry in self.entries:
            period = entry.period
            if period == 1 or k % period == 0:
                if entry.gather is not None:
                    entry.gather.take()
                hold(entry.channel, t_ns, entry.first, entry.second)
        recorder = self.recorder
        scan = self.scan
        if scan is not None and k % scan.period == 0:
            recorder.write_scan(
                t_ns, scan.angles, scan.current(), scan.range_min, scan.range_max, scan.scan_time
            )
        if self.moving and k % self.obstacle_steps == 0:
            # /obstacles at the poses the lidar saw at t_ns, when any obstacle moved since the last one.
            obstacles = self.moved_obstacles(t_ns)
            if obstacles is not None:
                recorder.write_obstacles(t_ns, obstacles)
        command = self.command
        if command is not None and k % command.period == 0:
            recorder.write_cmd_vel(t_ns, command.v.value(), command.omega.value())
        if (k + 1) % self.pose_steps == 0:
            self.write_pose(min(t_ns + h_ns, self.stop_ns))
        for sensor in self.sensors:
            end_ns = t_ns + h_ns
            if (k + 1) % sensor.steps == 0 and end_ns <= self.stop_ns:
                recorder.write_payload(sensor.topic, end_ns, sensor.sample(end_ns, *self.current_pose()))
