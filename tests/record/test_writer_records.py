"""ChunkWriter.add_records (records packed by the caller, many at once) must write exactly the file
that ChunkWriter.add_message writes one message at a time: same chunks, same MessageIndex records
(each channel's (log time, offset) pairs in write order), same statistics."""

from __future__ import annotations

import io

import numpy as np
from mcap.reader import make_reader

from cosim.record.mcap_format import MESSAGE_HEAD
from cosim.record.writer import ChunkWriter


def _messages(count: int, seed: int) -> list[tuple[int, int, bytes]]:
    """Interleaved channels (1..6, in no order), times non-decreasing, payloads of varied length."""
    rng = np.random.default_rng(seed)
    channels = rng.integers(1, 7, count)
    times = np.cumsum(rng.integers(0, 3_000_000, count))
    return [
        (int(channel), int(t_ns), rng.bytes(int(rng.integers(0, 300))))
        for channel, t_ns in zip(channels, times, strict=True)
    ]


def add_packed(writer: ChunkWriter, part, sequences: dict[int, int]) -> None:
    """`part` (channel, t_ns, payload) handed to `writer.add_records` as one batch of Message
    records packed here by the format's layout (opcode 5, length, channel, sequence, log and
    publish time, payload), `sequences` counting per channel."""
    records, offsets, position = [], [], 0
    for channel, t_ns, payload in part:
        record = MESSAGE_HEAD.pack(5, 22 + len(payload), channel, sequences[channel], t_ns, t_ns) + payload
        sequences[channel] += 1
        records.append(record)
        offsets.append(position)
        position += len(record)
    writer.add_records(
        b"".join(records),
        np.array([channel for channel, _, _ in part], dtype=np.int64),
        np.array([t_ns for _, t_ns, _ in part], dtype=np.uint64),
        np.array(offsets, dtype=np.int64),
    )


def _file(messages, batches: list[int] | None, chunk_size: int, window_ns: int) -> bytes:
    stream = io.BytesIO()
    writer = ChunkWriter(stream, chunk_size=chunk_size, chunk_duration_ns=window_ns)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("test/msg/Blob", "ros2msg", b"uint8[] data")
    for channel in range(1, 7):
        assert writer.register_channel(f"/topic{channel}", "cdr", schema, {}) == channel
    sequences = dict.fromkeys(range(1, 7), 0)
    if batches is None:
        for channel, t_ns, payload in messages:
            writer.add_message(channel, t_ns, payload, sequences[channel])
            sequences[channel] += 1
    else:
        first = 0
        for size in batches:
            part = messages[first : first + size]
            first += size
            add_packed(writer, part, sequences)
    writer.finish()
    return stream.getvalue()


def test_add_records_writes_the_bytes_of_one_message_at_a_time():
    messages = _messages(3000, seed=7)
    batches = [1, 2, 500, 37, 1000, 460, 1000]  # across chunk ends by size and by time window
    for chunk_size, window_ns in ((4096, 0), (1 << 20, 50_000_000), (20_000, 200_000_000)):
        expected = _file(messages, None, chunk_size, window_ns)
        assert _file(messages, batches, chunk_size, window_ns) == expected
        # The index the file carries finds every message (read through the mcap library).
        read = [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(io.BytesIO(expected)).iter_messages(log_time_order=False)
        ]
        assert read == [(f"/topic{channel}", t_ns, payload) for channel, t_ns, payload in messages]
