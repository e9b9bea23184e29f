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

With a second core, an ended chunk's CRC, zstd compression and MessageIndex records are made on a
worker thread while the run goes on, and the chunks are written in order once made (`_Worker`,
`ChunkWriter._finish_chunk`): the same bytes as made inline.
"""

from __future__ import annotations

import os
import struct
import threading
import zlib
from _queue import SimpleQueue
from array import array
from collections import deque

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
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

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

# With a second core, a chunk ended between messages is checksummed, compressed and indexed on a
# worker thread (zlib and zstd release the GIL for such buffers, the run's C calls release it)
# while the caller goes on; one of fewer bytes is done inline: handing it over (~20-50 us) costs
# about what it takes (a 32 kB chunk ~50 us). The thread is used whatever the load average: it
# moves the same work off the caller's thread and adds none (unlike a forked helper process).
THREADED_BYTES = 32 * 1024


def _second_core() -> bool:
    try:
        return len(os.sched_getaffinity(0)) >= 2
    except (AttributeError, OSError):
        return False


SECOND_CORE = _second_core()  # on one core the thread only adds its hand-offs
# Chunks ended but not yet written at most: the worker gets the GIL back from the caller only when
# the caller releases it (a blocking call, or after the switch interval, 5 ms), so a chunk may be
# done a few chunks later; the caller waits only when this many are behind.
PENDING_CHUNKS = 8


def metadata_record(name: str, data: dict[str, str]) -> bytes:
    """The bytes of an MCAP Metadata record (`mcap.records.Metadata.write`'s): opcode, record length
    (u64), the name, the map's byte length (u32), then each key and value, each a u32 length and
    UTF-8; written out because a log's `unconnected_inputs` has hundreds of entries (~2.5x faster)."""
    parts = []
    for key, value in data.items():
        key_bytes, value_bytes = key.encode(), value.encode()
        parts += (
            len(key_bytes).to_bytes(4, "little"),
            key_bytes,
            len(value_bytes).to_bytes(4, "little"),
            value_bytes,
        )
    entries = b"".join(parts)
    name_bytes = name.encode()
    body = b"".join(
        (len(name_bytes).to_bytes(4, "little"), name_bytes, len(entries).to_bytes(4, "little"), entries)
    )
    return bytes((Opcode.METADATA,)) + len(body).to_bytes(8, "little") + body


class _Worker:
    """One daemon thread per process doing jobs (calls), in the order given: `_chunk_parts` of
    ended chunks.
    A plain thread and a C queue: `concurrent.futures` would cost a warm run ~2.5 ms of imports
    (it imports logging). Started when first needed, and again in a forked child (which has no
    copy of its parent's threads)."""

    _jobs: SimpleQueue | None = None
    _pid = 0

    @classmethod
    def submit(cls, function, *args) -> tuple:
        """A job, `function(*args)`: wait for its result with `_Worker.result(job)`."""
        if cls._jobs is None or cls._pid != os.getpid():
            cls._jobs, cls._pid = SimpleQueue(), os.getpid()
            threading.Thread(target=cls._work, args=(cls._jobs,), name="mcap-zstd", daemon=True).start()
        done = threading.Lock()
        done.acquire()
        job = (function, args, done, [])
        cls._jobs.put(job)
        return job

    @staticmethod
    def done(job: tuple) -> bool:
        return bool(job[3])

    @staticmethod
    def _work(jobs: SimpleQueue) -> None:
        while True:
            function, args, done, out = jobs.get()
            try:
                out.append(function(*args))
            except BaseException as error:  # raised again by `result` on the writer's thread
                out.append(error)
            finally:
                done.release()
            del function, args, done, out

    @staticmethod
    def result(job: tuple):
        """The result of a submitted job, once done."""
        job[2].acquire()
        result = job[3][0]
        if isinstance(result, BaseException):
            raise result
        return result


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


def _message_indexes(index: dict, runs=()) -> tuple[list[int], np.ndarray, np.ndarray]:
    """The MessageIndex records of a chunk (one per channel, in channel order; each channel's
    (log time, offset) pairs in `index` as an (n, 2) array or a flat array("Q"), and in `runs`,
    (channels, pairs) in write order, `ChunkWriter._append`): (channel ids, each record's start
    within the bytes, the bytes). Built at once: every pair grouped by channel, the heads and the
    pairs placed in one byte array."""
    ids, counts, pairs = _grouped_pairs(index, runs)
    if not ids:
        return ids, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.uint8)
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
    return ids, starts, out


def _chunk_parts(compressor, data: bytearray, index: dict, runs: list) -> tuple:
    """What a Chunk record and its MessageIndex records need of an ended chunk: (crc32, compressed
    bytes, `_message_indexes`)."""
    return zlib.crc32(data), compressor.compress(data), _message_indexes(index, runs)


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
        # The chunks ended but not yet written, oldest first: (worker job, chunk, index, start,
        # end) each, written in order once compressed (`_write_done`, `_drain`).
        self._pending: deque[tuple] = deque()

    # --- records outside chunks -----------------------------------------------------------

    def _write_record(self, record) -> tuple[int, int]:
        """Write one `mcap.records` record at the end of the file; returns (offset, length)."""
        record.write(self._builder)
        return self._write_bytes(self._builder.end())

    def _write_bytes(self, data: bytes) -> tuple[int, int]:
        """Write a record's bytes at the end of the file; returns (offset, length)."""
        self._drain()
        offset = self._stream.tell()
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
        offset, length = self._write_bytes(metadata_record(name, data))
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
        (kept as a run, grouped by channel when the chunk ends: `_message_indexes`)."""
        begin = int(offsets[0])
        base = len(self._chunk) - begin
        self._chunk += memoryview(records)[begin:end]
        pairs = np.empty((len(times), 2), dtype="<u8")
        pairs[:, 0] = times
        pairs[:, 1] = offsets + base
        # A copy: the worker thread may group the run after the caller has reused its array.
        channels = np.array(channels, dtype=np.int64)
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

    def _finish_chunk(self, last: bool = False) -> None:
        """End the open chunk. With a second core, one of at least `THREADED_BYTES` ended between
        messages is checksummed and compressed and its message indexes built on the worker
        thread (`_Worker`) while the caller goes on, and written before anything else is written
        (`_write_done`, `_drain`); otherwise, or when it is the `last` before the file is flushed
        or finished (waiting for the thread would only add its hand-offs), here. One chunk at a
        time either way, in order, so the file is the same bytes."""
        if self._chunk_messages == 0:
            return
        data = self._chunk  # never appended to again: the next chunk is a new bytearray
        parts = (self._compressor, data, self._index, self._runs)
        pending = (len(data), self._chunk_start, self._chunk_end)
        self._chunk = bytearray()
        self._index = {}
        self._runs = []
        self._chunk_messages = 0
        if last or not SECOND_CORE or len(data) < THREADED_BYTES:
            self._drain()
            self._write_chunk(*_chunk_parts(*parts), *pending)
            return
        self._write_done()
        self._pending.append((_Worker.submit(_chunk_parts, *parts), *pending))

    def _write_done(self) -> None:
        """Write the oldest chunks the worker has compressed, without waiting (but for the oldest
        when `PENDING_CHUNKS` wait)."""
        pending = self._pending
        while pending and (_Worker.done(pending[0][0]) or len(pending) >= PENDING_CHUNKS):
            job, *chunk = pending.popleft()
            self._write_chunk(*_Worker.result(job), *chunk)

    def _drain(self) -> None:
        """Write the chunks on the worker thread, if any (then the file holds every ended chunk)."""
        pending = self._pending
        while pending:
            job, *chunk = pending.popleft()
            self._write_chunk(*_Worker.result(job), *chunk)

    def _write_chunk(
        self,
        crc: int,
        compressed: bytes,
        indexes: tuple[list[int], np.ndarray, np.ndarray],
        size: int,
        chunk_start: int,
        chunk_end: int,
    ) -> None:
        """The Chunk record of `size` bytes of records (their `crc` and `compressed` bytes), then
        its message `indexes` (`_message_indexes`)."""
        stream = self._stream
        start = stream.tell()
        length = 8 + 8 + 8 + 4 + 4 + 4 + 8 + len(compressed)
        stream.write(CHUNK_HEAD.pack(OP_CHUNK, length, chunk_start, chunk_end, size, crc))
        stream.write(struct.pack("<I4sQ", 4, b"zstd", len(compressed)))
        stream.write(compressed)
        self._write_message_indexes(
            indexes, start, 1 + 8 + length, chunk_start, chunk_end, "zstd", len(compressed), size
        )

    def _write_message_indexes(
        self,
        records: tuple[list[int], np.ndarray, np.ndarray],
        start: int,
        chunk_length: int,
        start_time: int,
        end_time: int,
        compression: str,
        compressed_size: int,
        uncompressed_size: int,
    ) -> None:
        """The MessageIndex `records` (`_message_indexes`) after the chunk at `start`, and its
        ChunkIndex for the summary."""
        stream = self._stream
        index_start = stream.tell()
        ids, starts, out = records
        stream.write(memoryview(out))
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start_time,
                message_end_time=end_time,
                chunk_start_offset=start,
                chunk_length=chunk_length,
                message_index_offsets=dict(zip(ids, (index_start + starts).tolist(), strict=True)),
                message_index_length=len(out),
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
        self._finish_chunk(last=True)
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
            _message_indexes(index),
            start,
            len(record),
            start_time,
            end_time,
            compression,
            compressed_size,
            uncompressed_size,
        )

    def flush(self) -> None:
        """End the open chunk (if it holds messages) and hand everything to the OS."""
        self._finish_chunk(last=True)
        self._drain()
        self._stream.flush()

    def hand_over(self) -> None:
        """Hand the chunks ended so far to the OS (the open chunk stays open)."""
        self._drain()
        self._stream.flush()

    def finish(self) -> None:
        """End the data section; write the summary, its offsets and the footer."""
        self._finish_chunk(last=True)
        self._drain()
        for channel in np.flatnonzero(self._run_counts).tolist():  # the channels' counts of `_append`
            self._counts[channel] = self._counts.get(channel, 0) + int(self._run_counts[channel])
        self._run_counts = np.zeros(0, dtype=np.int64)
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
