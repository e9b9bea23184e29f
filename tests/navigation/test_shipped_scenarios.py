"""Every shipped scenario reaches its goal without a collision, and its unknown obstacles make VFH act.

Reduced settings: a 0.05 s macro step (the full runs use 0.01 s; the controllers run at 20 Hz in
both, so only the vehicle's integration is coarser) and /odom at 20 Hz. The outcomes were checked
to be the same as at full settings (the benchmark times the full runs). The run's own verdict is
cross-checked against the log with geometry written here: the last pose is within the goal
tolerance, and no recorded pose brings the footprint circle into an unknown obstacle.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
SHIPPED = sorted(
    p for p in SCENARIOS.glob("*.toml") if not p.name.startswith("fleet_")
)  # fleets: tests/fleet
REDUCED = ["simulation.macro_step=0.05", "output.pose_rate=20"]


def distance_to_polygon(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Distance [m] of each point (N x 2) to a closed polygon's boundary, 0 inside it."""
    starts, ends = vertices, np.roll(vertices, -1, axis=0)
    edge = ends - starts  # (M, 2)
    relative = points[:, None, :] - starts[None, :, :]  # (N, M, 2)
    fraction = np.clip((relative * edge).sum(-1) / (edge * edge).sum(-1), 0.0, 1.0)
    nearest = starts[None] + fraction[..., None] * edge[None]
    distance = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)).min(axis=1)
    # Inside by the crossing rule: a horizontal ray to +x crosses the boundary an odd number of times.
    y, x = points[:, 1:2], points[:, 0:1]
    straddles = (starts[None, :, 1] > y) != (ends[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing_x = starts[None, :, 0] + (y - starts[None, :, 1]) * edge[None, :, 0] / edge[None, :, 1]
    inside = (straddles & (x < crossing_x)).sum(axis=1) % 2 == 1
    return np.where(inside, 0.0, distance)


def densify(path: np.ndarray, spacing: float = 0.05) -> np.ndarray:
    """Points every `spacing` metres along a polyline (N x 2)."""
    pieces = [path[:1]]
    for start, end in zip(path[:-1], path[1:], strict=True):
        count = max(1, math.ceil(np.hypot(*(end - start)) / spacing))
        pieces.append(start + np.linspace(0.0, 1.0, count + 1)[1:, None] * (end - start))
    return np.concatenate(pieces)


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenario_reaches_goal(path: Path, tmp_path: Path):
    scenario = dataclasses.replace(load_scenario(path, REDUCED), plot=False)
    result = run_scenario(scenario, tmp_path / "run.mcap")
    outcome = result.outcome
    assert outcome.reason == "goal_reached", (path.name, outcome)
    assert result.exit_code == 0
    assert outcome.min_clearance > 0.0

    log = open_log(tmp_path / "run.mcap")
    assert log.outcome["reason"] == "goal_reached"
    trajectory = log.trajectory()
    final = np.array([trajectory.x[-1], trajectory.y[-1]])
    # /odom is sampled at 20 Hz: the last sample may trail the stopping pose by one period.
    speed_bound = 7.5 * 0.05
    assert np.hypot(*(final - scenario.goal[:2])) <= scenario.goal_tolerance + speed_bound

    poses = np.column_stack([trajectory.x, trajectory.y])
    # The first plan (made on the known map before the run; replans may avoid the obstacles).
    first = next(iter(log.messages("/plan"))).message
    plan = np.array([(pose.pose.position.x, pose.pose.position.y) for pose in first.poses])
    for obstacle in scenario.obstacles:
        if obstacle.motion is not None:
            continue  # tests/navigation/test_replanning.py checks the moving ones against their trajectories
        vertices = np.asarray(obstacle.polygon(), dtype=float)
        # The footprint circle never reaches into the obstacle ...
        assert distance_to_polygon(poses, vertices).min() > scenario.vehicle_radius - 0.02, obstacle
        # ... which stands ON the planned path: following the plan blindly would collide.
        assert distance_to_polygon(densify(plan), vertices).min() < scenario.vehicle_radius, obstacle
    if scenario.obstacles:
        assert outcome.vfh_interventions > 0


def test_polygon_distance_against_a_unit_square():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    points = np.array([[0.5, 0.5], [2.0, 0.5], [2.0, 2.0], [-0.5, 0.2]])
    assert distance_to_polygon(points, square) == pytest.approx([0.0, 1.0, math.sqrt(2.0), 0.5])


BICYCLES = [path for path in SHIPPED if path.stem.startswith("warehouse_bicycle")]


@pytest.mark.parametrize("path", BICYCLES, ids=[p.stem for p in BICYCLES])
def test_bicycle_scenarios_keep_the_thesis_tables(path: Path):
    """Tables 4.3-4.5: the values the thesis ran with stay in the shipped bicycle scenarios."""
    scenario = load_scenario(path)
    pure_pursuit = scenario.components["pure_pursuit"].parameters
    vfh = scenario.components["vfh"].parameters
    vehicle = scenario.components["vehicle"].parameters
    assert (pure_pursuit["desired_linear_velocity"], pure_pursuit["max_angular_velocity"]) == (7.0, 2.0)
    assert pure_pursuit["lookahead_distance"] == 5.0
    assert (vfh["distance_limit_min"], vfh["distance_limit_max"]) == (3.5, 20.0)
    assert (vfh["robot_radius"], vfh["safety_distance"], vfh["min_turning_radius"]) == (1.5, 0.75, 3.5)
    weights = (
        vfh["target_direction_weight"],
        vfh["current_direction_weight"],
        vfh["previous_direction_weight"],
    )
    assert weights == (5.0, 2.0, 2.0)
    assert vehicle["max_steering_angle"] == pytest.approx(math.pi / 4)
    assert scenario.lidar.angles == pytest.approx([-math.pi / 4, 0.0, math.pi / 4])
    assert scenario.lidar.range_max == 10.0
