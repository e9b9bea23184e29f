"""ChunkWriter with a second core checksums and compresses the chunks it ends between messages on a
worker thread and writes them later, in order: the file must be the bytes it writes when every
chunk is done inline, and the mcap library must read it back with every CRC checked."""

from __future__ import annotations

import io
import os
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from cosim.record import writer as writer_module
from cosim.record.mcap_format import MESSAGE_HEAD
from cosim.record.writer import ChunkWriter


class _Slow:
    """A compressor that takes its time (the worker is then behind the writer), or fails."""

    def __init__(self, compressor, seconds: float, fail_at: int | None = None) -> None:
        self._compressor, self._seconds, self._fail_at, self.calls = compressor, seconds, fail_at, 0

    def compress(self, data) -> bytes:
        self.calls += 1
        if self.calls == self._fail_at:
            raise ValueError("compressor failed")
        time.sleep(self._seconds)
        return self._compressor.compress(data)


def _file(monkeypatch, threaded: bool, seconds: float = 0.0, fail_at: int | None = None) -> bytes:
    """Messages of 2 channels over 40 chunks of ~40 kB (>= THREADED_BYTES), with metadata, an
    attachment and hand-overs between them (each writes what is pending first)."""
    monkeypatch.setattr(writer_module, "SECOND_CORE", threaded)
    rng = np.random.default_rng(3)
    stream = io.BytesIO()
    writer = ChunkWriter(stream, chunk_size=40_000)
    writer._compressor = _Slow(writer._compressor, seconds, fail_at)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("test/msg/Blob", "ros2msg", b"uint8[] data")
    channels = [writer.register_channel(f"/topic{k}", "cdr", schema, {}) for k in (1, 2)]
    for index in range(4000):
        # Runs of repeated bytes: zstd shrinks them, so a wrong chunk would not read back.
        payload = bytes(rng.integers(0, 4, 1)) * int(rng.integers(100, 700))
        writer.add_message(channels[index % 2], 1_000_000 * index, payload, index // 2)
        if index in (1500, 2600):
            writer.add_metadata(f"at{index}", {"index": str(index)})
        if index == 3100:
            writer.add_attachment(index, index, "note.txt", "text/plain", b"between chunks")
        if index % 700 == 0:
            writer.hand_over()
    writer.finish()
    return stream.getvalue()


def test_threaded_chunks_are_the_bytes_of_inline_ones(monkeypatch):
    inline = _file(monkeypatch, threaded=False)
    assert _file(monkeypatch, threaded=True) == inline
    # The worker behind the writer (more than PENDING_CHUNKS chunks waiting): the same bytes.
    assert _file(monkeypatch, threaded=True, seconds=0.002) == inline
    reader = make_reader(io.BytesIO(inline), validate_crcs=True)
    summary = reader.get_summary()
    assert summary.statistics.chunk_count > 2 * writer_module.PENDING_CHUNKS
    assert {index.compression for index in summary.chunk_indexes} == {"zstd"}
    assert (
        min(index.uncompressed_size for index in summary.chunk_indexes[:-1]) >= writer_module.THREADED_BYTES
    )
    messages = list(reader.iter_messages(log_time_order=False))
    assert len(messages) == 4000
    assert [message.log_time for _, _, message in messages] == [1_000_000 * k for k in range(4000)]
    assert [metadata.name for metadata in reader.iter_metadata()] == ["at1500", "at2600"]
    assert [attachment.data for attachment in reader.iter_attachments()] == [b"between chunks"]


def test_a_failed_compression_is_raised_on_the_writers_thread(monkeypatch):
    with pytest.raises(ValueError, match="compressor failed"):
        _file(monkeypatch, threaded=True, fail_at=5)


@pytest.mark.slow
def test_a_forked_child_starts_its_own_worker(monkeypatch):
    """A child forked after the parent's worker started has no copy of that thread."""
    expected = _file(monkeypatch, threaded=True)  # the parent's worker runs from here on
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover (the child's result comes back through the pipe)
        try:
            os.write(write, b"1" if _file(monkeypatch, threaded=True) == expected else b"0")
        finally:
            os._exit(0)
    os.close(write)
    try:
        assert os.read(read, 1) == b"1"
    finally:
        os.close(read)
        os.waitpid(child, 0)


def _packed_file(monkeypatch, threaded: bool) -> bytes:
    """Batches of 3 channels through `add_records`, the caller overwriting its arrays after each."""
    monkeypatch.setattr(writer_module, "SECOND_CORE", threaded)
    stream = io.BytesIO()
    writer = ChunkWriter(stream, chunk_size=40_000)
    writer._compressor = _Slow(writer._compressor, 0.002)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("test/msg/Blob", "ros2msg", b"uint8[] data")
    for k in (1, 2, 3):
        writer.register_channel(f"/topic{k}", "cdr", schema, {})
    channels = np.empty(300, dtype=np.int64)  # reused by every batch
    for batch in range(40):
        channels[:] = np.arange(300) % 3 + 1
        times = 1_000_000 * (300 * batch + np.arange(300, dtype=np.uint64))
        payload = bytes([batch % 7]) * 400
        records = b"".join(
            MESSAGE_HEAD.pack(5, 22 + len(payload), int(c), 300 * batch + j, int(t), int(t)) + payload
            for j, (c, t) in enumerate(zip(channels, times, strict=True))
        )
        writer.add_records(
            records, channels, times, np.arange(300, dtype=np.int64) * (MESSAGE_HEAD.size + len(payload))
        )
        channels[:] = 3  # the caller's next use of its array
    writer.finish()
    return stream.getvalue()


def test_the_worker_does_not_read_the_callers_arrays(monkeypatch):
    inline = _packed_file(monkeypatch, threaded=False)
    assert _packed_file(monkeypatch, threaded=True) == inline
    reader = make_reader(io.BytesIO(inline), validate_crcs=True)
    read = [(channel.topic, message.log_time) for _, channel, message in reader.iter_messages()]
    assert read == [(f"/topic{k % 3 + 1}", 1_000_000 * k) for k in range(12_000)]
