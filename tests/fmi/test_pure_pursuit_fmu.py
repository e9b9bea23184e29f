"""PurePursuit FMU against hand-computed geometry (MATLAB controllerPurePursuit semantics)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmu_harness import FmuInstance, array_inputs

CAPACITY = 1000


def follower(waypoints, parameters=None, pose=(0.0, 0.0, 0.0)) -> FmuInstance:
    """An initialised PurePursuit with the waypoints (N x 2, NaN-padded to the capacity) and pose."""
    inputs = {**array_inputs("waypoints", np.asarray(waypoints, dtype=float), CAPACITY)}
    inputs.update(x=pose[0], y=pose[1], theta=pose[2])
    parameters = {"max_angular_velocity": 100.0, **(parameters or {})}
    return FmuInstance("PurePursuit").initialize({**parameters, **inputs})


def drive_to(fmu: FmuInstance, pose) -> dict:
    fmu.set({"x": pose[0], "y": pose[1], "theta": pose[2]})
    fmu.step()
    return fmu.outputs()


def bearing(pose, point) -> float:
    """Angle of `point` seen from `pose`, wrapped to (-pi, pi]."""
    angle = math.atan2(point[1] - pose[1], point[0] - pose[0]) - pose[2]
    return math.atan2(math.sin(angle), math.cos(angle))


def test_straight_line_lookahead_and_omega():
    pose = (2.0, 0.5, 0.3)
    lookahead = 1.5
    parameters = {"lookahead_distance": lookahead, "desired_linear_velocity": 0.4}
    with follower([[0, 0], [10, 0]], parameters) as fmu:
        out = drive_to(fmu, pose)
    # Projection (2, 0); 1.5 m further along the line.
    assert out["lookahead_x"] == pytest.approx(3.5, abs=1e-12)
    assert out["lookahead_y"] == pytest.approx(0.0, abs=1e-12)
    alpha = math.atan2(-0.5, 1.5) - 0.3
    assert out["target_dir"] == pytest.approx(alpha, abs=1e-12)
    assert out["omega"] == pytest.approx(2 * math.sin(alpha) / lookahead, abs=1e-12)
    assert out["v"] == pytest.approx(0.4)
    assert out["goal_distance"] == pytest.approx(math.hypot(8.0, 0.5))
    assert not out["goal_reached"]


def test_nav2_law_scales_omega_by_speed():
    pose = (2.0, 0.5, 0.3)
    parameters = {"lookahead_distance": 1.5, "desired_linear_velocity": 0.4, "angular_velocity_law": 1}
    with follower([[0, 0], [10, 0]], parameters) as fmu:
        out = drive_to(fmu, pose)
    alpha = math.atan2(-0.5, 1.5) - 0.3
    assert out["omega"] == pytest.approx(0.4 * 2 * math.sin(alpha) / 1.5, abs=1e-12)


def test_l_shaped_path_lookahead_turns_the_corner_and_projection_only_moves_forward():
    corner_path = [[0, 0], [4, 0], [4, 4]]
    with follower(corner_path, {"lookahead_distance": 2.0}) as fmu:
        # Projection (3, 0): 1 m to the corner, the remaining 1 m up the second leg.
        out = drive_to(fmu, (3.0, 0.2, 0.0))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((4.0, 1.0), abs=1e-12)
        alpha = bearing((3.0, 0.2, 0.0), (4.0, 1.0))
        assert out["omega"] == pytest.approx(2 * math.sin(alpha) / 2.0, abs=1e-12)

        # Past the corner: projection (4, 1.5) on the second leg.
        out = drive_to(fmu, (3.9, 1.5, math.pi / 2))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((4.0, 3.5), abs=1e-12)

        # Back near the start: the projection does not go back to the first leg.
        out = drive_to(fmu, (1.0, 0.0, 0.0))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((4.0, 3.5), abs=1e-12)


def test_projection_advances_about_one_lookahead_per_call_after_a_jump():
    # Waypoints every 0.5 m along x. After a jump from x = 1 to x = 8 the forward search stops once
    # the path walked since the old projection point exceeds L = 1: it checks the segments starting
    # at 1.0, 1.5 and 2.0 (walked 0.5, 1.0, 1.5) and settles at (2.5, 0); lookahead (3.5, 0).
    path = np.column_stack([np.arange(0.0, 10.5, 0.5), np.zeros(21)])
    with follower(path, {"lookahead_distance": 1.0}) as fmu:
        out = drive_to(fmu, (1.0, 0.3, 0.0))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((2.0, 0.0), abs=1e-12)
        out = drive_to(fmu, (8.0, 0.3, 0.0))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((3.5, 0.0), abs=1e-12)


def polyline_lookahead(path: np.ndarray, point: np.ndarray, lookahead: float) -> np.ndarray:
    """A second implementation: global closest point on the polyline, then arc length + L."""
    starts, ends = path[:-1], path[1:]
    directions = ends - starts
    lengths = np.linalg.norm(directions, axis=1)
    t = np.clip(np.einsum("ij,ij->i", point - starts, directions) / lengths**2, 0.0, 1.0)
    closest = starts + t[:, None] * directions
    segment = int(np.argmin(np.linalg.norm(closest - point, axis=1)))
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    target_arc = cumulative[segment] + t[segment] * lengths[segment] + lookahead
    if target_arc >= cumulative[-1]:
        return path[-1]
    k = int(np.searchsorted(cumulative, target_arc, side="right")) - 1
    return path[k] + (target_arc - cumulative[k]) / lengths[k] * directions[k]


def test_circle_against_second_implementation_and_analytic_curvature():
    radius, lookahead = 5.0, 1.0
    angles = np.linspace(0.0, 1.5 * math.pi, 301)
    path = radius * np.column_stack([np.cos(angles), np.sin(angles)])
    with follower(path, {"lookahead_distance": lookahead, "desired_linear_velocity": 1.0}) as fmu:
        # Steps of 0.5 m of arc: the projection may advance only about one lookahead per call.
        phases = np.arange(0.1, 4.0, 0.1)
        offsets = np.resize([0.0, 0.1, -0.2, 0.05], phases.size)  # on, outside and inside the circle
        for phase, offset in zip(phases, offsets, strict=True):
            position = (radius + offset) * np.array([math.cos(phase), math.sin(phase)])
            pose = (*position, phase + math.pi / 2)
            out = drive_to(fmu, pose)
            expected = polyline_lookahead(path, position, lookahead)
            assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx(tuple(expected), abs=1e-9)
            alpha = bearing(pose, expected)
            assert out["omega"] == pytest.approx(2 * math.sin(alpha) / lookahead, abs=1e-9)
            if offset == 0.0:
                # On the circle, heading tangent: the pure-pursuit arc is the circle, omega = v / R.
                assert out["omega"] == pytest.approx(1.0 / radius, rel=2e-3)


def test_nan_rows_are_ignored():
    compact = np.array([[0, 0], [3, 1], [6, 0], [9, 2]], dtype=float)
    padded = np.array(
        [[0, 0], [math.nan, math.nan], [3, 1], [math.nan, 5.0], [6, 0], [7.0, math.nan], [9, 2]], dtype=float
    )
    pose = (2.5, 0.2, 0.1)
    parameters = {"lookahead_distance": 2.5}
    with follower(compact, parameters) as reference, follower(padded, parameters) as fmu:
        assert drive_to(fmu, pose) == drive_to(reference, pose)


def test_no_waypoints_gives_zero_command_and_the_pose_as_lookahead():
    with follower(np.empty((0, 2)), {"desired_linear_velocity": 0.5}) as fmu:
        out = drive_to(fmu, (1.5, -2.0, 0.7))
    assert out["v"] == 0.0 and out["omega"] == 0.0 and out["target_dir"] == 0.0
    assert (out["lookahead_x"], out["lookahead_y"]) == (1.5, -2.0)
    assert not out["goal_reached"] and math.isnan(out["goal_distance"])


def test_goal_reached_stops_the_vehicle():
    parameters = {"goal_tolerance": 0.2, "desired_linear_velocity": 0.5}
    with follower([[0, 0], [5, 0]], parameters) as fmu:
        out = drive_to(fmu, (4.7, 0.1, 0.0))
        assert out["goal_distance"] == pytest.approx(math.hypot(0.3, 0.1))
        assert not out["goal_reached"] and out["v"] == 0.5
        out = drive_to(fmu, (4.9, 0.1, 0.0))
        assert out["goal_distance"] == pytest.approx(math.hypot(0.1, 0.1))
        assert out["goal_reached"] and out["v"] == 0.0 and out["omega"] == 0.0


def test_omega_is_clipped_and_a_target_behind_turns_at_one_rad_per_second():
    with follower([[0, 0], [0, 10]], {"max_angular_velocity": 0.3}) as fmu:
        out = drive_to(fmu, (0.0, 0.0, 0.0))  # lookahead straight to the left: 2 sin(pi/2)/1 = 2
    assert out["omega"] == pytest.approx(0.3)
    with follower([[0, 0], [-10, 0]], {"max_angular_velocity": 5.0}) as fmu:
        out = drive_to(fmu, (0.0, 0.0, 0.0))  # alpha = pi: MATLAB replaces 2 sin(pi)/L by sign = 1
    assert abs(out["target_dir"]) == pytest.approx(math.pi)
    assert abs(out["omega"]) == 1.0


def test_a_new_plan_restarts_the_projection_search():
    with follower([[0, 0], [10, 0]], {"lookahead_distance": 1.0}) as fmu:
        drive_to(fmu, (8.0, 0.0, 0.0))
        # New plan along y, starting far behind the old projection: searched from its waypoint 1.
        fmu.set(array_inputs("waypoints", [[8, -5], [8, 5]], CAPACITY))
        out = drive_to(fmu, (8.0, 0.0, math.pi / 2))
    assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((8.0, 1.0), abs=1e-12)
    assert out["goal_distance"] == pytest.approx(5.0)


def test_waypoint_capacity_is_exactly_1000_rows():
    with FmuInstance("PurePursuit").initialize() as fmu:
        assert "waypoints[1000,2]" in fmu.variables
        assert "waypoints[1001,1]" not in fmu.variables
        with pytest.raises(FMICallException):
            fmu.fmu.setReal([3000], [1.0])  # one past waypoints[1000,2]
        assert any("3000" in message for message in fmu.messages)


def new_path(fmu: FmuInstance, waypoints) -> None:
    """Send a new plan mid-run, as a replanner does: every row, NaN-padded to the capacity."""
    fmu.set(array_inputs("waypoints", np.asarray(waypoints, dtype=float), CAPACITY))


def test_replanned_path_is_followed_from_the_current_pose_with_its_own_segment_index():
    # Path A: waypoints 1 m apart along x. Driven to x = 8 in steps of 0.5 m, the projection sits on
    # A's segment 8, an index path B (3 waypoints, 2 segments) does not have.
    path_a = [[float(k), 0.0] for k in range(11)]
    with follower(path_a, {"lookahead_distance": 1.0, "desired_linear_velocity": 0.3}) as fmu:
        for k in range(17):
            out = drive_to(fmu, (0.5 * k, 0.0, 0.0))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((9.0, 0.0), abs=1e-12)

        # Path B starts elsewhere: down x = 6 from y = 2 to y = -4, then along y = -4 to x = 9.
        # Closest point to (8, 0): (6, 0) on B's first leg (2 m; its second leg is 4 m away), so the
        # lookahead is 1 m further down that leg, (6, -1).
        new_path(fmu, [[6, 2], [6, -4], [9, -4]])
        pose = (8.0, 0.0, 0.0)
        out = drive_to(fmu, pose)
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((6.0, -1.0), abs=1e-12)
        assert out["target_dir"] == pytest.approx(math.atan2(-1.0, -2.0), abs=1e-12)
        assert out["omega"] == pytest.approx(-2.0 / math.sqrt(5.0), abs=1e-12)  # 2 sin(alpha) / L
        assert out["goal_distance"] == pytest.approx(math.hypot(1.0, 4.0)) and out["v"] == 0.3

        # B is then followed like any path: forward along its first leg and round its corner.
        out = drive_to(fmu, (6.0, -2.5, -math.pi / 2))
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((6.0, -3.5), abs=1e-12)
        out = drive_to(fmu, (6.0, -3.6, -math.pi / 2))  # 0.4 m to B's corner, then 0.6 m along y = -4
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((6.6, -4.0), abs=1e-12)


def test_more_waypoints_alone_restart_the_search_and_a_resent_plan_does_not():
    # Out along y = 0, back along y = 0.2. With L = 0.5 the forward-only search from the first leg
    # stops after 1 m walked, so it never reaches the return leg 0.05 m away from (3, 0.15).
    out_leg = [[0, 0], [4, 0]]
    out_and_back = [*out_leg, [4, 0.2], [0, 0.2]]
    poses = [(0.5 * k, 0.0, 0.0) for k in range(7)]  # up to (3, 0)
    near_return_leg = (3.0, 0.15, 0.0)
    with follower(out_and_back, {"lookahead_distance": 0.5}) as fmu:
        for pose in poses:
            new_path(fmu, out_and_back)  # the same plan every step: no change, no restart
            drive_to(fmu, pose)
        new_path(fmu, out_and_back)
        out = drive_to(fmu, near_return_leg)
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((3.5, 0.0), abs=1e-12)

    # The same plan, but its return leg arrives mid-run: only rows 3 and 4 change (NaN -> values),
    # i.e. the waypoint count. The search restarts over every segment and finds the return leg:
    # projection (3, 0.2), lookahead 0.5 m along it toward x = 0.
    with follower(out_leg, {"lookahead_distance": 0.5}) as fmu:
        for pose in poses:
            drive_to(fmu, pose)
        new_path(fmu, out_and_back)
        out = drive_to(fmu, near_return_leg)
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((2.5, 0.2), abs=1e-12)
        assert out["goal_distance"] == pytest.approx(math.hypot(3.0, 0.05))

        # Fewer waypoints again (the return leg dropped): back on the out leg, projection (3, 0).
        new_path(fmu, out_leg)
        out = drive_to(fmu, near_return_leg)
        assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((3.5, 0.0), abs=1e-12)


def test_a_new_plan_after_the_goal_drives_again():
    parameters = {"goal_tolerance": 0.1, "desired_linear_velocity": 0.5}
    with follower([[0, 0], [5, 0]], parameters) as fmu:
        out = drive_to(fmu, (4.95, 0.0, 0.0))
        assert out["goal_reached"] and out["v"] == 0.0
        new_path(fmu, [[5, 0], [5, 5]])
        out = drive_to(fmu, (4.95, 0.0, 0.0))
    # Projection (5, 0), the new path's start; lookahead 1 m up it.
    assert not out["goal_reached"] and out["v"] == 0.5
    assert (out["lookahead_x"], out["lookahead_y"]) == pytest.approx((5.0, 1.0), abs=1e-12)
    assert out["goal_distance"] == pytest.approx(math.hypot(0.05, 5.0))
    assert out["target_dir"] == pytest.approx(math.atan2(1.0, 0.05), abs=1e-12)


def test_closed_loop_with_the_drive_follows_a_path_replanned_mid_run():
    """PurePursuit and DifferentialDrive stepped together: path A along x; at t = 6 s, path B from
    the vehicle's pose up to (x, 3). The vehicle leaves A and stops at B's goal."""
    parameters = {"desired_linear_velocity": 0.5, "lookahead_distance": 0.8, "goal_tolerance": 0.1}
    with (
        follower([[0, 0], [20, 0]], parameters) as controller,
        FmuInstance("DifferentialDrive").initialize() as drive,
    ):
        switched_at = None
        for step in range(600):
            pose = (drive.get("x"), drive.get("y"), drive.get("theta"))
            if step == 120:
                switched_at = pose
                new_path(controller, [[pose[0], pose[1]], [pose[0] + 1.0, 1.0], [pose[0] + 1.0, 3.0]])
            out = drive_to(controller, pose)
            if out["goal_reached"]:
                break
            drive.set({"v": out["v"], "omega": out["omega"]})
            drive.step()
    assert switched_at[0] == pytest.approx(3.0, abs=0.05) and abs(switched_at[1]) < 1e-6
    assert out["goal_reached"] and step < 599
    assert math.hypot(pose[0] - (switched_at[0] + 1.0), pose[1] - 3.0) <= 0.1
