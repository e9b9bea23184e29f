"""The kernel path's recording and checks, a block of steps at a time (`cosim.record.replay`).

Every component of a block has rows (the kernel's, and, with `python_rows` tables, those
`run_blocks` writes for the lidar and planner), or is stepped by Python at most in the block's
first step (its live buffers hold that step's values to the block's end), so what the per-step
recording (`cosim.record.steps.StepRecording.after_step`) and the outcome checks do step by step
can be done over the block's rows: the positions are checked in one call of the monitor's
`check_positions` (the same arithmetic, step by step: in C for a static world), the lidar's
ranges are kept from its rows, and the columns the recording reads are copied into buffers that
collect the steps of several blocks. `flush()` turns those steps into their messages with NumPy
(signal records, /odom /tf /pose at the pose rate, /cmd_vel and the mixer's mode at the mixer's
rate, every sweep's /scan row at once: `Recorder.scan_rows`; moved obstacles were made at their
steps) and hands them to `Recorder.hold_steps`, which writes the bytes of the per-step path.
Steps are flushed every `WINDOWS` chunk windows of simulated time or the recorder's
`flush_interval` of wall time, whichever comes first (every window with a live view), before
anything else is written (a new plan, a goal), when the buffers are full, and at the end of the
run. A block the rows cannot
describe (a component stepped by Python due after its first step, a topic's first message) is
flushed and replayed step by step (`cosim.record.replay`).
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from cosim.core.timebase import NS_PER_S, due_from
from cosim.record.steps import SignalEntry, StepRecording

POSE_MESSAGES = 3  # a pose is written on /odom, /tf and /pose, in that order


class StepOrder(NamedTuple):
    """Where each message of a step sorts: key = step * `per_step` + slot, the order in which the
    per-step path writes them: the signal records (slot = their entry's index), then /scan,
    /obstacles, /cmd_vel, the pose's messages, and the pose sensors' (`StepRecording.sensors`)."""

    signals: int  # signal entries
    sensors: int = 0  # pose sensors

    def sensor(self, index: int) -> int:
        return self.signals + 3 + POSE_MESSAGES + index

    @property
    def scan(self) -> int:
        return self.signals

    @property
    def obstacles(self) -> int:
        return self.signals + 1

    @property
    def cmd_vel(self) -> int:
        return self.signals + 2

    @property
    def pose(self) -> int:
        return self.signals + 3  # POSE_MESSAGES keys from here

    @property
    def per_step(self) -> int:
        return self.signals + 3 + POSE_MESSAGES + self.sensors


class Column(NamedTuple):
    """One value in the collected rows: component `index` (in the kernel's plan), `column` of its row."""

    index: int
    column: int


class BlockEntry(NamedTuple):
    """A signal entry as a block records it."""

    slot: int  # its index among the step's records (`StepOrder`)
    index: int  # its component in the kernel's plan
    columns: np.ndarray | slice | None  # its record in the component's row; None: stepped by Python
    entry: SignalEntry


class OtherMessage(NamedTuple):
    """A message made at its step (a scan, moved obstacles, a twist), waiting for the flush."""

    key: int
    t_ns: int
    topic: str
    payload: bytes


def read_columns(component, outputs: set[int]) -> list[slice]:
    """The columns of a component's row (its inputs, then its outputs) that the recording reads,
    as runs: its scalar inputs (their run of slots, or all inputs when arrays lie between them, as
    `cosim.record.replay` holds them) and its `outputs` slots (recorded or observed). The other
    columns of the collected rows are never read (a replay sets them for its steps, then puts the
    live values back)."""
    n_in = len(component.inputs)
    slots = [i for i, port in enumerate(component.inputs) if not port.is_array_element]
    if not slots:
        columns = []
    elif slots == list(range(slots[0], slots[-1] + 1)):
        columns = slots
    else:
        columns = list(range(n_in))
    columns += sorted(n_in + slot for slot in outputs)
    return column_runs(columns)


def column_runs(columns: list[int]) -> list[slice]:
    """Ascending `columns` as runs of consecutive columns ([0, 1, 2, 5, 6] -> 0:3, 5:7)."""
    runs: list[slice] = []
    for column in columns:
        if runs and runs[-1].stop == column:
            runs[-1] = slice(runs[-1].start, column + 1)
        else:
            runs.append(slice(column, column + 1))
    return runs


class BlockRecording:
    """Records and checks blocks of kernel steps from their rows (module docstring).

    `recording` is the run's `StepRecording`; `monitor` checks positions (`check_positions(times,
    xs, ys)` -> (index, reason)) and counts modes (`check_mode(mode, period)`);
    `finish_checks(k, reason, before_write)` is the run's end of step k after its position check;
    `polled` the period [steps] of the goal poll (0 without)."""

    STEPS = 2048  # steps collected at most between two flushes
    WINDOWS = 2  # chunk windows collected at most between two flushes (1 with a live view): 4 s

    def __init__(
        self, system, master, recording: StepRecording, observed, monitor, finish_checks, polled: int
    ) -> None:
        self.system = system
        self.recording = recording
        self.recorder = recording.recorder
        self.monitor = monitor
        self.finish_checks = finish_checks
        self.polled = polled
        self.components = list(master.order)  # as the kernel's rows (`histories`) are ordered
        self.periods = [system.period_steps(component) for component in self.components]
        self.index = {component.name: i for i, component in enumerate(self.components)}
        self.start_ns = master.start_time_ns
        self.h_ns = system.macro_step_ns
        self.window_ns = self.recorder.window_ns
        self.observed = observed
        self.ready = False
        self.usable = True
        self.first = self.end = None  # steps collected, not yet flushed: [first, end)
        self.handed = time.monotonic()  # [s] wall clock of the last flush
        self.buffers: dict[int, np.ndarray] = {}
        self.ends_first, self.ends_table = 0, np.empty(0)  # `_ends`

    def _column(self, reference: str) -> Column:
        """Where an observed "component.port" output sits in the collected rows."""
        component, slot = self.system.resolve(reference, "output")
        return Column(self.index[component.name], len(component.inputs) + slot)

    def _setup(self, histories) -> None:
        """On the first block: which components have rows, the buffers, the message layout."""
        self.ready = True
        recorded = [history is not None for history in histories]
        recording, observed = self.recording, self.observed
        self.python = [  # stepped by Python: (plan index, period)
            (i, self.periods[i])
            for i, component in enumerate(self.components)
            if not recorded[i] and not component.constant_outputs
        ]
        needed = [*observed.pose, *(observed.command or ()), *([observed.mode] if observed.mode else [])]
        if not all(recorded[self._column(reference).index] for reference in needed):
            self.usable = False
            return
        # A lidar with rows (`KernelTables` with `python_rows`): each scan from its row.
        self.scan_rows: tuple[int, np.ndarray | slice] | None = None
        if recording.scan is not None and recorded[self.index[observed.scan.component]]:
            lidar = self.index[observed.scan.component]
            component = self.components[lidar]
            n_in = len(component.inputs)
            columns = [n_in + i for i, port in enumerate(component.outputs) if port.array_name == "ranges"]
            run = columns == list(range(columns[0], columns[0] + len(columns))) if columns else False
            self.scan_rows = (
                lidar,
                slice(columns[0], columns[-1] + 1) if run else np.array(columns, np.intp),
            )
        self.pose_columns = [self._column(reference) for reference in observed.pose]
        self.command_columns = [self._column(r) for r in observed.command] if observed.command else None
        self.mode_column = self._column(observed.mode) if observed.mode else None
        # Rows collected: per recorded component, row 0 the last row before the collected steps.
        # Only the columns anyone reads are copied in (`spans`): the scalar inputs and the outputs
        # recorded or observed (the scans are made from the lidar's rows as they come).
        read: dict[int, set[int]] = {i: set() for i in range(len(self.components))}
        for entry in recording.entries:
            read[self.index[entry.component.name]].update(entry.outputs)
        mode = [self.mode_column] if self.mode_column is not None else []
        for where in [*self.pose_columns, *(self.command_columns or ()), *mode]:
            read[where.index].add(where.column - len(self.components[where.index].inputs))
        self.buffers = {}
        self.spans: dict[int, list[slice]] = {}
        for i, component in enumerate(self.components):
            if recorded[i]:
                n_in = len(component.inputs)
                rows = np.empty((self.STEPS // self.periods[i] + 3, n_in + len(component.outputs)))
                rows[0, :n_in] = component.input_buffer
                rows[0, n_in:] = component.output_buffer
                self.buffers[i] = rows
                self.spans[i] = read_columns(component, read[i])
        self.counts = dict.fromkeys(self.buffers, 0)
        self.entries: list[BlockEntry] = []
        for slot, entry in enumerate(recording.entries):
            component = entry.component
            i = self.index[component.name]
            columns = None
            if recorded[i]:
                n_in = len(component.inputs)
                columns = np.array(list(entry.inputs) + [n_in + s for s in entry.outputs], dtype=np.intp)
                if np.array_equal(columns, np.arange(n_in + len(component.outputs))):
                    columns = slice(None)
            self.entries.append(BlockEntry(slot, i, columns, entry))
        self.order = StepOrder(len(self.entries), len(recording.sensors))
        self.flush_at = 0  # [ns] flush once a step starting at or after it is collected
        # Records of components stepped by Python, taken from their live buffers: slot -> [(k, row)].
        self.live = {block.slot: [] for block in self.entries if block.columns is None}
        self.live_entries = [block for block in self.entries if block.columns is None]
        self.others: list[OtherMessage] = []
        self.scans: list[tuple[np.ndarray, np.ndarray]] = []  # (steps, ranges) of the sweeps collected

    @property
    def settled(self) -> bool:
        """Whether every topic a block writes has had its first message (a block holding one is
        replayed step by step, so the run loop keeps such blocks short)."""
        recording, recorder = self.recording, self.recorder
        return (
            (recording.scan is None or recorder.has_channel("/scan"))
            and (recording.command is None or recorder.has_channel("/cmd_vel"))
            and all(recorder.has_channel(sensor.topic) for sensor in recording.sensors)
        )

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
            period = recording.scan.period
            if self.scan_rows is not None:  # every scan from its row
                if not recorder.has_channel("/scan") and due_from(first, period) < end:
                    return False
            elif due_from(first + 1, period) < end:
                return False  # a scan after the first step: its ranges are not held
            elif not recorder.has_channel("/scan") and first % period == 0:
                return False
        if recording.command is not None and not recorder.has_channel("/cmd_vel"):
            if due_from(first, recording.command.period) < end:
                return False
        for sensor in recording.sensors:
            if not recorder.has_channel(sensor.topic) and due_from(first + 1, sensor.steps) - 1 < end:
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
        start_ns, h_ns, per_step = self.start_ns, self.h_ns, self.order.per_step
        counts = self.counts
        x_column, y_column = self.pose_columns[:2]
        x_before, y_before = counts[x_column.index], counts[y_column.index]
        spans = self.spans
        for i, rows in self.buffers.items():
            history = histories[i]
            n = len(history)
            if n:
                at = counts[i] + 1
                for span in spans[i]:
                    rows[at : at + n, span] = history[:, span]
                counts[i] = at + n - 1
        self.end = end
        last = end - 1
        t_last = start_ns + last * h_ns
        # Records of components stepped by Python: due at most at the first step, from live buffers.
        for block in self.live_entries:
            if first % block.entry.period == 0:
                self.live[block.slot].append((first, block.entry.record()))
        recording = self.recording
        scan = recording.scan
        if scan is not None and self.scan_rows is not None:  # the sweeps from the lidar's rows
            lidar, columns = self.scan_rows
            rows = histories[lidar]
            if len(rows):
                steps = np.arange(due_from(first, scan.period), end, scan.period, dtype=np.int64)
                if len(steps) != len(rows):
                    raise RuntimeError(f"the lidar has {len(rows)} rows for {len(steps)} steps")
                ranges = rows[:, columns]  # a copy (the kernel writes its rows again), not a view
                self.scans.append((steps, ranges.copy() if isinstance(columns, slice) else ranges))
        elif scan is not None and first % scan.period == 0:  # from its live buffers
            self.scans.append((np.array([first], dtype=np.int64), scan.current()[None, :].copy()))
        for k, t_ns, payload in recording.obstacle_payloads(first, end, start_ns, h_ns):
            self.others.append(OtherMessage(k * per_step + self.order.obstacles, t_ns, "/obstacles", payload))
        # The positions after each step, as the monitor checks them.
        xs = self._values(x_column, first, end, x_before)
        ys = self._values(y_column, first, end, y_before)
        index, reason = self.monitor.check_positions(self._ends(first, end), xs, ys)
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

    def _ends(self, first: int, end: int) -> np.ndarray:
        """The end [s] of each step in [first, end) (a step cut at the stop time ends there):
        integer nanoseconds, exact in float64, divided once (as Python's int / int, correctly
        rounded); from a table of `STEPS` steps made at a time."""
        table_first = self.ends_first
        if not table_first <= first or end > table_first + len(self.ends_table):
            table_first = self.ends_first = first
            steps = np.arange(first + 1, first + max(self.STEPS, end - first) + 1, dtype=np.int64)
            self.ends_table = np.minimum(self.start_ns + steps * self.h_ns, self.recording.stop_ns) / NS_PER_S
        return self.ends_table[first - table_first : end - table_first]

    def _values(self, where: Column, first: int, end: int, before: int) -> np.ndarray:
        """The value at `where` after each step in [first, end) (held between its component's steps)."""
        rows = self.buffers[where.index]
        period = self.periods[where.index]
        if period == 1:
            return rows[before + 1 : before + 1 + end - first, where.column]
        due = due_from(first, period)
        at = before + 1 + (np.arange(first, end) - due) // period
        return rows[at, where.column]

    def _latest(self, where: Column, steps: np.ndarray) -> np.ndarray:
        """The value at `where` (in the collected rows) after each of `steps`."""
        period = self.periods[where.index]
        due = due_from(self.first, period)
        return self.buffers[where.index][(steps - due) // period + 1, where.column]

    def flush(self) -> None:
        """Hand the collected steps to the recorder (and the modes to the monitor)."""
        if self.first is None:
            return
        first, end = self.first, self.end
        start_ns, h_ns, order = self.start_ns, self.h_ns, self.order
        per_step = order.per_step
        recording = self.recording
        signals = []
        for slot, i, columns, entry in self.entries:
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
            signals.append((entry.channel, steps * per_step + slot, start_ns + steps * h_ns, rows))
        others = self.others
        if self.scans:
            scan = recording.scan
            steps = np.concatenate([steps for steps, _ in self.scans])
            ranges = np.concatenate([ranges for _, ranges in self.scans])
            self.scans = []
            limits = (scan.range_min, scan.range_max, scan.scan_time)
            times = start_ns + steps * h_ns
            rows = self.recorder.scan_rows(times, scan.angles, ranges, *limits)
            signals.append(
                (self.recorder.scan_channel(scan.angles, *limits), steps * per_step + order.scan, times, rows)
            )
        if recording.command is not None:
            period = recording.command.period
            steps = np.arange(due_from(first, period), end, period, dtype=np.int64)
            if len(steps):
                v_column, omega_column = self.command_columns
                values = np.column_stack((self._latest(v_column, steps), self._latest(omega_column, steps)))
                keys = steps * per_step + order.cmd_vel
                signals.append((self.recorder.cmd_vel_channel(), keys, start_ns + steps * h_ns, values))
        if self.mode_column is not None:
            mode = recording.mode
            steps = np.arange(due_from(first, mode.period), end, mode.period, dtype=np.int64)
            for value in self._latest(self.mode_column, steps).tolist():
                self.monitor.check_mode(value, mode.period_s)
        poses = None
        every = recording.pose_steps
        steps = np.arange(due_from(first + 1, every) - 1, end, every, dtype=np.int64)
        if len(steps):
            values = np.empty((len(steps), 5))  # x, y, theta, v, omega
            for column, where in enumerate(self.pose_columns):
                values[:, column] = self._latest(where, steps)
            if self.command_columns is None:
                values[:, 3:] = math.nan
            else:
                for column, where in enumerate(self.command_columns, start=3):
                    values[:, column] = self._latest(where, steps)
            ends = np.minimum(start_ns + (steps + 1) * h_ns, recording.stop_ns)
            poses = (steps * per_step + order.pose, ends, values)
        for index, sensor in enumerate(recording.sensors):
            steps = np.arange(due_from(first + 1, sensor.steps) - 1, end, sensor.steps, dtype=np.int64)
            ends = start_ns + (steps + 1) * h_ns
            steps, ends = steps[ends <= recording.stop_ns], ends[ends <= recording.stop_ns]
            x, y, theta = (self._latest(where, steps).tolist() for where in self.pose_columns)
            for k, t_ns, pose in zip(
                steps.tolist(), ends.tolist(), zip(x, y, theta, strict=True), strict=True
            ):
                key = k * per_step + order.sensor(index)
                others.append(OtherMessage(key, t_ns, sensor.topic, sensor.sample(t_ns, *pose)))
        other = None
        if others:
            other = (
                np.array([message.key for message in others], dtype=np.int64),
                np.array([message.t_ns for message in others], dtype=np.int64),
                [(message.topic, message.payload) for message in others],
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
