"""`[[robots]]` and `[fleet]`: each robot a single-robot scenario under its name."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import CosimError
from cosim.scenario.fleet import Fleet
from cosim.scenario.load import load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
HEAD_ON = SCENARIOS / "fleet_head_on.toml"


def _with_robots(robots: str, fleet: str = "") -> str:
    """fleet_head_on.toml with its [[robots]] (and [fleet]) replaced."""
    text = HEAD_ON.read_text()
    head, _, rest = text.partition("\n[fleet]")
    _, _, tail = rest.partition("# The scenario-wide")
    return f"{head}{fleet}\n{robots}\n# The scenario-wide{tail}"


def _parse(text: str, overrides=()) -> Fleet:
    return parse_scenario(text, "f.toml", SCENARIOS, overrides)


TWO = """
[[robots]]
name = "a"
start = { x = 12.0, y = 19.0 }
goal = { x = 35.0, y = 19.0 }

[[robots]]
name = "b"
start = { x = 35.0, y = 19.0, theta = 3.0 }
mission = [{ x = 12.0, y = 19.0, dwell = 5.0 }, { x = 20.0, y = 6.0, tolerance = 1.5 }]
repeat = 2
vfh = { safety_distance = 0.6 }
"""


def test_each_robot_is_the_scenario_with_its_start_goal_and_sections():
    fleet = _parse(_with_robots(TWO))
    assert [robot.name for robot in fleet.robots] == ["a", "b"]
    a, b = (robot.scenario for robot in fleet.robots)
    assert a.start == (12.0, 19.0, 0.0) and a.goal == (35.0, 19.0)
    assert b.start == (35.0, 19.0, 3.0) and b.goal == (12.0, 19.0)  # the mission's first goal
    # The robot's own key wins; the others come from the scenario-wide [vfh].
    assert a.components["vfh"].parameters["safety_distance"] == 0.3
    assert b.components["vfh"].parameters["safety_distance"] == 0.6
    assert b.components["vfh"].parameters["target_direction_weight"] == 5.0
    mission = fleet.robots[1].mission
    assert [(g.x, g.y, g.tolerance, g.dwell) for g in mission] == [
        (12.0, 19.0, 1.0, 5.0),
        (20.0, 6.0, 1.5, 0.0),
    ]
    assert fleet.robots[1].repeat == 2 and fleet.robots[0].repeat == 1
    assert fleet.settings.coordination == "none" and fleet.settings.on_collision == "stop"


def test_a_robot_with_another_vehicle_fmu_gets_only_its_own_section():
    robots = TWO.replace(
        "vfh = { safety_distance = 0.6 }",
        'vehicle = { fmu = "Bicycle", radius = 0.5, wheelbase = 1.0 }',
    )
    fleet = _parse(_with_robots(robots))
    a, b = (robot.scenario for robot in fleet.robots)
    assert a.vehicle_type == "differential" and b.vehicle_type == "bicycle"
    assert "track_width" not in b.components["vehicle"].parameters
    assert "track_width" in a.components["vehicle"].parameters


def test_set_addresses_a_robot_by_name():
    fleet = _parse(
        _with_robots(TWO), ["robots.a.vfh.safety_distance=0.45", "robots.1.pure_pursuit.lookahead_distance=4"]
    )
    a, b = (robot.scenario for robot in fleet.robots)
    assert a.components["vfh"].parameters["safety_distance"] == 0.45
    assert b.components["pure_pursuit"].parameters["lookahead_distance"] == 4
    with pytest.raises(CosimError, match=r"--set robots\.c\.vfh\.x=1: no robot named 'c'"):
        _parse(_with_robots(TWO), ["robots.c.vfh.x=1"])


@pytest.mark.parametrize(
    ("robots", "fleet", "message"),
    [
        (TWO.replace('name = "b"', 'name = "a"'), "", r"^f\.toml: \[\[robots\]\]\[1\]\.name: 'a' is already"),
        (
            TWO.replace('name = "b"', 'name = "b.c"'),
            "",
            r"^f\.toml: \[\[robots\]\]\[1\]\.name: must be an identifier",
        ),
        (TWO.replace("repeat = 2", "colour = 2"), "", r"^f\.toml: \[\[robots\]\]\[1\]\.colour: unknown key"),
        (
            TWO.replace("dwell = 5.0", "dwell = -1"),
            "",
            r"^f\.toml: \[\[robots\]\]\[1\]\.mission\[0\]\.dwell: must be >= 0",
        ),
        (
            TWO.replace("goal = { x = 35.0, y = 19.0 }", ""),
            "",
            r"^f\.toml: \[\[robots\]\]\[0\]\.goal: give either",
        ),
        # A robot's own section is checked as that section, and the message says which robot.
        (
            TWO.replace("vfh = { safety_distance = 0.6 }", "lidar = { count = 0 }"),
            "",
            r"^f\.toml: \[\[robots\]\]\[1\] \(b\): \[lidar\]\.count: must be >= 1",
        ),
        (
            TWO,
            '[fleet]\non_collision = "bounce"',
            r"^f\.toml: \[fleet\]\.on_collision: must be one of 'stop', 'continue'",
        ),
        (TWO, "[fleet]\ndeadlock_after = 0", r"^f\.toml: \[fleet\]\.deadlock_after: must be > 0"),
        (
            TWO.replace("tolerance = 1.5", "tolerance = 0.5"),
            "",
            r"^f\.toml: \[\[robots\]\]\[1\]\.mission\[1\]\.tolerance: must be >= the first goal's \(1 m\)",
        ),
        (
            TWO,
            '[fleet]\ncoordination = "cbs"',
            r"^f\.toml: \[fleet\]\.coordination: must be one of 'none', 'prioritized', 'mapf'",
        ),
        (
            TWO + "\n[start]\nx = 1\ny = 1\n",
            "",
            r"^f\.toml: \[start\]: a fleet gives each robot its own start",
        ),
        ("", "[fleet]", r"^f\.toml: \[fleet\]: needs at least one \[\[robots\]\] table"),
        # Topics only a single-robot log writes are refused, not silently left out.
        (TWO + "\n[imu]\nrate = 50.0\n", "", r"^f\.toml: \[imu\]: \[imu\] is not recorded for a fleet yet"),
        (TWO + "\n[bumper]\n", "", r"^f\.toml: \[bumper\]: \[bumper\] is not recorded for a fleet yet"),
    ],
)
def test_errors_name_the_file_and_the_key(robots, fleet, message):
    with pytest.raises(CosimError, match=message):
        _parse(_with_robots(robots, fleet))


def test_overlapping_starts_and_goals_in_walls_are_refused(tmp_path):
    text = _with_robots(
        TWO.replace("start = { x = 35.0, y = 19.0, theta = 3.0 }", "start = { x = 12.6, y = 19.0 }")
    )
    path = tmp_path / "f.toml"
    path.write_text(text.replace('"maps/warehouse.yaml"', f'"{SCENARIOS / "maps" / "warehouse.yaml"}"'))
    with pytest.raises(CosimError, match=r"\[\[robots\]\]\[1\]\.start: 'b' starts within 1 m of 'a'"):
        load_scenario(path, fleet=True)
    # The mission's second goal, (20, 13), lies in a rack.
    path.write_text(
        path.read_text().replace("x = 12.6", "x = 35.0").replace("x = 20.0, y = 6.0", "x = 20.0, y = 13.0")
    )
    with pytest.raises(CosimError, match=r"\[\[robots\]\]\[1\] \(b\): \[goal\]: \(20, 13\) is inside"):
        load_scenario(path, fleet=True)


def test_a_scenario_without_robots_is_one_robot():
    scenario = load_scenario(SCENARIOS / "warehouse_diff_drive_one_obstacle.toml")
    assert not isinstance(scenario, Fleet)
    raw = tomllib.loads((SCENARIOS / "warehouse_diff_drive_one_obstacle.toml").read_text())
    assert scenario.start == tuple(raw["start"].values())


def test_what_takes_one_robot_refuses_a_fleet_in_one_line(tmp_path):
    with pytest.raises(
        CosimError, match=r"fleet_head_on\.toml: a fleet \(\[\[robots\]\]\) runs with cosim run"
    ):
        load_scenario(HEAD_ON)
    assert main(["ssp", "export", str(HEAD_ON), "--out", str(tmp_path / "fleet.ssp")]) == 2
    assert not (tmp_path / "fleet.ssp").exists()


def test_shipped_fleet_scenarios_load():
    for path in sorted(SCENARIOS.glob("fleet_*.toml")):
        fleet = load_scenario(path, fleet=True)
        assert isinstance(fleet, Fleet) and len(fleet.robots) >= 2
