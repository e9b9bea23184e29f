"""A fleet run: the head-on robots' collision report against geometry computed here; the fleet
outcome; the deadlock rule."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.navigation.fleet import PROGRESS, Progress, run_fleet
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _bisect_contact(a0, a1, b0, b1, reach, t0, h):
    """The time in [t0, t0 + h] at which the linearly interpolated centres are `reach` apart,
    by bisection on the distance (a second method to the quadratic's root)."""
    low, high = 0.0, 1.0
    for _ in range(200):
        mid = 0.5 * (low + high)
        a, b = a0 + mid * (a1 - a0), b0 + mid * (b1 - b0)
        if math.hypot(*(b - a)) > reach:
            low = mid
        else:
            high = mid
    return t0 + high * h, a0 + high * (a1 - a0), b0 + high * (b1 - b0)


def test_head_on_robots_collide_and_the_report_matches_the_geometry():
    fleet = load_scenario(SCENARIOS / "fleet_head_on.toml", fleet=True)
    trace: list = []
    outcome = run_fleet(fleet, trace)
    (contact,) = outcome.collisions  # on_collision = "stop": the run ends at the first contact
    assert outcome.reason == "collision" and outcome.exit_code == 1
    assert (contact.first, contact.second) == ("robot1", "robot2")
    radii = [robot.scenario.vehicle_radius for robot in fleet.robots]
    assert (contact.first_radius, contact.second_radius) == tuple(radii)
    reach = sum(radii)
    times = np.array([t for t, _ in trace])
    positions = np.array([p for _, p in trace])  # steps x robots x 2
    gaps = np.hypot(*(positions[:, 1] - positions[:, 0]).T)
    # The step in which the footprints first touch: the first step whose end is within reach, or
    # (grazing) one whose segment comes within reach; none before it does.
    k = int(np.flatnonzero(gaps <= reach)[0])
    samples = np.linspace(0.0, 1.0, 101)
    for step in range(k - 1, k):  # the step before could have touched within it and separated
        a0, a1, b0, b1 = (
            positions[step, 0],
            positions[step + 1, 0],
            positions[step, 1],
            positions[step + 1, 1],
        )
        within = np.hypot(*((b0 - a0) + samples[:, None] * ((b1 - b0) - (a1 - a0))).T)
        if within.min() <= reach:
            k = step + 1
    assert gaps[:k].min() > reach
    time, at_a, at_b = _bisect_contact(
        positions[k - 1, 0],
        positions[k, 0],
        positions[k - 1, 1],
        positions[k, 1],
        reach,
        times[k - 1],
        times[k] - times[k - 1],
    )
    assert contact.time == pytest.approx(time, abs=1e-9)
    assert contact.first_center == pytest.approx(tuple(at_a), abs=1e-9)
    assert contact.second_center == pytest.approx(tuple(at_b), abs=1e-9)
    assert math.dist(contact.first_center, contact.second_center) == pytest.approx(reach, abs=1e-9)
    # They met between their starts, both having swerved off the aisle's centre line (y = 19):
    # each saw the other (a wall-free straight aisle gives no reason to swerve).
    assert 12.0 < contact.first_center[0] < contact.second_center[0] < 35.0
    assert abs(contact.first_center[1] - 19.0) > 0.05 and abs(contact.second_center[1] - 19.0) > 0.05
    assert outcome.time == pytest.approx(times[k])
    for robot in outcome.robots:
        assert robot.min_clearance_robots <= 0.0 and robot.status != "completed"


def test_robots_completing_make_the_fleet_complete():
    # Two robots in different aisles, far apart: both reach their goals.
    fleet = load_scenario(
        SCENARIOS / "fleet_head_on.toml",
        fleet=True,
        overrides=[
            "robots.robot2.start={x=12.0,y=30.0,theta=0.0}",
            "robots.robot2.goal={x=30.0,y=30.0}",
            "robots.robot1.goal={x=30.0,y=19.0}",
        ],
    )
    outcome = run_fleet(fleet)
    assert outcome.reason == "completed" and outcome.exit_code == 0 and not outcome.collisions
    assert outcome.makespan == max(robot.completion_time for robot in outcome.robots)
    for robot in outcome.robots:
        assert robot.goals_reached == 1 and robot.status == "completed"
        assert 17.0 < robot.distance < 20.0  # about the 18 m straight line, less the 1 m tolerance
        assert 2.0 < robot.min_clearance_robots < 11.0 - 1.0 + 1e-9  # the aisles' centres are 11 m apart
    assert outcome.throughput == pytest.approx(2 * 3600.0 / outcome.time)


def test_deadlock_rule():
    progress = Progress(deadlock_after=5.0, t=0.0, remaining=10.0)
    assert progress.update(1.0, 9.6) is None  # 0.4 m closer: not progress
    assert progress.update(4.99, 9.0) is None  # progress at 4.99 s
    assert progress.update(9.98, 8.6) is None
    assert progress.update(9.99, 8.6) == 4.99  # 5 s without coming PROGRESS closer than 9.0
    assert progress.update(12.0, 9.0 - PROGRESS - 0.01) is None  # progress again: no longer
    progress.restart(20.0, 3.0)
    assert progress.update(24.0, 3.0) is None and progress.update(25.0, 3.0) == 20.0


def test_cosim_run_prints_the_fleet_and_exits_1_without_completion(capsys):
    assert main(["run", str(SCENARIOS / "fleet_head_on.toml"), "--no-plot"]) == 1
    text = capsys.readouterr().out
    assert "robot1 and robot2 collide at t = " in text and "fleet: collision" in text


def test_the_log_holds_one_tf_tree_under_map_and_namespaced_odometry(tmp_path):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)  # rosbags' own message definitions
    fleet = load_scenario(SCENARIOS / "fleet_head_on.toml", fleet=True)
    trace: list = []
    log = tmp_path / "fleet.mcap"
    outcome = run_fleet(fleet, trace, log_path=log)
    positions = {round(t * 1e9): p for t, p in trace}
    parents: dict[str, str] = {}
    odometry = {"robot1": 0, "robot2": 0}
    odometry_topics = [f"/{name}/odom" for name in odometry]
    scans = []
    headings: dict[int, float] = {}
    with open(log, "rb") as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(
            topics=["/robot1/scan", "/tf", *odometry_topics]
        ):
            data = store.deserialize_cdr(message.data, schema.name)
            if channel.topic == "/robot1/scan":
                assert data.header.frame_id == "robot1/base_link"
                scans.append((message.log_time, data))
            if channel.topic == "/tf":
                for transform in data.transforms:
                    parents[transform.child_frame_id] = transform.header.frame_id
                    if transform.child_frame_id == "robot1/base_link":
                        q = transform.transform.rotation
                        headings[message.log_time] = 2 * math.atan2(q.z, q.w)
            elif channel.topic.endswith("/odom"):
                name = channel.topic.split("/")[1]
                assert data.header.frame_id == f"{name}/odom" and data.child_frame_id == f"{name}/base_link"
                expected = positions[message.log_time][int(name[-1]) - 1]
                assert (data.pose.pose.position.x, data.pose.pose.position.y) == pytest.approx(
                    tuple(expected)
                )
                odometry[name] += 1
        (metadata,) = [m for m in reader.iter_metadata() if m.name == "fleet_outcome"]
    assert parents == {
        "robot1/odom": "map", "robot1/base_link": "robot1/odom",
        "robot2/odom": "map", "robot2/base_link": "robot2/odom",
    }  # fmt: skip
    # 50 Hz from t = 0 to the end of the run (a last pose at the end).
    assert odometry["robot1"] == odometry["robot2"] == math.floor(outcome.time * 50 + 1e-9) + 1
    # Robot 1's scans see robot 2's footprint where the trace puts it at the scan's time: along
    # each beam that meets the circle (centre at distance d, bearing off the beam a, radius r) the
    # range is d cos a - sqrt(r^2 - d^2 sin^2 a); nothing stands between them in the aisle.
    seen = 0
    for stamp, scan in scans:
        (x1, y1), (x2, y2) = positions[stamp]
        d = math.hypot(x2 - x1, y2 - y1)
        if d > 19.0:
            continue
        heading = math.atan2(y2 - y1, x2 - x1)
        ranges = np.asarray(scan.ranges, dtype=float)
        angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
        for angle, measured in zip(angles, ranges, strict=True):
            # The beam's angle in the map frame needs robot 1's heading at the scan: from /tf.
            world = angle + headings[stamp]
            a = math.remainder(heading - world, math.tau)
            if abs(d * math.sin(a)) < 0.4 and abs(a) < math.pi / 2:  # off the edge: float32 angles
                expected = d * math.cos(a) - math.sqrt(0.25 - (d * math.sin(a)) ** 2)
                assert measured == pytest.approx(expected, abs=1e-4)
                seen += 1
    assert seen > 20
    import json

    (collision,) = json.loads(metadata.metadata["collisions"])
    assert collision["robots"] == ["robot1", "robot2"] and collision["time"] == outcome.collisions[0].time


def test_a_mission_visits_its_goals_in_order_and_dwells():
    from cosim.scenario.load import parse_scenario

    text = (SCENARIOS / "fleet_head_on.toml").read_text()
    text = text.replace(
        "goal = { x = 35.0, y = 19.0, tolerance = 1.0 }",
        "mission = [{ x = 25.0, y = 19.0, dwell = 3.0 }, { x = 40.0, y = 19.0 }]",
    )
    text = text.replace(
        "start = { x = 35.0, y = 19.0, theta = 3.141592653589793 }", "start = { x = 12.0, y = 30.0 }"
    )
    text = text.replace("goal = { x = 12.0, y = 19.0, tolerance = 1.0 }", "goal = { x = 30.0, y = 30.0 }")
    fleet = parse_scenario(text, "mission.toml", SCENARIOS)
    trace: list = []
    outcome = run_fleet(fleet, trace)
    robot1 = outcome.robots[0]
    assert outcome.reason == "completed" and (robot1.goals_reached, robot1.goals) == (2, 2)
    times = np.array([t for t, _ in trace])
    path = np.array([p[0] for _, p in trace])
    # Reached when first within the 1 m tolerance of (25, 19); then it stays put for 3 s.
    first = int(np.flatnonzero(np.hypot(path[:, 0] - 25.0, path[:, 1] - 19.0) <= 1.0)[0])
    dwell = (times >= times[first]) & (times <= times[first] + 3.0 - 1e-9)
    stopping = (times >= times[first] + 1.0) & dwell  # after a second to brake (1.5 m/s)
    assert np.ptp(path[stopping, 0]) < 0.05 and np.ptp(path[stopping, 1]) < 0.05
    second = int(np.flatnonzero(np.hypot(path[:, 0] - 40.0, path[:, 1] - 19.0) <= 1.0)[0])
    assert robot1.completion_time == pytest.approx(times[second])
    assert times[second] > times[first] + 3.0 + (40.0 - 25.0 - 2.0) / 1.5  # dwell, then >= 13 m at 1.5 m/s


def _contact_events(trace, names, reach):
    """Every contact's beginning, found from the positions alone: a step in which a pair, apart
    at its start (or after having separated), comes within `reach`; its time by bisection."""
    times = [t for t, _ in trace]
    positions = [p for _, p in trace]
    samples = np.linspace(0.0, 1.0, 201)
    events = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            touching = math.dist(positions[0][i], positions[0][j]) <= reach
            for k in range(len(trace) - 1):
                a0, a1, b0, b1 = positions[k][i], positions[k + 1][i], positions[k][j], positions[k + 1][j]
                gaps = np.hypot(*((b0 - a0) + samples[:, None] * ((b1 - b0) - (a1 - a0))).T)
                if not touching and gaps.min() <= reach:
                    time, _, _ = _bisect_contact(a0, a1, b0, b1, reach, times[k], times[k + 1] - times[k])
                    events.append((names[i], names[j], time))
                touching = gaps[-1] <= reach
    return sorted(events, key=lambda event: event[2])


def test_every_contact_at_the_intersection_is_reported_once_at_its_time():
    fleet = load_scenario(SCENARIOS / "fleet_intersection.toml", ["simulation.stop_time=12"], fleet=True)
    assert fleet.settings.on_collision == "continue"
    trace: list = []
    outcome = run_fleet(fleet, trace)
    names = [robot.name for robot in fleet.robots]
    expected = _contact_events(trace, names, 1.0)
    assert len(expected) >= 2  # robots planning alone do meet there
    reported = [(c.first, c.second, c.time) for c in outcome.collisions]
    assert [event[:2] for event in reported] == [event[:2] for event in expected]
    for (_, _, got), (_, _, time) in zip(reported, expected, strict=True):
        assert got == pytest.approx(time, abs=1e-9)


def test_a_fleet_of_one_is_the_single_robot_run(tmp_path):
    # The one_obstacle scenario as a fleet of one robot: the same system, stepped in blocks by
    # the fleet run instead of the robot run, must reach the goal at the same step, having
    # driven the same distance with the same least clearance.
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import parse_scenario

    path = SCENARIOS / "warehouse_diff_drive_one_obstacle.toml"
    single = run_scenario(load_scenario(path), tmp_path / "single.mcap").outcome
    text = path.read_text()
    robot = '[[robots]]\nname = "solo"\nstart = { x = 6.0, y = 6.0 }\ngoal = { x = 84.0, y = 53.0 }\n'
    text = text[: text.index("\n[start]")] + "\n" + robot + text[text.index("\n[planner]") :]
    outcome = run_fleet(parse_scenario(text, "solo.toml", SCENARIOS))
    (solo,) = outcome.robots
    assert single.reached and solo.status == "completed"
    assert solo.completion_time == single.time
    assert solo.distance == pytest.approx(single.distance, rel=1e-12)
    assert solo.min_clearance_walls == single.min_clearance
