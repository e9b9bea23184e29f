"""The MessageIndex records ChunkWriter writes after each chunk (built at once for every channel of
the chunk) must index exactly the chunk's messages: one record per channel with messages, in
channel order, each (log time, offset) pair pointing at a message of that channel and log time,
in write order. Checked against the chunk's own bytes (decompressed and walked record by record),
for messages written one at a time, packed many at once, and both mixed in one chunk."""

from __future__ import annotations

import io
import struct

import numpy as np
import zstandard
from mcap.records import Chunk, MessageIndex
from mcap.stream_reader import StreamReader

from cosim.record.writer import ChunkWriter
from tests.record.test_writer_records import add_packed

CHANNELS = (3, 1, 5, 2, 4)  # the messages' channels drawn from these, in no order


def _write(messages, modes, chunk_size: int) -> bytes:
    """`messages` (channel, t_ns, payload) written in runs: per run (mode, count), "one" through
    `add_message`, "many" through `add_records`."""
    stream = io.BytesIO()
    writer = ChunkWriter(stream, chunk_size=chunk_size)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("test/msg/Blob", "ros2msg", b"uint8[] data")
    for channel in sorted(set(CHANNELS)):
        assert writer.register_channel(f"/topic{channel}", "cdr", schema, {}) == channel
    sequences = dict.fromkeys(CHANNELS, 0)
    first = 0
    for mode, count in modes:
        part = messages[first : first + count]
        first += count
        if mode == "one":
            for channel, t_ns, payload in part:
                writer.add_message(channel, t_ns, payload, sequences[channel])
                sequences[channel] += 1
            continue
        add_packed(writer, part, sequences)
    writer.finish()
    return stream.getvalue()


def _chunk_messages(chunk: Chunk) -> dict[int, list[tuple[int, int]]]:
    """channel -> (log time, offset) of each Message record in the chunk's bytes, in byte order."""
    data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    found: dict[int, list[tuple[int, int]]] = {}
    at = 0
    while at < len(data):
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode == 5:
            channel, _, log_time = struct.unpack_from("<HIQ", data, at + 9)
            found.setdefault(channel, []).append((log_time, at))
        at += 9 + length
    return found


def _check_indexes(data: bytes, messages) -> None:
    chunks = 0
    indexed = 0
    pending: dict[int, list[tuple[int, int]]] | None = None
    seen: list[int] = []
    for record in StreamReader(io.BytesIO(data), emit_chunks=True).records:
        if isinstance(record, Chunk):
            if pending is not None:
                assert seen == sorted(pending)
            pending, seen = _chunk_messages(record), []
            chunks += 1
        elif isinstance(record, MessageIndex):
            assert pending is not None
            seen.append(record.channel_id)
            assert [tuple(pair) for pair in record.records] == pending[record.channel_id]
            indexed += len(record.records)
    assert pending is not None and seen == sorted(pending)
    assert chunks > 2
    assert indexed == len(messages)


def test_message_indexes_index_each_chunk_for_every_way_of_writing():
    rng = np.random.default_rng(11)
    count = 2000
    channels = rng.choice(CHANNELS, count)
    times = np.cumsum(rng.integers(0, 2_000_000, count))
    messages = [
        (int(channel), int(t_ns), rng.bytes(int(rng.integers(0, 200))))
        for channel, t_ns in zip(channels, times, strict=True)
    ]
    plans = (
        [("one", count)],
        [("many", 700), ("many", 1), ("many", 1299)],
        [("one", 3), ("many", 400), ("one", 250), ("many", 600), ("one", 47), ("many", 700)],
    )
    files = []
    for modes in plans:
        for chunk_size in (3000, 40_000):
            data = _write(messages, modes, chunk_size)
            _check_indexes(data, messages)
            files.append((chunk_size, data))
    # However they were handed over, the same messages make the same file.
    for chunk_size in (3000, 40_000):
        assert len({data for size, data in files if size == chunk_size}) == 1
