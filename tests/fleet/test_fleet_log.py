"""A fleet's log holds what a robot's log holds, per robot under its namespace: its signals, read
back by a second reader, agree with its odometry; a fleet of one records the single-robot run's
signals."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cosim.logs.reader import open_log
from cosim.navigation.fleet import run_fleet
from cosim.scenario.load import load_scenario, parse_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.fixture(scope="module")
def head_on(tmp_path_factory):
    log = tmp_path_factory.mktemp("fleet") / "head_on.mcap"
    fleet = load_scenario(SCENARIOS / "fleet_head_on.toml", fleet=True)
    return fleet, run_fleet(fleet, log_path=log), log


def _read(path: Path, topics: list[str]) -> dict[str, list[tuple[int, object]]]:
    """(log time [ns], message) per topic, decoded by rosbags from each channel's own schema (the
    mcap package reads the file): a reader that shares nothing with navcosim's."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    found: dict[str, list[tuple[int, object]]] = {topic: [] for topic in topics}
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=True):
            if schema.name not in store.fielddefs:
                store.register(
                    get_types_from_msg(schema.data.decode().split("\n" + "=" * 80)[0], schema.name)
                )
            found[channel.topic].append((message.log_time, store.deserialize_cdr(message.data, schema.name)))
    return found


def test_each_robots_vehicle_signals_are_where_its_odometry_puts_it(head_on):
    fleet, outcome, log = head_on
    for robot in fleet.robots:
        name = robot.name
        messages = _read(log, [f"/{name}/signals/vehicle", f"/{name}/odom"])
        signals = dict(messages[f"/{name}/signals/vehicle"])
        odometry = messages[f"/{name}/odom"]
        assert len(odometry) == math.floor(outcome.time * 50 + 1e-9) + 1  # 50 Hz and the end
        # A record at t holds the outputs at t: the pose after the step that ended at t.
        for t_ns, odom in odometry:
            record = signals[t_ns]
            assert (record.x, record.y) == (odom.pose.pose.position.x, odom.pose.pose.position.y)
            q = odom.pose.pose.orientation
            assert math.remainder(record.theta - 2 * math.atan2(q.z, q.w), math.tau) == pytest.approx(
                0, abs=1e-12
            )
        stamps = sorted(signals)
        assert stamps[-1] == round(outcome.time * 1e9)  # the last record: at the end of the run
        assert np.all(np.diff(stamps) == 10_000_000)  # one record per 10 ms step
    with open_log(log) as read:
        assert read.fmus["robot2:vehicle"]["model_name"] == "DifferentialDrive"
        assert read.metadata["navcosim"]["robots"] == "robot1,robot2"
        assert "scenario.toml" in read.attachments and read.outcome["reason"] == "collision"
        assert json.loads(read.metadata["fleet_outcome"]["reason"]) == "collision"
        assert read.signals("robot2:vehicle")["x"][0] == fleet.robots[1].scenario.start[0]


def test_a_fleet_of_one_records_the_single_robot_runs_signals(tmp_path):
    # The one_obstacle scenario as a fleet of one robot: the same system stepped by the fleet run
    # must log, on /solo/signals/<component>, the records the robot run logs on /signals/<component>.
    from cosim.navigation.run import run_scenario

    path = SCENARIOS / "warehouse_diff_drive_one_obstacle.toml"
    run_scenario(load_scenario(path), tmp_path / "single.mcap")
    text = path.read_text()
    robot = '[[robots]]\nname = "solo"\nstart = { x = 6.0, y = 6.0 }\ngoal = { x = 84.0, y = 53.0 }\n'
    text = text[: text.index("\n[start]")] + "\n" + robot + text[text.index("\n[planner]") :]
    run_fleet(parse_scenario(text, "solo.toml", SCENARIOS), log_path=tmp_path / "solo.mcap")
    with open_log(tmp_path / "single.mcap") as single, open_log(tmp_path / "solo.mcap") as solo:
        assert solo.components == [f"solo:{name}" for name in single.components]
        for name in single.components:
            expected, got = single.signals(name), solo.signals(f"solo:{name}")
            assert got.names == expected.names
            np.testing.assert_array_equal(got.t_ns, expected.t_ns)
            np.testing.assert_array_equal(got.values, expected.values)
        last_scan = [
            list(log.messages(topic))[-1] for log, topic in ((single, "/scan"), (solo, "/solo/scan"))
        ]
        assert last_scan[0].t_ns == last_scan[1].t_ns
        np.testing.assert_array_equal(last_scan[0].message.ranges, last_scan[1].message.ranges)


def test_a_robot_that_hits_a_wall_halts_and_stays_an_obstacle_for_the_others(tmp_path):
    # Robot 1 starts with its footprint (r 0.5 m) 0.2 m into the rack whose edge is y = 15 m, so
    # it hits it in its first step; with on_collision = "continue" it is switched off at the end of
    # that block (t = 0.1 s) and stays there, while robot 2 drives past it along the aisle.
    text = (SCENARIOS / "fleet_head_on.toml").read_text()
    text = text.replace('on_collision = "stop"', 'on_collision = "continue"')
    text = text.replace(
        "start = { x = 12.0, y = 19.0, theta = 0.0 }",
        "start = { x = 20.0, y = 15.3, theta = 0.0 }\nplanner = { expansion_distance = 0.1 }",
    )
    fleet = parse_scenario(text.replace("stop_time = 60.0", "stop_time = 20.0"), "wall.toml", SCENARIOS)
    trace: list = []
    log = tmp_path / "fleet.mcap"
    outcome = run_fleet(fleet, trace, log_path=log)
    robot1, robot2 = outcome.robots
    assert robot1.status == "collision" and robot2.status == "completed"
    t_hit, x_hit, y_hit = robot1.collision
    halt = math.floor(t_hit * 10 + 1) / 10  # the end of the block (0.1 s) in which it hit
    times = np.array([t for t, _ in trace])
    positions = np.array([p[0] for _, p in trace])
    assert times[-1] > halt + 10.0
    stays = positions[times >= halt - 1e-9]
    assert np.all(stays == stays[0])
    assert math.dist(stays[0], (x_hit, y_hit)) <= 1.5 * (halt - t_hit) + 1e-9  # at most 1.5 m/s meanwhile
    with open_log(log) as read:
        odometry = read.robot_trajectory("robot1")
        after = odometry.t >= halt - 1e-9
        assert np.all(odometry.x[after] == stays[0][0]) and np.all(odometry.y[after] == stays[0][1])
        assert read.signals("robot1:vehicle").t[-1] <= halt + 0.01 + 1e-9  # not stepped after the halt
        # Robot 2's scans see robot 1's footprint where it stands: along each beam that meets the
        # circle (centre at distance d, bearing off the beam a) the range is d cos a - sqrt(r^2 -
        # d^2 sin^2 a); the rack behind it is farther.
        poses = read.robot_trajectory("robot2")
        at = {round(t * 1e9): pose for t, *pose in zip(poses.t, poses.x, poses.y, poses.theta, strict=True)}
        seen = 0
        for item in read.messages("/robot2/scan"):
            if item.t < halt + 0.05 or item.t_ns not in at:
                continue
            x, y, theta = at[item.t_ns]
            d = math.dist((x, y), stays[0])
            bearing = math.atan2(stays[0][1] - y, stays[0][0] - x)
            scan = item.message
            angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
            for angle, measured in zip(angles, np.asarray(scan.ranges, dtype=float), strict=True):
                a = math.remainder(bearing - (angle + theta), math.tau)
                if abs(d * math.sin(a)) < 0.4 and abs(a) < math.pi / 2 and d < 15.0:
                    assert measured == pytest.approx(
                        d * math.cos(a) - math.sqrt(0.25 - (d * math.sin(a)) ** 2), abs=1e-4
                    )
                    seen += 1
        assert seen > 50


def test_the_pose_templates_give_the_bytes_of_the_serialised_messages():
    # /robotN/odom and /tf are patched into templates; rosbags serialising each message in full
    # must give the same bytes, for any stamp and values (NaN twist, negative angles included).
    from types import SimpleNamespace

    from cosim.record import fleet_steps

    robots = [SimpleNamespace(odom_frame=f"r{n}/odom", base_frame=f"r{n}/base_link") for n in ("1", "22")]
    generator = np.random.default_rng(7)
    odometry = fleet_steps._Template(lambda t, v: fleet_steps._odometry(robots[1], t, v), 6)
    tf = fleet_steps._Template(lambda t, v: fleet_steps._tf(robots, t, v), 8)
    for t_ns in (0, 10_000_000, 1_999_999_999_990, 7_359_000_001):
        values = [*generator.normal(0.0, 30.0, 5), math.nan]
        assert odometry.fill(t_ns, values) == fleet_steps._odometry(robots[1], t_ns, values)
        values = list(generator.normal(0.0, 30.0, 8))
        assert tf.fill(t_ns, values) == fleet_steps._tf(robots, t_ns, values)


def test_steps_collected_over_windows_give_the_bytes_of_blocks_handed_over_one_by_one(tmp_path, monkeypatch):
    # The fleet's steps are collected for up to two chunk windows and handed to the recorder at
    # once, with the plans written meanwhile held between the right steps: the file must be the one
    # of each block handed over as it comes (the steps flushed after every block).
    from cosim.record import fleet_steps

    text = (SCENARIOS / "fleet_head_on.toml").read_text()
    collected = tmp_path / "collected.mcap"
    run_fleet(parse_scenario(text, "head_on.toml", SCENARIOS), log_path=collected)
    block = fleet_steps.FleetSteps.block

    def one_by_one(self, *args, **kwargs):
        block(self, *args, **kwargs)
        self.flush()

    monkeypatch.setattr(fleet_steps.FleetSteps, "block", one_by_one)
    handed = tmp_path / "handed.mcap"
    run_fleet(parse_scenario(text, "head_on.toml", SCENARIOS), log_path=handed)
    assert collected.read_bytes() == handed.read_bytes()
    plans = _read(collected, ["/robot1/plan", "/robot2/plan"])
    assert sum(len(found) for found in plans.values()) > 2  # plans written during the run, not only at t = 0
