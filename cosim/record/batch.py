"""Messages of fixed layout collected over a block of steps and packed into MCAP records at once.

Per message, Python then only stores a row (a signal record's float64 values, a pose's five
numbers) and the stream's number in the block's write order; `MessageBlock.pack` builds every
record of the block in one C call (`cosim.core.kernel.pack_records`: per message in write order,
the stream's template record (MCAP message head + CDR payload) with the sequence, log and publish
time, the stamps and the float64 fields written in; a ready payload behind its head) and hands
them to `ChunkWriter.add_records`. The bytes are exactly what the per-message path writes
(`rosmsg.signals_payload`, `odometry_cdr`, `tf_cdr`, `pose_stamped_cdr`, any ready CDR bytes).
`MessageBlock._records_numpy` builds the same bytes with NumPy structured views (the reference the
tests hold the C build to, and the stand-in past `kernel.MAX_STREAMS` streams).

`MessageBlock.add_batch` takes the messages of many steps at once (arrays in write order) and
leaves the block as holding them one at a time would have (the places a pack was due: a stream's
block full, or a message past the first held message's chunk window), so a schema or channel
registered between two messages lands where it would have; of the packs due within the batch
it does the last only, which writes the records the others would have.
"""

from __future__ import annotations

import functools
import itertools
import struct
from typing import NamedTuple

import numpy as np

from cosim.core import kernel
from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.record.mcap_format import MESSAGE_FIELDS, MESSAGE_HEAD, MESSAGE_HEAD_SIZE, OP_MESSAGE
from cosim.record.writer import ChunkWriter

NS_PER_S = 1_000_000_000
# Field offsets of the message head (struct "<BQHIQQ", packed).
_HEAD_FIELDS = {
    "length": ("<u8", 1),
    "channel": ("<u2", 9),
    "sequence": ("<u4", 11),
    "log_time": ("<u8", 15),
    "publish_time": ("<u8", 23),
}
_CDR = len(rosmsg.CDR_HEADER)
_HEAD_DTYPE = np.dtype(
    {
        "names": ["opcode", *_HEAD_FIELDS],
        "formats": ["u1", *(fmt for fmt, _ in _HEAD_FIELDS.values())],
        "offsets": [0, *(offset for _, offset in _HEAD_FIELDS.values())],
        "itemsize": MESSAGE_HEAD_SIZE,
    }
)  # one message head (MESSAGE_HEAD) as a structured record
RAW = "raw"  # the stream of messages held as ready payload bytes
RAW_STREAM = 0


def _scatter(out: np.ndarray, starts: np.ndarray, records: np.ndarray) -> None:
    """Copy row j of `records` (bytes) to out[starts[j]:]: one fancy-index assignment of whole
    rows, through a view of `out` whose row r starts at byte r (rows overlap; the rows written
    do not)."""
    size = records.shape[1]
    if size == 0 or len(starts) == 0:
        return
    rows = np.ndarray((len(out) - size + 1, size), np.uint8, out, 0, (1, 1))
    rows[starts] = records


def _record_dtype(payload_fields: dict[str, tuple], payload_size: int) -> np.dtype:
    """A packed structured dtype of one MCAP message record: head fields, then payload fields at
    their byte offsets within the payload (shifted by the head size). Made once per layout (a
    fleet's robots have the same layouts: their /cmd_vel, their /scan)."""
    return _layout_dtype(tuple(payload_fields.items()), payload_size)


@functools.lru_cache(maxsize=256)
def _layout_dtype(payload_fields: tuple, payload_size: int) -> np.dtype:
    names, formats, offsets = [], [], []
    for name, (fmt, offset) in _HEAD_FIELDS.items():
        names.append(name)
        formats.append(fmt)
        offsets.append(offset)
    for name, (fmt, offset) in payload_fields:
        names.append(name)
        formats.append(fmt)
        offsets.append(MESSAGE_HEAD_SIZE + offset)
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": MESSAGE_HEAD_SIZE + payload_size}
    )


class _Records:
    """Records of one channel with one payload layout: a template row, then varying fields."""

    def __init__(self, channel: int, template_payload: bytes, fields: dict[str, tuple]) -> None:
        self.channel = channel
        self.size = MESSAGE_HEAD_SIZE + len(template_payload)
        self.template = np.frombuffer(
            MESSAGE_HEAD.pack(OP_MESSAGE, MESSAGE_FIELDS.size + len(template_payload), channel, 0, 0, 0)
            + template_payload,
            np.uint8,
        )
        self.dtype = _record_dtype(fields, len(template_payload))
        # Byte offsets in the record of the stamps (sec; nanosec follows) written per message.
        self.stamps = [self.offset(name) for name in ("sec", "sec2") if name in fields]

    def offset(self, name: str) -> int:
        """Byte offset of field `name` in the record."""
        return self.dtype.fields[name][1]

    def build(self, times: np.ndarray, sequence: int) -> np.ndarray:
        """Rows of records (len(times) x size bytes as a structured array), stamps and sequence set."""
        raw = np.empty((len(times), self.size), dtype=np.uint8)
        raw[:] = self.template
        records = raw.view(self.dtype).reshape(-1)
        records["sequence"] = np.arange(sequence, sequence + len(times), dtype=np.uint32)
        records["log_time"] = times
        records["publish_time"] = times
        for suffix in ("", "2"):  # a TFMessage's second transform has its own stamp
            if "sec" + suffix in self.dtype.names:
                records["sec" + suffix] = times // NS_PER_S
                records["nanosec" + suffix] = times % NS_PER_S
        return records


def _stamp_fields(offset: int) -> dict[str, tuple]:
    return {"sec": ("<i4", offset), "nanosec": ("<u4", offset + 4)}


def _field_count(fmt) -> int:
    """float64 values of a field of format `fmt` ("<f8", or ("<f8", (count,)) for an array)."""
    return fmt[1][0] if isinstance(fmt, tuple) else 1


class FixedLayout(NamedTuple):
    """The records of a channel of one fixed CDR layout whose float64 fields each take a column of
    a stream's rows (a fleet robot's /odom, /pose, /cmd_vel: `MessageBlock.add_fixed_channel`):
    the payload of any one message, its fields (name -> (format, byte offset in the payload);
    "sec"/"nanosec" and "sec2"/"nanosec2" the stamps written per message) and the float64 fields
    the columns go into, in column order."""

    payload: bytes
    fields: dict[str, tuple]
    columns: tuple[str, ...]

    @property
    def width(self) -> int:
        """The rows' columns: one per float64 of the fields of `columns`."""
        return sum(_field_count(self.fields[name][0]) for name in self.columns)


class SignalStream:
    """Rows of one `/signals/<component>` channel: `values` float64 per record (or, with a
    `FixedLayout`, rows of another channel of fixed layout, one float64 field per column).

    A step stream (`split` = number of inputs) is handed a step's applied inputs and its end
    outputs; row n gets the inputs, and the outputs go into row n + 1, the record of the
    component's next step, at whose start they hold. So `rows[len(times)]` is always the pending
    record: its outputs are known, its inputs come with the next step (or, at the end, are the
    inputs last applied, held)."""

    def __init__(
        self,
        channel: int,
        size: int,
        capacity: int,
        split: int | None = None,
        initial: np.ndarray | None = None,
        period_ns: int = 0,
        start_ns: int = 0,
        layout: FixedLayout | None = None,
    ) -> None:
        if layout is None:
            payload = rosmsg.signals_payload(0, np.zeros(size))
            fields = _stamp_fields(_CDR)
            if size:
                fields["values"] = (("<f8", (size,)), rosmsg.SIGNAL_VALUES_OFFSET)
            # (field, first column, columns) of the rows written into each record
            self.parts = [("values", 0, size)] if size else []
        else:
            payload, fields = layout.payload, dict(layout.fields)
            self.parts, column = [], 0
            for name in layout.columns:
                count = _field_count(fields[name][0])
                self.parts.append((name, column, count))
                column += count
        self.layout = layout
        self.records = _Records(channel, payload, fields)
        self.split = split
        self.period_ns = period_ns
        self.rows = np.empty((capacity + 1, size))
        if split is not None:
            self.rows[0] = initial
        # Its row of the pack's stream table (`cosim.core.kernel.pack_records`), the columns that
        # do not change from pack to pack, and its field-table row (None: no values).
        records = self.records
        self.table = np.zeros(kernel.STREAM_COLUMNS, dtype=np.int64)
        self.table[kernel.P_KIND] = kernel.STREAM_FIXED
        self.table[kernel.P_CHANNEL] = channel
        self.table[kernel.P_SIZE] = records.size
        self.table[kernel.P_TEMPLATE] = records.template.ctypes.data
        self.table[kernel.P_MATRIX_COLUMNS] = size
        self.table[kernel.P_STAMP_COUNT] = len(records.stamps)
        self.table[kernel.P_STAMP_FIRST : kernel.P_STAMP_FIRST + len(records.stamps)] = records.stamps
        self.table[kernel.P_FIELD_COUNT] = len(self.parts)
        self.fields = [(records.offset(name), column, count) for name, column, count in self.parts]
        self._addressed: tuple[np.ndarray, int] | None = None
        self.times: list[int] = []
        self.pending_ns: int | None = None  # [ns] when the pending record's outputs hold (None: first step)
        self.ended = False

    def address(self) -> int:
        """The address of `rows` (a new array when they grew)."""
        if self._addressed is None or self._addressed[0] is not self.rows:
            self._addressed = (self.rows, self.rows.ctypes.data)
        return self._addressed[1]

    def carry(self) -> None:
        """After the held rows were packed: the pending record becomes row 0, with the inputs of
        the last record (for a last record at the end)."""
        held = len(self.times)
        if self.split is not None and held and not self.ended:
            self.rows[0, self.split :] = self.rows[held, self.split :]
            self.rows[0, : self.split] = self.rows[held - 1, : self.split]
            self.pending_ns = self.times[-1] + self.period_ns
        self.times = []


class PoseStream:
    """/odom, /tf and /pose written together from (t, x, y, theta, v, omega) rows."""

    def __init__(self, odom: int, tf: int, pose: int) -> None:
        zero_pose = (0.0, 0.0, 0.0)
        odom_payload = rosmsg.odometry_cdr(0, *zero_pose, 0.0, 0.0)
        pose_offset = _CDR + struct.calcsize(rosmsg.ODOMETRY_HEAD)
        odom_fields = _stamp_fields(_CDR) | {"pose": ("<f8", pose_offset), "pose_y": ("<f8", pose_offset + 8)}
        odom_fields |= {"qz": ("<f8", pose_offset + 40), "qw": ("<f8", pose_offset + 48)}
        twist_offset = pose_offset + 56 + 36 * 8
        odom_fields |= {"v": ("<f8", twist_offset), "omega": ("<f8", twist_offset + 40)}
        self.odom = _Records(odom, odom_payload, odom_fields)
        tf_offset = _CDR + struct.calcsize(rosmsg.TF_SECOND)  # the pose of odom -> base_link
        second_stamp = _CDR + struct.calcsize(rosmsg.TF_HEAD) + 7 * 8
        tf_fields = _stamp_fields(_CDR + 4) | {
            "sec2": ("<i4", second_stamp),
            "nanosec2": ("<u4", second_stamp + 4),
        }
        tf_fields |= {"pose": ("<f8", tf_offset), "pose_y": ("<f8", tf_offset + 8)}
        tf_fields |= {"qz": ("<f8", tf_offset + 40), "qw": ("<f8", tf_offset + 48)}
        self.tf = _Records(tf, rosmsg.tf_cdr(0, *zero_pose), tf_fields)
        stamped_offset = _CDR + struct.calcsize("<iII4s")
        pose_fields = _stamp_fields(_CDR) | {
            "pose": ("<f8", stamped_offset),
            "pose_y": ("<f8", stamped_offset + 8),
        }
        pose_fields |= {"qz": ("<f8", stamped_offset + 40), "qw": ("<f8", stamped_offset + 48)}
        self.pose = _Records(pose, rosmsg.pose_stamped_cdr(0, *zero_pose), pose_fields)
        self.rows: list[tuple] = []  # (t_ns, x, y, theta, v, omega) held one at a time, not yet in `blocks`
        self.blocks: list[tuple[np.ndarray, np.ndarray]] = []  # (t_ns, rows of x, y, theta, v, omega)
        self.count = 0  # poses held

    def add_rows(self, times: np.ndarray, values: np.ndarray) -> None:
        self.settle()
        self.blocks.append((times, values))
        self.count += len(times)

    def settle(self) -> None:
        """The poses held one at a time as a block."""
        if self.rows:
            times = np.array([row[0] for row in self.rows], dtype=np.int64)
            self.blocks.append((times, np.array([row[1:] for row in self.rows], dtype=np.float64)))
            self.rows = []

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """Every held pose: (t_ns, rows of x, y, theta, v, omega); none held after."""
        self.held()
        (times, values), self.blocks, self.count = self.blocks[0], [], 0
        return times, values

    def held(self) -> tuple[np.ndarray, np.ndarray]:
        """The held poses as one block, still held."""
        self.settle()
        if len(self.blocks) != 1:
            self.blocks = [
                (np.concatenate([t for t, _ in self.blocks]), np.concatenate([v for _, v in self.blocks]))
            ]
        return self.blocks[0]


class MessageBlock:
    """Messages of a block of steps, in write order, until `pack` hands them to the writer."""

    def __init__(
        self, writer: ChunkWriter, sequences: dict[int, int], capacity: int = 512, window_ns: int = 0
    ) -> None:
        self.writer = writer
        # A message past the window of the first one held asks for a pack, so the writer can end
        # that window's chunk (what a killed run keeps) without waiting for a full block.
        self.window_ns = window_ns
        self.deadline = 0  # [ns] end of the first held message's window (when window_ns)
        self.sequences = sequences  # channel -> next sequence number (shared with the Recorder)
        self.capacity = capacity
        self.signals: dict[int, SignalStream] = {}
        self.streams: list = [RAW]  # stream number -> SignalStream, a PoseStream part, or RAW
        self.stream_of: dict[int, int] = {}  # signal channel -> stream number
        self.pose: PoseStream | None = None
        self.pose_streams = (-1, -1, -1)
        self.raw: list[tuple[int, int, bytes]] = []  # (channel, t_ns, payload) of any other message
        # Stream number of each message, in write order: `order_parts` (arrays held at once, by
        # `add_batch`, `add_signal_rows`), then `order` (held one at a time).
        self.order: list[int] = []
        self.order_parts: list[np.ndarray] = []
        self.count = 0  # messages held
        # Packs skipped (`add_batch`): the held messages before `mark` would have been packed, the
        # others form the current group, `group` messages, `group_sizes` per stream number (poses
        # counted once, at the /odom stream). A schema or channel registered while a group is
        # open after the mark goes before that group's first message (`definitions`).
        self.mark = 0
        self.group = 0
        self.group_sizes: dict[int, int] = {}
        self.definitions: list[tuple[int, list]] = []  # (message position, schema/channel records)
        self.batch_limit = 0  # messages held across skipped packs at most (0: pack every time)
        self.clock_due = None  # () -> True when held messages are to reach the file now (wall clock)
        # Records built in C (`cosim.core.kernel.pack_records`); False: with NumPy (`_records_numpy`).
        self.native = True
        self._out: bytearray | None = None  # the buffer packs write their records into
        self._signal_table_cache: dict[tuple, tuple] = {}  # `_signal_tables`
        # Steps collected outside the block (`Recorder.collect`): its `flush()` hands them over
        # (through `add_batch`), called before any other message is held, packed or registered.
        self.collector = None

    def _grouped(self, number: int, messages: int) -> bool:
        """Account for a message of stream `number` (`messages` records) in the group; True when
        its stream's block is full."""
        self.count += messages
        self.group += messages
        size = self.group_sizes.get(number, 0) + 1
        self.group_sizes[number] = size
        return size == self.capacity

    def skip_pack(self, definitions: bool) -> bool:
        """Where a pack was due (a stream's block full, a window passed): the held messages count
        as packed for what follows, and are to be packed (True) when enough are held
        (`batch_limit`), `definitions` (schemas or channels) wait to be written or the wall clock
        asks for it (`clock_due`); the caller packs them (`add_batch`)."""
        self.mark = self.count
        self.group = 0
        self.group_sizes = {}
        if self.count >= self.batch_limit or definitions:
            return True
        return self.clock_due is not None and self.clock_due()

    def registered(self) -> None:
        """After a schema or channel was registered: it goes before the current group."""
        if self.mark:
            self.definitions.append((self.mark, self.writer.take_definitions()))

    def _grow(self, stream: SignalStream, rows: int) -> None:
        """Room for `rows` held rows (plus the pending one) in `stream.rows`."""
        if rows + 1 > len(stream.rows):
            grown = np.empty((max(rows + 1, 2 * len(stream.rows)), stream.rows.shape[1]))
            grown[: len(stream.rows)] = stream.rows
            stream.rows = grown

    def _window_end(self, t_ns: int) -> int:
        """[ns] the end of the chunk window holding `t_ns`."""
        return (t_ns // self.window_ns + 1) * self.window_ns

    def _due(self, t_ns: int) -> bool:
        """True when `t_ns` (of the message just held) is past the first held message's window."""
        if not self.window_ns:
            return False
        if self.group == 1:
            self.deadline = self._window_end(t_ns)
            return False
        return t_ns >= self.deadline

    def add_signal_channel(
        self,
        channel: int,
        size: int,
        split: int | None = None,
        initial: np.ndarray | None = None,
        period_ns: int = 0,
    ) -> None:
        self.signals[channel] = SignalStream(channel, size, self.capacity, split, initial, period_ns)
        self.stream_of[channel] = len(self.streams)
        self.streams.append(self.signals[channel])

    def add_fixed_channel(self, channel: int, layout: FixedLayout) -> None:
        """A channel of fixed layout held as rows (`FixedLayout`), as a signal channel is."""
        self.signals[channel] = SignalStream(channel, layout.width, self.capacity, layout=layout)
        self.stream_of[channel] = len(self.streams)
        self.streams.append(self.signals[channel])

    def fixed_row(self, channel: int, t_ns: int, payload: bytes) -> np.ndarray | None:
        """The row of a message of a fixed-layout channel (`add_fixed_channel`) given as its CDR
        payload, or None when the channel is not one; a payload of another layout is refused (the
        channel's messages are numbered as rows)."""
        stream = self.signals.get(channel)
        if stream is None or stream.layout is None:
            return None
        records = stream.records
        row = np.zeros(stream.layout.width)
        record = None
        if len(payload) + MESSAGE_HEAD_SIZE == records.size:
            for name, column, count in stream.parts:
                at = records.offset(name) - MESSAGE_HEAD_SIZE
                row[column : column + count] = np.frombuffer(payload, "<f8", count, at)
            record = records.build(np.array([t_ns], dtype=np.uint64), 0)
            for name, column, count in stream.parts:
                shaped = record.dtype[name].shape != ()
                record[name] = row[column : column + count] if shaped else row[column]
        if record is None or record.view(np.uint8)[MESSAGE_HEAD_SIZE:].tobytes() != bytes(payload):
            raise CosimError(f"channel {channel}: a message not of the channel's layout")
        return row

    def settle(self) -> None:
        """Hand the steps a collector holds back (`collector`) to the block, before anything else
        is held, packed or registered: they come first in the log."""
        if self.collector is not None:
            self.collector.flush()

    def add_signals(
        self, channel: int, t_ns: int, values: np.ndarray, more: np.ndarray | None = None
    ) -> bool:
        """Hold one signal record (`values`, then `more` when given); True when the block is full
        (the caller packs it). On a step stream: a step's inputs and end outputs (`SignalStream`)."""
        self.settle()
        stream = self.signals[channel]
        held = len(stream.times)
        self._grow(stream, held + 1)
        split = stream.split
        if split is not None:
            if stream.ended:
                raise CosimError(f"signal channel {channel}: a step after end_steps")
            if more is None:
                stream.rows[held, :split] = values[:split]
                stream.rows[held + 1, split:] = values[split:]
            else:
                stream.rows[held, :split] = values
                stream.rows[held + 1, split:] = more
        elif more is None:
            stream.rows[held] = values
        else:  # two slice copies: about 1 us less than np.concatenate(..., out=row)
            row = stream.rows[held]
            split = len(values)
            row[:split] = values
            row[split:] = more
        stream.times.append(t_ns)
        number = self.stream_of[channel]
        self.order.append(number)
        return self._grouped(number, 1) or self._due(t_ns)

    def add_signal_rows(self, blocks: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Hold many records at once: (channel, times [ns], rows) per channel, in the order one
        record at a time would have been written (by time, then by position in `blocks`).
        Packs first when they do not fit next to what is held."""
        self.settle()
        counts = [len(times) for _, times, _ in blocks]
        if any(
            len(self.signals[c].times) + n >= len(self.signals[c].rows)
            for (c, _, _), n in zip(blocks, counts, strict=True)
        ):
            self.pack()
        for (channel, times, rows), count in zip(blocks, counts, strict=True):
            stream = self.signals[channel]
            if count + 1 > len(stream.rows):
                grown = np.empty((count + 1, stream.rows.shape[1]))
                grown[0] = stream.rows[0]  # the pending record (nothing else is held after pack)
                stream.rows = grown
            held = len(stream.times)
            split = stream.split
            if split is None:
                stream.rows[held : held + count] = rows
            else:
                if stream.ended and count:
                    raise CosimError(f"signal channel {channel}: a step after end_steps")
                stream.rows[held : held + count, :split] = rows[:, :split]
                stream.rows[held + 1 : held + count + 1, split:] = rows[:, split:]
            stream.times.extend(np.asarray(times, dtype=np.int64).tolist())
        all_times = np.concatenate([np.asarray(times, dtype=np.int64) for _, times, _ in blocks])
        position = np.repeat(np.arange(len(blocks)), counts)
        streams = np.array([self.stream_of[channel] for channel, _, _ in blocks], dtype=np.int64)
        self._order_part(streams[position[np.lexsort((position, all_times))]])
        self.count += int(sum(counts))

    def end_steps(self, end_ns: int) -> None:
        """Hold the last record of every step stream: the final outputs, stamped when they hold
        (the end of the component's last step) or at `end_ns` when that is earlier (the run
        stopped inside a slower component's step, or before its first); then no more steps."""
        self.settle()
        for channel, stream in self.signals.items():
            if stream.split is None or stream.ended:
                continue
            held = len(stream.times)
            if held:
                pending = stream.times[-1] + stream.period_ns
                stream.rows[held, : stream.split] = stream.rows[held - 1, : stream.split]
            else:  # nothing held: the pending record is row 0 (initial values, or carried)
                pending = stream.pending_ns
            stream.ended = True
            # Row `held` exists: a stream is packed before its pending row is the last one.
            stream.times.append(int(end_ns if pending is None else min(pending, end_ns)))
            self.order.append(self.stream_of[channel])
            self.count += 1
        self.pack()

    def pose_stream(self, channels: tuple[int, int, int]) -> tuple[int, int, int]:
        """The stream numbers of /odom, /tf, /pose (made on first use)."""
        if self.pose is None:
            self.pose = PoseStream(*channels)
            first = len(self.streams)
            self.streams += ["odom", "tf", "pose"]
            self.pose_streams = (first, first + 1, first + 2)
        return self.pose_streams

    def add_pose(self, channels: tuple[int, int, int], row: tuple) -> bool:
        self.settle()
        self.pose_stream(channels)
        self.pose.rows.append(row)
        self.pose.count += 1
        self.order.extend(self.pose_streams)
        full = self._grouped(self.pose_streams[0], 3)
        if self.group == 3 and self.window_ns:  # the first messages of the group
            self.deadline = self._window_end(row[0])
        return full or self._due(row[0])

    def add_raw(self, channel: int, t_ns: int, payload: bytes) -> bool:
        self.settle()
        self.raw.append((channel, t_ns, payload))
        self.order.append(RAW_STREAM)
        return self._grouped(RAW_STREAM, 1) or self._due(t_ns)

    def add_batch(
        self,
        order: np.ndarray,
        times: np.ndarray,
        signal_rows: dict[int, np.ndarray],
        pose_rows: np.ndarray | None = None,
        raw: list[tuple[int, bytes]] = (),
    ) -> None:
        """Hold many messages at once, packing where holding them one at a time would have
        (`add_signals`, `add_pose`, `add_raw` and a pack whenever one returned True).

        `order`: the stream number of each message in write order (a pose is its three streams,
        `pose_stream`, one after the other); `times` [ns]: each message's stamp, never decreasing;
        `signal_rows`: per signal stream number, its rows in order (a step stream's row: the
        step's inputs, then its end outputs); `pose_rows`: per pose, x, y, theta, v, omega;
        `raw`: per RAW_STREAM message, (channel, payload).

        The places where one message at a time would have packed or skipped a pack are found
        first (`_account`); the messages are then held a stream at a time up to the last pack and
        after it (`_hold_batch`), with one pack there: the packs skipped before it would have
        written the same records (nothing registers a schema or channel meanwhile), and the block
        is left as it would have been."""
        self.settle()
        order = np.asarray(order, dtype=np.int64)
        times = np.asarray(times, dtype=np.int64)
        cursors = dict.fromkeys(signal_rows, 0)
        cursors[RAW_STREAM] = 0
        cursors[self.pose_streams[0]] = 0
        # Each stream's stamps in write order, at once (a stream's next messages are its next
        # stamps: `cursors`): one stable sort by stream number (a radix sort on 16 bits).
        numbers = order.astype(np.uint16) if len(self.streams) <= 1 << 16 else order
        by_stream = np.argsort(numbers, kind="stable")
        grouped = times[by_stream]
        counts = np.bincount(order, minlength=len(self.streams))
        bounds = np.cumsum(counts).tolist()
        stamps = {
            number: grouped[bounds[number] - n : bounds[number]]
            for number, n in enumerate(counts.tolist())
            if n
        }
        count = len(order)
        window = self.window_ns
        held = self.count
        last_pack = None  # the end of the messages packed last, where one was due
        definitions = self.writer.has_definitions()  # written by the first pack
        i = 0
        while i < count:
            end, full = count, False
            if window:
                if self.group == 0:
                    deadline, low = self._window_end(int(times[i])), i + 1
                else:
                    deadline, low = self.deadline, i
                later = np.flatnonzero(times[low:] >= deadline)
                if len(later):
                    end, full = low + int(later[0]) + 1, True
            room = self._room()
            if end - i >= room:  # a stream may fill its block first
                stop = self._filled(order, i, end)
                if stop is not None and stop < end:
                    end, full = stop, True
            if full and order[end - 1] == self.pose_streams[0]:
                end += 2  # a pose's three messages are held together
            self._account(order, times, i, end)
            if full and self.skip_pack(definitions):
                last_pack, definitions = end, False
                self.count = self.mark = 0  # as after the pack (`pack`)
            i = end
        state = (self.count, self.mark, self.group, self.group_sizes, self.deadline)
        self.count = held
        if last_pack is not None:
            self._hold_batch(order, 0, last_pack, stamps, signal_rows, pose_rows, raw, cursors)
            self.pack()
        self._hold_batch(order, last_pack or 0, count, stamps, signal_rows, pose_rows, raw, cursors)
        self.count, self.mark, self.group, self.group_sizes, self.deadline = state

    def _room(self) -> int:
        """Messages that can be held before some stream's block is full, at least."""
        return self.capacity - max(self.group_sizes.values(), default=0)

    def _filled(self, order: np.ndarray, first: int, end: int) -> int | None:
        """End (exclusive) of the first message in order[first:end] that fills its stream's block."""
        stop = None
        part = order[first:end]
        counts = np.bincount(part, minlength=len(self.streams)).tolist()
        sizes = self.group_sizes
        ends = [(RAW_STREAM, self.capacity - sizes.get(RAW_STREAM, 0))]
        if self.pose is not None:
            ends.append((self.pose_streams[2], self.capacity - sizes.get(self.pose_streams[0], 0)))
        ends += [(n, self.capacity - sizes.get(n, 0)) for n in self.stream_of.values()]
        for number, room in ends:
            if counts[number] >= room > 0:  # only then is the room-th message's place needed
                candidate = first + int(np.flatnonzero(part == number)[room - 1]) + 1
                stop = candidate if stop is None else min(stop, candidate)
        return stop

    def _account(self, order: np.ndarray, times: np.ndarray, first: int, end: int) -> None:
        """Count messages order[first:end] in the group as holding them would (`_grouped`)."""
        if first >= end:
            return
        if self.group == 0 and self.window_ns:
            self.deadline = self._window_end(int(times[first]))
        counts = np.bincount(order[first:end], minlength=len(self.streams)).tolist()
        sizes = self.group_sizes
        skipped = self.pose_streams[1:]  # poses counted once, at the /odom stream
        for number in np.flatnonzero(counts).tolist():
            if number not in skipped:
                sizes[number] = sizes.get(number, 0) + counts[number]
        self.count += end - first
        self.group += end - first

    def _hold_batch(self, order, first, end, stamps, signal_rows, pose_rows, raw, cursors) -> None:
        """Hold messages order[first:end] (no pack, no group counted: `_account`); `stamps`: each
        stream's stamps in write order, from its cursor on."""
        if first >= end:
            return
        part = order[first:end]
        counts = np.bincount(part, minlength=len(self.streams)).tolist()
        streams = self.streams
        for number in np.flatnonzero(counts).tolist():
            n = counts[number]
            stream = streams[number]
            if type(stream) is SignalStream:  # the most messages: tested first
                at = cursors[number]
                rows = signal_rows[number]
                if at or n != len(rows):
                    rows = rows[at : at + n]
                cursors[number] = at + n
                held_times = stream.times
                held = len(held_times)
                if held + n + 1 > len(stream.rows):
                    self._grow(stream, held + n)
                split = stream.split
                if split is None:
                    stream.rows[held : held + n] = rows
                else:
                    if stream.ended:
                        raise CosimError(f"signal channel {stream.records.channel}: a step after end_steps")
                    stream.rows[held : held + n, :split] = rows[:, :split]
                    stream.rows[held + 1 : held + n + 1, split:] = rows[:, split:]
                held_times += stamps[number][at : at + n].tolist()
                continue
            if number == self.pose_streams[1] or number == self.pose_streams[2]:
                continue
            if number == RAW_STREAM:
                at = cursors[RAW_STREAM]
                self.raw += [
                    (channel, t_ns, payload)
                    for (channel, payload), t_ns in zip(
                        raw[at : at + n], stamps[RAW_STREAM][at : at + n].tolist(), strict=True
                    )
                ]
                cursors[RAW_STREAM] = at + n
            elif number == self.pose_streams[0]:
                at = cursors[number]
                self.pose.add_rows(stamps[number][at : at + n], pose_rows[at : at + n])
                cursors[number] = at + n
        self._order_part(part.copy())  # (the caller's array)
        self.count += end - first

    def _order_part(self, part: np.ndarray) -> None:
        """Messages of stream numbers `part` (int64, ours) held after those held so far."""
        if self.order:
            self.order_parts.append(np.array(self.order, dtype=np.int64))
            self.order = []
        self.order_parts.append(part)

    def _sequence(self, channel: int, count: int) -> int:
        first = self.sequences[channel]
        self.sequences[channel] = first + count
        return first

    def pack(self) -> None:
        """Build the held messages' records and append them to the writer in write order."""
        self.settle()
        if self.count == 0:
            return
        if self.order or not self.order_parts:
            self.order_parts.append(np.array(self.order, dtype=np.int64))
        parts = self.order_parts
        order = parts[0] if len(parts) == 1 else np.concatenate(parts)
        self.order_parts = []
        if self.native and len(self.streams) <= kernel.MAX_STREAMS:
            data, offsets, channels, times = self._records_native(order)
        else:
            data, offsets, channels, times = self._records_numpy(order)
        self.order = []
        self.count = self.mark = self.group = 0
        self.group_sizes = {}
        first = 0
        for position, definitions in self.definitions:
            if position > first:
                self._add_records(data, channels, times, offsets, first, position)
            self.writer.put_definitions(definitions)
            first = position
        self.definitions = []
        self._add_records(data, channels, times, offsets, first, len(offsets))

    def _pose_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The held poses, taken: (t_ns as uint64, rows of x, y, theta, v, omega, the orientation
        quaternion's z and w)."""
        times, rows = self.pose.take()
        half = rows[:, 2] / 2.0
        return times.astype(np.uint64), rows, np.column_stack((np.sin(half), np.cos(half)))

    def _raw_sequences(self, channels: np.ndarray) -> np.ndarray:
        """The sequence number of each held raw message (of `channels`: counting per channel, in
        held order; the channels' counters advanced in channel order)."""
        by_channel = np.argsort(channels, kind="stable")
        grouped = channels[by_channel]
        starts = np.flatnonzero(np.diff(grouped, prepend=grouped[0] - 1))
        counts = np.diff(np.append(starts, len(grouped)))
        firsts = [
            self._sequence(int(channel), int(count))
            for channel, count in zip(grouped[starts], counts, strict=True)
        ]
        sequences = np.empty(len(channels), dtype=np.int64)
        sequences[by_channel] = np.repeat(np.array(firsts, dtype=np.int64) - starts, counts) + np.arange(
            len(grouped)
        )
        return sequences

    def _records_native(self, order: np.ndarray) -> tuple[bytearray, np.ndarray, np.ndarray, np.ndarray]:
        """The held messages' records built in C (`cosim.core.kernel.pack_records`): every held
        message taken, the step streams carried (`SignalStream.carry`)."""
        streams = np.zeros((len(self.streams), kernel.STREAM_COLUMNS), dtype=np.int64)
        fields: list[tuple[int, int, int]] = []
        alive: list[np.ndarray] = []  # arrays the tables point into, alive until the C call returns
        carried: list[SignalStream] = []
        signal_fields = None
        size = 0

        def fixed(number: int, records: _Records, times: np.ndarray, matrix: np.ndarray, parts) -> int:
            count = len(times)
            row = streams[number]
            row[kernel.P_KIND] = kernel.STREAM_FIXED
            row[kernel.P_CHANNEL] = records.channel
            row[kernel.P_SEQUENCE] = self._sequence(records.channel, count)
            row[kernel.P_SIZE] = records.size
            row[kernel.P_TEMPLATE] = records.template.ctypes.data
            row[kernel.P_TIMES] = times.ctypes.data
            row[kernel.P_MATRIX] = matrix.ctypes.data
            row[kernel.P_MATRIX_COLUMNS] = matrix.shape[1]
            row[kernel.P_STAMP_COUNT] = len(records.stamps)
            row[kernel.P_STAMP_FIRST : kernel.P_STAMP_FIRST + len(records.stamps)] = records.stamps
            row[kernel.P_FIELD_FIRST] = len(fields) + (0 if signal_fields is None else len(signal_fields))
            row[kernel.P_FIELD_COUNT] = len(parts)
            fields.extend((records.offset(name), column, width) for name, column, width in parts)
            alive.extend((times, matrix))
            return count * records.size

        numbers = [
            n for n, stream in enumerate(self.streams) if type(stream) is SignalStream and stream.times
        ]
        if numbers:  # the signal streams' rows at once: their fixed columns kept (`SignalStream.table`)
            carried = [self.streams[n] for n in numbers]
            counts = [len(stream.times) for stream in carried]
            total = sum(counts)
            times = np.fromiter(itertools.chain.from_iterable(s.times for s in carried), np.uint64, total)
            alive.append(times)
            starts = np.zeros(len(counts), dtype=np.int64)
            np.cumsum(counts[:-1], out=starts[1:])
            table, signal_fields, channels = self._signal_tables(numbers, carried)
            rows = table.copy()
            sequence = self._sequence
            rows[:, kernel.P_SEQUENCE] = [sequence(c, n) for c, n in zip(channels, counts, strict=True)]
            rows[:, kernel.P_TIMES] = times.ctypes.data + 8 * starts
            # rows: float64, C-contiguous (made by `SignalStream`, `_grow`)
            rows[:, kernel.P_MATRIX] = [stream.address() for stream in carried]
            alive += [stream.rows for stream in carried]
            streams[numbers] = rows
            sizes = rows[:, kernel.P_SIZE]
            size += int(np.dot(sizes, counts))
        if self.pose is not None and self.pose.count:
            times, rows, quaternion = self._pose_rows()
            # columns x, y, qz, qw, v, omega (float64 whatever the rows held)
            matrix = np.column_stack((rows[:, :2], quaternion, rows[:, 3:5])).astype(np.float64, copy=False)
            pose = self.pose
            located = [("pose", 0, 2), ("qz", 2, 2)]  # x, y adjacent; qz, qw adjacent
            for number, records in zip(self.pose_streams, (pose.odom, pose.tf, pose.pose), strict=True):
                parts = located + [("v", 4, 1), ("omega", 5, 1)] if records is pose.odom else located
                size += fixed(number, records, times, matrix, parts)
        raw_table = np.zeros((len(self.raw), kernel.RAW_COLUMNS), dtype=np.int64)
        streams[RAW_STREAM, kernel.P_KIND] = kernel.STREAM_RAW
        blob = b""
        if self.raw:
            channels, stamps, payloads = zip(*self.raw, strict=True)
            lengths = list(map(len, payloads))
            raw_table[:, kernel.RAW_CHANNEL] = channels
            raw_table[:, kernel.RAW_SEQUENCE] = self._raw_sequences(raw_table[:, kernel.RAW_CHANNEL])
            raw_table[:, kernel.RAW_TIME] = stamps
            raw_table[:, kernel.RAW_SIZE] = lengths
            raw_table[1:, kernel.RAW_START] = np.cumsum(lengths[:-1])
            blob = b"".join(payloads)
            size += MESSAGE_HEAD_SIZE * len(self.raw) + len(blob)
            self.raw = []
        table = np.array(fields, dtype=np.int64).reshape(-1, kernel.FIELD_COLUMNS)
        if signal_fields is not None:  # the signal streams' fields first (their P_FIELD_FIRST)
            table = np.concatenate((signal_fields, table)) if len(table) else signal_fields
        # Into the last pack's buffer, grown when too small: its pages are already the process's
        # (a new one of a pack's megabytes costs about as much as packing it). The writer copies
        # the records out (`ChunkWriter.add_records`) before the next pack.
        if self._out is None or len(self._out) < size:
            self._out = bytearray(size + size // 4)
        packed = kernel.pack_records(order, streams, table, raw_table, blob, size, self._out)
        for stream in carried:
            stream.carry()
        return packed

    def _signal_tables(self, numbers: list[int], carried: list[SignalStream]) -> tuple:
        """The fixed part of the stream table's rows of signal streams `numbers` (`carried`) packed
        together (`SignalStream.table`, each one's first field in the field table, which they begin),
        their field table, and their channels; made once per set of streams (a run packs the same
        streams again and again)."""
        key = tuple(numbers)
        found = self._signal_table_cache.get(key)
        if found is None:
            rows = np.array([stream.table for stream in carried])
            field_counts = rows[:, kernel.P_FIELD_COUNT]
            rows[:, kernel.P_FIELD_FIRST] = np.cumsum(field_counts) - field_counts
            fields = np.array(
                list(itertools.chain.from_iterable(stream.fields for stream in carried)), dtype=np.int64
            ).reshape(-1, kernel.FIELD_COLUMNS)
            found = (rows, fields, [stream.records.channel for stream in carried])
            if len(self._signal_table_cache) >= 16:
                self._signal_table_cache.clear()
            self._signal_table_cache[key] = found
        return found

    def _records_numpy(self, order: np.ndarray) -> tuple[bytes, np.ndarray, np.ndarray, np.ndarray]:
        """The held messages' records built with NumPy (the reference for `_records_native`, and
        its stand-in for more streams than it takes): every held message taken, the step streams
        carried."""
        parts: dict[int, tuple[np.ndarray, np.ndarray, int, np.ndarray]] = {}  # stream -> rows, times...
        for number, stream in enumerate(self.streams):
            if isinstance(stream, SignalStream) and stream.times:
                times = np.array(stream.times, dtype=np.uint64)
                records = stream.records.build(times, self._sequence(stream.records.channel, len(times)))
                for name, column, count in stream.parts:
                    values = stream.rows[: len(times), column : column + count]
                    records[name] = values[:, 0] if records.dtype[name].shape == () else values
                parts[number] = (records, times, stream.records.channel)
                stream.carry()
        if self.pose is not None and self.pose.count:
            times, rows, quaternion = self._pose_rows()
            qz, qw = quaternion[:, 0], quaternion[:, 1]
            for number, records_of in zip(
                self.pose_streams, (self.pose.odom, self.pose.tf, self.pose.pose), strict=True
            ):
                records = records_of.build(times, self._sequence(records_of.channel, len(times)))
                records["pose"] = rows[:, 0]
                records["pose_y"] = rows[:, 1]
                records["qz"] = qz
                records["qw"] = qw
                if records_of is self.pose.odom:
                    records["v"] = rows[:, 3]
                    records["omega"] = rows[:, 4]
                parts[number] = (records, times, records_of.channel)
        sizes = np.zeros(len(self.streams), dtype=np.int64)
        for number, (records, _, _) in parts.items():
            sizes[number] = records.dtype.itemsize
        raw = self.raw
        message_sizes = sizes[order]
        if raw:
            raw_channels = np.array([channel for channel, _, _ in raw], dtype=np.int64)
            raw_times = np.array([t_ns for _, t_ns, _ in raw], dtype=np.uint64)
            raw_sizes = np.array([len(payload) for _, _, payload in raw], dtype=np.int64)
            sequences = np.empty(len(raw), dtype=np.int64)
            for channel in sorted(set(raw_channels.tolist())):  # per channel (np.unique imports numpy.ma)
                at = np.flatnonzero(raw_channels == channel)
                sequences[at] = self._sequence(channel, len(at)) + np.arange(len(at))
            message_sizes[order == RAW_STREAM] = MESSAGE_HEAD_SIZE + raw_sizes
        offsets = np.zeros(len(order), dtype=np.int64)
        np.cumsum(message_sizes[:-1], out=offsets[1:])
        out = np.empty(int(offsets[-1] + message_sizes[-1]), dtype=np.uint8)
        channels = np.empty(len(order), dtype=np.int64)
        times = np.empty(len(order), dtype=np.uint64)
        for number, (records, record_times, channel) in parts.items():
            where = np.flatnonzero(order == number)
            size = records.dtype.itemsize
            _scatter(out, offsets[where], records.view(np.uint8).reshape(-1, size))
            channels[where] = channel
            times[where] = record_times
        if raw:
            # Messages of equal size as the rows of one array: head fields, then the payload bytes.
            where = np.flatnonzero(order == RAW_STREAM)
            for size in sorted(set(raw_sizes.tolist())):
                at = np.flatnonzero(raw_sizes == size)
                heads = np.zeros(len(at), dtype=_HEAD_DTYPE)
                heads["opcode"] = 5
                heads["length"] = 22 + size
                heads["channel"] = raw_channels[at]
                heads["sequence"] = sequences[at]
                heads["log_time"] = raw_times[at]
                heads["publish_time"] = raw_times[at]
                payloads = np.frombuffer(b"".join([raw[j][2] for j in at.tolist()]), np.uint8)
                records = np.concatenate(
                    (
                        heads.view(np.uint8).reshape(len(at), MESSAGE_HEAD_SIZE),
                        payloads.reshape(len(at), size),
                    ),
                    axis=1,
                )
                _scatter(out, offsets[where[at]], records)
            channels[where] = raw_channels
            times[where] = raw_times
            self.raw = []
        return out.tobytes(), offsets, channels, times

    def _add_records(self, data: bytes, channels, times, offsets, first: int, end: int) -> None:
        """Records first..end (exclusive) of a pack to the writer."""
        if first >= end:
            return
        if first == 0 and end == len(offsets):
            self.writer.add_records(data, channels, times, offsets)
            return
        begin = int(offsets[first])
        stop = int(offsets[end]) if end < len(offsets) else len(data)
        self.writer.add_records(
            data[begin:stop], channels[first:end], times[first:end], offsets[first:end] - begin
        )
