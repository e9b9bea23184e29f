"""The recording's message records built in C (`cosim.core.kernel.pack_records`, used by
`MessageBlock.pack`) are the bytes of the NumPy build (`MessageBlock._records_numpy`, the second
implementation) and of the per-message CDR builders of `cosim.record.rosmsg`, read back with the
mcap library: same payloads, sequences, log and publish times, same file."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader

from cosim.core import kernel
from cosim.record import rosmsg
from cosim.record.batch import MessageBlock
from cosim.record.recorder import Recorder
from cosim.record.writer import ChunkWriter

NS = 1_000_000_000


def _run(tmp_path, name: str, native: bool, seed: int) -> tuple[bytes, dict]:
    """A log of step channels, a plain channel, poses, twists and sensor payloads written one at a
    time and many steps at once (`hold_steps`), with a channel registered in the middle of the
    run; the file's bytes and what was written (for the independent check)."""
    rng = np.random.default_rng(seed)
    path = tmp_path / name
    written = {"plain": [], "twist": [], "pose": []}
    with Recorder(path, trace=False) as recorder:
        recorder._block.native = native
        recorder._block.capacity = 37  # small blocks: many packs, skipped packs, carried rows
        sizes = (3, 0, 7)
        steps = [
            recorder.signal_channel(
                f"c{i}",
                [f"v{j}" for j in range(size)],
                inputs=size // 2,
                initial=rng.normal(size=size),
                period_ns=(i + 1) * 10_000_000,
            )
            for i, size in enumerate(sizes)
        ]
        plain = recorder.signal_channel("plain", ["a", "b"])
        recorder.write_cmd_vel(0, 0.5, -0.5)  # /cmd_vel registered before steps are handed over at once
        written["twist"].append((0, 0.5, -0.5))
        k = 0
        for _ in range(40):
            if rng.random() < 0.5:  # one step at a time
                t_ns = k * 10_000_000
                for i, channel in enumerate(steps):
                    if k % (i + 1) == 0:
                        recorder.hold_signals(channel, t_ns, rng.normal(size=sizes[i]))
                if k % 3 == 0:
                    values = rng.normal(size=2)
                    recorder.write_signals(plain, t_ns, values)
                    written["plain"].append((t_ns, values))
                if k % 2 == 0:
                    v, omega = rng.normal(size=2)
                    recorder.write_cmd_vel(t_ns, v, omega)
                    written["twist"].append((t_ns, v, omega))
                if k % 5 == 4:
                    pose = (t_ns + 10_000_000, *rng.normal(size=2), 0.0, *rng.normal(size=2))
                    recorder.write_pose(*pose)
                    written["pose"].append(pose)
                k += 1
            else:  # many steps at once, as the kernel path hands them over
                count = int(rng.integers(1, 90))
                ks = np.arange(k, k + count)
                per_step = len(steps) + 4
                signals = []
                for i, channel in enumerate(steps):
                    due = ks[ks % (i + 1) == 0]
                    rows = rng.normal(size=(len(due), sizes[i]))
                    signals.append((channel, due * per_step + i, due * 10_000_000, rows))
                twists = ks[ks % 2 == 0]
                others = [(twist_k * per_step + len(steps), twist_k * 10_000_000) for twist_k in twists]
                payloads = []
                for _ in others:
                    v, omega = rng.normal(size=2)
                    payloads.append(("/cmd_vel", rosmsg.twist_cdr(v, omega)))
                    written["twist"].append((None, v, omega))
                pose_k = ks[ks % 5 == 4]
                n = len(pose_k)
                pose_rows = np.column_stack((rng.normal(size=(n, 2)), np.zeros(n), rng.normal(size=(n, 2))))
                poses = (pose_k * per_step + len(steps) + 1, (pose_k + 1) * 10_000_000, pose_rows)
                other = (
                    np.array([key for key, _ in others], dtype=np.int64),
                    np.array([t_ns for _, t_ns in others], dtype=np.int64),
                    payloads,
                )
                recorder.hold_steps(signals, poses, other)
                for row, t_ns in zip(pose_rows, poses[1], strict=True):
                    written["pose"].append((int(t_ns), *row[:3], *row[3:]))
                k += count
            if k > 300 and not recorder.has_channel("/imu"):  # a channel registered mid-run
                recorder.write_payload("/imu", k * 10_000_000, rosmsg.twist_cdr(1.0, 2.0))
        recorder.end_steps(k * 10_000_000)
    return path.read_bytes(), written


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_native_records_are_the_numpy_records(tmp_path, monkeypatch, seed):
    calls = []
    pack = kernel.pack_records

    def counting(*args):
        calls.append(len(args[0]))
        return pack(*args)

    monkeypatch.setattr(kernel, "pack_records", counting)
    native, _ = _run(tmp_path, "native.mcap", True, seed)
    assert calls and sum(calls) > 500  # the C path built the records
    calls.clear()
    reference, _ = _run(tmp_path, "numpy.mcap", False, seed)
    assert calls == []
    assert native == reference


def test_native_records_read_back_as_the_per_message_builders(tmp_path):
    data, written = _run(tmp_path, "native.mcap", True, 4)
    by_topic: dict[str, list] = {}
    for _, channel, message in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
        by_topic.setdefault(channel.topic, []).append(message)
    for topic, messages in by_topic.items():
        assert [m.sequence for m in messages] == list(range(len(messages))), topic
        assert all(m.log_time == m.publish_time for m in messages), topic
    plain = by_topic["/signals/plain"]
    assert [(m.log_time, bytes(m.data)) for m in plain] == [
        (t_ns, rosmsg.signals_payload(t_ns, values)) for t_ns, values in written["plain"]
    ]
    twists = by_topic["/cmd_vel"]
    assert [bytes(m.data) for m in twists] == [rosmsg.twist_cdr(v, omega) for _, v, omega in written["twist"]]
    # theta = 0 (qz = sin 0 = 0, qw = cos 0 = 1 whichever sine is used): the layout is under test.
    builders = {"/odom": rosmsg.odometry_cdr, "/tf": rosmsg.tf_cdr, "/pose": rosmsg.pose_stamped_cdr}
    for topic, build in builders.items():
        expected = []
        for t_ns, x, y, theta, v, omega in written["pose"]:
            args = (t_ns, x, y, theta, v, omega) if topic == "/odom" else (t_ns, x, y, theta)
            expected.append((t_ns, build(*args)))
        assert [(m.log_time, bytes(m.data)) for m in by_topic[topic]] == expected, topic
    # The step channels' stamps: the steps' starts, each record's stamp its log time.
    for topic, messages in by_topic.items():
        if topic.startswith("/signals/c"):
            for m in messages:
                sec, nanosec = np.frombuffer(bytes(m.data)[4:12], dtype="<u4")
                assert int(sec) * NS + int(nanosec) == m.log_time


def test_pack_records_refuses_a_wrong_size():
    block = MessageBlock(ChunkWriter(io.BytesIO()), {})
    block.raw = [(1, 5, b"abc")]
    streams = np.zeros((1, kernel.STREAM_COLUMNS), dtype=np.int64)
    streams[0, kernel.P_KIND] = kernel.STREAM_RAW
    raw = np.array([[1, 0, 5, 0, 3]], dtype=np.int64)
    empty = np.zeros((0, kernel.FIELD_COLUMNS), dtype=np.int64)
    order = np.zeros(1, dtype=np.int64)
    data, offsets, channels, times = kernel.pack_records(order, streams, empty, raw, b"abc", 34)
    assert (
        bytes(data)
        == bytes([5])
        + (25).to_bytes(8, "little")
        + bytes([1, 0, 0, 0, 0, 0])
        + (5).to_bytes(8, "little") * 2
        + b"abc"
    )
    assert offsets.tolist() == [0] and channels.tolist() == [1] and times.tolist() == [5]
    with pytest.raises(ValueError):
        kernel.pack_records(order, streams, empty, raw, b"abc", 33)  # one byte short: refused, not overrun


def test_head_constants_are_the_mcap_message_record():
    from cosim.record import mcap_format

    assert kernel.MESSAGE_HEAD_BYTES == mcap_format.MESSAGE_HEAD.size
    assert kernel.MESSAGE_FIELD_BYTES == mcap_format.MESSAGE_FIELDS.size
    assert kernel.OPCODE_MESSAGE == mcap_format.OP_MESSAGE
    head = mcap_format.MESSAGE_HEAD.pack(0, 1, 2, 3, 4, 5)
    at = {name: head.index(bytes([value])) for name, value in zip("LCSTP", (1, 2, 3, 4, 5), strict=True)}
    assert (at["L"], at["C"], at["S"], at["T"], at["P"]) == (
        kernel.HEAD_LENGTH,
        kernel.HEAD_CHANNEL,
        kernel.HEAD_SEQUENCE,
        kernel.HEAD_LOG_TIME,
        kernel.HEAD_PUBLISH_TIME,
    )


def test_a_payload_of_another_layout_on_a_channel_held_as_rows_is_refused(tmp_path):
    # /cmd_vel is held as rows of v, omega: a Twist with another non-zero field has no such row
    # (its bytes could not be rebuilt), so it is refused instead of written wrong.
    from cosim.errors import CosimError

    with Recorder(tmp_path / "twist.mcap", trace=False) as recorder:
        recorder.write_cmd_vel(0, 0.25, -1.5)
        channel = recorder.cmd_vel_channel()
        payload = rosmsg.twist_cdr(0.75, 2.0)
        row = recorder._block.fixed_row(channel, 10, payload)
        assert row.tolist() == [0.75, 2.0]
        other = rosmsg.CDR_HEADER + np.array([0.75, 0.5, 0.0, 0.0, 0.0, 2.0]).tobytes()
        with pytest.raises(CosimError, match="layout"):
            recorder.write_payload("/cmd_vel", 10, other)
        with pytest.raises(CosimError, match="layout"):
            recorder.write_payload("/cmd_vel", 10, payload + b"\0")
        recorder.write_payload("/cmd_vel", 20, payload)
    messages = [
        (m.log_time, m.sequence, bytes(m.data))
        for _, _, m in make_reader(open(tmp_path / "twist.mcap", "rb")).iter_messages()
    ]
    assert messages == [(0, 0, rosmsg.twist_cdr(0.25, -1.5)), (20, 1, payload)]


def test_steps_collected_outside_the_recorder_reach_the_log_before_anything_else_and_at_close(tmp_path):
    # A collector (`Recorder.collect`: the fleet's steps) is flushed before a message is written
    # around it and at close, so the log holds its rows in time order and is complete.
    path = tmp_path / "collected.mcap"
    recorder = Recorder(path, trace=False)
    channel = recorder.signal_channel("c", ["a", "b"])

    class Collector:
        def __init__(self) -> None:
            self.pending: list[tuple[int, np.ndarray]] = []

        def flush(self) -> None:
            taken, self.pending = self.pending, []
            if taken:
                times = np.array([t_ns for t_ns, _ in taken], dtype=np.int64)
                rows = np.array([row for _, row in taken])
                recorder.hold_steps([(channel, times, times, rows)])

        def written(self, channel: int, t_ns: int, payload: bytes) -> bool:
            return False

    collector = Collector()
    recorder.collect(collector)
    collector.pending += [(k * 10, np.array([k, -k], dtype=float)) for k in range(3)]
    recorder.write_goal(30, 1.0, 2.0, None)  # registers /goal: the collected rows go first
    collector.pending += [(k * 10, np.array([k, -k], dtype=float)) for k in range(4, 6)]
    recorder.close()  # no end_steps: the collected rows still reach the log, which is complete
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary() is not None
        messages = [
            (c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=False)
        ]
    expected = [
        ("/signals/c", k * 10, rosmsg.signals_payload(k * 10, np.array([k, -k], float))) for k in range(3)
    ]
    assert messages[:3] == expected and messages[3][:2] == ("/goal", 30)
    assert messages[4:] == [
        ("/signals/c", k * 10, rosmsg.signals_payload(k * 10, np.array([k, -k], float))) for k in range(4, 6)
    ]
