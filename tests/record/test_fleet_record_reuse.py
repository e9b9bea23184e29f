"""What a fleet's recording makes once and reuses, checked against a second way of making it:
- each robot's /scan layout: a LaserScan serialised once per frame name length, the others that
  message with the name replaced, read back by rosbags as each robot's own scan;
- the records of the components stepped by Python, copied a block at a time side by side per
  period (`fleet_steps._Live`): each component's rows are its `SignalEntry.record()` of each block;
- the records packed into a buffer kept from pack to pack (`kernel.pack_records(out=...)`): the
  bytes of a fresh buffer."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cosim.core import kernel
from cosim.record import rosmsg
from cosim.record.fleet_steps import _Live
from cosim.record.recorder import Recorder
from cosim.record.steps import Gather, SignalEntry


def test_scan_payloads_of_robots_read_back_as_their_own_scans(tmp_path, monkeypatch):
    serialised = []
    serialize = rosmsg.serialize

    def counting(message, typename):
        serialised.append(typename)
        return serialize(message, typename)

    monkeypatch.setattr(rosmsg, "serialize", counting)
    angles = np.linspace(-math.pi, math.pi, 12, endpoint=False)
    angles.flags.writeable = False
    names = ["robot1", "robot2", "robot9", "robot10", "robot11", "r"]
    rng = np.random.default_rng(5)
    with Recorder(tmp_path / "scans.mcap", trace=False) as recorder:
        views = [recorder.namespaced(name) for name in names]
        payloads = []
        for number, view in enumerate(views):
            ranges = rng.uniform(0.5, 9.0, len(angles))
            ranges[number % len(angles)] = np.nan  # no return: +inf in the message
            t_ns = 1_234_567_890 + number * 100_000_000
            payloads.append((view, t_ns, ranges, view.scan_payload(t_ns, angles, ranges, 0.2, 10.0, 0.1)))
    # One LaserScan serialised per length of "<name>/base_link": 7, 8 and 2 characters of name.
    assert serialised.count("sensor_msgs/msg/LaserScan") == 3
    for view, t_ns, ranges, payload in payloads:
        message = rosmsg.TYPESTORE.deserialize_cdr(payload, "sensor_msgs/msg/LaserScan")
        assert message.header.frame_id == f"{view.namespace}/base_link"
        assert message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec == t_ns
        assert message.angle_min == np.float32(angles[0])
        assert (message.range_min, message.range_max) == (np.float32(0.2), np.float32(10.0))
        expected = np.where(np.isnan(ranges), np.inf, ranges).astype(np.float32)
        np.testing.assert_array_equal(message.ranges, expected)
        assert len(message.intensities) == 0


def _entry(period: int, inputs: np.ndarray, outputs: np.ndarray, gathered: bool) -> SignalEntry:
    """A component's record: views of one run of its buffers, or gathered from scattered slots."""
    if not gathered:
        return SignalEntry(period, 1, inputs[:2], outputs[1:4], None, None, [0, 1], [1, 2, 3])
    record = np.empty(3)
    gather = Gather(inputs, np.array([2, 0]), record[:2], outputs, np.array([3]), record[2:])
    return SignalEntry(period, 1, record, None, gather, None, [2, 0], [3])


def test_live_groups_hold_each_entrys_records_of_each_block():
    rng = np.random.default_rng(8)
    buffers = [(rng.normal(size=4), rng.normal(size=5)) for _ in range(5)]
    layout = [(10, False), (10, True), (20, False), (10, False), (20, True)]  # period, gathered
    entries = {
        slot: _entry(period, *buffers[slot], gathered) for slot, (period, gathered) in enumerate(layout)
    }
    groups: dict[int, _Live] = {}
    for slot, entry in entries.items():
        groups.setdefault(entry.period, _Live(entry.period)).add(slot, entry)
    blocks, expected = [], {slot: ([], []) for slot in entries}
    for first in range(0, 100, 10):  # the buffers change between blocks
        for inputs, outputs in buffers:
            inputs[:] = rng.normal(size=len(inputs))
            outputs[:] = rng.normal(size=len(outputs))
        for group in groups.values():
            if first % group.period == 0:
                for gather in group.gathers:
                    gather.take()
                blocks.append((group, first, np.concatenate(group.parts)))
        for slot, entry in entries.items():  # the second way: each entry's own record
            if first % entry.period == 0:
                expected[slot][0].append(first)
                expected[slot][1].append(entry.record())
    records = _Live.records(blocks)
    assert set(records) == set(entries)
    for slot, (steps, rows) in records.items():
        np.testing.assert_array_equal(steps, expected[slot][0])
        np.testing.assert_array_equal(rows, np.array(expected[slot][1]))


def test_records_packed_into_a_kept_buffer_are_those_of_a_fresh_one():
    rng = np.random.default_rng(2)
    raw = [rng.bytes(int(size)) for size in rng.integers(1, 40, 9)]
    blob = b"".join(raw)
    table = np.zeros((len(raw), kernel.RAW_COLUMNS), dtype=np.int64)
    table[:, kernel.RAW_CHANNEL] = rng.integers(1, 4, len(raw))
    table[:, kernel.RAW_SEQUENCE] = np.arange(len(raw))
    table[:, kernel.RAW_TIME] = np.sort(rng.integers(0, 10**12, len(raw)))
    table[:, kernel.RAW_SIZE] = [len(payload) for payload in raw]
    table[1:, kernel.RAW_START] = np.cumsum(table[:-1, kernel.RAW_SIZE])
    streams = np.zeros((1, kernel.STREAM_COLUMNS), dtype=np.int64)
    streams[0, kernel.P_KIND] = kernel.STREAM_RAW
    fields = np.zeros((0, kernel.FIELD_COLUMNS), dtype=np.int64)
    order = np.zeros(len(raw), dtype=np.int64)
    size = 31 * len(raw) + len(blob)
    fresh = kernel.pack_records(order, streams, fields, table, blob, size)
    kept = bytearray(b"\xaa" * (size + 100))  # a larger buffer, holding an earlier pack's bytes
    reused = kernel.pack_records(order, streams, fields, table, blob, size, kept)
    assert bytes(reused[0]) == bytes(fresh[0]) and len(reused[0]) == size
    for left, right in zip(reused[1:], fresh[1:], strict=True):
        np.testing.assert_array_equal(left, right)
    exact = bytearray(size)
    assert bytes(kernel.pack_records(order, streams, fields, table, blob, size, exact)[0]) == bytes(fresh[0])
    # Each record: opcode 5, its length, then the payload given.
    head = 0
    for payload in raw:
        record = bytes(reused[0])[head : head + 31 + len(payload)]
        assert record[0] == 5 and int.from_bytes(record[1:9], "little") == 22 + len(payload)
        assert record[31:] == payload
        head += 31 + len(payload)


def test_a_fleets_steps_are_flushed_by_the_wall_time_of_their_own_collection(tmp_path, monkeypatch):
    # The recorder's flush_interval counts from when the steps held began to be collected: a slow
    # set-up (the clock far on at the first block) flushes nothing early; a block that comes after
    # flush_interval of collection does flush, and the log is the same either way.
    from types import SimpleNamespace

    from cosim.navigation.fleet import run_fleet
    from cosim.record import fleet_steps
    from cosim.scenario.load import parse_scenario

    scenarios = Path(__file__).resolve().parents[2] / "scenarios"
    text = (scenarios / "fleet_head_on.toml").read_text()
    reference = tmp_path / "reference.mcap"
    run_fleet(parse_scenario(text, "head_on.toml", scenarios), log_path=reference)

    clock = [0.0]
    monkeypatch.setattr(fleet_steps, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    flushed: list[tuple[int, int]] = []
    blocks: list[tuple[int, int]] = []
    block, flush = fleet_steps.FleetSteps.block, fleet_steps.FleetSteps.flush

    def timed_block(self, first, end, *args, **kwargs):
        clock[0] += 100.0 if not blocks else 0.0  # the set-up took long
        if len(blocks) == 3:
            clock[0] += 100.0  # the 4th block comes long after the collection began
        blocks.append((first, end))
        block(self, first, end, *args, **kwargs)

    def recorded_flush(self):
        if self.first is not None:
            flushed.append((self.first, self.end))
        flush(self)

    monkeypatch.setattr(fleet_steps.FleetSteps, "block", timed_block)
    monkeypatch.setattr(fleet_steps.FleetSteps, "flush", recorded_flush)
    timed = tmp_path / "timed.mcap"
    run_fleet(parse_scenario(text, "head_on.toml", scenarios), log_path=timed)
    assert len(blocks) > 5
    assert flushed[0] == (blocks[0][0], blocks[3][1])  # at the 4th block, not at the first
    assert timed.read_bytes() == reference.read_bytes()
