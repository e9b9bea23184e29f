"""A fleet's per-step topics, a block of steps at a time: each robot's under its ROS namespace.

A fleet is one `System` of every robot's components (`robot1:vehicle`, ...) stepped by one master a
block of steps at a time. `FleetSteps` records each robot as the single-robot run records one
(`cosim.record.steps.StepRecording` on the recorder's view of the robot, `Recorder.namespaced`):
- `/<robot>/signals/<component>`: every scalar input and output of each of the robot's components
  at each of its steps, stamped as in a robot's log (the record at t holds the inputs applied at t
  and the outputs at t; the last one, at the end, the final outputs); a component whose outputs
  never change once, at t = 0;
- `/<robot>/scan` at each lidar step, `/<robot>/cmd_vel` at each step of the commanding component;
- the world's `/obstacles` (the fleet shares them) when a moving obstacle has moved, at the first
  robot's lidar steps, as in a robot's log;
- the poses the fleet hands over (`poses`, `write_poses`): `/<robot>/odom` (frame `<robot>/odom`,
  child `<robot>/base_link`, twist the command), `/<robot>/pose`, then one `/tf` message for every
  robot (`map -> <robot>/odom`, the identity: odometry without drift, and `<robot>/odom ->
  <robot>/base_link`, the pose): one tree under `map`.

`block(first, end, histories, poses)` takes the rows of the steps [first, end) as the master hands
them over (`Master.run_blocks`, `run_recorded`: per component of the master's order its inputs,
then its outputs, after each of its steps; None for a component stepped by Python, which steps at
most in the block's first step and holds its buffers to the block's end: the fleet cuts its blocks
at those components' periods) and collects them; `flush()` hands their messages to
`Recorder.hold_steps` in time order (the key of a message: its step, then its place in the step:
every robot's signal records, every robot's scan and command, the obstacles, then the poses of the
step's end). Per-stream work (hundreds of streams at N = 50) is done once per flush, not per
block: steps are flushed every `WINDOWS` chunk windows of simulated time or the recorder's
`flush_interval` of wall time since the first of them was collected (not since the last flush: a
slow set-up flushes no lone first block), whichever comes first (as `cosim.record.blocks` does),
before a robot halts, and before anything else reaches the recorder (`Recorder.collect`: a schema or
channel registered, metadata, the end), except a message written meanwhile (a plan, a goal), which
is held after the collected steps and before the next block's. Every robot's /scan, /cmd_vel,
/odom and /pose are rows of fixed-layout streams (`Recorder.fixed_channel`), packed in C; only /tf
and /obstacles are CDR payloads. The bytes are those of each block handed over as it comes.
"""

from __future__ import annotations

import math
import struct
import time
from functools import partial
from typing import NamedTuple

import numpy as np

from cosim.core.timebase import NS_PER_S, due_from
from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.record.batch import FixedLayout
from cosim.record.blocks import column_runs
from cosim.record.steps import SignalEntry, StepRecording

ODOM = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
_SENTINEL_NS = 1_234_567_891_987_654_321  # a stamp no run writes, to find in a template
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: int32 sec, uint32 nanosec
_FLOAT64 = struct.Struct("<d")


class _Entry(NamedTuple):
    slot: int  # its place among a step's messages
    index: int  # its component in the master's order (`histories`)
    columns: np.ndarray | slice  # its record in the component's row (a slice: adjacent columns)
    entry: SignalEntry
    kept: np.ndarray | slice | None = None  # its record in the flush's kept columns (`FleetSteps._kept`)


class _Port(NamedTuple):
    """Where an observed output is read: its component's rows (`index`, `column`, `period`), or,
    stepped by Python (no rows), `reading` (its live buffer)."""

    index: int
    column: int
    period: int
    reading: object  # `cosim.record.steps.Reading`
    kept: int = 0  # its column in the flush's kept columns (`FleetSteps._kept`)


class _Live:
    """The entries of components stepped by Python of one period (`period` [steps]), recorded from
    their live buffers with one copy of all their records side by side: `parts` the buffers'
    views in that order (after the `gathers` of gathered records), `places` slot -> the columns
    of its record."""

    def __init__(self, period: int) -> None:
        self.period = period
        self.parts: list[np.ndarray] = []
        self.gathers: list = []
        self.places: dict[int, slice] = {}
        self.width = 0

    def add(self, slot: int, entry: SignalEntry) -> None:
        if entry.gather is not None:
            self.gathers.append(entry.gather)
        parts = (entry.first,) if entry.second is None else (entry.first, entry.second)
        width = sum(len(part) for part in parts)
        self.parts += parts
        self.places[slot] = slice(self.width, self.width + width)
        self.width += width

    @staticmethod
    def records(blocks: list) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """slot -> (steps, records) of the collected blocks' (`FleetSteps.live`)."""
        taken: dict[_Live, tuple[list, list]] = {}
        for group, k, row in blocks:
            steps, rows = taken.setdefault(group, ([], []))
            steps.append(k)
            rows.append(row)
        out = {}
        for group, (steps, rows) in taken.items():
            steps = np.array(steps, dtype=np.int64)
            matrix = np.array(rows)
            for slot, columns in group.places.items():
                out[slot] = (steps, matrix[:, columns])
        return out


class _Robot:
    def __init__(self, name: str, view, recording: StepRecording, entries: list[_Entry], command) -> None:
        self.name = name
        self.view = view
        self.recording = recording
        self.entries = entries
        self.command = command  # (period, [_Port v, _Port omega]) or None
        self.last_command = (
            [port.reading.value() for port in command[1]] if command is not None else None
        )  # after the last step handed over
        self.halted = False  # no longer stepped (`FleetSteps.halt`)
        self.cmd_channel: int | None = None  # its /cmd_vel (`Recorder.fixed_channel`), on first use
        self.scan_channel: int | None = None  # its /scan (`Recorder.scan_channel`), on first use
        self.commands: list[tuple[np.ndarray, np.ndarray]] = []  # read from live buffers: (steps, v omega)
        self.sweeps: list[tuple[int, np.ndarray]] = []  # (step, ranges) of its lidar's collected sweeps
        self.odom_frame = f"{name}/{rosmsg.ODOM_FRAME}"
        self.base_frame = f"{name}/{rosmsg.ROBOT_FRAME}"

    def register_scan(self, scan) -> None:
        """Its /scan channel, registered on first use (the layout of `scan`, its lidar's: the run's)."""
        if self.scan_channel is None:
            self.scan_channel = self.view.scan_channel(
                scan.angles, scan.range_min, scan.range_max, scan.scan_time
            )

    def register_command(self) -> None:
        """Its /cmd_vel channel, registered on first use."""
        if self.cmd_channel is None:
            self.cmd_channel = self.view.cmd_vel_channel()


class FleetSteps:
    """Records a fleet's robots (module docstring). `robots`: (name, system, observed, scenario) of
    each robot in fleet order: its own system (whose components, named `<name>:<component>`, are
    the fleet master's), the description's `Observed` and its scenario."""

    STEPS = 2048  # steps collected at most between two flushes
    WINDOWS = 2  # chunk windows collected at most between two flushes (1 with a live view)

    def __init__(self, recorder, master, robots) -> None:
        self.recorder = recorder
        self.start_ns = master.start_time_ns
        self.h_ns = master.system.macro_step_ns
        index = {id(component): i for i, component in enumerate(master.order)}
        self.robots: list[_Robot] = []
        slot = 0
        for name, system, observed, scenario in robots:
            view = recorder.namespaced(name)
            own = {id(component) for component in system.components.values()}
            order = [component for component in master.order if id(component) in own]
            recording = StepRecording(system, master, view, observed, scenario, order=order)
            entries = []
            for entry in recording.entries:
                inputs = len(entry.component.inputs)
                columns = np.array([*entry.inputs, *(inputs + s for s in entry.outputs)], dtype=np.intp)
                if len(columns) and (columns == np.arange(columns[0], columns[0] + len(columns))).all():
                    columns = slice(int(columns[0]), int(columns[0]) + len(columns))  # a view, not a copy
                entries.append(_Entry(slot, index[id(entry.component)], columns, entry))
                slot += 1
            command = None
            if recording.command is not None:
                ports = []
                for reference, reading in zip(
                    observed.command, (recording.command.v, recording.command.omega), strict=True
                ):
                    component, output = system.resolve(reference, "output")
                    column = len(component.inputs) + output
                    ports.append(_Port(index[id(component)], column, system.period_steps(component), reading))
                command = (recording.command.period, ports)
            self.robots.append(_Robot(name, view, recording, entries, command))
        self.kept = self._kept(master.order)
        # Per component with kept columns, those columns as one slice or an index array.
        self.taken = {
            index: runs[0]
            if len(runs) == 1
            else np.concatenate([np.arange(run.start, run.stop) for run in runs])
            for index, (runs, _) in self.kept.items()
        }
        self.scan_slot = slot  # robot r's scan: scan_slot + 2 r, its command: + 1
        self.obstacle_slot = slot + 2 * len(self.robots)
        self.pose_slot = self.obstacle_slot + 1  # every robot's /odom and /pose, then /tf
        self.per_step = self.pose_slot + 2 * len(self.robots) + 1
        self.world = self.robots[0].recording  # the obstacles the fleet shares
        self._channels: list[int] | None = None  # `_pose_channels`
        self._tf: _Filled | None = None
        # Steps collected, not yet handed to the recorder (`block`, `flush`): [first, end).
        self.first = self.end = None
        self.kinds: tuple[bool, ...] = ()  # per component: stepped by Python (no rows)
        self.collected: list[list] = []  # each block's histories
        # (key, t_ns, channel, payload); keys doubled (`flush`): odd, written between two blocks
        self.others: list[tuple] = []
        # The records of the components stepped by Python: (`_Live` group, step k, every record of
        # the group at k, side by side) per block in which the group stepped.
        self.live: list[tuple[_Live, int, np.ndarray]] = []
        self.poses: list[tuple] = []  # (k, t_ns, `_given` rows)
        self.deferred: set[int] = set()  # robots whose commands are read from the rows at the flush
        self.planned: tuple | None = None  # (kinds, `_plan`)
        self._compacting: tuple | None = None  # (kinds, (component index, kept columns) to copy)
        self.handed = time.monotonic()  # [s] wall clock when the steps held began to be collected
        self.window_ns = recorder.window_ns
        self.windows = self.WINDOWS if recorder.batching else 1
        self.flush_at = 0
        recorder.collect(self)

    def _kept(self, order: list) -> dict[int, tuple[list[slice], int]]:
        """The columns of a component's rows the flush reads (its entry's, its commands'), kept in
        a compact matrix when they are not all of them (array inputs such as a VFH's ranges are not
        recorded): component index -> (runs of kept columns, their count); the entries' and ports'
        `kept` columns address that matrix."""
        needed: dict[int, set[int]] = {}
        for robot in self.robots:
            for entry in robot.entries:
                columns = entry.columns
                taken = range(columns.start, columns.stop) if isinstance(columns, slice) else columns.tolist()
                needed.setdefault(entry.index, set()).update(taken)
            for port in robot.command[1] if robot.command is not None else ():
                needed.setdefault(port.index, set()).add(port.column)
        kept = {}
        place: dict[int, dict[int, int]] = {}
        for index, columns in needed.items():
            columns = sorted(columns)
            component = order[index]
            if columns == list(range(len(component.inputs) + len(component.outputs))):
                place[index] = {column: column for column in columns}
                continue
            kept[index] = (column_runs(columns), len(columns))
            place[index] = {column: at for at, column in enumerate(columns)}
        for robot in self.robots:
            entries = []
            for entry in robot.entries:
                columns = entry.columns
                taken = range(columns.start, columns.stop) if isinstance(columns, slice) else columns.tolist()
                at = [place[entry.index][column] for column in taken]
                if at == list(range(at[0], at[0] + len(at))) if at else True:
                    compact = slice(at[0], at[0] + len(at)) if at else slice(0, 0)
                else:
                    compact = np.array(at, dtype=np.intp)
                entries.append(entry._replace(kept=compact))
            robot.entries = entries
            if robot.command is not None:
                period, ports = robot.command
                robot.command = (
                    period,
                    [port._replace(kept=place[port.index][port.column]) for port in ports],
                )
        return kept

    @property
    def views(self) -> dict[str, object]:
        """Each robot's recorder (`Recorder.namespaced`), by name."""
        return {robot.name: robot.view for robot in self.robots}

    def halt(self, name: str) -> None:
        """Robot `name` is no longer stepped (switched off by the fleet): no more records of its
        components, scans or commands; its signals' last records come at the end of the run, its
        poses from the fleet as before."""
        self.flush()  # the steps collected so far still record it
        next(robot for robot in self.robots if robot.name == name).halted = True
        self.planned = None

    def register_step_channels(self, first: int, end: int) -> None:
        """Register now the channels that `block` of the steps [first, end) would register first
        (each robot's /scan, then its /cmd_vel, robot after robot, those due in the block), as it
        would: the same channels in the same order (~0.1 ms a robot, a fleet's first block's time
        else). Call it where nothing is written to the recorder before that block but its plans
        (which then follow the channels' records instead of preceding them)."""
        for robot in self.robots:
            if robot.halted:
                continue
            scan = robot.recording.scan
            if scan is not None and first % scan.period == 0:
                robot.register_scan(scan)
            if robot.command is not None and due_from(first, robot.command[0]) < end:
                robot.register_command()

    def write_constant(self, t_ns: int) -> None:
        """The records of the components whose outputs are fixed for the run."""
        for robot in self.robots:
            robot.recording.write_constant(t_ns)

    def write_poses(self, t_ns: int, rows) -> None:
        """Every robot's pose messages at t_ns (`rows`: x, y, theta [m, m, rad], v, omega [m/s,
        rad/s] per robot, in fleet order)."""
        self.flush()
        signals, tf = self._pose_messages([(0, t_ns, _given(rows))], 0, 2 * len(self.robots))
        self.recorder.hold_steps(signals, None, tf)

    def _pose_channels(self) -> list[int]:
        """Every robot's /odom, then every robot's /pose (held as rows: `Recorder.fixed_channel`),
        then the /tf channel; registered on first use, in that order."""
        if self._channels is None:
            odometry = [_layout(partial(_odometry, robot), 6) for robot in self.robots]
            pose = _layout(_pose_stamped, 4)
            self._channels = [
                *(
                    r.view.fixed_channel("/odom", layout)
                    for r, layout in zip(self.robots, odometry, strict=True)
                ),
                *(r.view.fixed_channel("/pose", pose) for r in self.robots),
                self.recorder.channel("/tf"),
            ]
            self._tf = _Filled(_Template(partial(_tf, self.robots), 4 * len(self.robots)))
        return self._channels

    @staticmethod
    def _odometry(rows: np.ndarray) -> np.ndarray:
        """Per row x, y, qz, qw, v, omega of a robot's /odom (`rows`: x, y, theta, v, omega, any
        leading shape); the quaternion as `rosmsg.quaternion` computes it."""
        given = rows.reshape(-1, 5)
        halves = (given[:, 2] / 2.0).tolist()
        values = np.empty((len(given), 6))
        values[:, :2] = given[:, :2]
        values[:, 2] = list(map(math.sin, halves))
        values[:, 3] = list(map(math.cos, halves))
        values[:, 4:] = given[:, 3:]
        return values.reshape(*rows.shape[:-1], 6)

    def _pose_messages(self, taken: list, per_step: int, slot: int) -> tuple[list, tuple | None]:
        """The pose messages of `taken` ((step k, t_ns, rows as `write_poses` takes them, float64)
        per pose time): the rows of every robot's /odom and /pose (keys k * per_step + slot + 2 r,
        + 1) for `hold_steps`' signals, and the /tf messages (key k * per_step + slot + 2 N) as its
        others."""
        channels = self._pose_channels()
        if not taken:
            return [], None
        count = len(self.robots)
        steps = np.array([k for k, _, _ in taken], dtype=np.int64)
        times = np.array([t_ns for _, t_ns, _ in taken], dtype=np.int64)
        # pose time, robot, column (`_odometry`): every pose time's at once
        values = self._odometry(np.stack([rows for _, _, rows in taken]))
        base = steps * per_step + slot
        signals = []
        for number in range(count):
            signals.append((channels[number], base + 2 * number, times, values[:, number]))
            signals.append((channels[count + number], base + 2 * number + 1, times, values[:, number, :4]))
        tf = self._tf
        payloads = [(channels[-1], payload) for payload in tf.fill_all(times.tolist(), values[:, :, :4])]
        return signals, (base + 2 * count, times, payloads)

    def block(self, first: int, end: int, histories, poses=()) -> None:
        """Collect the steps [first, end) from their rows (module docstring); `poses`: (step k,
        t_ns, rows as for `write_poses`) of the poses written at the end of step k. The arrays
        of `histories` that own their data (base None) are kept until the steps are flushed: the
        caller must not change them after (the others are copied)."""
        start_ns, h_ns, per_step = self.start_ns, self.h_ns, self.per_step
        kinds = tuple([rows is None for rows in histories])
        if self.first is not None and (kinds != self.kinds or end - self.first > self.STEPS):
            self.flush()
        robots, live = self._plan(kinds)
        # What may register a channel first (the collected steps go before it: `Recorder.settle`):
        # each robot's scan, then its command, robot after robot.
        others = []
        sweeps = []  # (robot, its ranges) of the lidars stepped in the block
        commands = []  # robots whose commands are read from the rows at the flush
        due: dict[int, np.ndarray] = {}  # period -> its steps in the block
        for number, robot, scan, python in robots:
            if scan is not None and first % scan.period == 0:  # a lidar steps in a block's first step
                robot.register_scan(scan)
                sweeps.append((robot, scan.current().copy()))
            if python is None:
                continue
            period, ports = robot.command
            steps = due.get(period)
            if steps is None:
                steps = due[period] = np.arange(due_from(first, period), end, period, dtype=np.int64)
            if len(steps):
                robot.register_command()
                if python:  # read now, from live buffers
                    values = [self._held(histories, port, first, end, steps, last)
                              for port, last in zip(ports, robot.last_command, strict=True)]  # fmt: skip
                    robot.commands.append((steps, np.array(values).T))
                    robot.last_command = [float(value[-1]) for value in values]
                else:
                    commands.append(number)
        for k, t_ns, payload in self.world.obstacle_payloads(first, end, start_ns, h_ns):
            others.append(
                (k * per_step + self.obstacle_slot, t_ns, self.recorder.channel("/obstacles"), payload)
            )
        taken = [(k, t_ns, _given(rows)) for k, t_ns, rows in poses]
        if taken:
            self._pose_channels()
        # Then the block joins the collected steps.
        if self.first is None:  # the first steps held: their wall time counts from now
            self.first, self.kinds = first, kinds
            self.handed = time.monotonic()
            self.flush_at = ((start_ns + first * h_ns) // self.window_ns + self.windows) * self.window_ns
        self.end = end
        self.collected.append(self._compact(histories, kinds))
        for number in commands:
            self.deferred.add(number)
        for robot, ranges in sweeps:
            robot.sweeps.append((first, ranges))
        for group in live:  # stepped by Python: their live buffers, a group's in one copy
            if first % group.period == 0:
                for gather in group.gathers:
                    gather.take()
                self.live.append((group, first, np.concatenate(group.parts)))
        self.others += [(2 * key, t_ns, channel, payload) for key, t_ns, channel, payload in others]
        self.poses += taken
        t_last = start_ns + (end - 1) * h_ns
        if t_last >= self.flush_at or end - self.first >= self.STEPS:
            self.flush()
        elif time.monotonic() - self.handed >= self.recorder.flush_interval:
            self.flush()  # a killed run loses no more wall time of steps than the recorder's flushes

    def _compact(self, histories, kinds: tuple[bool, ...]) -> list:
        """A block's rows as the flush reads them: of a component with `kept` columns only those,
        in their compact order (a copy); the others as they are when they own their data, else a
        copy (the caller's buffers may be refilled)."""
        if self._compacting is None or self._compacting[0] != kinds:
            taken = self.taken
            self._compacting = (
                kinds,
                [(index, taken.get(index)) for index, python in enumerate(kinds) if not python],
            )
        out = [None] * len(histories)
        for index, columns in self._compacting[1]:
            rows = histories[index]
            if columns is None:
                out[index] = rows if rows.base is None else rows.copy()
            elif type(columns) is slice:
                out[index] = rows[:, columns].copy()
            else:
                out[index] = rows.take(columns, axis=1)
        return out

    def _plan(self, kinds: tuple[bool, ...]) -> tuple[list, list]:
        """What a block records of the robots still stepped, for components stepped by Python where
        `kinds` says (made again when that or a robot's halt changes it): per robot (its number,
        the robot, its scan ports or None, whether a command port is stepped by Python or None: no
        command), and the entries stepped by Python, grouped by period (`_Live`)."""
        if self.planned is None or self.planned[0] != kinds:
            robots, groups = [], {}
            for number, robot in enumerate(self.robots):
                if robot.halted:
                    continue
                python = None
                if robot.command is not None:
                    python = any(kinds[port.index] for port in robot.command[1])
                robots.append((number, robot, robot.recording.scan, python))
                for entry in robot.entries:
                    if kinds[entry.index]:
                        groups.setdefault(entry.entry.period, _Live(entry.entry.period)).add(
                            entry.slot, entry.entry
                        )
            self.planned = (kinds, (robots, list(groups.values())))
        return self.planned[1]

    def written(self, channel: int, t_ns: int, payload: bytes) -> bool:
        """A message written to the log while steps are collected (a plan, a goal): held after
        them (True), or False when none are (the recorder writes it)."""
        if self.first is None:
            return False
        self.others.append((2 * self.end * self.per_step - 1, t_ns, channel, payload))  # odd: between
        return True

    def flush(self) -> None:
        """Hand the collected steps' messages to `Recorder.hold_steps`."""
        if self.first is None:
            return
        first, end, kinds, collected = self.first, self.end, self.kinds, self.collected
        others, live, taken, deferred = self.others, self.live, self.poses, self.deferred
        self.first = self.end = None
        self.collected, self.others, self.live, self.poses, self.deferred = [], [], [], [], set()
        start_ns, h_ns = self.start_ns, self.h_ns
        # Keys doubled: a message written between two blocks (`written`) sorts between them (odd key).
        per_step = 2 * self.per_step
        rows_of: dict[int, np.ndarray] = {}
        live = _Live.records(live)

        def rows(index: int) -> np.ndarray:
            found = rows_of.get(index)
            if found is None:
                parts = [part[index] for part in collected]  # (`_compact`)
                found = parts[0] if len(parts) == 1 else np.concatenate(parts)
                rows_of[index] = found
            return found

        signals = []
        due: dict[int, tuple] = {}  # period -> the steps' count, keys (slot 0) and stamps, for all robots
        for number, robot in enumerate(self.robots):
            if robot.halted:
                continue
            for slot, index, _, entry, columns in robot.entries:
                if kinds[index]:  # stepped by Python: in a block's first step at most
                    records = live.get(slot)
                    if records is not None:
                        steps, values = records
                        signals.append(
                            (entry.channel, steps * per_step + 2 * slot, start_ns + steps * h_ns, values)
                        )
                    continue
                period = entry.period
                shared = due.get(period)
                if shared is None:
                    steps = np.arange(due_from(first, period), end, period, dtype=np.int64)
                    shared = due[period] = (len(steps), steps * per_step, start_ns + steps * h_ns)
                count, keys, times = shared
                if count:
                    signals.append((entry.channel, keys + 2 * slot, times, rows(index)[:count, columns]))
            if robot.sweeps:
                scan, view = robot.recording.scan, robot.view
                limits = (scan.range_min, scan.range_max, scan.scan_time)
                steps = np.array([k for k, _ in robot.sweeps], dtype=np.int64)
                times = start_ns + steps * h_ns
                sweep_rows = view.scan_rows(
                    times, scan.angles, np.array([r for _, r in robot.sweeps]), *limits
                )
                robot.sweeps = []
                keys = steps * per_step + 2 * (self.scan_slot + 2 * number)
                signals.append((robot.scan_channel, keys, times, sweep_rows))
            slot = 2 * (self.scan_slot + 2 * number + 1)
            if number in deferred:
                period, ports = robot.command
                steps = np.arange(due_from(first, period), end, period, dtype=np.int64)
                values = np.empty((len(steps), 2))
                for column, (port, last) in enumerate(zip(ports, robot.last_command, strict=True)):
                    values[:, column] = _latest(
                        rows(port.index)[:, port.kept], first, port.period, steps, last
                    )
                robot.last_command = values[-1].tolist()
                signals.append((robot.cmd_channel, steps * per_step + slot, start_ns + steps * h_ns, values))
            elif robot.commands:
                steps = np.concatenate([steps for steps, _ in robot.commands])
                values = np.concatenate([values for _, values in robot.commands])
                robot.commands = []
                signals.append((robot.cmd_channel, steps * per_step + slot, start_ns + steps * h_ns, values))
        poses, tf = self._pose_messages(taken, self.per_step, self.pose_slot)
        signals += [(channel, 2 * keys, times, values) for channel, keys, times, values in poses]
        if tf is not None:
            keys, times, payloads = tf
            others += [
                (2 * key, t_ns, *payload)
                for key, t_ns, payload in zip(keys.tolist(), times.tolist(), payloads, strict=True)
            ]
        other = None
        if others:
            keys = np.array([key for key, _, _, _ in others], dtype=np.int64)
            times = np.array([message[1] for message in others], dtype=np.int64)
            other = (keys, times, [(channel, payload) for _, _, channel, payload in others])
        self.recorder.hold_steps(signals, None, other)

    @staticmethod
    def _held(histories, port: _Port, first: int, end: int, steps: np.ndarray, last: float) -> list[float]:
        """The value of `port` after each of `steps` (in [first, end)): its component's latest row
        at or before the step (before its first row in the block: `last`)."""
        rows = histories[port.index]
        if rows is None:
            return [port.reading.value()] * len(steps)
        due = due_from(first, port.period)
        column = rows[: len(range(due, end, port.period)), port.column]
        at = (steps - due) // port.period
        return [float(column[j]) if j >= 0 else last for j in at.tolist()]


def _given(rows) -> np.ndarray:
    """Poses as `FleetSteps.write_poses` takes them (x, y, theta, v, omega per robot): a float64
    copy, robot by robot (the caller may reuse its buffers)."""
    return np.array(rows, dtype=np.float64).reshape(-1, 5)


def _latest(column: np.ndarray, first: int, period: int, steps: np.ndarray, last: float) -> np.ndarray:
    """The value of a column of a component's rows from step `first` on (one row per step k with
    k % period == 0) after each of `steps`: its latest row at or before the step (`last` before
    its first)."""
    at = (steps - due_from(first, period)) // period
    values = column[np.maximum(at, 0)]
    if len(at) and at[0] < 0:
        values = np.where(at >= 0, values, last)
    return values


def _layout(build, count: int) -> FixedLayout:
    """The `FixedLayout` of messages `build(t_ns, values)` makes (`count` float64 values, at most two
    stamps), found by serialising sentinel values once (`_Template`)."""
    template = _Template(build, count)
    if len(template.stamps) > 2:
        raise CosimError("unexpected CDR layout of a pose message")
    fields = {}
    for suffix, at in zip(("", "2"), template.stamps, strict=False):
        fields |= {"sec" + suffix: ("<i4", at), "nanosec" + suffix: ("<u4", at + 4)}
    names = tuple(f"f{column}" for column in range(count))
    fields |= {name: ("<f8", at) for name, at in zip(names, template.fields, strict=True)}
    return FixedLayout(bytes(template.data), fields, names)


class _Filled:
    """A `_Template`'s bytes for a time and values by fancy-index assignments (the /tf message of
    every robot: `fill(t_ns, values)`, values an array of the template's float64 fields), or for
    many at once (`fill_all`)."""

    def __init__(self, template: _Template) -> None:
        self.data = np.frombuffer(bytes(template.data), np.uint8).copy()
        self.stamp_bytes = (np.array(template.stamps, dtype=np.intp)[:, None] + np.arange(8)).reshape(-1)
        self.field_bytes = (np.array(template.fields, dtype=np.intp)[:, None] + np.arange(8)).reshape(-1)
        self.stamps = len(template.stamps)

    def fill(self, t_ns: int, values: np.ndarray) -> bytes:
        return self.fill_all([t_ns], np.asarray(values)[None])[0]

    def fill_all(self, times: list[int], values: np.ndarray) -> list[bytes]:
        """The messages at `times` [ns] (`values`: the fields of each time, first axis the times)."""
        count = len(times)
        data = np.empty((count, len(self.data)), np.uint8)
        data[:] = self.data
        stamps = np.empty(count, dtype=[("sec", "<i4"), ("nanosec", "<u4")])
        for row, t_ns in enumerate(times):  # as _STAMP packs them (int32 seconds: checked)
            stamps[row] = divmod(int(t_ns), NS_PER_S)
        data[:, self.stamp_bytes] = np.tile(stamps.view(np.uint8).reshape(count, 8), self.stamps)
        fields = np.ascontiguousarray(values, dtype="<f8").reshape(count, -1)
        data[:, self.field_bytes] = fields.view(np.uint8)
        return [row.tobytes() for row in data]


class _Template:
    """The CDR bytes of one message layout with the offsets of its stamps and of its varying float64
    fields, found by serialising sentinel values once (`build(t_ns, values)` -> bytes): the layout
    does not depend on the values, so `fill(t_ns, values)` gives the bytes `build` gives, without
    building the message (the fleet writes 2 N + 1 pose messages at each pose time)."""

    def __init__(self, build, count: int) -> None:
        sentinels = [1.0e250 * (index + 1.5) for index in range(count)]
        data = build(_SENTINEL_NS, sentinels)
        self.data = bytearray(data)
        self.stamps = rosmsg.pattern_offsets(data, _STAMP.pack(*divmod(_SENTINEL_NS, NS_PER_S)))
        self.fields = [rosmsg.pattern_offsets(data, _FLOAT64.pack(value)) for value in sentinels]
        if not self.stamps or any(len(found) != 1 for found in self.fields):
            raise CosimError("unexpected CDR layout of a pose message")
        self.fields = [found[0] for found in self.fields]

    def fill(self, t_ns: int, values) -> bytes:
        data = self.data
        stamp = _STAMP.pack(*divmod(int(t_ns), NS_PER_S))
        for at in self.stamps:
            data[at : at + 8] = stamp
        for at, value in zip(self.fields, values, strict=True):
            data[at : at + 8] = _FLOAT64.pack(value)
        return bytes(data)


def _pose_stamped(t_ns: int, values) -> bytes:
    """/<robot>/pose: x, y, qz, qw of `values` in frame map (the bytes of `rosmsg.pose_stamped_cdr`)."""
    x, y, qz, qw = values
    orientation = rosmsg.make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=qz, w=qw)
    pose = rosmsg.make("geometry_msgs/msg/Pose", position=rosmsg.point(x, y), orientation=orientation)
    message = rosmsg.make(
        "geometry_msgs/msg/PoseStamped", header=rosmsg.header(t_ns, rosmsg.MAP_FRAME), pose=pose
    )
    return rosmsg.serialize(message, "geometry_msgs/msg/PoseStamped")


def _odometry(robot: _Robot, t_ns: int, values) -> bytes:
    """/<robot>/odom: pose (x, y, qz, qw) in `<robot>/odom` of child `<robot>/base_link`, twist (v,
    omega), zero covariances."""
    x, y, qz, qw, v, omega = values
    orientation = rosmsg.make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=qz, w=qw)
    pose = rosmsg.make("geometry_msgs/msg/Pose", position=rosmsg.point(x, y), orientation=orientation)
    message = rosmsg.make(
        ODOM,
        header=rosmsg.header(t_ns, robot.odom_frame),
        child_frame_id=robot.base_frame,
        pose=rosmsg.make("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36)),
        twist=rosmsg.make(
            "geometry_msgs/msg/TwistWithCovariance", twist=rosmsg.twist(v, omega), covariance=np.zeros(36)
        ),
    )
    return rosmsg.serialize(message, ODOM)


def _tf(robots: list[_Robot], t_ns: int, values) -> bytes:
    """/tf: per robot `map -> <robot>/odom` (the identity) and `<robot>/odom -> <robot>/base_link`
    (x, y, qz, qw of `values`, 4 per robot)."""
    transforms = []
    for number, robot in enumerate(robots):
        x, y, qz, qw = values[4 * number : 4 * number + 4]
        transforms.append(_transform(t_ns, rosmsg.MAP_FRAME, robot.odom_frame, 0.0, 0.0, 0.0, 1.0))
        transforms.append(_transform(t_ns, robot.odom_frame, robot.base_frame, x, y, qz, qw))
    return rosmsg.serialize(rosmsg.make(TF, transforms=transforms), TF)


def _transform(t_ns: int, parent: str, child: str, x: float, y: float, qz: float, qw: float):
    return rosmsg.make(
        "geometry_msgs/msg/TransformStamped",
        header=rosmsg.header(t_ns, parent),
        child_frame_id=child,
        transform=rosmsg.make(
            "geometry_msgs/msg/Transform",
            translation=rosmsg.vector3(x, y, 0.0),
            rotation=rosmsg.make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=qz, w=qw),
        ),
    )
