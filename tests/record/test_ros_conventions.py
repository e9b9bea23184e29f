"""A run's log follows the ROS conventions, read back by rosbags: REP-105 frames (/tf is the tree
map -> odom -> base_link, /odom is in odom of base_link), REP-117 ranges (+inf without a return),
scan_time = 1 / rate, and [output.topics] renames topics (the reader follows the renaming)."""

from __future__ import annotations

import math
import zlib
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
RENAMED = [
    'output.topics.odom="/ground-truth-pose"',
    'output.topics.cmd_vel="/mobile-base/commands/velocity"',
]


@pytest.fixture(scope="module")
def renamed_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("ros") / "run.mcap"
    scenario = load_scenario(SCENARIO, ["simulation.stop_time=3.0", "lidar.range=[0.0, 8.0]", *RENAMED])
    run_scenario(scenario, path)
    return scenario, path


def _compose(a, b):
    """Planar transform a * b, each (x, y, yaw) from a geometry_msgs/Transform."""
    ax, ay, ayaw = a
    bx, by, byaw = b
    return (
        ax + math.cos(ayaw) * bx - math.sin(ayaw) * by,
        ay + math.sin(ayaw) * bx + math.cos(ayaw) * by,
        ayaw + byaw,
    )


def _planar(transform):
    q = transform.rotation
    return transform.translation.x, transform.translation.y, 2.0 * math.atan2(q.z, q.w)


def test_tf_tree_odom_frames_and_renamed_topics_through_rosbags(renamed_log):
    _, path = renamed_log
    topics: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, _, raw in reader.messages():
            topics.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    assert "/odom" not in topics and "/cmd_vel" not in topics
    odometry, commands = topics["/ground-truth-pose"], topics["/mobile-base/commands/velocity"]
    assert len(commands) > 0 and len(odometry) == len(topics["/tf"]) == len(topics["/pose"])
    for message, odom, pose in zip(topics["/tf"], odometry, topics["/pose"], strict=True):
        parents = {t.child_frame_id: (t.header.frame_id, _planar(t.transform)) for t in message.transforms}
        assert parents.keys() == {"odom", "base_link"}
        assert parents["odom"][0] == "map" and parents["base_link"][0] == "odom"  # one chain to the root
        robot = _compose(parents["odom"][1], parents["base_link"][1])  # map -> base_link
        assert odom.header.frame_id == "odom" and odom.child_frame_id == "base_link"
        assert pose.header.frame_id == "map"
        assert robot[:2] == pytest.approx((pose.pose.position.x, pose.pose.position.y), abs=1e-12)
        assert robot[:2] == pytest.approx((odom.pose.pose.position.x, odom.pose.pose.position.y), abs=1e-12)


def test_scan_uses_inf_for_no_return_and_its_period(renamed_log):
    scenario, path = renamed_log
    log = open_log(path)
    scans = [item.message for item in log.messages("/scan")]
    assert scans and all(scan.scan_time == pytest.approx(1.0 / scenario.lidar.rate) for scan in scans)
    assert all(scan.time_increment == 0.0 for scan in scans)  # every beam at the stamp
    ranges = np.concatenate([np.asarray(scan.ranges, dtype=float) for scan in scans])
    # With an 8 m range in the warehouse some beams see nothing: +inf, never NaN (a beam per bin).
    assert np.isposinf(ranges).any() and not np.isnan(ranges).any()
    assert (ranges[np.isfinite(ranges)] <= 8.0).all()
    # The reader follows the renaming: "/odom" is /ground-truth-pose in this log.
    assert log.topic_name("/odom") == "/ground-truth-pose" and log.has_topic("/odom")
    first = next(iter(log.messages("/odom"))).message
    assert (first.pose.pose.position.x, first.pose.pose.position.y) == scenario.start[:2]


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            'output.topics.odometry="/x"',
            r"\[output\]\.topics\.odometry: not a topic of the log \(did you mean",
        ),
        ('output.topics.odom="x"', r"\[output\]\.topics\.odom: a topic name starts with '/'"),
        ('output.topics.odom="/pose"', r"\[output\]\.topics\.odom: '/pose' is already the name"),
    ],
)
def test_bad_topic_names_are_errors_naming_the_key(override, message):
    with pytest.raises(CosimError, match=message):
        load_scenario(SCENARIO, [override])


def test_foxglove_layout_frames_the_whole_map():
    """The 3D panel looks straight down at the map's centre from far enough that the 100 m x 60 m
    warehouse fits a 16:9 view (height 2 d tan(fovy / 2)), and shows the three REP-105 frames."""
    import json

    from planner.grid import OccupancyGrid

    layout = Path(__file__).resolve().parents[2] / "foxglove" / "navcosim-layout.json"
    panel = json.loads(layout.read_text())["configById"]["3D!navcosim"]
    camera = panel["cameraState"]
    grid = OccupancyGrid.from_file(SCENARIO.parent / "maps" / "warehouse.yaml")
    width, height = grid.shape[1] * grid.resolution, grid.shape[0] * grid.resolution
    centre = (grid.origin[0] + width / 2, grid.origin[1] + height / 2)
    assert tuple(camera["target"][:2]) == pytest.approx(centre)
    seen_height = 2 * camera["distance"] * math.tan(math.radians(camera["fovy"]) / 2)
    assert seen_height >= height and seen_height * 16 / 9 >= width
    assert seen_height < 1.5 * max(height, width * 9 / 16)  # and not lost in the distance
    assert {"frame:map", "frame:odom", "frame:base_link"} <= set(panel["transforms"])


def test_the_log_types_are_rosbags_humble_definitions():
    """The messages a log is made of are held without rosbags' whole Humble store (`rosmsg.LOG_TYPES`):
    each has Humble's definition, so the schema a log carries and the bytes are Humble's."""
    from cosim.record import rosmsg

    humble = get_typestore(Stores.ROS2_HUMBLE)
    assert rosmsg.log_fielddefs() == {name: humble.fielddefs[name] for name in rosmsg.LOG_TYPES}
    for name in rosmsg.LOG_TYPES:
        assert rosmsg.message_definition(name) == humble.generate_msgdef(name, ros_version=2)[0]
    # Every message a log contains is there (a type outside would need the whole store).
    from cosim.record.recorder import TOPIC_TYPES

    contained, pending = set(), list(TOPIC_TYPES.values())
    while pending:
        name = pending.pop()
        contained.add(name)
        for _, (kind, detail) in humble.fielddefs[name][1]:
            while kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
                kind, detail = detail[0]
            if kind == Nodetype.NAME and detail not in contained:
                pending.append(detail)
    assert contained <= set(rosmsg.LOG_TYPES)


def test_a_message_outside_the_log_types_comes_from_the_humble_store():
    from cosim.record import rosmsg

    humble = get_typestore(Stores.ROS2_HUMBLE)
    name = "sensor_msgs/msg/NavSatFix"
    assert name not in rosmsg.LOG_TYPES
    fields = {
        "header": rosmsg.header(1_500_000_000, "gps"),
        "latitude": 48.1,
        "longitude": 11.6,
        "altitude": 0.5,
    }
    fields.update(status=rosmsg.make("sensor_msgs/msg/NavSatStatus", status=0, service=1))
    fields.update(position_covariance=np.arange(9.0), position_covariance_type=2)
    ours = rosmsg.serialize(rosmsg.make(name, **fields), name)
    message = humble.deserialize_cdr(ours, name)
    assert (message.header.stamp.sec, message.header.stamp.nanosec, message.header.frame_id) == (
        1,
        500_000_000,
        "gps",
    )
    assert (message.latitude, message.status.service, message.position_covariance_type) == (48.1, 1, 2)
    assert list(message.position_covariance) == list(range(9))
    assert rosmsg.message_definition(name) == humble.generate_msgdef(name, ros_version=2)[0]


def _sample(store, typename: str, seed: int):
    """A message of `typename` with every field set, from `seed` (sequences of 0-2 elements)."""
    numbers = iter(range(seed, seed + 10_000))
    base = {"float32": np.float32, "float64": np.float64, "int8": np.int8, "uint8": np.uint8}
    base.update(int32=np.int32, uint32=np.uint32)

    def value(description):
        kind, detail = description
        if kind == Nodetype.NAME:
            return message(detail)
        if kind == Nodetype.BASE:
            name = detail[0]
            if name == "string":
                return "frame" * (next(numbers) % 3)
            if name == "bool":
                return bool(next(numbers) % 2)
            return int(next(numbers) % 100) if name.startswith(("int", "uint")) else next(numbers) / 7.0
        element, size = detail
        count = size if kind == Nodetype.ARRAY else next(numbers) % 3
        if element[0] == Nodetype.BASE and element[1][0] in base:
            return np.array([value(element) for _ in range(count)], dtype=base[element[1][0]])
        return [value(element) for _ in range(count)]

    def message(name):
        return store.types[name](**{field: value(d) for field, d in store.fielddefs[name][1]})

    return message(typename)


def _outcome(function, *args):
    """The bytes `function` returns, or the error it raises (ROS 1 has another Header)."""
    try:
        return bytes(function(*args))
    except Exception as error:
        return type(error).__name__, str(error)


def test_the_log_type_store_serialises_as_rosbags_does():
    """`rosmsg.TYPESTORE` makes rosbags' functions of a type one by one as they are used: every one of
    them gives rosbags' own bytes and messages (CDR both ways and endiannesses, ROS 1 and conversions)."""
    from cosim.record import rosmsg

    humble = get_typestore(Stores.ROS2_HUMBLE)
    ours = rosmsg.TYPESTORE
    for name in rosmsg.LOG_TYPES:
        # The sample's seed comes from the type's name, not its place in LOG_TYPES: a type added
        # among them leaves the others' samples (and their byte-level checks) as they were.
        seed = zlib.crc32(name.encode()) % 1000
        message = _sample(ours, name, seed)
        theirs = _sample(humble, name, seed)
        for little in (True, False):
            data = bytes(ours.serialize_cdr(message, name, little_endian=little))
            assert data == bytes(humble.serialize_cdr(theirs, name, little_endian=little)), name
            assert (
                bytes(ours.serialize_cdr(ours.deserialize_cdr(data, name), name, little_endian=little))
                == data
            )
        ros1 = bytes(ours.serialize_ros1(message, name))
        assert ros1 == bytes(humble.serialize_ros1(theirs, name)), name
        assert _outcome(ours.ros1_to_cdr, ros1, name) == _outcome(humble.ros1_to_cdr, ros1, name)
        little = bytes(ours.serialize_cdr(message, name, little_endian=True))
        assert _outcome(ours.cdr_to_ros1, little, name) == _outcome(humble.cdr_to_ros1, little, name)
        assert bytes(ours.serialize_ros1(ours.deserialize_ros1(ros1, name), name)) == ros1


def test_the_log_type_store_makes_the_classes_rosbags_registers():
    """`rosmsg.TYPESTORE` makes each class on first use: the same definitions, fields and constants as
    rosbags' `Typestore.register` of all `LOG_TYPES` at once, and nothing for a name it does not hold."""
    import dataclasses

    from rosbags.typesys.store import Typestore

    from cosim.record import rosmsg

    registered = Typestore()
    registered.register(rosmsg.log_fielddefs())
    ours = rosmsg.TYPESTORE
    assert "navcosim_msgs/msg/NoSuchType" not in ours.types
    assert ours.types.get("navcosim_msgs/msg/NoSuchType") is None
    for name in rosmsg.LOG_TYPES:
        assert name in ours.types
        theirs, made = registered.types[name], ours.types[name]
        assert ours.fielddefs[name] == registered.fielddefs[name]
        assert ours.types[name] is made
        assert [(f.name, f.type, f.default) for f in dataclasses.fields(made)] == [
            (f.name, f.type, f.default) for f in dataclasses.fields(theirs)
        ]
        constants = {key: value for key, value in vars(theirs).items() if key.isupper()}
        assert {key: value for key, value in vars(made).items() if key.isupper()} == constants
        assert (made.__name__, made.__module__, made.__msgtype__) == (
            theirs.__name__,
            theirs.__module__,
            theirs.__msgtype__,
        )
