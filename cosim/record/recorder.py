"""Write a run's log: one MCAP file of ROS 2 messages (cdr, profile "ros2"), zstd-compressed chunks.

Topics: `/odom`, `/tf` (map -> base_link), `/pose`, `/scan`, `/cmd_vel`, `/plan`, `/map`,
`/map_inflated`, `/obstacles`, `/goal`, `/imu`, `/bumper` (the table: `cosim.scenario.topics`), and
`/signals/<component>` (one generated float64 struct per component; see `cosim.record.rosmsg`).
The run loop writes messages in time order.

Speed: signals, poses, commands and scans (the per-step topics) are held in a
`cosim.record.batch.MessageBlock` (/cmd_vel and /scan, as the signals, as rows of float64 fields of
a fixed layout: `fixed_channel`; a message given as CDR bytes becomes its row) and packed into MCAP
records a block at a time, in C
(`navcosim_pack_records` of the core kernel; a NumPy build of the same records is kept as the tested
reference) (at most 512 records of a channel); the records and their order are exactly those of writing one
message at a time. Any other write, `flush()` and `close()` pack the held messages first. The run
loop's kernel path hands over many steps at once (`hold_steps`): their packs are skipped where they
were due and done every `BATCH_MESSAGES` messages, with the same bytes (a schema or channel
registered meanwhile is written where the skipped pack would have put it).

Same run, same bytes: nothing in the file comes from the wall clock or the machine. Attachments
carry the simulation time they were attached at; chunks end by content alone (`CHUNK_SIZE` bytes
of records, or `CHUNK_DURATION` of simulated time: a chunk holds one window [n D, (n + 1) D)).

A killed run: every `flush_interval` seconds of wall time (the clock is read every 16 held
messages) the chunks already ended are handed to the OS (`file.flush()`, which does not change
the bytes). So SIGKILL loses the open chunk (at most `CHUNK_DURATION` of simulated time, or
`CHUNK_SIZE` bytes) plus at most `flush_interval` of wall time of ended chunks; on the run loop's
kernel path also the steps not yet handed over or packed: at most 2 windows of steps or
`flush_interval` of wall time, and `BATCH_MESSAGES` messages or `flush_interval` of wall time
(with a live view, `sink`: one window, no skipped packs). A smaller
`CHUNK_DURATION` loses less but makes more, smaller chunks (more per-chunk overhead when reading,
slightly worse compression). Only `close()` writes the summary and footer, so a file without them
is a run that did not end normally (`cosim.logs.reader` reads it up to its last complete record;
`cosim log recover` rewrites it as a complete, indexed file).

Signals recorded from steps (`signal_channel(..., inputs=n, initial=..., period_ns=...)`): the
caller hands over, after each step of a component, the inputs applied at the step's start t and
the outputs at its end. The recorder stamps each value at the time it holds: the record at t holds
the inputs applied at t and the outputs at t (those of the previous step; the first record holds
the initial outputs), and `end_steps(t_end)` adds a last record at the end time with the final
outputs (and the inputs last applied, held).
"""

from __future__ import annotations

import copy
import json
import math
import struct
import time
from pathlib import Path
from typing import BinaryIO

import numpy as np

from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.record.batch import RAW_STREAM, FixedLayout, MessageBlock
from cosim.record.inputs import METADATA_NAME as UNCONNECTED_INPUTS
from cosim.record.inputs import unconnected_metadata
from cosim.record.logfile import navcosim_version
from cosim.record.markers import ObstacleMarkers, marker_array
from cosim.record.writer import ChunkWriter
from cosim.scenario.topics import TOPIC_TYPES

CHUNK_SIZE = 512 * 1024  # bytes of uncompressed records after which a chunk ends
CHUNK_DURATION = 2.0  # [s] of simulated time per chunk window: what SIGKILL loses at most
# With a live view (`sink`) the messages reach it a window at a time, so its windows are shorter.
LIVE_CHUNK_DURATION = 0.5
# zstd level: 1 compresses a run's log to the size level 3 does (1.96 vs 1.97 MB for
# one_obstacle: most bytes are float64 samples), in about 30 % less time.
COMPRESSION_LEVEL = 1
MAP_FRAME = rosmsg.MAP_FRAME
ROBOT_FRAME = rosmsg.ROBOT_FRAME
SCAN_ANGLE_TOLERANCE = 1e-6  # [rad] below which beam angles count as exactly on the ROS angle grid
SCAN_MAX_SUBDIVISION = 16
BATCH_MESSAGES = 2048  # messages of `hold_steps` packed at once (at the next chunk window)
CLOCK_EVERY = 16  # held messages between two looks at the wall clock for the OS flush
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: int32 sec, uint32 nanosec

SIGNAL_NAMES_KEY = rosmsg.SIGNAL_NAMES_KEY
SIGNAL_UNITS_KEY = rosmsg.SIGNAL_UNITS_KEY
SIGNAL_INPUTS_KEY = rosmsg.SIGNAL_INPUTS_KEY
COMPONENT_KEY = rosmsg.COMPONENT_KEY
SCAN_LAYOUT_KEY = "navcosim.scan_angles"


def _library() -> str:
    """The MCAP header's library: "navcosim <version>", or "navcosim" alone from a bare checkout."""
    version = navcosim_version()
    return "navcosim" if version == "unknown" else f"navcosim {version}"


# The signals a run's default plot draws (`cosim.logs.plot`), kept in memory by `RunTrace`.
TRACE_SIGNALS = {
    "vehicle": ("x", "y", "theta", "v_actual", "v", "omega_actual", "yaw_rate", "steering_angle_actual"),
    "mixer": ("mode", "v", "omega", "steering_angle"),
    "pure_pursuit": ("target_dir",),
    "vfh": ("steering_dir",),
}
TRACE_LIMIT = 20_000_000  # values kept at most; a longer run's plot reads its log instead


class RunTrace:
    """What the default plot of a run draws, kept as the run writes its log: the last grid of each
    map topic, every /plan and /goal message (the first and each change), the obstacle frames
    (marker centres), per scan the shortest valid range, the /pose rows and the `TRACE_SIGNALS`
    columns of each signal channel, appended a block at a time. Every value is the one the log
    holds, computed as `cosim.logs.reader` decodes it (the plans and goals are the messages
    written), so a plot drawn from the trace is the plot of the log (`cosim.logs.plot.plot_trace`).

    `complete` is False until the log was closed; `dropped` is True when the run wrote more than
    `TRACE_LIMIT` values (the trace then stops growing and the plot reads the log)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.metadata: dict[str, dict[str, str]] = {}
        self.grids: dict[
            str, tuple[np.ndarray, float, tuple[float, float]]
        ] = {}  # topic -> (occupied, res, origin)
        self.plans: list[tuple[int, object]] = []  # (t_ns, nav_msgs/Path) of each /plan message
        self.goals: list[tuple[int, object]] = []  # (t_ns, geometry_msgs/PoseStamped) of each /goal
        self.obstacle_markers: list[
            tuple[int, int, float, float]
        ] = []  # (t_ns, id, x, y) of each frame's markers
        self.obstacle_messages = 0  # /obstacles messages written
        self.last_obstacles: tuple[int, list] | None = None  # (t_ns, shapes) of the last message
        self.scan_t_ns: list[int] = []
        self.scan_minima: list[float] = []
        self.poses: list[np.ndarray] = []  # blocks of rows (t_ns, x, y, qz, qw)
        self.components: list[str] = []  # every signal channel's component
        self.columns: dict[int, tuple[str, list[str], list[int]]] = {}  # channel -> component, names, indices
        self.signal_blocks: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}  # component -> (t_ns, rows)
        self.complete = False
        self.dropped = False
        self._values = 0

    def _count(self, values: int) -> bool:
        """Account for `values` more kept values; False (and the trace dropped) past the limit."""
        self._values += values
        if self._values > TRACE_LIMIT:
            self.dropped = True
            self.poses, self.signal_blocks, self.obstacle_markers = [], {}, []
            self.scan_t_ns, self.scan_minima = [], []
        return not self.dropped

    def add_channel(self, channel: int, component: str, names: list[str]) -> None:
        self.components.append(component)
        wanted = TRACE_SIGNALS.get(component, ())
        kept = [name for name in names if name in wanted]
        if kept:
            self.columns[channel] = (component, kept, [names.index(name) for name in kept])
            self.signal_blocks[component] = []

    def take_block(self, block: MessageBlock) -> None:
        """The signal records and poses `block` is about to pack (exactly the logged values)."""
        if self.dropped:
            return
        for channel, (component, _, indices) in self.columns.items():
            stream = block.signals[channel]
            count = len(stream.times)
            if count and self._count(count * (len(indices) + 1)):
                rows = stream.rows[:count, indices]
                self.signal_blocks[component].append((np.array(stream.times, dtype=np.int64), rows))
        pose = block.pose
        if pose is not None and pose.count and self._count(5 * pose.count):
            times, rows = pose.held()
            half = rows[:, 2] / 2.0
            self.poses.append(
                np.column_stack((times.astype(np.float64), rows[:, :2], np.sin(half), np.cos(half)))
            )

    def add_scan(self, t_ns: int, ranges: np.ndarray, range_min: float, range_max: float) -> None:
        """`ranges`: the float32 ranges as written; the shortest within the float32 limits, or NaN."""
        if self.dropped or not self._count(2):
            return
        # The shortest range >= range_min (NaN fails the comparison) is the answer when it is within
        # range_max (+inf, no return, counts only below an infinite range_max: then the full test).
        above = ranges[ranges >= np.float32(range_min)]
        shortest = math.nan
        if len(above):
            candidate = float(above.min())
            if math.isinf(candidate) and math.isinf(range_max):
                valid = (
                    (ranges >= np.float32(range_min))
                    & (ranges <= np.float32(range_max))
                    & np.isfinite(ranges)
                )
                shortest = float(ranges[valid].min()) if valid.any() else math.nan
            elif candidate <= np.float32(range_max):
                shortest = candidate
        self.scan_t_ns.append(int(t_ns))
        self.scan_minima.append(shortest)

    def add_scans(self, t_ns: list[int], rows: np.ndarray, range_min: float, range_max: float) -> None:
        """`add_scan` of each row of `rows` (one sweep's float32 ranges a row) at `t_ns`, the rows'
        shortest ranges found at once: the least range >= range_min of each row (NaN fails the
        comparison), then as `add_scan` takes it (a row whose least is infinite with an infinite
        range_max, or that has none, row by row)."""
        if self.dropped or not len(t_ns) or not self._count(2 * len(t_ns)):
            return
        low = np.float32(range_min)
        above = rows >= low
        least = np.where(above, rows, np.float32(np.inf)).min(axis=1)
        within = (least <= np.float32(range_max)).tolist()
        plain = (above.any(axis=1) & np.isfinite(least)).tolist()
        for t, row, shortest, inside, simple in zip(t_ns, rows, least.tolist(), within, plain, strict=True):
            if simple:
                self.scan_t_ns.append(int(t))
                self.scan_minima.append(shortest if inside else math.nan)
            else:  # (counted above)
                self._values -= 2
                self.add_scan(t, row, range_min, range_max)

    def add_obstacles(self, t_ns: int, obstacles: list) -> None:
        """The obstacles of an /obstacles message: each marker's centre as the reader takes it from
        the message (a polygon's vertex mean, else the marker's position), and the last frame."""
        self.last_obstacles = (int(t_ns), list(obstacles))
        self.obstacle_messages += 1
        if self.dropped or not self._count(4 * len(obstacles)):
            return
        for index, obstacle in enumerate(obstacles):
            if getattr(obstacle, "kind", None) == "polygon":
                vertices = [(float(px), float(py)) for px, py in np.asarray(obstacle.polygon(), dtype=float)]
                x = sum(px for px, _ in vertices) / len(vertices)
                y = sum(py for _, py in vertices) / len(vertices)
            else:
                x, y = (float(value) for value in obstacle.center)
            self.obstacle_markers.append((int(t_ns), index, x, y))

    def obstacles_message(self):
        """The last /obstacles message as written (a MarkerArray), or None."""
        if self.last_obstacles is None:
            return None
        t_ns, obstacles = self.last_obstacles
        return marker_array(t_ns, obstacles)


class _TracedBlock(MessageBlock):
    """The recorder's block: hands what it packs to the run's trace first."""

    trace: RunTrace | None = None

    def pack(self) -> None:
        self.settle()
        if self.count and self.trace is not None:
            self.trace.take_block(self)
        super().pack()


class Recorder:
    """Writes one run to `path` (parent folders created). Use as a context manager: leaving the
    `with` block, normally or by an exception, finalises the file."""

    def __init__(
        self,
        path: Path,
        *,
        flush_interval: float = 0.5,
        chunk_duration: float | None = None,
        sink=None,
        topics: dict[str, str] | None = None,
        stream: BinaryIO | None = None,
        trace: bool = True,
    ) -> None:
        """`sink` (`cosim.record.live.Sink`): also gets every schema, channel and message written.
        `chunk_duration` [s]: the chunk window, by default `CHUNK_DURATION` (`LIVE_CHUNK_DURATION`
        with a sink that is watched: one without a `watched` attribute False).
        `topics`: a topic's name in the log, by its name here ("/odom" -> "/ground-truth-pose").
        `stream`: the file already opened for `path` (`cosim.record.logfile.claim_log`); it is
        closed by `close()`. Without it `path` is opened (and truncated) here.
        `trace`: keep a `RunTrace` (`self.trace`) of what the default plot draws (None without)."""
        self.path = Path(path)
        self.topics = dict(topics or {})
        try:
            if stream is None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                stream = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        except OSError as error:
            raise CosimError(f"{self.path}: cannot write the log ({error.strerror})") from None
        self._file = stream
        if chunk_duration is None:
            # A live view gets the messages a window at a time: shorter windows. A sink that no
            # one watches (`Pacer`: --realtime alone) keeps the file's bytes as without it.
            watched = sink is not None and getattr(sink, "watched", True)
            chunk_duration = LIVE_CHUNK_DURATION if watched else CHUNK_DURATION
        if not chunk_duration > 0:
            self._file.close()
            raise CosimError(f"{self.path}: chunk_duration must be > 0 s, got {chunk_duration}")
        window_ns = round(chunk_duration * 1e9)
        self.window_ns = window_ns  # [ns] chunk window (`CHUNK_DURATION`)
        self._writer = ChunkWriter(
            self._file,
            chunk_size=CHUNK_SIZE,
            compression_level=COMPRESSION_LEVEL,
            chunk_duration_ns=window_ns,
        )
        self._writer.start(profile="ros2", library=_library())
        if sink is not None:  # the live view: same channels, same bytes as the file
            from cosim.record.live import tee_writer

            self._writer = tee_writer(self._writer, sink)
        self.flush_interval = flush_interval
        self._last_flush = time.monotonic()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequences: dict[int, int] = {}
        self._signal_sizes: dict[int, int] = {}
        self._scan_layouts: dict[tuple, tuple] = {}  # (angles, limits) -> `_scan_template`
        self._scan_grids: dict[bytes, tuple] = {}  # angles -> `scan_layout` (shared by the views)
        self._scan_bytes_of: dict[tuple, tuple] = {}  # `_scan_bytes` (shared by the views)
        self._obstacle_markers = ObstacleMarkers(str(self.path))
        # Signals, poses, commands and scans are held for a block of steps and packed at once
        # (`cosim.record.batch`); any other write, a flush and close pack the block first.
        self._block = _TracedBlock(self._writer, self._sequences, window_ns=window_ns)
        # Steps held at once (`hold_steps`) are packed every BATCH_MESSAGES messages instead of at
        # each chunk window: same bytes, fewer packs; a live view gets them at each window.
        self.batching = sink is None
        self._block.batch_limit = BATCH_MESSAGES if self.batching else 0
        self._block.clock_due = self._sync_due
        self.trace = RunTrace(self.path) if trace else None
        self._block.trace = self.trace
        self._pose_channels: tuple[int, int, int] | None = None
        self._until_clock = 1
        self._last_scan: tuple | None = None  # (angles, range_min, range_max, layout) of the last sweep
        self._closed = False
        self.namespace = ""  # a fleet's robot (`namespaced`)
        self.robot_frame = ROBOT_FRAME

    def namespaced(self, namespace: str) -> Recorder:
        """This recorder for one robot of a fleet, under its ROS namespace: the same file (writer,
        held messages, schemas), the robot's own channels: a topic of the table is
        `/<namespace><topic>` (after `topics`' renaming), the scan's frame `<namespace>/base_link`,
        and the signals of component `<namespace>:<name>` (the fleet's name of the robot's
        component) go on `/<namespace>/signals/<name>`. Close the recorder itself, not the view."""
        view = copy.copy(self)
        view.namespace = namespace
        view.robot_frame = f"{namespace}/{ROBOT_FRAME}"
        view.topics = {topic: f"/{namespace}{self.topics.get(topic, topic)}" for topic in TOPIC_TYPES}
        view._channels = {}
        view._pose_channels = None
        view._scan_layouts = {}
        view._last_scan = None
        return view

    def _component_topic(self, kind: str, component: str) -> str:
        """`/<kind>/<component>`, or under a namespace `/<namespace>/<kind>/<name>` (`namespaced`)."""
        if not self.namespace:
            return f"/{kind}/{component}"
        return f"/{self.namespace}/{kind}/{component.removeprefix(self.namespace + ':')}"

    # --- file-level records --------------------------------------------------------------

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A named metadata record (string keys and values)."""
        self._block.pack()
        record = {str(key): str(value) for key, value in data.items()}
        self._writer.add_metadata(name, record)
        if self.trace is not None:
            self.trace.metadata[name] = record

    def add_unconnected_inputs(self, system) -> None:
        """The metadata record `unconnected_inputs` of `system` (`cosim.record.inputs`), when it has
        an input that no connection feeds."""
        kept = unconnected_metadata(system)
        if kept:
            self.add_metadata(UNCONNECTED_INPUTS, kept)

    def add_attachment(self, name: str, media_type: str, data: bytes, t_ns: int = 0) -> None:
        """An attached file (the scenario, the map) stored as-is; its create and log time are the
        simulation time `t_ns` [ns] it was attached at (not the wall clock: same run, same bytes)."""
        self._block.pack()
        self._writer.add_attachment(int(t_ns), int(t_ns), name, media_type, bytes(data))

    def flush(self) -> None:
        """End the open chunk and hand everything to the OS (a later SIGKILL keeps it). This
        changes where a chunk ends: call it at points that depend on the simulation only."""
        self._block.pack()
        self._writer.flush()
        self._sync()

    def _sync_due(self) -> bool:
        """Whether `flush_interval` of wall time has passed since the last `_sync`."""
        return time.monotonic() - self._last_flush >= self.flush_interval

    def _sync(self) -> None:
        """Hand the chunks already ended to the OS; the bytes of the file do not change."""
        self._writer.hand_over()
        self._last_flush = time.monotonic()

    def end_steps(self, end_ns: int) -> None:
        """The run ended at `end_ns` [ns]: add each step channel's last record, its final outputs,
        at the end of its last step or at `end_ns` when the run stopped inside that step."""
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        self._block.end_steps(int(end_ns))

    def close(self, outcome: dict[str, str] | None = None) -> None:
        """Write `outcome` as metadata "outcome", then the summary and footer. Idempotent."""
        if self._closed:
            return
        try:
            self._block.settle()  # steps collected outside the recorder (`collect`), while it is open
        finally:
            self._closed = True
            self._finish(outcome)

    def _finish(self, outcome: dict[str, str] | None) -> None:
        """`close` after the collected steps: the held messages, the outcome, summary and footer."""
        try:
            self._block.pack()
            if outcome is not None:
                self.add_metadata("outcome", outcome)
            self._writer.finish()
            if self.trace is not None:
                self.trace.complete = True
        finally:
            self._file.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # --- channels ------------------------------------------------------------------------

    def _schema(self, typename: str, definition: str | None = None) -> int:
        if typename not in self._schemas:
            self._block.settle()  # collected steps go before the definition
            text = definition if definition is not None else rosmsg.message_definition(typename)
            self._schemas[typename] = self._writer.register_schema(typename, "ros2msg", text.encode())
            self._block.registered()
        return self._schemas[typename]

    def _channel(self, topic: str, metadata: dict[str, str] | None = None) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            self._block.settle()
            schema = self._schema(TOPIC_TYPES[topic])
            name = self.topics.get(topic, topic)
            channel = self._writer.register_channel(name, "cdr", schema, metadata or {})
            self._block.registered()
            self._channels[topic] = channel
            self._sequences[channel] = 0
        return channel

    def _write(self, channel: int, t_ns: int, data: bytes) -> None:
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        collector = self._block.collector
        if collector is not None and collector.written(channel, t_ns, data):
            return
        self._block.pack()
        sequence = self._sequences[channel]
        self._sequences[channel] = sequence + 1
        self._writer.add_message(channel, t_ns, data, sequence)
        if self._sync_due():
            self._sync()

    def _held(self, full: bool) -> None:
        """After a message went into the block: pack a full block; flush when the interval is up."""
        # The clock is read every CLOCK_EVERY held messages (every one with a zero interval):
        # a run writes a few messages per millisecond of wall time, far below the interval.
        self._until_clock -= 1
        if self._until_clock <= 0:
            self._until_clock = CLOCK_EVERY if self.flush_interval > 0 else 1
            if self._sync_due():
                self._sync()
        if full:
            self._block.pack()

    def _write_message(self, topic: str, t_ns: int, message) -> None:
        self._write(self._channel(topic), t_ns, rosmsg.serialize(message, TOPIC_TYPES[topic]))

    # --- signals -------------------------------------------------------------------------

    def signal_channel(
        self,
        component: str,
        names: list[str],
        *,
        units: list[str] | None = None,
        inputs: int | None = None,
        initial: np.ndarray | None = None,
        period_ns: int = 0,
    ) -> int:
        """Register `/signals/<component>` with one float64 field per name; returns its handle.

        `units` (one per name, "" for none) go into the channel metadata. With `inputs` the
        channel is recorded from steps: the first `inputs` names are inputs, the rest outputs,
        `initial` holds every value after initialisation and `period_ns` [ns] is the component's
        step; `hold_signals`/`hold_signal_rows` then take a step's applied inputs and end outputs
        and the records are stamped as the module docstring says."""
        topic = self._component_topic("signals", component)
        if topic in self._channels:
            raise CosimError(f"{self.path}: signal channel {topic} registered twice")
        self._block.settle()
        names = list(names)
        fields = rosmsg.field_names(names)
        typename = rosmsg.signals_type_name(component)
        schema = self._schema(typename, rosmsg.signals_definition(fields))
        metadata = {COMPONENT_KEY: component, SIGNAL_NAMES_KEY: json.dumps(names)}
        if units is not None:
            if len(units) != len(names):
                raise CosimError(f"{self.path}: {len(units)} units for the {len(names)} signals of {topic}")
            metadata[SIGNAL_UNITS_KEY] = json.dumps([str(unit) for unit in units])
        if inputs is not None:
            if initial is None or np.size(initial) != len(names) or not 0 <= inputs <= len(names):
                raise CosimError(f"{self.path}: {topic}: a step channel needs {len(names)} initial values")
            if period_ns <= 0:
                raise CosimError(
                    f"{self.path}: {topic}: a step channel needs a period > 0, got {period_ns} ns"
                )
            metadata[SIGNAL_INPUTS_KEY] = str(inputs)
        channel = self._writer.register_channel(topic, "cdr", schema, metadata)
        self._block.registered()
        self._channels[topic] = channel
        self._sequences[channel] = 0
        self._signal_sizes[channel] = len(names)
        self._block.add_signal_channel(channel, len(names), inputs, initial, period_ns)
        if self.trace is not None:
            self.trace.add_channel(channel, component, names)
        return channel

    def text_channel(self, component: str, names: list[str], fmi_types: list[str], inputs: int) -> int:
        """Register `/text_signals/<component>`: one field per String (`string`) or Binary
        (`uint8[]`) variable, the first `inputs` of them inputs; returns its handle for
        `write_text`."""
        topic = self._component_topic("text_signals", component)
        if topic in self._channels:
            raise CosimError(f"{self.path}: text channel {topic} registered twice")
        self._block.settle()
        fields = rosmsg.field_names(list(names))
        schema = self._schema(
            rosmsg.text_type_name(component), rosmsg.text_definition(fields, list(fmi_types))
        )
        metadata = {
            rosmsg.TEXT_COMPONENT_KEY: component,
            rosmsg.TEXT_NAMES_KEY: json.dumps(list(names)),
            rosmsg.TEXT_TYPES_KEY: json.dumps(list(fmi_types)),
            rosmsg.TEXT_INPUTS_KEY: str(inputs),
        }
        channel = self._writer.register_channel(topic, "cdr", schema, metadata)
        self._block.registered()
        self._channels[topic] = channel
        self._sequences[channel] = 0
        return channel

    def write_text(self, channel: int, t_ns: int, values: list[str | bytes]) -> None:
        """One record of a text channel at `t_ns` [ns], the values in the channel's order."""
        self._write(channel, t_ns, rosmsg.text_payload(t_ns, values))

    def write_signals(self, channel: int, t_ns: int, values: np.ndarray) -> None:
        """One record of a component's signals at `t_ns` [ns]: float64 values in the channel's
        order, stamped as given (not for a step channel)."""
        if values.dtype != np.float64:
            values = np.asarray(values, dtype=np.float64)
        if values.size != self._signal_sizes[channel]:
            raise CosimError(
                f"{self.path}: {values.size} signal values for a channel of {self._signal_sizes[channel]}"
            )
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        if self._block.signals[channel].split is not None:
            raise CosimError(f"{self.path}: channel {channel} is recorded from steps: use hold_signals")
        self._held(self._block.add_signals(channel, t_ns, values))

    def hold_signals(
        self, channel: int, t_ns: int, first: np.ndarray, second: np.ndarray | None = None
    ) -> None:
        """`write_signals` for the run loop: the values are `first` (float64), or `first` then
        `second` (a component's input and output buffers); shapes are checked by NumPy only. On a
        step channel `t_ns` is the step's start and the values are its inputs and end outputs."""
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        self._held(self._block.add_signals(channel, t_ns, first, second))

    def hold_signal_rows(self, blocks: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Many signal records at once (`Master.run_recorded`'s blocks): (channel, times [ns],
        rows of float64 values) per channel; written as if one record at a time, in time order
        and, at equal times, in the order of `blocks`. On a step channel the times are the steps'
        starts and a row is a step's inputs then its end outputs, as for `hold_signals`."""
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        for channel, times, rows in blocks:
            if rows.ndim != 2 or rows.shape[1] != self._signal_sizes[channel] or len(rows) != len(times):
                raise CosimError(f"{self.path}: signal rows of shape {rows.shape} for channel {channel}")
        self._block.add_signal_rows(blocks)
        self._held(True)

    def has_channel(self, topic: str) -> bool:
        """Whether `topic` (a name of `TOPIC_TYPES` or "/signals/<component>") is registered."""
        return topic in self._channels

    def channel(self, topic: str) -> int:
        """The handle of `topic` (a name of `TOPIC_TYPES`; registered on first use), for `hold_steps`."""
        return self._channel(topic)

    def collect(self, collector) -> None:
        """Steps are collected outside the recorder (`cosim.record.fleet_steps.FleetSteps`):
        `collector.flush()` hands them over (`hold_steps`) before anything else is held, packed or
        registered, and `collector.written(channel, t_ns, payload)` may keep a message written
        meanwhile (True) to hold it after them."""
        self._block.collector = collector

    def fixed_channel(self, topic: str, layout: FixedLayout) -> int:
        """The handle of `topic` (`channel`), whose messages `hold_steps` then takes as rows of
        float64 fields, as a signal channel's (`cosim.record.batch.FixedLayout`: every message of
        the topic has its layout)."""
        channel = self._channel(topic)
        if channel not in self._block.signals:
            self._block.add_fixed_channel(channel, layout)
            self._signal_sizes[channel] = layout.width
        return channel

    def hold_steps(
        self,
        signals: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]],
        poses: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        others: tuple[np.ndarray, np.ndarray, list[tuple[str, bytes]]] | None = None,
    ) -> None:
        """The messages of many steps at once, with the bytes, order and chunks of writing them one
        at a time (`hold_signals`, `write_pose`, `write_scan`, ...). Each message has an integer
        key; they are written in key order (keys are distinct).

        `signals`: per signal channel (channel, keys, t_ns, rows) as for `hold_signal_rows`;
        `poses`: (keys, t_ns, rows of x, y, theta, v, omega) of /odom, /tf and /pose (one pose:
        keys key, key + 1, key + 2); `others`: (keys, t_ns, [(topic, CDR payload)]) of messages
        of registered topics (`scan_payload`, `obstacles_payload`, ...), a topic given by its name or
        its handle (`channel`: a namespaced recorder's too); one of a channel held as rows
        (`fixed_channel`: /cmd_vel, /scan) becomes its row. Stamps must not decrease in key order;
        others of equal keys are written in the order given."""
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        block = self._block
        if others is not None and len(others[0]):
            signals, others = self._fixed_others(signals, others)
        keys, streams, stamps = [], [], []
        signal_rows = {}
        numbers, counts = [], []
        stream_of, signal_sizes = block.stream_of, self._signal_sizes
        for channel, channel_keys, times, rows in signals:
            count = len(channel_keys)
            if not count:
                continue
            number = stream_of[channel]
            if number in signal_rows:
                raise CosimError(f"{self.path}: channel {channel} given twice")
            if rows.ndim != 2 or rows.shape[1] != signal_sizes[channel] or len(rows) != len(times):
                raise CosimError(f"{self.path}: signal rows of shape {rows.shape} for channel {channel}")
            signal_rows[number] = rows
            keys.append(channel_keys)
            numbers.append(number)
            counts.append(count)
            stamps.append(times)
        if numbers:
            streams.append(np.repeat(np.array(numbers, dtype=np.int64), counts))
        pose_rows = None
        if poses is not None and len(poses[0]):
            if self._pose_channels is None:
                self._pose_channels = (self._channel("/odom"), self._channel("/tf"), self._channel("/pose"))
            pose_keys, times, pose_rows = poses
            numbers = block.pose_stream(self._pose_channels)
            keys.append((pose_keys[:, None] + np.arange(3)).reshape(-1))
            streams.append(np.tile(numbers, len(pose_keys)))
            stamps.append(np.repeat(times, 3))
        raw = []
        if others is not None and len(others[0]):
            other_keys, times, messages = others
            by_key = np.argsort(other_keys, kind="stable")
            raw = [
                (topic if isinstance(topic, int) else self._channels[topic], payload)
                for topic, payload in (messages[j] for j in by_key.tolist())
            ]
            keys.append(other_keys)
            streams.append(np.full(len(other_keys), RAW_STREAM))
            stamps.append(times)
        if not keys:
            return
        order = np.argsort(np.concatenate(keys), kind="stable")
        block.add_batch(
            np.concatenate(streams)[order], np.concatenate(stamps)[order], signal_rows, pose_rows, raw
        )
        if self._sync_due():
            self._sync()

    def _fixed_others(self, signals: list, others: tuple) -> tuple[list, tuple]:
        """`hold_steps`' others whose channel is held as rows (`fixed_channel`) as its signals (rows
        in key order, with the rows given for the channel, if any)."""
        other_keys, times, messages = others
        channels = [topic if isinstance(topic, int) else self._channels[topic] for topic, _ in messages]
        fixed = [j for j, channel in enumerate(channels) if channel in self._block.signals]
        if not fixed:
            return signals, others
        other_keys, times = np.asarray(other_keys, dtype=np.int64), np.asarray(times, dtype=np.int64)
        given = {channel: (keys, stamps, rows) for channel, keys, stamps, rows in signals}
        for channel in dict.fromkeys(channels[j] for j in fixed):
            at = [j for j in fixed if channels[j] == channel]
            rows = np.array(
                [self._block.fixed_row(channel, int(times[j]), messages[j][1]) for j in at], dtype=np.float64
            )
            keys, stamps = other_keys[at], times[at]
            if channel in given:
                keys = np.concatenate((given[channel][0], keys))
                stamps = np.concatenate((given[channel][1], stamps))
                rows = np.concatenate((given[channel][2], rows))
            by_key = np.argsort(keys, kind="stable")
            given[channel] = (keys[by_key], stamps[by_key], rows[by_key])
        kept = [j for j in range(len(messages)) if channels[j] not in self._block.signals]
        signals = [(channel, *value) for channel, value in given.items()]
        return signals, (other_keys[kept], times[kept], [messages[j] for j in kept])

    # --- robot topics --------------------------------------------------------------------

    def write_pose(self, t_ns: int, x: float, y: float, theta: float, v: float, omega: float) -> None:
        """Robot pose [m, m, rad] and body velocities [m/s, rad/s] on /odom, /tf and /pose."""
        if self._pose_channels is None:
            self._pose_channels = (self._channel("/odom"), self._channel("/tf"), self._channel("/pose"))
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        row = (int(t_ns), float(x), float(y), float(theta), float(v), float(omega))
        self._held(self._block.add_pose(self._pose_channels, row))

    def write_cmd_vel(self, t_ns: int, v: float, omega: float) -> None:
        """The commanded body velocities [m/s, rad/s] on /cmd_vel (Twist has no stamp: log time only)."""
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        values = np.array((float(v), float(omega)))
        self._held(self._block.add_signals(self.cmd_vel_channel(), int(t_ns), values))

    def cmd_vel_channel(self) -> int:
        """The handle of /cmd_vel, whose messages are rows of v, omega for `hold_steps`' signals
        (every /cmd_vel message goes that way: `write_cmd_vel` too)."""
        return self.fixed_channel("/cmd_vel", _twist_layout())

    def write_payload(self, topic: str, t_ns: int, payload: bytes) -> None:
        """A message of `topic` (of the topic table) already in CDR: a sensor's (`StepRecording`)."""
        self._hold(self._channel(topic), t_ns, payload)

    def write_bool(self, topic: str, t_ns: int, value: bool) -> None:
        """A std_msgs/Bool message on `topic` (/bumper)."""
        self._write_message(topic, t_ns, rosmsg.make("std_msgs/msg/Bool", data=bool(value)))

    def _hold(self, channel: int, t_ns: int, payload: bytes) -> None:
        if self._closed:
            raise CosimError(f"{self.path}: the log is already closed")
        row = self._block.fixed_row(channel, int(t_ns), payload)
        if row is not None:  # a channel held as rows (`fixed_channel`)
            self._held(self._block.add_signals(channel, int(t_ns), row))
            return
        self._held(self._block.add_raw(channel, int(t_ns), payload))

    def write_goal(self, t_ns: int, x: float, y: float, theta: float | None) -> None:
        """The goal [m] on /goal; without a heading the orientation is the identity."""
        message = rosmsg.pose_stamped(t_ns, x, y, 0.0 if theta is None else theta)
        self._write_message("/goal", t_ns, message)
        if self.trace is not None:
            self.trace.goals.append((int(t_ns), message))

    def write_path(self, t_ns: int, path: np.ndarray) -> None:
        """The planned path, N x 2 (x, y) or N x 3 (x, y, theta) [m, m, rad], on /plan. Without
        headings each pose faces the next waypoint."""
        points = np.asarray(path, dtype=float)
        if points.ndim != 2 or points.shape[1] not in (2, 3):
            raise CosimError(f"{self.path}: a path must be N x 2 or N x 3, not {points.shape}")
        if points.shape[1] >= 3:
            headings = points[:, 2]
        elif len(points) >= 2:
            steps = np.diff(points[:, :2], axis=0)
            headings = np.arctan2(steps[:, 1], steps[:, 0])
            headings = np.append(headings, headings[-1])
        else:
            headings = np.zeros(len(points))
        if self.trace is None and len(points):
            payload = _path_layout().cdr(t_ns, points[:, 0], points[:, 1], headings)
            if payload is not None:
                self._write(self._channel("/plan"), t_ns, payload)
                return
        message = _path_message(t_ns, points[:, 0], points[:, 1], headings)
        self._write_message("/plan", t_ns, message)
        if self.trace is not None:
            self.trace.plans.append((int(t_ns), message))

    def write_grid(self, t_ns: int, grid, topic: str = "/map") -> None:
        """An occupancy grid (`planner.OccupancyGrid`: `.occupied` [row, col] with row 0 at the top,
        `.resolution` [m], `.origin` lower-left corner [m]) as nav_msgs/OccupancyGrid, whose rows run
        bottom to top: the rows are flipped. Occupied cells are 100, free cells 0."""
        if topic not in ("/map", "/map_inflated"):
            raise CosimError(f"{self.path}: grid topic must be /map or /map_inflated, not {topic}")
        occupied = np.asarray(grid.occupied)
        cells = occupied.astype(np.int8) * 100 if occupied.dtype == bool else np.clip(occupied, -1, 100)
        origin = tuple(float(value) for value in grid.origin)
        origin_yaw = origin[2] if len(origin) > 2 else 0.0
        info = rosmsg.make(
            "nav_msgs/msg/MapMetaData",
            map_load_time=rosmsg.time_msg(t_ns),
            resolution=float(grid.resolution),
            width=int(occupied.shape[1]),
            height=int(occupied.shape[0]),
            origin=rosmsg.pose(origin[0], origin[1], origin_yaw),
        )
        data = np.ascontiguousarray(np.flipud(cells).astype(np.int8)).reshape(-1)
        message = rosmsg.make(
            "nav_msgs/msg/OccupancyGrid", header=rosmsg.header(t_ns, MAP_FRAME), info=info, data=data
        )
        self._write_message(topic, t_ns, message)
        if self.trace is not None:  # as the reader decodes it: cells >= 50, a float32 resolution
            resolution = float(f"{float(np.float32(grid.resolution)):.7g}")
            origin_xy = (info.origin.position.x, info.origin.position.y)
            self.trace.grids[topic] = (cells >= 50, resolution, origin_xy)

    def write_scan(
        self,
        t_ns: int,
        angles: np.ndarray,
        ranges: np.ndarray,
        range_min: float,
        range_max: float,
        scan_time: float = 0.0,
    ) -> None:
        """A lidar sweep on /scan (`scan_payload`)."""
        payload = self.scan_payload(t_ns, angles, ranges, range_min, range_max, scan_time)
        self._hold(self._channels["/scan"], t_ns, payload)

    def scan_payload(
        self,
        t_ns: int,
        angles: np.ndarray,
        ranges: np.ndarray,
        range_min: float,
        range_max: float,
        scan_time: float = 0.0,
    ) -> bytes:
        """A lidar sweep on /scan: beam angles [rad] in the robot frame and ranges [m]; `scan_time`
        [s] between sweeps (1 / rate). REP-117: a beam without a return (NaN from the lidar) is
        +inf. All beams are taken at the stamp, so `time_increment` is 0. LaserScan needs equally
        spaced angles, so beams go into bins of a uniform grid (see `scan_layout`); bins without a
        beam hold NaN (no measurement). Returns the message's CDR bytes (the first sweep registers
        /scan), for `write_scan` or `hold_steps`."""
        bins, binned, head, tail = self._scan_layout(angles, range_min, range_max, scan_time)
        if bins is None:  # one beam per bin, in order
            binned[:] = ranges
            np.copyto(binned, np.inf, where=np.isnan(binned))
        else:
            binned[bins] = ranges
            beams = binned[bins]
            binned[bins[np.isnan(beams)]] = np.inf
        # Only the stamp and the ranges change between sweeps: the CDR bytes are the template's
        # head (encapsulation, stamp, frame, angles, limits, ranges length), the ranges, and the
        # empty intensities.
        stamp = _STAMP.pack(*divmod(int(t_ns), 1_000_000_000))
        payload = b"".join((head[:4], stamp, head[12:], binned.tobytes(), tail))
        if self.trace is not None:
            self.trace.add_scan(t_ns, binned, range_min, range_max)
        return payload

    def scan_channel(
        self, angles: np.ndarray, range_min: float, range_max: float, scan_time: float = 0.0
    ) -> int:
        """The handle of /scan for sweeps of this layout (registered by the first, as `scan_payload`
        registers it), whose messages `hold_steps` takes as rows (`scan_rows`)."""
        self._scan_layout(angles, range_min, range_max, scan_time)
        return self._channels["/scan"]

    def scan_rows(
        self,
        t_ns: np.ndarray,
        angles: np.ndarray,
        ranges: np.ndarray,
        range_min: float,
        range_max: float,
        scan_time: float = 0.0,
    ) -> np.ndarray:
        """The rows on `scan_channel` of sweeps at `t_ns` [ns] (`ranges`: one sweep a row), for
        `hold_steps`' signals: the bytes of `scan_payload`'s messages (each row: the ranges as
        float32 on the LaserScan's bins, padded with the empty intensities' zero length to whole
        float64s)."""
        bins, binned, _, _ = self._scan_layout(angles, range_min, range_max, scan_time)
        count = len(binned)
        out = np.empty((len(ranges), count + count % 2), dtype=np.float32)
        out[:, :count] = binned  # bins without a beam: NaN
        out[:, count:] = 0.0  # the first 4 bytes of the tail (a sequence of length 0)
        if bins is None:  # one beam per bin, in order
            beams = out[:, :count]
            beams[...] = ranges
            np.copyto(beams, np.inf, where=np.isnan(beams))
        else:
            beams = np.asarray(ranges, dtype=np.float32)
            out[:, bins] = np.where(np.isnan(beams), np.float32(np.inf), beams)
        if self.trace is not None:
            self.trace.add_scans(np.asarray(t_ns).tolist(), out[:, :count], range_min, range_max)
        return out.view(np.float64)

    def _scan_layout(self, angles, range_min: float, range_max: float, scan_time: float) -> tuple:
        """(bins, binned, head, tail) of the LaserScan layout of these sweeps (`_scan_template`),
        made and the /scan channel registered on first use."""
        last = self._last_scan
        if (
            last is not None
            and angles is last[0]
            and (range_min, range_max, scan_time) == (last[1], last[2], last[4])
        ):
            return last[3]  # the run loop passes the same angle array every sweep
        angle_array = np.asarray(angles, dtype=float)
        key = (angle_array.tobytes(), float(range_min), float(range_max), float(scan_time))
        layout = self._scan_layouts.get(key)
        if layout is None:
            layout = self._scan_template(angle_array, float(range_min), float(range_max), float(scan_time))
            self._scan_layouts[key] = layout
        # Keyed by identity only for a read-only array, which cannot change between sweeps.
        frozen = isinstance(angles, np.ndarray) and not angles.flags.writeable
        self._last_scan = (angles, range_min, range_max, layout, scan_time) if frozen else None
        return layout

    def _scan_template(
        self, angles: np.ndarray, range_min: float, range_max: float, scan_time: float
    ) -> tuple:
        """(bins, NaN-filled float32 ranges to fill, CDR head, CDR tail) of a LaserScan layout;
        bins None when beam i is bin i."""
        grid = self._scan_grids.get(angles.tobytes())
        if grid is None:
            grid = self._scan_grids[angles.tobytes()] = scan_layout(angles)
        angle_min, increment, bins, description = grid
        if "/scan" not in self._channels:
            self._channel("/scan", {SCAN_LAYOUT_KEY: description})
        binned = np.full(int(bins[-1]) + 1 if len(bins) else 0, np.nan, dtype=np.float32)
        template = self._scan_bytes(angles, grid, binned, range_min, range_max, scan_time)
        tail = bytes(4)  # intensities: a sequence of length 0
        head = template[: len(template) - binned.nbytes - len(tail)]
        if head + binned.tobytes() + tail != template:  # the layout the fast path relies on
            raise CosimError(f"{self.path}: unexpected LaserScan CDR layout")
        if np.array_equal(bins, np.arange(len(binned))):
            bins = None  # each beam its own bin, in order: filled by a slice
        # Every /scan message is a row of a fixed layout (`scan_rows`; a payload becomes its row):
        # the stamp, then the ranges and the intensities' length (zero) as whole float64s.
        count = len(binned)
        fields = {"sec": ("<i4", 4), "nanosec": ("<u4", 8)}
        fields["ranges"] = (("<f8", ((count + 1) // 2,)), len(head))
        if head[4:12] != bytes(8) or len(tail) != 4:  # the stamp of t = 0; the intensities' length
            raise CosimError(f"{self.path}: unexpected LaserScan CDR layout")
        self.fixed_channel("/scan", FixedLayout(template, fields, ("ranges",)))
        return bins, binned, head, tail

    def _scan_bytes(
        self, angles: np.ndarray, grid: tuple, binned: np.ndarray, range_min: float, range_max: float,
        scan_time: float,
    ) -> bytes:  # fmt: skip
        """The CDR bytes of the LaserScan of `_scan_template` (stamp 0, ranges `binned`). Those of
        a frame name of a length already serialised (a fleet's robots: `robot1/base_link`, ...)
        are that message's with the name's bytes replaced: a CDR string's length alone places
        what follows it (shared by the views: serialising one costs ~50 us)."""
        frame = self.robot_frame.encode()
        key = (angles.tobytes(), range_min, range_max, scan_time, len(frame))
        found = self._scan_bytes_of.get(key)
        if found is not None:
            data, at = found
            return data[:at] + frame + data[at + len(frame) :]
        angle_min, increment, _, _ = grid
        message = rosmsg.laser_scan(
            0, self.robot_frame, angle_min, increment, binned, scan_time, range_min, range_max
        )
        data = rosmsg.serialize(message, TOPIC_TYPES["/scan"])
        named = rosmsg.pattern_offsets(data, struct.pack("<I", len(frame) + 1) + frame + b"\0")
        if len(named) == 1:  # the frame name's bytes: after its length (uint32, with the NUL)
            self._scan_bytes_of[key] = (data, named[0] + 4)
        return data

    def write_obstacles(self, t_ns: int, obstacles: list) -> None:
        """The unknown obstacles (`cosim.world.shapes` shapes) on /obstacles: circles as cylinders,
        rectangles as cubes (same centre, size, yaw), polygons as closed line strips.

        Moving obstacles are republished with every scan, so circles and rectangles reuse the CDR
        bytes of the first message of the same shapes (`cosim.record.markers`): only the stamps and
        the centres change. The message is held in the block like /scan (a direct write packs the
        block first); the block keeps the order of the messages, so the log reads the same."""
        self._hold(self._channel("/obstacles"), t_ns, self.obstacles_payload(t_ns, obstacles))

    def obstacles_payload(self, t_ns: int, obstacles: list) -> bytes:
        """The CDR bytes of the /obstacles message of `write_obstacles` (for it or `hold_steps`)."""
        payload = self._obstacle_markers.payload(t_ns, obstacles)
        if self.trace is not None:
            self.trace.add_obstacles(t_ns, obstacles)
        return payload


def scan_layout(angles: np.ndarray) -> tuple[float, float, np.ndarray, str]:
    """Place beam angles [rad, increasing] on a uniform angle grid for sensor_msgs/LaserScan.

    Returns (angle_min, angle_increment, bin of each beam, description). Uniform angles map 1:1.
    Otherwise the grid step is the smallest beam spacing divided by the smallest m <= 16 that puts
    every beam within 1e-6 rad of a grid angle (bins between beams hold NaN); when no such m
    exists each beam goes to its nearest bin at m = 16 and the description states the largest
    angle error.
    """
    count = len(angles)
    if count == 0:
        return 0.0, 0.0, np.zeros(0, dtype=np.int64), "empty"
    if np.any(np.diff(angles) <= 0.0):
        raise CosimError("lidar beam angles must be strictly increasing to be written as a LaserScan")
    angle_min = float(angles[0])
    if count == 1:
        return angle_min, 0.0, np.zeros(1, dtype=np.int64), "uniform"
    spacing = float(np.min(np.diff(angles)))
    for subdivision in range(1, SCAN_MAX_SUBDIVISION + 1):
        increment = spacing / subdivision
        position = (angles - angle_min) / increment
        bins = np.rint(position).astype(np.int64)
        error = float(np.max(np.abs(position - bins)) * increment)
        if error <= SCAN_ANGLE_TOLERANCE:
            uniform = subdivision == 1 and bins[-1] == count - 1
            return angle_min, increment, bins, "uniform" if uniform else "exact, NaN between beams"
    return angle_min, increment, bins, f"nearest bin, angle error up to {error:.3g} rad"


__all__ = ["Recorder", "RunTrace", "TRACE_SIGNALS", "scan_layout", "TOPIC_TYPES"]


def _path_cdr(t_ns: int, xs, ys, headings) -> bytes:
    return rosmsg.serialize(_path_message(t_ns, xs, ys, headings), "nav_msgs/msg/Path")


def _path_message(t_ns: int, xs, ys, headings):
    """nav_msgs/Path in frame map: a PoseStamped (frame map, stamped t_ns) per point."""
    poses = [rosmsg.pose_stamped(t_ns, px, py, yaw) for px, py, yaw in zip(xs, ys, headings, strict=True)]
    return rosmsg.make("nav_msgs/msg/Path", header=rosmsg.header(t_ns, MAP_FRAME), poses=poses)


class _PathLayout:
    """The CDR bytes of a /plan Path without building its messages (a plan has hundreds of poses):
    the bytes before the poses, the first pose's and each further pose's (CDR aligns the float64s
    to 8 bytes, so the first pose may be padded differently), a layout that does not depend on the
    values, found once by serialising paths of sentinel values, with the offsets of the stamps and
    of x, y, qz, qw (the quaternion's z, w, as `rosmsg.quaternion` computes them). `cdr(t_ns, xs,
    ys, headings)` is None when the layout is not so (the message is built then)."""

    def __init__(self) -> None:
        self.usable = False
        empty = _path_cdr(_SENTINEL_NS, [], [], [])
        sentinels = [1.0e250 * (index + 1.5) for index in range(4)]
        one = _path_cdr(_SENTINEL_NS, sentinels[:1], sentinels[2:3], [0.0])
        two = _path_cdr(_SENTINEL_NS, sentinels[:2], sentinels[2:], [0.0, 0.0])
        if not empty.endswith(struct.pack("<I", 0)):
            return
        self.head = bytearray(empty[:-4])  # the poses' count (uint32) ends the empty path
        stamp = _STAMP.pack(*divmod(_SENTINEL_NS, 1_000_000_000))
        self.head_stamps = rosmsg.pattern_offsets(bytes(self.head), stamp)
        self.first = self._pose(one[len(empty) :], stamp, sentinels[0], sentinels[2])
        self.rest = self._pose(two[len(one) :], stamp, sentinels[1], sentinels[3])
        if self.first is None or self.rest is None or not self.head_stamps:
            return
        self.usable = True
        # The same bytes as the messages serialised, or never used.
        for count in (1, 2, 3, 6):
            xs = [0.37 * i - 5.1 for i in range(count)]
            ys = [-1.3 * i + 2.9 for i in range(count)]
            headings = [0.91 * i - 2.7 for i in range(count)]
            if self.cdr(123_456_789_012, xs, ys, headings) != _path_cdr(123_456_789_012, xs, ys, headings):
                self.usable = False
                return

    @staticmethod
    def _pose(data: bytes, stamp: bytes, x: float, y: float) -> tuple | None:
        """(bytes as uint8, stamp offsets, offset of x) of one pose, or None: y, z, the quaternion
        do not follow x."""
        stamps = rosmsg.pattern_offsets(data, stamp)
        found = [rosmsg.pattern_offsets(data, struct.pack("<d", value)) for value in (x, y)]
        if not stamps or any(len(at) != 1 for at in found):
            return None
        at = found[0][0]
        if found[1][0] != at + 8 or at + 56 > len(data):
            return None
        return np.frombuffer(data, np.uint8), stamps, at

    def cdr(self, t_ns: int, xs, ys, headings) -> bytes | None:
        if not self.usable:
            return None
        count = len(xs)
        stamp = _STAMP.pack(*divmod(int(t_ns), 1_000_000_000))
        head = self.head
        for at in self.head_stamps:
            head[at : at + 8] = stamp
        halves = [yaw / 2.0 for yaw in np.asarray(headings, dtype=float).tolist()]
        values = np.empty((count, 7))  # x, y, z, then the quaternion x, y, z, w
        values[:, 0] = xs
        values[:, 1] = ys
        values[:, 2:5] = 0.0
        values[:, 5] = [math.sin(half) for half in halves]
        values[:, 6] = [math.cos(half) for half in halves]
        parts = [bytes(head), struct.pack("<I", count)]
        stamp_bytes = np.frombuffer(stamp, np.uint8)
        for (pose, stamps, at), rows in ((self.first, values[:1]), (self.rest, values[1:])):
            if not len(rows):
                continue
            block = np.tile(pose, len(rows)).reshape(len(rows), len(pose))
            for offset in stamps:
                block[:, offset : offset + 8] = stamp_bytes
            block[:, at : at + 56] = rows.view(np.uint8)
            parts.append(block.tobytes())
        return b"".join(parts)


_TWIST_LAYOUT: FixedLayout | None = None


def _twist_layout() -> FixedLayout:
    """/cmd_vel (geometry_msgs/Twist, no stamp) as rows of v, omega (`rosmsg.twist_cdr`)."""
    global _TWIST_LAYOUT
    if _TWIST_LAYOUT is None:
        sentinels = (1.0e250 * 1.5, 1.0e250 * 2.5)
        data = rosmsg.twist_cdr(*sentinels)
        found = [rosmsg.pattern_offsets(data, struct.pack("<d", value)) for value in sentinels]
        if any(len(at) != 1 for at in found):
            raise CosimError("unexpected CDR layout of a twist message")
        fields = {"v": ("<f8", found[0][0]), "omega": ("<f8", found[1][0])}
        _TWIST_LAYOUT = FixedLayout(rosmsg.twist_cdr(0.0, 0.0), fields, ("v", "omega"))
    return _TWIST_LAYOUT


_SENTINEL_NS = 1_234_567_891_987_654_321  # a stamp no run writes, to find in a template
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: int32 sec, uint32 nanosec
_PATH_LAYOUT: _PathLayout | None = None


def _path_layout() -> _PathLayout:
    global _PATH_LAYOUT
    if _PATH_LAYOUT is None:
        _PATH_LAYOUT = _PathLayout()
    return _PATH_LAYOUT
