"""Each robot the navigation template under its name; the links by which robots see each other."""

from __future__ import annotations

from pathlib import Path

from cosim.cli import main
from cosim.scenario.compose import describe_system
from cosim.scenario.fleet_compose import describe_fleet
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_every_robot_is_the_template_and_sees_the_others():
    fleet = load_scenario(
        SCENARIOS / "fleet_intersection.toml", ["robots.robot3.vfh.safety_distance=0.45"], fleet=True
    )
    described = describe_fleet(fleet)
    single = describe_system(fleet.robots[0].scenario)
    flat = described.flat()
    names = [f"{robot.name}.{name}" for robot in fleet.robots for name in single.components]
    assert list(flat.components) == names
    assert flat.components["robot3.vfh"].parameters["safety_distance"] == 0.45
    assert flat.components["robot1.vfh"].parameters["safety_distance"] == 0.3
    # A section the robot gives for itself is named where the component is declared.
    assert flat.components["robot3.vfh"].where == "[vfh] + [[robots]][2].vfh"
    assert flat.components["robot1.vfh"].where == "[vfh]"
    # Each robot's lidar sees the three others, in fleet order, fed by their vehicles' x and y.
    assert described.seen["robot2"] == ("robot1", "robot3", "robot4")
    feeds = {c.target: c.source for c in described.links}
    assert len(described.links) == 4 * 3 * 2
    assert feeds["robot2.lidar.robots_x[3]"] == "robot4.vehicle.x"
    assert feeds["robot2.lidar.robots_y[1]"] == "robot1.vehicle.y"
    lidar = described.robots["robot2"].components["lidar"]
    assert lidar.robot_radii == (0.5, 0.5, 0.5)
    assert lidar.inputs[3:] == (
        *(f"robots_x[{j}]" for j in (1, 2, 3)),
        *(f"robots_y[{j}]" for j in (1, 2, 3)),
    )
    # Every connection end in the flat system names a component of it.
    for connection in flat.connections:
        for end in (connection.source, connection.target):
            robot, component, _ = end.split(".", 2)
            assert f"{robot}.{component}" in flat.components
    assert len(flat.connections) == 4 * len(single.connections) + len(described.links)


def test_cosim_system_groups_the_robots(capsys):
    assert main(["system", str(SCENARIOS / "fleet_head_on.toml")]) == 0
    text = capsys.readouterr().out
    assert "robot1.vehicle" in text and "robot2.lidar" in text
    assert "robot2.vehicle.x" in text and "robot1.lidar.robots_x[1]" in text
    assert "robots (2; coordination none, on_collision stop, deadlock_after 30 s)" in text
    rows = [line.split() for line in text.splitlines()]
    assert ["robot2", "(35,", "19,", "3.14159)", "(12,", "19)", "r", "0.5", "m", "robot1"] in rows


def test_the_fleet_is_one_system_with_every_lidar_before_any_vehicle():
    from cosim.navigation.build import build_run
    from cosim.navigation.fleet import fleet_system

    fleet = load_scenario(SCENARIOS / "fleet_intersection.toml", fleet=True)
    described = describe_fleet(fleet)
    builts = [build_run(robot.scenario, described.robots[robot.name]) for robot in fleet.robots]
    system, parameters = fleet_system(fleet, described, builts)
    names = [component.name for component in system.order()]
    assert sorted(names) == sorted(name.replace(".", ":", 1) for name in described.flat().components)
    lidars = [names.index(f"{robot.name}:lidar") for robot in fleet.robots]
    vehicles = [names.index(f"{robot.name}:vehicle") for robot in fleet.robots]
    assert max(lidars) < min(vehicles)  # each scan at t sees every robot's pose at t
    links = {(c.source, c.target) for c in system.connections}
    assert ("robot4:vehicle.x", "robot2:lidar.robots_x[3]") in links
    assert set(parameters) == {name for name in names if not name.endswith((":lidar", ":planner"))}
