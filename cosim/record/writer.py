"""A small MCAP writer for run logs: chunked, zstd, fully indexed, with a batched message path.

Why not `mcap.writer.Writer` for the messages: its `add_message` builds a record object per message
and tops out near 84k messages/s in Python, while a run writes several messages per step. This
writer keeps the open chunk as one `bytearray`; a message is one `struct.pack` appended to it, and
`add_records` appends many pre-packed message records (built with NumPy, `cosim.record.batch`)
at once. The file layout is what `mcap.writer.Writer` writes: header; schemas and channels inside
the chunk where they are first used (so a cut file is self-describing); each chunk followed by one
MessageIndex per channel; attachments and metadata between chunks; then DataEnd, the summary
(schemas, channels, statistics, chunk/attachment/metadata indexes), summary offsets and footer.
The non-message records are written with `mcap.records`.

Chunk boundaries depend only on the messages, never on the wall clock, so the same messages give
the same bytes: a chunk ends when it holds more than `chunk_size` bytes of records, and (with
`chunk_duration_ns`) before the first message of a later window of log time, windows being
[n D, (n + 1) D). `copy_chunk` writes a chunk read from another file as it is (`cosim log recover`).
"""

from __future__ import annotations

import struct
import zlib
from array import array
from typing import TYPE_CHECKING

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

if TYPE_CHECKING:  # imported when the first large chunk is compressed: it imports logging (~2.5 ms)
    from concurrent.futures import ThreadPoolExecutor

from cosim.record.mcap_format import (
    CHUNK_HEAD,
    MAGIC,
    MESSAGE_FIELDS,
    MESSAGE_HEAD,
    MESSAGE_INDEX_HEAD,
    OP_CHUNK,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
)

# A chunk of fewer bytes is compressed inline: handing it to the thread and back (two wake-ups
# and GIL hand-offs, ~0.15-0.2 ms) costs more than compressing it (~0.1 ms for 50 kB).
THREADED_BYTES = 256 * 1024


_INDEX_HEAD_DTYPE = np.dtype(
    {
        "names": ["opcode", "length", "channel", "size"],
        "formats": ["u1", "<u8", "<u2", "<u4"],
        "offsets": [0, 1, 9, 11],
        "itemsize": MESSAGE_INDEX_HEAD.size,
    }
)  # a MessageIndex record's head (MESSAGE_INDEX_HEAD) as a structured record


def _place(out: np.ndarray, starts: np.ndarray, rows: np.ndarray) -> None:
    """Copy row j of `rows` (bytes) to out[starts[j]:]: one fancy-index assignment of whole rows
    (as raw items of their size), through a view of `out` whose item r starts at byte r (items
    overlap; the items written do not)."""
    size = rows.shape[1]
    if size == 0 or len(starts) == 0:
        return
    item = np.dtype(f"V{size}")
    view = np.ndarray((len(out) - size + 1,), item, out, 0, (1,))
    view[starts] = np.ascontiguousarray(rows).view(item).reshape(-1)


def _grouped_pairs(index: dict, runs: list) -> tuple[list[int], list[int], np.ndarray]:
    """(channel ids ascending, their pair counts, every (log time, offset) pair as little-endian
    uint64 rows grouped by channel in that order, each channel's in write order) of a chunk's
    index entries: `index` channel -> pairs (in write order), `runs` (channels, pairs) in write
    order."""
    ids = sorted(index)
    parts = [_pair_rows(index[channel]) for channel in ids]
    if not runs:
        return ids, [len(part) for part in parts], _concatenated(parts)
    channels = np.concatenate([run[0] for run in runs])
    pairs = np.concatenate([run[1] for run in runs])
    if parts:  # messages one at a time too: offsets rise in write order within the chunk
        channels = np.concatenate(
            [channels, *(np.full(len(p), c, np.int64) for c, p in zip(ids, parts, strict=True))]
        )
        pairs = np.concatenate([pairs, *parts])
        by_channel = np.lexsort((pairs[:, 1], channels))
    else:  # channel ids fit uint16 (MCAP): a stable sort of those keeps write order
        by_channel = np.argsort(channels.astype(np.uint16), kind="stable")
    channels, pairs = channels.take(by_channel), pairs.take(by_channel, axis=0)
    ids = sorted(set(ids).union(channels[np.flatnonzero(np.diff(channels, prepend=-1))].tolist()))
    keys = np.array(ids, dtype=np.int64)
    counts = np.searchsorted(channels, keys, side="right") - np.searchsorted(channels, keys, side="left")
    return ids, counts.tolist(), pairs


def _pair_rows(pairs) -> np.ndarray:
    """(log time, offset) pairs (an (n, 2) array or a flat array("Q")) as (n, 2) little-endian uint64."""
    if isinstance(pairs, array):
        pairs = np.frombuffer(pairs, dtype=np.uint64) if len(pairs) else np.zeros(0, dtype=np.uint64)
    return np.asarray(pairs).astype("<u8", copy=False).reshape(-1, 2)


def _concatenated(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype="<u8")


class ChunkWriter:
    """Writes one MCAP file to a binary `stream` (not closed by `finish`)."""

    def __init__(
        self,
        stream,
        chunk_size: int = 512 * 1024,
        compression_level: int = 3,
        chunk_duration_ns: int | None = None,
    ) -> None:
        self._stream = stream
        self.chunk_size = chunk_size
        self.chunk_duration_ns = chunk_duration_ns  # [ns] of log time per chunk window, or None
        self._deadline = 0  # [ns] end of the open chunk's window
        self._compressor = zstandard.ZstdCompressor(level=compression_level)
        self._chunk = bytearray()
        self._chunk_start = 0  # [ns] earliest log time in the open chunk
        self._chunk_end = 0
        self._chunk_messages = 0
        self._index: dict[int, array] = {}  # channel -> (log time, offset) pairs of the open chunk
        # (channels, (log time, offset) pairs) of each run of records appended (`_append`) to the
        # open chunk, in write order: grouped by channel when the chunk ends.
        self._runs: list[tuple[np.ndarray, np.ndarray]] = []
        self._run_counts = np.zeros(0, dtype=np.int64)  # messages per channel id in `_runs` so far
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._unwritten: list = []  # schemas/channels not yet written into a chunk
        self._counts: dict[int, int] = {}
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._builder = RecordBuilder()
        self._pool: ThreadPoolExecutor | None = None  # compresses the ended chunk (`_finish_chunk`)
        self._pending: tuple | None = None  # that chunk, until written (`_drain`)

    # --- records outside chunks -----------------------------------------------------------

    def _write_record(self, record) -> tuple[int, int]:
        """Write one `mcap.records` record at the end of the file; returns (offset, length)."""
        self._drain()
        offset = self._stream.tell()
        record.write(self._builder)
        data = self._builder.end()
        self._stream.write(data)
        return offset, len(data)

    def start(self, profile: str, library: str) -> None:
        self._stream.write(MAGIC)
        self._write_record(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes, schema_id: int | None = None) -> int:
        """A schema (id: the next free one unless given), written before the first message after it."""
        schema = Schema(
            id=schema_id if schema_id is not None else len(self._schemas) + 1,
            name=name,
            encoding=encoding,
            data=data,
        )
        self._schemas[schema.id] = schema
        self._unwritten.append(schema)
        return schema.id

    def register_channel(
        self,
        topic: str,
        encoding: str,
        schema_id: int,
        metadata: dict[str, str],
        channel_id: int | None = None,
    ) -> int:
        channel = Channel(
            id=channel_id if channel_id is not None else len(self._channels) + 1,
            topic=topic,
            message_encoding=encoding,
            schema_id=schema_id,
            metadata=dict(metadata),
        )
        self._channels[channel.id] = channel
        self._counts.setdefault(channel.id, 0)
        self._unwritten.append(channel)
        return channel.id

    def has_definitions(self) -> bool:
        """Whether schemas or channels wait for the next message."""
        return bool(self._unwritten)

    def take_definitions(self) -> list:
        """The schemas and channels waiting for the next message, no longer waiting."""
        taken, self._unwritten = self._unwritten, []
        return taken

    def put_definitions(self, records: list) -> None:
        """Schemas and channels (`take_definitions`) to write before the next message."""
        self._unwritten.extend(records)

    def write_definitions(self) -> None:
        """Write the schemas and channels registered since the last chunk as top-level records now
        (for chunks copied with `copy_chunk`, which may not hold them)."""
        for record in self._unwritten:
            self._write_record(record)
        self._unwritten.clear()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        offset, length = self._write_record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    def add_attachment(
        self, create_time: int, log_time: int, name: str, media_type: str, data: bytes
    ) -> None:
        record = Attachment(
            create_time=create_time, log_time=log_time, name=name, media_type=media_type, data=data
        )
        offset, length = self._write_record(record)
        self._attachment_indexes.append(
            AttachmentIndex(
                offset=offset,
                length=length,
                create_time=create_time,
                log_time=log_time,
                data_size=len(data),
                name=name,
                media_type=media_type,
            )
        )

    # --- messages -------------------------------------------------------------------------

    def _open_records(self, t_ns: int) -> None:
        """Put pending schema/channel records into the chunk and widen its time range."""
        if self._unwritten:
            for record in self._unwritten:
                record.write(self._builder)
            self._chunk += self._builder.end()
            self._unwritten.clear()
        if self._chunk_messages == 0:
            self._chunk_start = self._chunk_end = t_ns
            if self.chunk_duration_ns:
                self._deadline = (t_ns // self.chunk_duration_ns + 1) * self.chunk_duration_ns

    def _past_window(self, t_ns: int) -> bool:
        return bool(self.chunk_duration_ns) and self._chunk_messages > 0 and t_ns >= self._deadline

    def add_message(self, channel: int, t_ns: int, data: bytes, sequence: int) -> None:
        """One message (log time = publish time = t_ns)."""
        if self._past_window(t_ns):
            self._finish_chunk()
        self._open_records(t_ns)
        chunk = self._chunk
        offset = len(chunk)
        chunk += MESSAGE_HEAD.pack(OP_MESSAGE, MESSAGE_FIELDS.size + len(data), channel, sequence, t_ns, t_ns)
        chunk += data
        index = self._index.get(channel)
        if index is None:
            index = self._index[channel] = array("Q")
        index.append(t_ns)
        index.append(offset)
        self._count(channel, 1, t_ns, t_ns)
        if len(chunk) > self.chunk_size:
            self._finish_chunk()

    def add_records(
        self, records: bytes, channels: np.ndarray, times: np.ndarray, offsets: np.ndarray
    ) -> None:
        """Append message records packed by the caller (in log-time order): `channels`, `times`
        [ns] and byte `offsets` (within `records`) per message. The records are split where a
        chunk ends (its size, its time window)."""
        count = len(times)
        if count == 0:
            return
        times = np.asarray(times, dtype=np.uint64)
        offsets = np.asarray(offsets, dtype=np.int64)
        ends = np.empty(count, dtype=np.int64)
        ends[:-1] = offsets[1:]
        ends[-1] = len(records)
        first = 0
        while first < count:
            if self._past_window(int(times[first])):
                self._finish_chunk()
            self._open_records(int(times[first]))
            stop = count
            if self.chunk_duration_ns:
                later = np.flatnonzero(times[first:] >= self._deadline)
                if len(later):
                    stop = first + max(int(later[0]), 1)
            room = self.chunk_size - len(self._chunk) + int(offsets[first])
            over = int(np.searchsorted(ends[first:stop], room, side="right"))
            stop = min(stop, first + over + 1)  # the record that passes the size ends the chunk
            self._append(
                records, channels[first:stop], times[first:stop], offsets[first:stop], ends[stop - 1]
            )
            first = stop
            if first < count or len(self._chunk) > self.chunk_size:
                self._finish_chunk()

    def _append(
        self, records: bytes, channels: np.ndarray, times: np.ndarray, offsets: np.ndarray, end: int
    ) -> None:
        """Records `offsets[0]:end` of `records` into the open chunk, with their index entries
        (kept as a run, grouped by channel when the chunk ends: `_write_message_indexes`)."""
        begin = int(offsets[0])
        base = len(self._chunk) - begin
        self._chunk += memoryview(records)[begin:end]
        pairs = np.empty((len(times), 2), dtype="<u8")
        pairs[:, 0] = times
        pairs[:, 1] = offsets + base
        channels = np.asarray(channels, dtype=np.int64)
        self._runs.append((channels, pairs))
        counts = np.bincount(channels)
        if len(counts) > len(self._run_counts):
            self._run_counts = np.concatenate(
                (self._run_counts, np.zeros(len(counts) - len(self._run_counts), dtype=np.int64))
            )
        self._run_counts[: len(counts)] += counts
        self._count_totals(len(channels), int(times.min()), int(times.max()))

    def _count(self, channel: int, count: int, first: int, last: int) -> None:
        self._counts[channel] = self._counts.get(channel, 0) + count
        self._count_totals(count, first, last)

    def _count_file(self, channel: int, count: int, first: int, last: int) -> None:
        self._counts[channel] = self._counts.get(channel, 0) + count
        self._count_file_totals(count, first, last)

    def _count_totals(self, count: int, first: int, last: int) -> None:
        """`count` messages in [first, last] counted in the open chunk and the file (the channels'
        counts apart)."""
        self._count_file_totals(count, first, last)
        self._chunk_messages += count
        self._chunk_start = min(self._chunk_start, first)
        self._chunk_end = max(self._chunk_end, last)

    def _count_file_totals(self, count: int, first: int, last: int) -> None:
        if self._message_count == 0:
            self._start_time, self._end_time = first, last
        self._message_count += count
        self._start_time = min(self._start_time, first)
        self._end_time = max(self._end_time, last)

    def _finish_chunk(self) -> None:
        """End the open chunk. One of at least `THREADED_BYTES` is compressed on a worker thread
        (zstd releases the GIL) while the caller goes on, and written, with its message indexes,
        before anything else is written (`_drain`); a smaller one is compressed and written here.
        One chunk at a time either way, so the file is the same bytes."""
        if self._chunk_messages == 0:
            return
        data = self._chunk  # never appended to again: the next chunk is a new bytearray
        pending = (data, (self._index, self._runs), self._chunk_start, self._chunk_end)
        self._chunk = bytearray()
        self._index = {}
        self._runs = []
        self._chunk_messages = 0
        self._drain()
        if len(data) < THREADED_BYTES:
            self._write_chunk(self._compressor.compress(data), *pending)
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcap-zstd")
        self._pending = (self._pool.submit(self._compressor.compress, data), *pending)

    def _drain(self) -> None:
        """Write the chunk being compressed, if any (then the file holds every ended chunk)."""
        if self._pending is None:
            return
        future, *pending = self._pending
        self._pending = None
        self._write_chunk(future.result(), *pending)

    def _write_chunk(
        self,
        compressed: bytes,
        data: bytearray,
        index: tuple[dict[int, array], list],
        chunk_start: int,
        chunk_end: int,
    ) -> None:
        """The Chunk record of `data` (compressed), then its message indexes."""
        stream = self._stream
        start = stream.tell()
        length = 8 + 8 + 8 + 4 + 4 + 4 + 8 + len(compressed)
        stream.write(CHUNK_HEAD.pack(OP_CHUNK, length, chunk_start, chunk_end, len(data), zlib.crc32(data)))
        stream.write(struct.pack("<I4sQ", 4, b"zstd", len(compressed)))
        stream.write(compressed)
        by_channel, runs = index
        self._write_message_indexes(
            by_channel,
            start,
            1 + 8 + length,
            chunk_start,
            chunk_end,
            "zstd",
            len(compressed),
            len(data),
            runs,
        )

    def _write_message_indexes(
        self,
        index: dict[int, np.ndarray | array],
        start: int,
        chunk_length: int,
        start_time: int,
        end_time: int,
        compression: str,
        compressed_size: int,
        uncompressed_size: int,
        runs: list[tuple[np.ndarray, np.ndarray]] = (),
    ) -> None:
        """The MessageIndex records after the chunk at `start` (one per channel, in channel order;
        each channel's (log time, offset) pairs in `index` as an (n, 2) array or a flat
        array("Q"), and in `runs`, (channels, pairs) in write order, `_append`) and its ChunkIndex
        for the summary. The records are built at once: every pair grouped by channel, the heads
        and the pairs placed in one byte array."""
        stream = self._stream
        index_start = stream.tell()
        ids, counts, pairs = _grouped_pairs(index, runs)
        offsets = {}
        position = index_start
        if ids:
            counts = np.asarray(counts, dtype=np.int64)
            sizes = MESSAGE_INDEX_HEAD.size + 16 * counts
            starts = np.zeros(len(ids), dtype=np.int64)
            np.cumsum(sizes[:-1], out=starts[1:])
            out = np.empty(int(starts[-1] + sizes[-1]), dtype=np.uint8)
            heads = np.empty(len(ids), dtype=_INDEX_HEAD_DTYPE)
            heads["opcode"] = OP_MESSAGE_INDEX
            heads["length"] = 2 + 4 + 16 * counts
            heads["channel"] = ids
            heads["size"] = 16 * counts
            _place(out, starts, heads.view(np.uint8).reshape(len(ids), MESSAGE_INDEX_HEAD.size))
            # Pair j of a channel at its record's start + head + 16 j.
            firsts = np.zeros(len(ids), dtype=np.int64)
            np.cumsum(counts[:-1], out=firsts[1:])
            rank = np.arange(len(pairs), dtype=np.int64) - np.repeat(firsts, counts)
            places = np.repeat(starts + MESSAGE_INDEX_HEAD.size, counts) + 16 * rank
            _place(out, places, pairs.view(np.uint8).reshape(len(pairs), 16))
            stream.write(memoryview(out))
            offsets = dict(zip(ids, (index_start + starts).tolist(), strict=True))
            position = index_start + len(out)
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start_time,
                message_end_time=end_time,
                chunk_start_offset=start,
                chunk_length=chunk_length,
                message_index_offsets=offsets,
                message_index_length=position - index_start,
                compression=compression,
                compressed_size=compressed_size,
                uncompressed_size=uncompressed_size,
            )
        )

    def copy_chunk(
        self,
        record: bytes,
        index: dict[int, np.ndarray],
        compression: str,
        compressed_size: int,
        uncompressed_size: int,
    ) -> None:
        """Write a whole Chunk record (opcode to end) as it is, then message indexes from `index`
        (channel -> (n, 2) log time [ns], offset pairs); the open chunk is ended first."""
        self._finish_chunk()
        self._drain()
        self.write_definitions()
        start = self._stream.tell()
        self._stream.write(record)
        start_time = min(int(pairs[:, 0].min()) for pairs in index.values() if len(pairs))
        end_time = max(int(pairs[:, 0].max()) for pairs in index.values() if len(pairs))
        for channel, pairs in index.items():
            if len(pairs):
                self._count_file(channel, len(pairs), int(pairs[:, 0].min()), int(pairs[:, 0].max()))
        self._write_message_indexes(
            index, start, len(record), start_time, end_time, compression, compressed_size, uncompressed_size
        )

    def flush(self) -> None:
        """End the open chunk (if it holds messages) and hand everything to the OS."""
        self._finish_chunk()
        self._drain()
        self._stream.flush()

    def hand_over(self) -> None:
        """Hand the chunks ended so far to the OS (the open chunk stays open)."""
        self._drain()
        self._stream.flush()

    def finish(self) -> None:
        """End the data section; write the summary, its offsets and the footer."""
        self._finish_chunk()
        self._drain()
        for channel in np.flatnonzero(self._run_counts).tolist():  # the channels' counts of `_append`
            self._counts[channel] = self._counts.get(channel, 0) + int(self._run_counts[channel])
        self._run_counts = np.zeros(0, dtype=np.int64)
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._stream.tell()
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []
        statistics = Statistics(
            message_count=self._message_count,
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_time,
            message_end_time=self._end_time,
            channel_message_counts=dict(self._counts),
        )
        groups = (
            (Opcode.SCHEMA, list(self._schemas.values())),
            (Opcode.CHANNEL, list(self._channels.values())),
            (Opcode.STATISTICS, [statistics]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, self._attachment_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            group_start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + group_start,
                    group_length=builder.count - group_start,
                )
            )
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start), crc)
        self._stream.write(summary)
        self._write_record(
            Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc)
        )
        self._stream.write(MAGIC)
        self._stream.flush()
