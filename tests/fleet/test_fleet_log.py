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
