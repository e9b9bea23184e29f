"""The recorder's files, read by readers other than our own: rosbags' AnyReader (ROS 2 type
store), mcap-ros2-support's decoder and the plain `mcap` reader."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from log_synthetic import (
    ANGLES,
    COMPONENTS,
    GOAL,
    OBSTACLES,
    RADIUS,
    SCAN_EVERY,
    SPEED,
    STEP_NS,
    STEPS,
    make_grid,
    planned_path,
    pose_at,
    scan_at,
    values_at,
    write_log,
)
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from cosim.errors import CosimError
from cosim.record import rosmsg
from cosim.record.recorder import Recorder, scan_layout


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    return write_log(tmp_path_factory.mktemp("rec") / "run.mcap").path


def _read_all(log_path):
    """{topic: [(log_time, message), ...]} decoded by rosbags' AnyReader."""
    topics: dict[str, list] = {}
    with AnyReader([log_path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, timestamp, raw in reader.messages():
            topics.setdefault(connection.topic, []).append(
                (timestamp, reader.deserialize(raw, connection.msgtype))
            )
    return topics


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))


def _angle_difference(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def test_every_channel_is_ros2_cdr_with_a_ros2msg_schema(log_path):
    with open(log_path, "rb") as handle:
        reader = make_reader(handle)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert len(summary.channels) == 10 + len(COMPONENTS)  # ten robot topics + one per component
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        assert summary.schemas[channel.schema_id].encoding == "ros2msg"


def test_robot_topics_round_trip_through_anyreader(log_path):
    topics = _read_all(log_path)
    assert len(topics["/odom"]) == len(topics["/tf"]) == len(topics["/pose"]) == STEPS
    for k in (0, 37, STEPS - 1):
        t = k * STEP_NS / 1e9
        x, y, theta = pose_at(t)
        log_time, odometry = topics["/odom"][k]
        assert log_time == k * STEP_NS
        assert odometry.header.stamp.sec * 10**9 + odometry.header.stamp.nanosec == k * STEP_NS
        # REP-105: odometry in "odom" of "base_link"; /tf is the tree map -> odom -> base_link.
        assert odometry.header.frame_id == "odom" and odometry.child_frame_id == "base_link"
        assert (odometry.pose.pose.position.x, odometry.pose.pose.position.y) == (x, y)
        assert _angle_difference(_yaw(odometry.pose.pose.orientation), theta) < 1e-12
        assert odometry.twist.twist.linear.x == SPEED and odometry.twist.twist.angular.z == SPEED / RADIUS
        to_odom, transform = topics["/tf"][k][1].transforms
        assert (to_odom.header.frame_id, to_odom.child_frame_id) == ("map", "odom")
        assert (transform.header.frame_id, transform.child_frame_id) == ("odom", "base_link")
        assert to_odom.header.stamp == transform.header.stamp == odometry.header.stamp
        identity = to_odom.transform
        assert (identity.translation.x, identity.translation.y, identity.translation.z) == (0.0, 0.0, 0.0)
        assert (identity.rotation.x, identity.rotation.y, identity.rotation.z, identity.rotation.w) == (
            0,
            0,
            0,
            1,
        )
        assert (transform.transform.translation.x, transform.transform.translation.y) == (x, y)
        assert _angle_difference(_yaw(transform.transform.rotation), theta) < 1e-12
        pose = topics["/pose"][k][1].pose
        assert (pose.position.x, pose.position.y) == (x, y)
    twist = topics["/cmd_vel"][5][1]
    assert (twist.linear.x, twist.angular.z) == (SPEED, SPEED / RADIUS)
    goal = topics["/goal"][0][1]
    assert (goal.pose.position.x, goal.pose.position.y) == GOAL


def test_scan_round_trips_with_its_angles(log_path):
    scans = _read_all(log_path)["/scan"]
    assert len(scans) == STEPS // SCAN_EVERY
    log_time, scan = scans[3]
    k = 3 * SCAN_EVERY
    assert log_time == k * STEP_NS
    beam_angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
    np.testing.assert_allclose(beam_angles, ANGLES, atol=1e-6)  # float32 fields
    # REP-117: a beam without a return (NaN from the lidar) is +inf on /scan.
    np.testing.assert_array_equal(scan.ranges, np.nan_to_num(scan_at(k), nan=np.inf).astype(np.float32))
    assert scan.header.frame_id == "base_link"


def test_path_round_trips(log_path):
    plan = _read_all(log_path)["/plan"][0][1]
    points = np.array([(pose.pose.position.x, pose.pose.position.y) for pose in plan.poses])
    np.testing.assert_array_equal(points, planned_path())
    headings = [_yaw(pose.pose.orientation) for pose in plan.poses]
    step = np.diff(planned_path(), axis=0)
    assert _angle_difference(headings[0], math.atan2(step[0, 1], step[0, 0])) < 1e-12


def test_map_rows_are_flipped_to_ros_order(log_path):
    """ROS: data[i*width + j] is the cell whose lower-left corner is origin + (j, i) * resolution."""
    grid_message = _read_all(log_path)["/map"][0][1]
    grid = make_grid()
    info = grid_message.info
    assert (info.width, info.height) == (grid.shape[1], grid.shape[0])
    assert info.resolution == np.float32(grid.resolution)
    assert (info.origin.position.x, info.origin.position.y) == grid.origin
    data = np.asarray(grid_message.data).reshape(info.height, info.width)
    for i in range(info.height):
        for j in range(info.width):
            centre = (
                info.origin.position.x + (j + 0.5) * info.resolution,
                info.origin.position.y + (i + 0.5) * info.resolution,
            )
            row, col = grid.world_to_cell(centre)
            assert data[i, j] == (100 if grid.occupied[row, col] else 0)


def test_obstacle_markers(log_path):
    markers = _read_all(log_path)["/obstacles"][0][1].markers
    circle, rectangle, polygon = markers
    assert circle.type == 3  # CYLINDER
    assert (circle.pose.position.x, circle.pose.position.y, circle.scale.x) == (2.0, 2.0, 0.8)
    assert rectangle.type == 1
    assert (rectangle.scale.x, rectangle.scale.y) == (1.2, 0.6)
    assert _angle_difference(_yaw(rectangle.pose.orientation), 0.5) < 1e-12
    assert polygon.type == 4
    vertices = [(point.x, point.y) for point in polygon.points]
    assert vertices == [(1, -1), (2, -1), (1.5, 0), (1, -1)]  # closed strip
    assert len({marker.id for marker in markers}) == len(OBSTACLES)


def test_signals_decode_by_field_name(log_path):
    topics = _read_all(log_path)
    for component, names in COMPONENTS.items():
        records = topics[f"/signals/{component}"]
        assert len(records) == STEPS
        log_time, message = records[11]
        expected = values_at(component, 11)
        for name, value in zip(rosmsg.field_names(names), expected, strict=True):
            np.testing.assert_array_equal(getattr(message, name), value)
        assert message.stamp.sec * 10**9 + message.stamp.nanosec == log_time == 11 * STEP_NS


def test_mcap_ros2_support_decodes_every_topic(log_path):
    counts: dict[str, int] = {}
    for item in read_ros2_messages(str(log_path)):
        counts[item.channel.topic] = counts.get(item.channel.topic, 0) + 1
        if item.channel.topic == "/signals/vehicle" and item.log_time_ns == 7 * STEP_NS:
            assert item.ros_msg.x == values_at("vehicle", 7)[0]
    assert counts["/signals/vehicle"] == counts["/odom"] == counts["/cmd_vel"] == STEPS
    assert counts["/scan"] == STEPS // SCAN_EVERY
    for topic in ("/map", "/map_inflated", "/plan", "/obstacles", "/goal"):
        assert counts[topic] == 1


def test_packed_messages_equal_rosbags_serialisation():
    rng = np.random.default_rng(3)
    for _ in range(20):
        t_ns = int(rng.integers(0, 10**13))
        x, y, yaw, v, omega = rng.normal(size=5) * 10
        assert rosmsg.pose_stamped_cdr(t_ns, x, y, yaw) == rosmsg.serialize(
            rosmsg.pose_stamped(t_ns, x, y, yaw), "geometry_msgs/msg/PoseStamped"
        )
        assert rosmsg.twist_cdr(v, omega) == rosmsg.serialize(
            rosmsg.twist(v, omega), "geometry_msgs/msg/Twist"
        )
        header = rosmsg.header(t_ns, "odom")
        to_odom = rosmsg.make(
            "geometry_msgs/msg/TransformStamped",
            header=rosmsg.header(t_ns, "map"),
            child_frame_id="odom",
            transform=rosmsg.make(
                "geometry_msgs/msg/Transform",
                translation=rosmsg.vector3(0.0, 0.0),
                rotation=rosmsg.quaternion(0.0),
            ),
        )
        transform = rosmsg.make(
            "geometry_msgs/msg/TransformStamped",
            header=header,
            child_frame_id="base_link",
            transform=rosmsg.make(
                "geometry_msgs/msg/Transform",
                translation=rosmsg.vector3(x, y),
                rotation=rosmsg.quaternion(yaw),
            ),
        )
        expected_tf = rosmsg.serialize(
            rosmsg.make("tf2_msgs/msg/TFMessage", transforms=[to_odom, transform]), "tf2_msgs/msg/TFMessage"
        )
        assert rosmsg.tf_cdr(t_ns, x, y, yaw) == expected_tf
        odometry = rosmsg.make(
            "nav_msgs/msg/Odometry",
            header=header,
            child_frame_id="base_link",
            pose=rosmsg.make(
                "geometry_msgs/msg/PoseWithCovariance", pose=rosmsg.pose(x, y, yaw), covariance=np.zeros(36)
            ),
            twist=rosmsg.make(
                "geometry_msgs/msg/TwistWithCovariance", twist=rosmsg.twist(v, omega), covariance=np.zeros(36)
            ),
        )
        assert rosmsg.odometry_cdr(t_ns, x, y, yaw, v, omega) == rosmsg.serialize(
            odometry, "nav_msgs/msg/Odometry"
        )


def test_field_names_are_valid_ros2_and_unique():
    names = [
        "x",
        "X",
        "waypoints[3,1]",
        "Steering.Angle",
        "2nd",
        "__a__",
        "class",
        "a__b",
        "",
        "ünï",
        "stamp",
    ]
    fields = rosmsg.field_names(names)
    assert len(set(fields)) == len(fields) and "stamp" not in fields
    for field in fields:
        assert re.fullmatch(r"[a-z][a-z0-9_]*", field) and "__" not in field and not field.endswith("_")
    assert fields[:4] == ["x", "x_2", "waypoints_3_1", "steering_angle"]
    assert rosmsg.signals_type_name("pure_pursuit") == "navcosim_msgs/msg/PurePursuitSignals"


@pytest.mark.parametrize(
    ("angles", "description"),
    [
        (np.array([-np.pi / 4, 0.0, np.pi / 4]), "uniform"),
        (np.linspace(-np.pi, np.pi, 360, endpoint=False), "uniform"),
        (np.array([-0.6, -0.2, 0.0, 0.2, 0.6]), "exact, NaN between beams"),
        (np.array([0.0, 0.1, 0.1 + np.sqrt(2) / 10, 0.5]), "nearest bin"),
    ],
)
def test_scan_layout_places_beams_honestly(angles, description):
    angle_min, increment, bins, text = scan_layout(angles)
    assert text.startswith(description)
    grid_angles = angle_min + increment * bins
    error = np.max(np.abs(grid_angles - angles))
    if description == "nearest bin":
        bound = float(text.split("up to ")[1].split(" rad")[0])
        assert 1e-6 < error <= bound * 1.001
        assert error <= np.min(np.diff(angles)) / 32 + 1e-12
    else:
        assert error < 1e-6
    assert len(set(bins.tolist())) == len(bins)


def test_exception_inside_with_finalises_the_file(tmp_path):
    target = tmp_path / "deep" / "folder" / "error.mcap"
    with pytest.raises(RuntimeError, match="boom"):
        with Recorder(target) as recorder:
            channel = recorder.signal_channel("vehicle", ["x"])
            recorder.write_signals(channel, 0, np.array([1.5]))
            raise RuntimeError("boom")
    with open(target, "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()  # only a finished file has one
        assert summary is not None and summary.statistics.message_count == 1
        assert "outcome" not in {record.name for record in reader.iter_metadata()}


def test_close_is_idempotent_and_writing_after_close_fails(tmp_path):
    recorder = Recorder(tmp_path / "a.mcap")
    channel = recorder.signal_channel("vehicle", ["x", "y"])
    recorder.close({"reached": "false"})
    recorder.close({"reached": "true"})
    with pytest.raises(CosimError, match="closed"):
        recorder.write_signals(channel, 0, np.zeros(2))
    with Recorder(tmp_path / "b.mcap") as recorder:
        channel = recorder.signal_channel("vehicle", ["x", "y"])
        with pytest.raises(CosimError, match="3 signal values for a channel of 2"):
            recorder.write_signals(channel, 0, np.zeros(3))


def test_ended_chunks_reach_the_disk_before_close_and_the_wall_clock_changes_no_byte(tmp_path):
    """Chunks end by simulated time (windows of `chunk_duration`): while the recorder is still
    open (what a SIGKILL would leave) another reader sees every record before the open window.
    The wall-clock flush (here at every write) only hands ended chunks to the OS, so the file's
    bytes are those of a recorder that never flushed."""
    from cosim.logs import open_log

    targets = {interval: tmp_path / f"open{interval}.mcap" for interval in (0.0, 1e9)}
    for interval, target in targets.items():
        recorder = Recorder(target, flush_interval=interval, chunk_duration=0.5)
        channel = recorder.signal_channel("vehicle", ["x"])
        for k in range(25):  # t = 0 .. 2.4 s: windows [0, 0.5) .. [1.5, 2) ended, [2, 2.5) open
            recorder.write_signals(channel, k * 100_000_000, np.array([k * 0.5]))
        if interval == 0.0:
            log = open_log(target)
            assert not log.is_complete
            np.testing.assert_array_equal(log.signals("vehicle")["x"], np.arange(20) * 0.5)
            assert len(log._index.blocks) == 4
        recorder.close()
    assert targets[0.0].read_bytes() == targets[1e9].read_bytes()
    assert len(open_log(targets[0.0]).signals("vehicle").t) == 25


def test_held_messages_are_the_bytes_and_order_of_one_message_at_a_time(tmp_path):
    """Signals, poses, commands and scans are packed per block with NumPy; every record must be
    what the per-message CDR functions (and rosbags for the scan) give, in the order written,
    across block boundaries (more messages than one block holds)."""
    from cosim.record import rosmsg
    from cosim.record.recorder import TOPIC_TYPES

    target = tmp_path / "held.mcap"
    angles = np.linspace(-1.0, 1.0, 7)
    expected = []
    with Recorder(target, flush_interval=1e9) as recorder:
        vehicle = recorder.signal_channel("vehicle", ["x", "y", "theta"])
        mixer = recorder.signal_channel("mixer", ["v"])
        for k in range(1300):
            t_ns = k * 10_000_000 + 3
            values = np.array([k * 0.1, math.sin(k), -1.5 * k])
            recorder.write_signals(vehicle, t_ns, values)
            expected.append(("/signals/vehicle", t_ns, rosmsg.signals_payload(t_ns, values)))
            if k % 5 == 0:
                recorder.write_signals(mixer, t_ns, np.array([k * 0.3]))
                expected.append(("/signals/mixer", t_ns, rosmsg.signals_payload(t_ns, np.array([k * 0.3]))))
                recorder.write_cmd_vel(t_ns, 0.5, k * 0.01)
                expected.append(("/cmd_vel", t_ns, rosmsg.twist_cdr(0.5, k * 0.01)))
            if k % 10 == 0:
                ranges = np.where(np.arange(7) == k % 7, np.nan, 0.01 * k + np.arange(7))
                recorder.write_scan(t_ns, angles, ranges, 0.0, 10.0)
                message = rosmsg.make(
                    "sensor_msgs/msg/LaserScan",
                    header=rosmsg.header(t_ns, "base_link"),
                    angle_min=-1.0,
                    angle_max=-1.0 + (angles[1] - angles[0]) * 6,
                    angle_increment=float(angles[1] - angles[0]),
                    time_increment=0.0,
                    scan_time=0.0,
                    range_min=0.0,
                    range_max=10.0,
                    ranges=np.where(np.isnan(ranges), np.inf, ranges).astype(np.float32),
                    intensities=np.zeros(0, dtype=np.float32),
                )
                expected.append(("/scan", t_ns, rosmsg.serialize(message, TOPIC_TYPES["/scan"])))
            if k % 2 == 1:
                pose = (0.01 * k, -0.02 * k, 0.003 * k - 2.0)
                recorder.write_pose(t_ns + 10_000_000, *pose, 0.7, 0.1)
                t_pose = t_ns + 10_000_000
                expected.append(("/odom", t_pose, rosmsg.odometry_cdr(t_pose, *pose, 0.7, 0.1)))
                expected.append(("/tf", t_pose, rosmsg.tf_cdr(t_pose, *pose)))
                expected.append(("/pose", t_pose, rosmsg.pose_stamped_cdr(t_pose, *pose)))
    with open(target, "rb") as stream:
        written = [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]
    assert len(written) == len(expected)
    assert written == expected


@pytest.mark.parametrize("chunk_duration", [0.05, 1000.0])
def test_steps_held_at_once_write_the_bytes_of_one_message_at_a_time(tmp_path, chunk_duration):
    """`Recorder.hold_steps` (the kernel path's recording) against the per-message path: the same
    file, byte for byte, with chunks cut by short windows (0.05 s) or by full blocks (a long
    window: more than 512 records of a channel), and a signal channel and /plan registered
    mid-run while held steps skipped packs (their records go where the per-message path puts them)."""
    from cosim.record.recorder import TOPIC_TYPES  # noqa: F401

    h_ns = 10_000_000
    angles = np.linspace(-1.0, 1.0, 9)
    angles.flags.writeable = False

    def row(k, size, scale):
        return np.array([math.sin(k * scale + j) for j in range(size)])

    def scan(k):
        return np.where(np.arange(9) == k % 9, np.nan, 0.01 * k + np.arange(9))

    late_at, path_at, steps = 700, 900, 1400
    paths = {}
    for way in ("one", "batch"):
        target = tmp_path / f"{way}.mcap"
        paths[way] = target
        with Recorder(target, flush_interval=1e9, chunk_duration=chunk_duration) as recorder:
            a = recorder.signal_channel(
                "a", ["u", "x", "y"], inputs=1, initial=row(-1, 3, 0.1), period_ns=h_ns
            )
            b = recorder.signal_channel(
                "b", ["p", "q"], inputs=1, initial=row(-1, 2, 0.2), period_ns=3 * h_ns
            )
            late = None
            recorder.write_pose(0, 0.0, 0.0, 0.0, 0.0, 0.0)
            k = 0
            while k < steps:
                if k == late_at:
                    late = recorder.signal_channel(
                        "late", ["w"], inputs=0, initial=row(-2, 1, 0.3), period_ns=h_ns
                    )
                if k == path_at:
                    recorder.write_path(k * h_ns, np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 2.5]]))
                end = k + 1 if way == "one" or k == 0 else min(steps, k + 1 + k % 37)
                end = min(end, late_at) if k < late_at else end
                end = min(end, path_at) if k < path_at else end
                if way == "one" or k == 0:
                    t_ns = k * h_ns
                    recorder.hold_signals(a, t_ns, row(k, 3, 0.1))
                    if k % 3 == 0:
                        recorder.hold_signals(b, t_ns, row(k, 2, 0.2))
                    if late is not None:
                        recorder.hold_signals(late, t_ns, row(k, 1, 0.3))
                    if k % 5 == 0:
                        recorder.write_scan(t_ns, angles, scan(k), 0.0, 10.0)
                    if k % 2 == 0:
                        recorder.write_cmd_vel(t_ns, 0.5, k * 0.01)
                    if k % 2 == 1:
                        recorder.write_pose(t_ns + h_ns, *row(k, 3, 0.4), 0.7, k * 0.02)
                else:
                    ks = np.arange(k, end)
                    signals = [(a, ks * 10, ks * h_ns, np.array([row(j, 3, 0.1) for j in ks]))]
                    kb = ks[ks % 3 == 0]
                    signals.append(
                        (b, kb * 10 + 1, kb * h_ns, np.array([row(j, 2, 0.2) for j in kb]).reshape(-1, 2))
                    )
                    if late is not None:
                        signals.append((late, ks * 10 + 2, ks * h_ns, np.array([row(j, 1, 0.3) for j in ks])))
                    keys, stamps, messages = [], [], []
                    for j in ks.tolist():
                        if j % 5 == 0:
                            payload = recorder.scan_payload(j * h_ns, angles, scan(j), 0.0, 10.0)
                            (
                                keys.append(j * 10 + 3),
                                stamps.append(j * h_ns),
                                messages.append(("/scan", payload)),
                            )
                        if j % 2 == 0:
                            payload = rosmsg.twist_cdr(0.5, j * 0.01)
                            (
                                keys.append(j * 10 + 4),
                                stamps.append(j * h_ns),
                                messages.append(("/cmd_vel", payload)),
                            )
                    kp = ks[ks % 2 == 1]
                    poses = np.array([(*row(j, 3, 0.4), 0.7, j * 0.02) for j in kp]).reshape(-1, 5)
                    recorder.hold_steps(
                        signals,
                        (kp * 10 + 5, (kp + 1) * h_ns, poses),
                        (np.array(keys, dtype=np.int64), np.array(stamps, dtype=np.int64), messages),
                    )
                k = end
            recorder.end_steps(steps * h_ns)
    one, batch = paths["one"].read_bytes(), paths["batch"].read_bytes()
    assert len(one) == len(batch) and one == batch
    with open(paths["one"], "rb") as stream:
        reader = make_reader(stream)
        chunks = list(reader.get_summary().chunk_indexes)
        counts = reader.get_summary().statistics.channel_message_counts
    assert len(chunks) >= 2 and sum(counts.values()) > 4000
