"""`cosim log recover`: cut logs rewritten as complete, indexed MCAP files that other readers open.

Truth: rosbags' AnyReader and `mcap`'s indexed reader (both refuse the cut file) on the recovered
file, and the closed-form values the writers below wrote.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore
from test_log_crash import WRITER

from cosim.cli import main
from cosim.logs import open_log
from cosim.logs.recover import recover_log
from cosim.record.recorder import Recorder

WIDE = 50  # variables of the wide channel: chunks that end by size, larger than a zstd block


def _rosbags_messages(path) -> dict[str, list]:
    """{topic: [(log time, decoded message)]} through rosbags' AnyReader."""
    topics: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, timestamp, raw in reader.messages():
            topics.setdefault(connection.topic, []).append(
                (timestamp, reader.deserialize(raw, connection.msgtype))
            )
    return topics


def _mcap_summary(path):
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        decoded = [
            (channel.topic, message.log_time) for _, channel, message, _ in reader.iter_decoded_messages()
        ]
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
        attachments = {record.name: bytes(record.data) for record in reader.iter_attachments()}
    return summary, decoded, metadata, attachments


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    """A writer killed by SIGKILL mid-run (as tests/logs/test_log_crash.py makes one)."""
    target = tmp_path_factory.mktemp("recover") / "killed.mcap"
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(target)], stdout=subprocess.PIPE, text=True)
    process.stdout.readline()
    time.sleep(0.3)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    process.stdout.close()
    return target


@pytest.mark.slow
def test_a_killed_run_is_refused_by_indexed_readers_and_recovered_for_them(killed, capsys):
    with pytest.raises(AnyReaderError):
        _rosbags_messages(killed)
    with open(killed, "rb") as stream, pytest.raises(McapError):
        make_reader(stream).get_summary().statistics  # noqa: B018 - the summary is what fails
    cut = open_log(killed)
    counts = {topic.name: topic.count for topic in cut.topics}
    assert main(["log", "recover", str(killed)]) == 0
    out = capsys.readouterr().out
    recovered = killed.with_suffix(".recovered.mcap")
    assert out.startswith(f"wrote {recovered}: {sum(counts.values())} messages on 4 channels")
    assert "the source was cut" in out
    # rosbags: every message, decoded; the signals are the writer's closed-form values.
    topics = _rosbags_messages(recovered)
    assert {topic: len(items) for topic, items in topics.items()} == counts
    signals = topics["/signals/vehicle"]
    k = np.arange(len(signals))
    assert [stamp for stamp, _ in signals] == (k * 1_000_000).tolist()
    assert np.array_equal([message.x for _, message in signals], k * 0.001)
    assert np.array_equal([message.y for _, message in signals], np.sin(k * 0.001))
    # mcap's indexed reader: a summary whose statistics and indexes agree with the messages.
    summary, decoded, metadata, _ = _mcap_summary(recovered)
    assert summary.statistics.message_count == len(decoded) == sum(counts.values())
    by_topic = {channel.id: channel.topic for channel in summary.channels.values()}
    assert {by_topic[c]: n for c, n in summary.statistics.channel_message_counts.items()} == counts
    assert summary.statistics.message_end_time == max(time for _, time in decoded)
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 1
    assert metadata == {"navcosim": {"scenario_name": "killed", "goal": "100,0"}}
    assert {schema.name for schema in summary.schemas.values()} >= {"navcosim_msgs/msg/VehicleSignals"}
    # Our reader: complete now, the same signals bit for bit.
    again = open_log(recovered)
    assert again.is_complete
    assert again.signals("vehicle").values.tobytes() == cut.signals("vehicle").values.tobytes()


def _wide_log(path, records: int = 1800) -> np.ndarray:
    """One 50-variable channel at 1 kHz in one time window: chunks end by size (512 KiB), so a
    chunk spans several zstd blocks and a cut inside it leaves readable blocks."""
    values = np.sin(np.arange(records)[:, None] * 1e-3 + np.arange(WIDE)[None, :])
    with Recorder(path, chunk_duration=1000.0) as recorder:
        recorder.add_metadata("navcosim", {"scenario_name": "wide"})
        recorder.add_attachment("scenario.toml", "application/toml", b'name = "wide"\n')
        channel = recorder.signal_channel("vehicle", [f"v{i}" for i in range(WIDE)], units=["m"] * WIDE)
        for k in range(records):
            recorder.write_signals(channel, k * 1_000_000, values[k])
    return values


def test_a_log_cut_inside_a_chunk_keeps_the_complete_records_of_its_prefix(tmp_path):
    full = tmp_path / "full.mcap"
    values = _wide_log(full)
    summary, _, _, _ = _mcap_summary(full)
    first = min(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
    assert first.uncompressed_size > 3 * 128 * 1024  # several zstd blocks
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: first.chunk_start_offset + first.chunk_length * 3 // 4])
    log = open_log(cut)
    read = log.signals("vehicle")
    assert 0 < len(read.t) < first.uncompressed_size // (31 + 12 + 8 * WIDE)
    assert read.values.tobytes() == values[: len(read.t)].tobytes()
    recovery = recover_log(cut)
    assert (recovery.chunks_copied, recovery.chunks_rebuilt) == (0, 1)
    assert recovery.messages == len(read.t) and recovery.target == tmp_path / "cut.recovered.mcap"
    topics = _rosbags_messages(recovery.target)
    decoded = np.array(
        [[getattr(message, f"v{i}") for i in range(WIDE)] for _, message in topics["/signals/vehicle"]]
    )
    assert decoded.tobytes() == values[: len(read.t)].tobytes()
    summary, decoded_messages, metadata, attachments = _mcap_summary(recovery.target)
    assert summary.statistics.message_count == len(decoded_messages) == len(read.t)
    assert metadata == {"navcosim": {"scenario_name": "wide"}}
    assert attachments == {"scenario.toml": b'name = "wide"\n'}
    channel = next(iter(summary.channels.values()))
    assert channel.metadata["navcosim.signal_units"] == '["m", ' + '"m", ' * (WIDE - 2) + '"m"]'


def test_a_complete_log_recovers_to_the_same_messages(tmp_path):
    full = tmp_path / "full.mcap"
    _wide_log(full)
    target = tmp_path / "copy.mcap"
    recovery = recover_log(full, target)
    assert recovery.was_complete and recovery.chunks_rebuilt == 0 and recovery.chunks_copied >= 2
    original, copy = _mcap_summary(full), _mcap_summary(target)
    assert original[1] == copy[1] and original[2] == copy[2] and original[3] == copy[3]


def test_a_file_that_is_not_mcap_is_one_line_and_exit_2(tmp_path, capsys):
    bogus = tmp_path / "notes.mcap"
    bogus.write_text("not a log\n")
    assert main(["log", "recover", str(bogus)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "notes.mcap: not an MCAP file" in error
    assert not (tmp_path / "notes.recovered.mcap").exists()
    assert main(["log", "recover", str(tmp_path / "absent.mcap")]) == 2
    assert "no such log file" in capsys.readouterr().err
