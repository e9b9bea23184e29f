"""`cosim run --live`: a WebSocket client (written here with `websockets`, speaking the subprotocol
the foxglove-sdk server answers with) subscribes to /odom and /scan, decodes the messages with the
advertised schemas (rosbags), and gets the poses and ranges the log holds at the same times. A
client that publishes a PoseStamped (serialised by rosbags) on /goal_pose moves the goal: the robot
replans and ends at the new goal."""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
import signal
import socket
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
BICYCLE = ROOT / "scenarios" / "warehouse_bicycle_no_obstacle.toml"
# From the start (6, 6) the scenarios' goal is (84, 53); this one lies where the vertical aisle at
# x = 38..46 m crosses the aisle at y = 26..34 m (maps/warehouse.yaml), another way from the start.
NEW_GOAL = (42.0, 30.0)
IN_A_RACK = (20.0, 14.0)  # the rack row y = 12..16 m, x = 10..38 m
OFF_THE_MAP = (-5.0, 3.0)
SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk's own; the classic one: tests/record/test_live_front.py
TOPICS = ("/odom", "/scan")


def _typestore(advertised: list[dict]):
    """A rosbags typestore knowing the advertised ros2msg schemas (definition + dependencies)."""
    store = get_typestore(Stores.EMPTY)
    for channel in advertised:
        name, text = channel["schemaName"], channel["schema"]
        sections = text.split("=" * 80 + "\n")
        types = dict(get_types_from_msg(sections[0], name))
        for section in sections[1:]:
            header, _, body = section.partition("\n")
            types.update(get_types_from_msg(body, header.removeprefix("MSG: ").strip()))
        store.register({key: value for key, value in types.items() if key not in store.fielddefs})
    return store


async def _listen(
    url: str, topics: tuple[str, ...] = TOPICS, enough: int | None = None
) -> tuple[dict[str, dict], dict[str, list[tuple[int, bytes]]]]:
    """Subscribe to `topics` and collect (timestamp [ns], payload) per topic until the server
    stops (or, given `enough`, until every topic has that many)."""
    advertised: dict[str, dict] = {}
    subscriptions: dict[int, str] = {}
    received: dict[str, list[tuple[int, bytes]]] = {topic: [] for topic in topics}
    pending: list[dict] = []  # every subscription sent
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as client:
        assert client.subprotocol == SUBPROTOCOL
        try:
            async for frame in client:
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message["op"] == "status" and message["message"].startswith("Unknown channel ID"):
                        # The SDK's server can answer a subscription sent right after an advertise
                        # with this (its channel table lags the advertise): subscribe again.
                        channel_id = int(message["message"].rsplit(":", 1)[1])
                        await asyncio.sleep(0.02)
                        again = [item for item in pending if item["channelId"] == channel_id]
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": again}))
                        continue
                    if message["op"] != "advertise":
                        continue
                    wanted = []
                    for channel in message["channels"]:
                        if channel["topic"] in topics and channel["topic"] not in advertised:
                            advertised[channel["topic"]] = channel
                            subscription = len(subscriptions) + 1
                            subscriptions[subscription] = channel["topic"]
                            wanted.append({"id": subscription, "channelId": channel["id"]})
                    pending += wanted
                    if wanted:
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
                elif frame[0] == 1:  # message data: subscription id, log time, payload
                    subscription, stamp = struct.unpack_from("<IQ", frame, 1)
                    received[subscriptions[subscription]].append((stamp, bytes(frame[13:])))
                    if enough is not None and all(len(items) >= enough for items in received.values()):
                        break
        except websockets.ConnectionClosed:
            pass
    return advertised, received


def _log_messages(
    path: Path, topics: tuple[str, ...] = TOPICS
) -> tuple[dict[str, dict[int, bytes]], dict[str, bytes]]:
    """Per topic {log time [ns]: payload} and the schema texts, read with the mcap package."""
    messages: dict[str, dict[int, bytes]] = {topic: {} for topic in topics}
    schemas: dict[str, bytes] = {}
    with open(path, "rb") as handle:
        for schema, channel, message in make_reader(handle).iter_messages(topics=list(topics)):
            messages[channel.topic][message.log_time] = message.data
            schemas[channel.topic] = schema.data
    return messages, schemas


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    log = tmp_path_factory.mktemp("live") / "live.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=3", "--live", "--port", "0", "--realtime", "3", "--linger", "0.5",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()
        assert line.startswith("live view: ws://"), line
        url = line.split()[2]
        advertised, received = asyncio.run(asyncio.wait_for(_listen(url), timeout=120))
        rest = process.stderr.read()
        assert process.wait(timeout=120) == 1, rest  # the stop time comes before the goal
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return log, advertised, received


@pytest.mark.slow
def test_live_stream_carries_the_logs_bytes_and_schemas(live_run):
    log, advertised, received = live_run
    messages, schemas = _log_messages(log)
    for topic in TOPICS:
        channel = advertised[topic]
        assert (channel["encoding"], channel["schemaEncoding"]) == ("cdr", "ros2msg")
        assert channel["schema"].encode() == schemas[topic]
        assert len(received[topic]) >= 3, topic
        for stamp, payload in received[topic]:
            assert messages[topic][stamp] == payload


@pytest.mark.slow
def test_live_poses_and_ranges_decode_to_the_logged_ones(live_run):
    log, advertised, received = live_run
    store = _typestore(list(advertised.values()))
    messages, _ = _log_messages(log)
    odom_type, scan_type = advertised["/odom"]["schemaName"], advertised["/scan"]["schemaName"]
    poses = []
    for stamp, payload in received["/odom"]:
        live = store.deserialize_cdr(payload, odom_type).pose.pose.position
        logged = store.deserialize_cdr(messages["/odom"][stamp], odom_type).pose.pose.position
        assert (live.x, live.y) == (logged.x, logged.y)
        poses.append((live.x, live.y))
    start = np.array(poses[0])
    assert np.linalg.norm(np.array(poses[-1]) - start) > 0.1  # the robot moved while streamed
    for stamp, payload in received["/scan"]:
        live = store.deserialize_cdr(payload, scan_type)
        logged = store.deserialize_cdr(messages["/scan"][stamp], scan_type)
        np.testing.assert_array_equal(live.ranges, logged.ranges)
        assert live.header.stamp.sec * 10**9 + live.header.stamp.nanosec == stamp


@pytest.mark.slow
def test_port_in_use_is_one_line_and_exit_2(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        command = [
            sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(tmp_path / "x.mcap"),
            "--live", "--port", str(port), "--quiet",
        ]  # fmt: skip
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and str(port) in lines[0], done.stderr
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.slow
def test_a_client_joining_after_the_run_gets_the_map_and_ctrl_c_ends_the_wait(tmp_path):
    log = tmp_path / "late.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--set", "simulation.stop_time=0.5", "--live", "--port", "0", "--realtime", "50",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        url = process.stderr.readline().split()[2]
        while "run ended" not in (line := process.stderr.readline()):
            assert line, "the run ended without lingering"
        assert "until Ctrl-C" in line
        latched = ("/map", "/plan")
        _, received = asyncio.run(asyncio.wait_for(_listen(url, latched, enough=1), timeout=120))
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=120) == 1
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    messages, _ = _log_messages(log, latched)
    for topic in latched:
        stamp, payload = received[topic][0]
        assert messages[topic][stamp] == payload


def test_pacer_holds_messages_until_their_time_over_r_and_slips_when_late(monkeypatch):
    """A fake clock: each message leaves at origin + t / R; a late one restarts the schedule."""
    from cosim.record import live

    clock = [100.0]
    monkeypatch.setattr(live.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(live.time, "sleep", lambda seconds: clock.__setitem__(0, clock[0] + seconds))
    pacer = live.Pacer(2.0)
    departures = []
    for t in (0.0, 0.1, 0.2, 0.2, 0.4):
        pacer.message(1, int(t * 1e9), b"")
        departures.append(clock[0])
    assert departures == pytest.approx([100.0, 100.05, 100.1, 100.1, 100.2])
    clock[0] += 1.0  # the run stalls for a second of wall time
    pacer.message(1, int(0.5e9), b"")
    assert clock[0] == pytest.approx(101.2)  # sent at once, not held
    pacer.message(1, int(0.7e9), b"")  # and the schedule goes on from there at R = 2
    assert clock[0] == pytest.approx(101.3)


def _pose_stamped_cdr(x: float, y: float, frame_id: str = "map") -> bytes:
    """A geometry_msgs/msg/PoseStamped at (x, y), serialised by rosbags (not by navcosim)."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    message = types["geometry_msgs/msg/PoseStamped"](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=frame_id
        ),
        pose=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    )
    return bytes(store.serialize_cdr(message, "geometry_msgs/msg/PoseStamped"))


async def _publish_goals(url: str, goals: list[tuple[float, float]]) -> tuple[dict, list[str]]:
    """Advertise /goal_pose (cdr, ros2msg) and, once /odom flows, publish each goal in turn; the
    next after the server's status about the previous one. Returns the server info and the
    status messages, collected until the server stops."""
    definition, _ = get_typestore(Stores.ROS2_HUMBLE).generate_msgdef("geometry_msgs/msg/PoseStamped")
    statuses: list[str] = []
    info: dict = {}
    pending = list(goals)
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as client:
        try:
            async for frame in client:
                if not isinstance(frame, str):
                    if pending and len(statuses) == len(goals) - len(pending):
                        x, y = pending.pop(0)
                        await client.send(struct.pack("<BI", 1, 7) + _pose_stamped_cdr(x, y))
                    continue
                message = json.loads(frame)
                if message["op"] == "serverInfo":
                    info = message
                    goal_channel = {
                        "id": 7,
                        "topic": "/goal_pose",
                        "encoding": "cdr",
                        "schemaName": "geometry_msgs/msg/PoseStamped",
                        "schemaEncoding": "ros2msg",
                        "schema": definition,
                    }
                    await client.send(json.dumps({"op": "advertise", "channels": [goal_channel]}))
                elif message["op"] == "advertise":
                    odom = [c for c in message["channels"] if c["topic"] == "/odom"]
                    if odom:
                        subscription = {"id": 1, "channelId": odom[0]["id"]}
                        await client.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
                elif message["op"] == "status" and "/goal_pose" in message["message"]:
                    statuses.append(message["message"])
        except websockets.ConnectionClosed:
            pass
    return info, statuses


@pytest.mark.slow
def test_a_goal_published_on_goal_pose_is_replanned_to_and_reached(tmp_path):
    """Two refused goals (in a rack, off the map) leave the run going; the third one is reached."""
    log = tmp_path / "goal.mcap"
    command = [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet",
        "--live", "--port", "0", "--realtime", "10", "--linger", "0",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        url = process.stderr.readline().split()[2]
        goals = [IN_A_RACK, OFF_THE_MAP, NEW_GOAL]
        info, statuses = asyncio.run(asyncio.wait_for(_publish_goals(url, goals), timeout=300))
        rest = process.stderr.read()
        assert process.wait(timeout=120) == 0, rest  # the goal (now NEW_GOAL) was reached
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert "clientPublish" in info["capabilities"] and "cdr" in info["supportedEncodings"]
    assert len(statuses) == 3, statuses
    assert "refused" in statuses[0] and "refused" in statuses[1] and "new goal" in statuses[2]
    assert rest.count("cosim: warning: /goal_pose") == 2, rest

    from cosim.logs import open_log

    opened = open_log(log)
    assert opened.outcome["reached"] is True and opened.outcome["reason"] == "goal_reached"
    assert opened.outcome["goal"] == f"{NEW_GOAL[0]},{NEW_GOAL[1]}"
    assert opened.outcome["replans"] >= 1
    logged_goals = [
        (item.message.pose.position.x, item.message.pose.position.y) for item in opened.messages("/goal")
    ]
    assert logged_goals == [(84.0, 53.0), NEW_GOAL]
    new_goal_time = list(opened.messages("/goal"))[1].t_ns
    plans = list(opened.messages("/plan"))
    assert any(item.t_ns == new_goal_time for item in plans)  # the replan to it, same step
    last = plans[-1].message.poses[-1].pose.position
    assert math.dist((last.x, last.y), NEW_GOAL) <= 0.5 * math.sqrt(0.5)  # the goal's 0.5 m cell
    trajectory = opened.trajectory()
    end = (trajectory.x[-1], trajectory.y[-1])
    assert math.dist(end, NEW_GOAL) <= 1.0  # the scenario's goal tolerance


def test_the_bicycle_replans_to_a_new_goal_with_hybrid_a_star(tmp_path):
    """The run's goal hook (no server): a bicycle given a new goal replans with Hybrid A* from where
    it is and reaches it; refused goals change nothing."""
    from test_shipped_scenarios import REDUCED

    from cosim.logs import open_log
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    class Goals:
        def __init__(self, goals):
            self.goals, self.reports, self.calls = list(goals), [], 0

        def take(self):
            self.calls += 1
            return self.goals.pop(0) if self.goals and self.calls % 5 == 0 else None

        def report(self, text, warning=True):
            self.reports.append((warning, text))

    scenario = dataclasses.replace(load_scenario(BICYCLE, REDUCED), plot=False)
    goals = Goals([OFF_THE_MAP, IN_A_RACK, NEW_GOAL])
    result = run_scenario(scenario, tmp_path / "bicycle.mcap", goals=goals)
    assert [warning for warning, _ in goals.reports] == [True, True, False], goals.reports
    assert result.outcome.reason == "goal_reached" and result.outcome.min_clearance > 0
    log = open_log(tmp_path / "bicycle.mcap")
    end = log.trajectory()
    assert math.dist((end.x[-1], end.y[-1]), NEW_GOAL) <= scenario.goal_tolerance
    plans = list(log.messages("/plan"))
    assert len(plans) == 2
    poses = plans[1].message.poses
    last = poses[-1].pose.position
    assert math.dist((last.x, last.y), NEW_GOAL) <= 0.5 * math.sqrt(0.5)  # the goal's 0.5 m cell
    first = poses[0].pose.position
    assert math.dist((first.x, first.y), (end.x[0], end.y[0])) > 1.0  # from where it was, not the start
    # Hybrid A*'s arcs (3.5 m turning radius), not a grid path: a grid A* path turns 45 degrees within
    # a cell (three points on a circle of 0.79 m); here no three points lie on a circle under 2 m.
    points = np.array([(pose.pose.position.x, pose.pose.position.y) for pose in poses])
    a, b, c = points[:-2], points[1:-1], points[2:]
    sides = np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - b, axis=1) * np.linalg.norm(c - a, axis=1)
    u, v = b - a, c - a
    twice_area = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    with np.errstate(divide="ignore"):
        assert (sides / (2.0 * twice_area)).min() > 2.0


def test_set_goal_keeps_the_old_goal_and_plan_when_there_is_no_path():
    """The planner's set_goal on a corridor the lidar has seen closed at x = 10 m: a goal behind the
    wall, off the map or on an occupied cell is refused (goal, plan and replans as they were, no
    `no_path`: the run goes on); one in front of it is planned to from the given pose."""
    from cosim.navigation.planner import PlannerComponent, Replanning
    from cosim.scenario.load import PlannerSettings
    from planner.grid import OccupancyGrid

    occupied = np.zeros((10, 40), dtype=bool)
    occupied[[0, -1], :] = True  # a 4 m wide corridor (rows 1..8) along x, 20 m long
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    angles = np.linspace(-math.pi / 3, math.pi / 3, 61)
    planner = PlannerComponent(
        "planner",
        grid,
        (2.0, 2.5, 0.0),
        (5.0, 2.5),
        PlannerSettings(expansion_distance=0.5, smoothing="none"),
        replanning=Replanning(angles, 0.0, 30.0, vehicle_radius=0.5),
    )
    planner.plan_path()
    planner.on_setup(0.0, {})
    ranges = np.where(np.abs(np.tan(angles) * 8.0) < 2.6, 8.0 / np.cos(angles), np.nan)
    planner.costmap.integrate(2.0, 2.5, 0.0, ranges)  # the wall across the corridor at x = 10 m
    waypoints, version = planner.waypoints.copy(), planner.plan_version
    for goal, why in (((15.0, 2.5), "no path"), ((25.0, 2.5), "outside"), ((10.0, 2.5), "on an occupied")):
        assert planner.set_goal(*goal, 1.0, (2.0, 2.5, 0.0)).startswith(why)
        assert planner.goal == (5.0, 2.5) and planner.no_path is None and planner.replans == []
        np.testing.assert_array_equal(planner.waypoints, waypoints)
        assert planner.plan_version == version
    assert planner.set_goal(8.0, 3.0, 2.0, (3.0, 2.5, 0.0)) is None
    assert planner.goal == (8.0, 3.0) and planner.plan_version == version + 1
    assert tuple(planner.waypoints[-1]) == (8.0, 3.0)
    assert math.dist(planner.waypoints[0], (3.0, 2.5)) <= 0.5 * math.sqrt(0.5)  # from the pose's cell
    assert [(replan.time, replan.reason) for replan in planner.replans] == [(2.0, "new_goal")]
    np.testing.assert_array_equal(
        planner.output_buffer[: 2 * len(planner.waypoints)], planner.waypoints.ravel()
    )


def test_decode_goal_pose_takes_a_cdr_pose_stamped_in_map_only():
    from cosim.record.live import decode_goal_pose

    schema = "geometry_msgs/msg/PoseStamped"
    assert decode_goal_pose("cdr", schema, _pose_stamped_cdr(12.5, -3.25)) == (12.5, -3.25)
    assert decode_goal_pose("cdr", schema, _pose_stamped_cdr(1.0, 2.0, frame_id="")) == (1.0, 2.0)
    for encoding, name, data, why in (
        ("cdr", schema, _pose_stamped_cdr(1.0, 2.0, frame_id="odom"), "frame_id 'odom'"),
        ("json", schema, b"{}", "expected encoding cdr"),
        ("cdr", "geometry_msgs/msg/Pose", b"", "expected encoding cdr"),
        ("cdr", schema, _pose_stamped_cdr(1.0, 2.0)[:20], "not a CDR PoseStamped"),
    ):
        with pytest.raises(ValueError, match=why):
            decode_goal_pose(encoding, name, data)
