"""Replanning on the costmap (known map + lidar returns) and the moving-obstacle scenario, checked
against geometry written here: the wall's polygon, the person's analytic trajectory, ray-circle
intersections. Reduced settings as tests/navigation/test_shipped_scenarios.py."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from test_shipped_scenarios import REDUCED, densify, distance_to_polygon

from cosim.logs import open_log
from cosim.navigation.costmap import Costmap
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from planner.grid import OccupancyGrid

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _run(name: str, tmp_path: Path, *overrides: str):
    scenario = dataclasses.replace(load_scenario(SCENARIOS / name, [*REDUCED, *overrides]), plot=False)
    log = tmp_path / f"run{len(list(tmp_path.glob('run*.mcap')))}.mcap"  # an existing log is refused
    result = run_scenario(scenario, log)
    return scenario, result, open_log(log)


def _plans(log) -> list[np.ndarray]:
    return [
        np.array([(pose.pose.position.x, pose.pose.position.y) for pose in item.message.poses])
        for item in log.messages("/plan")
    ]


def test_blocked_aisle_needs_the_replan(tmp_path: Path):
    """Without replanning the robot does not reach the goal and the run ends at the stop time
    (exit 1) with no collision; with it, it replans (once, when the lidar shows the wall on the
    plan) round another aisle and reaches the goal."""
    scenario, blind, log = _run("warehouse_blocked_aisle.toml", tmp_path, "planner.replan=false")
    assert blind.outcome.reason == "stop_time" and blind.exit_code == 1
    assert blind.outcome.time == pytest.approx(scenario.stop_time)
    assert not blind.outcome.reached and blind.outcome.replans == 0
    assert blind.outcome.min_clearance > 0.0 and blind.outcome.collision_point is None
    # It ends in the thesis's recovery (section 4.3.3): no free VFH direction (NaN), and the mixer
    # turns the robot on the spot, v = 0 and omega = +-recovery_angular_velocity (0.5 rad/s, the
    # FMU's default), so the pose stays put while it turns.
    mixer, vehicle = log.signals("mixer"), log.signals("vehicle")
    blocked = np.isnan(mixer["steering_dir"])
    recovering = mixer["mode"] == 2
    assert blind.outcome.recovery_time > 10.0 and blocked[-1]
    # The logged outputs are those of the step that read the previous sample's inputs.
    assert np.array_equal(recovering[1:], blocked[:-1])
    assert np.all(mixer["v"][recovering] == 0.0)
    assert np.allclose(np.abs(mixer["omega"][recovering]), 0.5)
    last = np.flatnonzero(~blocked)[-1] + 3  # once the final recovery's command has moved the robot
    assert np.ptp(vehicle["x"][last:]) < 1e-9 and np.ptp(vehicle["y"][last:]) < 1e-9
    assert np.ptp(np.unwrap(vehicle["theta"][last:])) > 2 * math.pi  # it keeps turning

    scenario, result, log = _run("warehouse_blocked_aisle.toml", tmp_path)
    wall = np.asarray(scenario.obstacles[0].polygon())
    assert result.outcome.reason == "goal_reached" and result.exit_code == 0
    assert result.outcome.min_clearance > 0.0
    assert result.outcome.replans >= 1 and log.outcome["replans"] == result.outcome.replans
    plans = _plans(log)
    assert len(plans) == 1 + result.outcome.replans
    # The first plan runs through the wall; the last one keeps the footprint clear of it.
    assert distance_to_polygon(densify(plans[0]), wall).min() == 0.0
    assert distance_to_polygon(densify(plans[-1]), wall).min() > scenario.vehicle_radius
    trajectory = log.trajectory()
    poses = np.column_stack([trajectory.x, trajectory.y])
    assert distance_to_polygon(poses, wall).min() > scenario.vehicle_radius


def test_beam_spacing_against_the_arc_between_beams():
    """The widest gap between adjacent beams at the range, as the arc range * angle."""
    from cosim.navigation.planner import Replanning

    thesis = Replanning(np.array([-math.pi / 4, 0.0, math.pi / 4]), 0.0, 10.0, vehicle_radius=1.5)
    assert thesis.beam_spacing == pytest.approx(10.0 * math.pi / 4)  # not the 270 degrees behind
    assert not thesis.resolves_obstacles  # 7.85 m > the 3 m car
    full = Replanning(-math.pi + 2 * math.pi * np.arange(360) / 360, 0.0, 20.0, vehicle_radius=0.5)
    assert full.beam_spacing == pytest.approx(20.0 * math.pi / 180)  # the wrap at +-pi included
    assert full.resolves_obstacles  # 0.35 m <= the 1 m robot
    uneven = Replanning(np.array([-1.0, -0.5, 0.2, 0.3]), 0.0, 2.0, vehicle_radius=1.0)
    assert uneven.beam_spacing == pytest.approx(2.0 * 0.7)
    assert uneven.resolves_obstacles == (1.4 <= 2.0)


def test_bicycle_three_obstacles_leaves_obstacles_on_the_plan_to_vfh(tmp_path: Path):
    """With replanning on (the default), Table 4.5's three beams do not replan round a first return
    (the replan round the pallet row's first return brushed its unseen corner at t = 2.6 s): the
    car reaches the goal without a collision, VFH passing the obstacles as without replanning."""
    scenario, result, log = _run("warehouse_bicycle_three_obstacles.toml", tmp_path)
    assert scenario.planner.replan
    assert result.outcome.reason == "goal_reached" and result.exit_code == 0
    assert result.outcome.min_clearance > 0.0 and result.outcome.vfh_interventions > 0
    # VFH is never stuck for replan_after nor progress stalled here: no replan at all, so the run is
    # the fixed plan's run step for step.
    assert result.outcome.replans == 0 and len(_plans(log)) == 1
    _, fixed, _ = _run("warehouse_bicycle_three_obstacles.toml", tmp_path, "planner.replan=false")
    assert (result.outcome.time, result.outcome.min_clearance) == (
        fixed.outcome.time,
        fixed.outcome.min_clearance,
    )
    trajectory = log.trajectory()
    poses = np.column_stack([trajectory.x, trajectory.y])
    for obstacle in scenario.obstacles:
        vertices = np.asarray(obstacle.polygon(), dtype=float)
        assert distance_to_polygon(poses, vertices).min() > scenario.vehicle_radius - 0.02


def _person_centre(t: float) -> tuple[float, float]:
    """The person of warehouse_moving_crossing: x = 62, y bouncing 15.5 <-> 22.5 at 1 m/s."""
    s = math.fmod(1.0 * t, 14.0)
    return 62.0, 15.5 + (14.0 - s if s > 7.0 else s)


def test_moving_crossing_poses_and_ranges_follow_the_trajectory(tmp_path: Path):
    scenario, result, log = _run("warehouse_moving_crossing.toml", tmp_path)
    assert result.outcome.reason == "goal_reached" and result.outcome.min_clearance > 0.0
    radius = scenario.obstacles[0].radius

    # /obstacles: republished with the scans while the person moves, each at the analytic pose.
    messages = list(log.messages("/obstacles"))
    assert len(messages) > 0.9 * result.outcome.time * scenario.lidar.rate
    for item in messages:
        (marker,) = item.message.markers
        expected = _person_centre(item.t)
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(expected, abs=1e-9)
        assert marker.scale.x == pytest.approx(2 * radius)
    tracks = log.obstacle_tracks()
    assert len(tracks) == 1 and len(tracks[0]) == len(messages)

    # /scan: every beam that meets the person's circle (at its analytic centre at the scan's time,
    # from the pose the lidar used) reads the near intersection, unless a rack is in front.
    lidar = log.signals("lidar")
    pose_at = {
        round(t, 6): (x, y, th)
        for t, x, y, th in zip(lidar.t, lidar["x"], lidar["y"], lidar["theta"], strict=True)
    }
    checked = 0
    for item in log.messages("/scan"):
        scan = item.message
        x, y, theta = pose_at[round(item.t, 6)]
        cx, cy = _person_centre(item.t)
        angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges)) + theta
        dx, dy = np.cos(angles), np.sin(angles)
        b = dx * (x - cx) + dy * (y - cy)
        c = (x - cx) ** 2 + (y - cy) ** 2 - radius**2
        disc = b * b - c
        hits = disc >= 0
        near = np.where(hits, -b - np.sqrt(np.where(hits, disc, 0.0)), np.inf)
        ranges = np.asarray(scan.ranges, dtype=float)
        seen = hits & (near > 0) & (near <= scan.range_max) & np.isfinite(ranges)
        in_front = seen & (ranges > near - 1e-3)  # nothing nearer than the person on that beam
        assert np.allclose(ranges[in_front], near[in_front], atol=1e-4)
        assert not np.any(ranges[seen] > near[seen] + 1e-3)  # the person is never seen through
        checked += int(in_front.sum())
    assert checked > 100


def test_costmap_marks_returns_and_forgets_what_moved():
    grid = OccupancyGrid(np.zeros((20, 20), dtype=bool), 0.5, (0.0, 0.0))
    costmap = Costmap(grid, np.array([0.0]), 0.0, 8.0)
    # A return 3.0 m ahead of (1.25, 5.1) along +x marks the cell holding (4.25, 5.1).
    costmap.integrate(1.25, 5.1, 0.0, np.array([3.0]))
    cell = grid.world_to_cell((4.25 + 1e-6, 5.1))
    assert costmap.marked[cell] and costmap.marked.sum() == 1
    assert costmap.grid().occupied[cell]
    # The obstacle left: a ray to 6 m passes through the cell and clears it.
    costmap.integrate(1.25, 5.1, 0.0, np.array([6.0]))
    assert not costmap.marked[cell] and costmap.marked.sum() == 1
    # No return at all (NaN) clears up to range_max.
    costmap.integrate(1.25, 5.1, 0.0, np.array([np.nan]))
    assert costmap.marked.sum() == 0
    # Only cells marked after a snapshot count as new on a plan.
    costmap.integrate(1.25, 5.1, 0.0, np.array([3.0]))
    before = costmap.snapshot()
    path = np.array([[4.5, 4.6], [4.5, 5.2]])  # points; the cell centre (4.5, 5.25) is 0.05 m away
    assert not costmap.new_marks_near(path, 0.5, before)
    assert costmap.new_marks_near(path, 0.5, np.zeros_like(before))


def test_a_replan_without_a_path_sets_no_path():
    """A corridor whose only way to the goal the lidar shows closed: the replan finds no path even
    for the footprint, and says so (the run then ends with reason no_path)."""
    from cosim.navigation.planner import PlannerComponent, Replanning
    from cosim.scenario.load import PlannerSettings

    occupied = np.zeros((10, 40), dtype=bool)
    occupied[[0, -1], :] = True  # a 4 m wide corridor (rows 1..8) along x, 20 m long
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    settings = PlannerSettings(expansion_distance=0.5, smoothing="none")
    angles = np.linspace(-math.pi / 3, math.pi / 3, 61)
    replanning = Replanning(angles, 0.0, 30.0, vehicle_radius=0.5)
    planner = PlannerComponent("planner", grid, (2.0, 2.5, 0.0), (18.0, 2.5), settings, replanning=replanning)
    planner.plan_path()
    assert planner.replan(0.0, (2.0, 2.5, 0.0), "obstacle_on_plan")  # nothing seen yet: a path
    # A wall across the corridor at x = 10 m, seen from (2, 2.5): each beam returns where it meets x = 10.
    ranges = np.where(np.abs(np.tan(angles) * 8.0) < 2.6, 8.0 / np.cos(angles), np.nan)
    planner.costmap.integrate(2.0, 2.5, 0.0, ranges)
    assert not planner.replan(1.0, (2.0, 2.5, 0.0), "obstacle_on_plan")
    assert planner.no_path.startswith("no path from (2.00, 2.50) m at t = 1.00 s")
    assert [replan.reason for replan in planner.replans] == ["obstacle_on_plan"] * 2
    assert math.isnan(planner.replans[-1].length)


def test_replans_leave_no_costmap_grids_behind():
    """Each replan searches a one-off costmap grid that keeps its prepared search, which keeps the
    grid (a cycle only the cyclic collector frees). With the collector off, as between the rare
    collections of a run, no grid of a finished replan may stay: counted by the collector's own
    census of what is alive."""
    import gc

    from cosim.navigation.planner import PlannerComponent, Replanning
    from cosim.scenario.load import PlannerSettings

    occupied = np.zeros((10, 40), dtype=bool)
    occupied[[0, -1], :] = True
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    settings = PlannerSettings(expansion_distance=0.5, smoothing="none")
    angles = np.linspace(-math.pi / 3, math.pi / 3, 61)
    planner = PlannerComponent(
        "planner", grid, (2.0, 2.5, 0.0), (18.0, 2.5), settings, replanning=Replanning(angles, 0.0, 30.0, 0.5)
    )
    planner.plan_path()

    def grids() -> int:
        return sum(isinstance(thing, OccupancyGrid) for thing in gc.get_objects())

    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        before = grids()
        for k in range(5):
            assert planner.replan(float(k), (2.0, 2.5, 0.0), "obstacle_on_plan")
        assert grids() == before
    finally:
        if enabled:
            gc.enable()
