"""Scenario loading, overrides, the true world's distance and the outcome logic, against independent truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import CosimError
from cosim.navigation.outcome import OutcomeMonitor
from cosim.navigation.planner import downsample_path
from cosim.scenario.compose import describe_system
from cosim.scenario.load import load_scenario, parse_scenario
from cosim.world.distance import WorldDistance, distance_to_obstacle
from cosim.world.shapes import Circle, Polygon, Rectangle
from planner.grid import OccupancyGrid

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "scenarios" / "example_commented.toml"
MINIMAL = """
[scenario]
name = "minimal"
[map]
file = "maps/warehouse.yaml"
[start]
x = 6.0
y = 6.0
[goal]
x = 20.0
y = 6.0
[vehicle]
fmu = "DifferentialDrive"
"""


def test_example_loads_with_its_documented_values():
    scenario = load_scenario(EXAMPLE)
    assert scenario.name == "example_commented"
    assert scenario.start == (6.0, 6.0, 0.0) and scenario.goal == (84.0, 53.0)
    assert scenario.vehicle_type == "differential"
    vfh = scenario.components["vfh"].parameters
    # MATLAB-style pairs are split into the FMU's scalar parameters (Table 4.2).
    assert (vfh["distance_limit_min"], vfh["distance_limit_max"]) == (3.5, 20.0)
    assert vfh["robot_radius"] == 0.5 and vfh["min_turning_radius"] == 1.3
    assert len(scenario.lidar.angles) == 360
    # A full turn does not repeat -pi: spacing is exactly 2 pi / count.
    assert np.allclose(np.diff(scenario.lidar.angles), 2 * math.pi / 360)
    assert isinstance(scenario.obstacles[0], Rectangle)


def test_defaults_of_a_minimal_scenario():
    scenario = parse_scenario(MINIMAL, "minimal.toml", REPO / "scenarios")
    assert scenario.macro_step == 0.01 and scenario.stop_time == 300.0
    assert scenario.master == "gauss-seidel" and scenario.controller_rate == 20.0
    assert scenario.lidar.rate == 10.0 and scenario.lidar.range_max == 20.0
    assert scenario.components["vehicle"].rate is None  # every macro step
    assert scenario.components["vfh"].rate == 20.0
    assert scenario.vehicle_radius == 0.5
    assert scenario.planner.expansion_distance == scenario.vehicle_radius
    assert scenario.log_pattern == "logs/{scenario}-{timestamp}.mcap"


def test_overrides_use_toml_values_and_the_same_validation():
    scenario = load_scenario(
        EXAMPLE, ["vfh.robot_radius=0.6", "simulation.master=jacobi", "obstacles.0.yaw=0.5"]
    )
    assert scenario.components["vfh"].parameters["robot_radius"] == 0.6
    assert scenario.master == "jacobi"  # a bare word is a string
    assert scenario.obstacles[0].yaw == 0.5
    # The range is the FMU's (its modelDescription.xml), checked when the system is described.
    with pytest.raises(CosimError, match=r"\[vfh\]\.robot_radius: must be >= 0, got -1"):
        describe_system(load_scenario(EXAMPLE, ["vfh.robot_radius=-1"]))
    with pytest.raises(CosimError, match="expected key=value"):
        load_scenario(EXAMPLE, ["vfh.robot_radius"])
    with pytest.raises(CosimError, match="no item 5 in obstacles"):
        load_scenario(EXAMPLE, ["obstacles.5.yaw=1"])


def test_explicit_lidar_angles_and_ports_with_scale():
    text = MINIMAL + "[lidar]\nangles = [-0.7853981633974483, 0.0, 0.7853981633974483]\nrange = [0.0, 10.0]\n"
    text = text.replace(
        'fmu = "DifferentialDrive"',
        'fmu = "DifferentialDrive"\nports = { v = "speed", omega = { name = "turn", scale = -1.0 } }',
    )
    scenario = parse_scenario(text, "t.toml", REPO / "scenarios")
    assert np.allclose(scenario.lidar.angles, [-math.pi / 4, 0, math.pi / 4])
    ports = scenario.components["vehicle"].ports
    assert ports["v"].variable == "speed" and ports["v"].scale == 1.0
    assert ports["omega"].variable == "turn" and ports["omega"].scale == -1.0


def _brute_force_distance(grid: OccupancyGrid, obstacles, x: float, y: float) -> float:
    """Distance by dense sampling of every obstacle's boundary (a different method)."""
    best = math.inf
    half = grid.resolution / 2
    for cx, cy in grid.cells_to_world(np.argwhere(grid.occupied)):
        if abs(x - cx) <= half and abs(y - cy) <= half:
            return 0.0
        # The square's boundary, sampled every 1 mm.
        t = np.linspace(-half, half, round(2 * half / 0.001) + 1)
        edges = np.concatenate([np.column_stack((t, np.full_like(t, side))) for side in (-half, half)])
        edges = np.concatenate((edges, edges[:, ::-1])) + (cx, cy)
        best = min(best, float(np.min(np.hypot(edges[:, 0] - x, edges[:, 1] - y))))
    for obstacle in obstacles:
        outline = obstacle.polygon(2000) if isinstance(obstacle, Circle) else obstacle.polygon()
        closed = np.vstack((outline, outline[:1]))
        t = np.linspace(0.0, 1.0, 10 if isinstance(obstacle, Circle) else 2001)[:, None, None]
        points = (closed[:-1] + t * (closed[1:] - closed[:-1])).reshape(-1, 2)
        best = min(best, float(np.min(np.hypot(points[:, 0] - x, points[:, 1] - y))))
    return best


def test_world_distance_is_exact_against_brute_force():
    occupied = np.zeros((20, 30), dtype=bool)
    occupied[5:8, 10:12] = True
    occupied[15, 3] = True
    grid = OccupancyGrid(occupied, resolution=0.5, origin=(1.0, -2.0))
    obstacles = (Circle((9.0, 4.0), 0.7), Rectangle((4.0, 0.0), (1.0, 2.0), 0.3))
    world = WorldDistance(grid, obstacles)
    rng = np.random.default_rng(1)
    for x, y in rng.uniform((1.5, -1.5), (15.5, 7.5), size=(60, 2)):
        exact = world.distance(x, y)
        edge = min(x - 1.0, 16.0 - x, y + 2.0, 8.0 - y)
        expected = min(_brute_force_distance(grid, obstacles, x, y), edge)
        if world_inside := any(distance_to_obstacle(x, y, o) == 0 for o in obstacles):
            assert exact == 0.0
        else:
            assert exact == pytest.approx(expected, abs=2e-3), (x, y)
        assert world.lower_bound(x, y) <= exact + 1e-12
        assert world_inside or exact >= 0
    assert world.distance(0.0, 0.0) == 0.0  # off the map counts as an obstacle


def test_polygon_distance_and_inside():
    square = Polygon(((0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)))
    assert distance_to_obstacle(1.0, 1.0, square) == 0.0
    assert distance_to_obstacle(5.0, 1.0, square) == pytest.approx(3.0)
    assert distance_to_obstacle(5.0, 6.0, square) == pytest.approx(5.0)  # 3-4-5 to the corner


def test_downsample_keeps_ends_and_capacity():
    path = np.column_stack((np.linspace(0, 100, 5000), np.zeros(5000)))
    reduced = downsample_path(path, 1000)
    assert len(reduced) <= 1000
    assert np.array_equal(reduced[0], path[0]) and np.array_equal(reduced[-1], path[-1])
    assert np.max(np.diff(reduced[:, 0])) < 0.2  # evenly spread along the path
    assert downsample_path(path[:10], 1000) is not None and len(downsample_path(path[:10], 1000)) == 10


def test_outcome_monitor_goal_collision_and_interventions():
    grid = OccupancyGrid(np.zeros((40, 40), dtype=bool), resolution=0.5)
    world = WorldDistance(grid, (Circle((10.0, 10.0), 1.0),))
    monitor = OutcomeMonitor(world, goal=(15.0, 10.0), tolerance=0.5, radius=0.5, start_xy=(2.0, 10.0))
    assert monitor.check_position(1.0, 5.0, 10.0) is None
    assert monitor.outcome.distance == pytest.approx(3.0)
    # Clearance = distance to the circle minus the robot radius: 10 - 1 - 7.0 - 0.5.
    assert monitor.check_position(2.0, 7.0, 10.0) is None
    assert monitor.outcome.min_clearance == pytest.approx(1.5)
    for mode in (0, 1, 1, 0, 1, 2, 2):
        monitor.check_mode(mode, 0.05)
    assert monitor.outcome.vfh_interventions == 2
    assert monitor.outcome.recovery_time == pytest.approx(0.1)
    assert monitor.check_position(3.0, 8.6, 10.0) == "collision"  # 0.4 m from the circle < 0.5
    other = OutcomeMonitor(world, goal=(15.0, 10.0), tolerance=0.5, radius=0.5, start_xy=(14.0, 5.0))
    assert other.check_position(1.0, 14.7, 10.2) == "goal_reached"


@pytest.mark.parametrize(
    ("angle_min", "angle_max", "count"),
    [(-math.pi, math.pi, 8), (-math.pi / 2, math.pi / 2, 5), (-1.0, 1.0, 1), (0.0, math.pi, 2)],
)
def test_lidar_keys_give_the_same_beams_as_the_lidar_component(angle_min, angle_max, count):
    from cosim.world.lidar import Lidar

    text = MINIMAL + f"[lidar]\nangle_min = {angle_min!r}\nangle_max = {angle_max!r}\ncount = {count}\n"
    scenario = parse_scenario(text, "beams.toml", REPO / "scenarios")
    component = Lidar(angle_min=angle_min, angle_max=angle_max, count=count).beam_angles
    np.testing.assert_array_equal(np.asarray(scenario.lidar.angles), component)
    # Both ends are beams, except that a full turn leaves out its end (the start's own direction).
    full_turn = angle_max - angle_min >= 2 * math.pi - 1e-9
    expected_step = (angle_max - angle_min) / (count if full_turn else max(count - 1, 1))
    assert component[0] == angle_min
    if count > 1:
        np.testing.assert_allclose(np.diff(component), expected_step)
