"""The reading API (`cosim.logs`): signals to the bit, topics, metadata, the robot's world, and
files from other writers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from log_synthetic import (
    COMPONENTS,
    GOAL,
    METADATA,
    OBSTACLES,
    OUTCOME,
    RADIUS,
    SCAN_EVERY,
    SCENARIO_TEXT,
    STEP_NS,
    STEPS,
    make_grid,
    make_inflated,
    planned_path,
    pose_at,
    write_log,
)
from mcap.writer import CompressionType, Writer
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.record import rosmsg
from cosim.record.rosmsg import COMPONENT_KEY, SIGNAL_NAMES_KEY


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return write_log(tmp_path_factory.mktemp("logs") / "run.mcap")


@pytest.fixture(scope="module")
def log(written):
    with open_log(written.path) as opened:
        yield opened


def test_signals_equal_what_was_recorded_to_the_bit(log, written):
    assert log.components == list(COMPONENTS)
    for component, names in COMPONENTS.items():
        signals = log.signals(component)
        assert signals.names == names
        np.testing.assert_array_equal(signals.t_ns, written.t_ns)
        np.testing.assert_array_equal(signals.t, written.t_ns / 1e9)
        expected = written.signals[component]
        assert signals.values.dtype == np.float64 and signals.values.shape == expected.shape
        # bit equality, NaN and inf included
        assert signals.values.tobytes() == expected.tobytes()
        for column, name in enumerate(names):
            assert signals[name].tobytes() == expected[:, column].tobytes()
    assert log.signals("vfh")["ranges_1"] is not None  # by ROS field name too


def test_signals_agree_with_rosbags_decoding(log, written):
    """Our vectorised slicing against rosbags' per-message decoder on the same channel."""
    fields = rosmsg.field_names(COMPONENTS["pure_pursuit"])
    rows, times = [], []
    with AnyReader([written.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        connections = [c for c in reader.connections if c.topic == "/signals/pure_pursuit"]
        for connection, timestamp, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            rows.append([getattr(message, field) for field in fields])
            times.append(timestamp)
    signals = log.signals("pure_pursuit")
    np.testing.assert_array_equal(signals.values, np.array(rows))
    np.testing.assert_array_equal(signals.t_ns, np.array(times))


def test_topics_counts_and_rates(log):
    topics = {topic.name: topic for topic in log.topics}
    rate = 1e9 / STEP_NS
    assert topics["/odom"].count == STEPS and topics["/odom"].rate == pytest.approx(rate)
    assert topics["/scan"].count == STEPS // SCAN_EVERY and topics["/scan"].rate == pytest.approx(
        rate / SCAN_EVERY
    )
    assert topics["/map"].count == 1 and topics["/map"].rate == 0.0
    assert topics["/signals/vfh"].type == "navcosim_msgs/msg/VfhSignals"
    assert log.duration == pytest.approx((STEPS - 1) * STEP_NS / 1e9)
    assert log.is_complete and log.warnings == []


def test_metadata_scenario_and_outcome(log):
    assert log.metadata["navcosim"] == METADATA["navcosim"]
    assert log.scenario_name == "synthetic_quarter_circle"
    assert log.scenario_text == SCENARIO_TEXT
    assert log.metadata["outcome"] == OUTCOME  # as written
    assert log.outcome == {
        "reached": True,
        "reason": "goal",
        "time": 5.95,
        "distance": 2.98,
        "min_clearance": 0.7,
    }
    assert log.fmus["vehicle"]["guid"] == METADATA["fmu/vehicle"]["guid"]


def test_world_round_trips(log):
    grid, inflated = log.map(), log.map("/map_inflated")
    expected = make_grid()
    np.testing.assert_array_equal(grid.occupied, expected.occupied)
    assert (grid.resolution, grid.origin) == (expected.resolution, expected.origin)
    np.testing.assert_array_equal(inflated.occupied, make_inflated().occupied)
    np.testing.assert_array_equal(log.plan(), planned_path())
    assert log.goal() == GOAL
    assert log.start() == pytest.approx((RADIUS, 0.0, math.pi / 2))
    obstacles = log.obstacles()
    assert [type(shape) for shape in obstacles] == [type(shape) for shape in OBSTACLES]
    for got, want in zip(obstacles, OBSTACLES, strict=True):
        np.testing.assert_allclose(got.polygon(), want.polygon(), atol=1e-12)
    trajectory = log.trajectory()
    x, y, theta = pose_at(trajectory.t[-1])
    assert (trajectory.x[-1], trajectory.y[-1], trajectory.theta[-1]) == (x, y, theta)


def test_messages_decode_ros_types(log):
    scans = list(log.messages("/scan"))
    assert len(scans) == STEPS // SCAN_EVERY
    assert scans[1].t_ns == SCAN_EVERY * STEP_NS and scans[1].t == pytest.approx(SCAN_EVERY * STEP_NS / 1e9)
    assert type(scans[0].message).__name__.endswith("LaserScan")
    with pytest.raises(CosimError, match="no topic /nothing"):
        list(log.messages("/nothing"))
    with pytest.raises(CosimError, match="components: vehicle, pure_pursuit, vfh, mixer"):
        log.signals("lidar")


def test_log_without_outcome_warns(tmp_path):
    target = write_log(tmp_path / "no_outcome.mcap", steps=5, outcome={}).path
    # an empty outcome dict is still an outcome; a file closed without one warns
    from cosim.record.recorder import Recorder

    with Recorder(tmp_path / "bare.mcap") as recorder:
        recorder.write_cmd_vel(0, 1.0, 0.0)
    assert open_log(target).warnings == []
    bare = open_log(tmp_path / "bare.mcap")
    assert bare.outcome is None and any("no outcome" in warning for warning in bare.warnings)


def _signals_channel(writer: Writer, names: list[str]) -> int:
    fields = rosmsg.field_names(names)
    schema = writer.register_schema(
        "navcosim_msgs/msg/VehicleSignals", "ros2msg", rosmsg.signals_definition(fields).encode()
    )
    metadata = {COMPONENT_KEY: "vehicle", SIGNAL_NAMES_KEY: json.dumps(names)}
    return writer.register_channel("/signals/vehicle", "cdr", schema, metadata)


@pytest.mark.parametrize(
    "options",
    [
        {"use_chunking": False},
        {"compression": CompressionType.LZ4, "chunk_size": 300},
        {"compression": CompressionType.NONE, "chunk_size": 1000},
    ],
)
def test_other_writer_layouts_read_the_same(tmp_path, options):
    """Unchunked files, lz4 and stored chunks: the signals come out the same."""
    target = tmp_path / "other.mcap"
    values = np.random.default_rng(1).normal(size=(50, 3))
    with open(target, "wb") as handle:
        writer = Writer(handle, **options)
        writer.start(profile="ros2", library="test")
        channel = _signals_channel(writer, ["x", "y", "theta"])
        for k, row in enumerate(values):
            writer.add_message(channel, k * 10, rosmsg.signals_payload(k * 10, row), k * 10)
        writer.finish()
    signals = open_log(target).signals("vehicle")
    np.testing.assert_array_equal(signals.values, values)
    np.testing.assert_array_equal(signals.t_ns, np.arange(50) * 10)


def test_mcap_from_another_tool_without_signal_channels(tmp_path):
    target = tmp_path / "chatter.mcap"
    with open(target, "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data")
        for k in range(10):
            writer.write_message("/chatter", schema, {"data": f"hello {k}"}, log_time=k, publish_time=k)
        writer.finish()
    log = open_log(target)
    assert log.components == []
    assert [(topic.name, topic.count) for topic in log.topics] == [("/chatter", 10)]
    assert [item.message.data for item in log.messages("/chatter")][-1] == "hello 9"
    assert log.trajectory() is None and log.map() is None and log.plan() is None and log.obstacles() == []
    with pytest.raises(CosimError, match="not a navcosim run log"):
        log.signals("vehicle")


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "empty file"), (b"hello, world\n" * 10, "not an MCAP file"), (b"\x89MCAP0\r\n", None)],
)
def test_bad_files(tmp_path, content, message):
    target = tmp_path / "bad.mcap"
    target.write_bytes(content)
    if message is None:  # only the magic: an empty, cut log
        log = open_log(target)
        assert not log.is_complete and log.topics == [] and log.warnings
    else:
        with pytest.raises(CosimError, match=message):
            open_log(target)
    with pytest.raises(CosimError, match="no such log file"):
        open_log(tmp_path / "missing.mcap")


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("true", True),
        ("false", False),
        ("12", 12),
        ("-3", -3),
        ("41.250000", 41.25),
        ("1e-3", 1e-3),
        ("inf", float("inf")),
        ("goal_reached", "goal_reached"),
        ("6.0,8.0", "6.0,8.0"),
        ("", ""),
        ("True", "True"),  # only the recorder's own spelling is a bool
    ],
)
def test_outcome_values_are_typed(text, value):
    from cosim.logs.reader import typed_value

    assert typed_value(text) == value and type(typed_value(text)) is type(value)


def test_a_nan_outcome_value_is_a_float_nan():
    import math

    from cosim.logs.reader import typed_value

    assert math.isnan(typed_value("nan"))
