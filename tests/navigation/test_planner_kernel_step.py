"""The replanning planner's C step (`PlannerComponent.kernel_step`, native/costmap.c's
`planner_step`), which the compiled kernel calls, and which hands a step to the Python `step`
where a replan may follow: a planner stepped that way keeps the state, makes the replans and gives
the outputs of one stepped by its Python `step` alone (the truth), step for step, through every
trigger (no free direction, stalled, a new mark on the plan ahead) and a look that finds nothing."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

from cosim.navigation.planner import PENDING_MARKS, PENDING_REPLAN, PlannerComponent, Replanning
from cosim.scenario.load import PlannerSettings
from planner.grid import OccupancyGrid

ANGLES = np.linspace(-math.pi / 3, math.pi / 3, 121)  # 1 degree apart: 0.52 m at 30 m
H = 0.1  # [s] the planner's step
BOX = (10.0, 11.0, 2.0, 3.5)  # x from, x to, y from, y to [m]: on the plan, seen as it comes


def _planner() -> PlannerComponent:
    occupied = np.zeros((16, 48), dtype=bool)
    occupied[[0, -1], :] = True  # a 7 m wide corridor along x, 24 m long
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    settings = PlannerSettings(expansion_distance=0.5, smoothing="none")
    replanning = Replanning(
        ANGLES, 0.0, 30.0, vehicle_radius=0.5, replan_after=1.0, replan_stall_time=3.0, replan_interval=1.0
    )
    planner = PlannerComponent("planner", grid, (2.0, 2.5, 0.0), (20.0, 2.5), settings, replanning=replanning)
    planner.plan_path()
    planner.instantiate()
    planner.setup(0.0, {})
    planner.initialize()
    return planner


def _ranges(x: float, y: float, theta: float) -> np.ndarray:
    """Where each beam from (x, y) meets the box's near face (x = BOX[0]), NaN where it misses."""
    directions = theta + ANGLES
    distance = (BOX[0] - x) / np.cos(directions)
    hit = BOX[2] + 0.0 * distance <= y + distance * np.sin(directions)
    hit &= y + distance * np.sin(directions) <= BOX[3]
    return np.where((distance > 0) & hit, distance, np.nan)


def _inputs(k: int) -> tuple[float, float, float, float]:
    """x, y, theta, steering at step k: on to the box, blocked a while, then standing still."""
    t = k * H
    x = min(2.0 + 0.6 * t, 8.5)
    steering = math.nan if 40 <= k < 60 else 0.0  # no free direction for 2 s
    return x, 2.5, 0.0, steering


def _state(planner: PlannerComponent) -> tuple:
    state = planner._state
    return tuple(getattr(state, name) for name, _ in state._fields_ if name not in ("pending", "reason"))


@pytest.mark.parametrize("looks", ["in C", "in Python"])
def test_the_c_step_and_python_step_make_the_same_run(looks):
    truth, stepped = _planner(), _planner()
    if looks == "in Python":  # no scratch for the points ahead: every look handed over
        stepped._state.ahead_capacity = 0
    function, address = stepped.kernel_step()
    c_step = ctypes.CFUNCTYPE(ctypes.c_int64, ctypes.c_void_p, ctypes.c_double)(function)
    handed = {PENDING_MARKS: 0, PENDING_REPLAN: 0}
    for k in range(200):
        t = k * H
        x, y, theta, steering = _inputs(k)
        for planner in (truth, stepped):
            planner.input_buffer[:4] = (x, y, theta, steering)
            planner.input_buffer[4:] = _ranges(x, y, theta)
        truth.do_step(t, H)
        if c_step(address, t):
            handed[stepped._state.pending] += 1
            stepped.do_step(t, H)
        assert stepped._state.pending == 0
        assert np.array_equal(stepped.output_buffer, truth.output_buffer, equal_nan=True), k
        # Same state, field for field (the plan's addresses differ: each planner has its own).
        mine, theirs = _state(stepped), _state(truth)
        names = [name for name, _ in stepped._state._fields_ if name not in ("pending", "reason")]
        differing = [n for n, a, b in zip(names, mine, theirs, strict=True) if a != b and not _both_nan(a, b)]
        own = {"costmap", "scan", "inputs", "points", "arc", "marks_at_plan", "ahead", "ahead_capacity"}
        assert set(differing) <= own, (k, differing)
        assert np.array_equal(stepped.costmap.marked, truth.costmap.marked)
    reasons = [replan.reason for replan in truth.replans]
    assert [(r.time, r.reason, r.length) for r in stepped.replans] == [
        (r.time, r.reason, r.length) for r in truth.replans
    ]
    # Every trigger fired, and the C step handed over the replans, and the looks it has no room for.
    assert {"obstacle_on_plan", "no_free_direction", "stalled"} <= set(reasons), reasons
    assert handed[PENDING_REPLAN] > 0, handed
    assert (handed[PENDING_MARKS] > 0) == (looks == "in Python"), handed


def _both_nan(a, b) -> bool:
    return isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)


def test_no_c_step_without_replanning_or_when_told():
    planner = _planner()
    assert planner.kernel_step() is not None
    planner.kernel_steps = False  # a run that polls goals after each planner step
    assert planner.kernel_step() is None


def _look_in_c(planner: PlannerComponent) -> tuple[int, np.ndarray]:
    """native/costmap.c's `planner_look_ahead` on the planner's state: its finding (-1: more points
    than its scratch) and the points it left in the scratch."""
    from cosim.navigation.costmap import _kernels

    near = _kernels().planner_look_ahead(ctypes.addressof(planner._state))
    capacity = planner._state.ahead_capacity
    return near, planner._ahead[capacity:].reshape(-1, 2)


@pytest.mark.parametrize("seed", range(6))
def test_the_c_look_ahead_makes_numpys_points_and_finds_what_python_finds(seed):
    """The points every half cell along the plan ahead (`_plan_ahead`: np.arange, np.interp) made in
    C bit for bit, and the same finding as `_look_ahead`: plans with repeated points (zero-length
    segments), progress at a waypoint, at the plan's end and between, horizons ending on a point,
    past the end, at a multiple of the spacing; marks near the plan and away from it."""
    rng = np.random.default_rng(seed)
    planner = _planner()
    found = {True: 0, False: 0, "Python": 0}
    for case in range(90):
        count = int(rng.integers(2, 40))
        steps = rng.normal(0.0, 1.0, (count, 2)) * rng.choice([0.0, 0.3, 1.0, 2.0], (count, 1))
        waypoints = np.cumsum(steps, axis=0) + (12.0, 4.0)
        planner.waypoints = np.ascontiguousarray(waypoints)
        planner._arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(waypoints, axis=0).T))))
        state = planner._state
        state.points, state.arc, state.waypoint_count = (
            planner.waypoints.ctypes.data,
            planner._arc.ctypes.data,
            count,
        )
        last = float(planner._arc[-1])
        progress = [0.0, float(planner._arc[rng.integers(count)]), last, float(rng.uniform(0.0, last))][
            case % 4
        ]
        spacing = planner.grid.resolution / 2.0
        horizon = [float(rng.uniform(0.0, 12.0)), last - progress, 8 * spacing, 1e-17][
            case % 3 if case % 7 else 3
        ]
        planner._progress = progress
        state.replan_horizon = horizon
        planner.replanning = Replanning(ANGLES, 0.0, 30.0, vehicle_radius=0.5, replan_horizon=horizon)
        # marks newer than the plan: a few cells anywhere
        planner._marks_at_plan = planner.costmap.snapshot()
        state.marks_at_plan = planner._marks_at_plan.ctypes.data
        planner.costmap._marked[:] = False
        planner.costmap._marked[rng.integers(0, 16, 3), rng.integers(0, 48, 3)] = True
        expected_points = planner._plan_ahead(horizon)
        if case % 2 and len(expected_points):  # a mark at a point ahead (when on the grid)
            x, y = expected_points[rng.integers(len(expected_points))]
            row, col = 15 - math.floor(y / 0.5), math.floor(x / 0.5)
            if 0 <= row < 16 and 0 <= col < 48:
                planner.costmap._marked[row, col] = True
        expected = planner._look_ahead() == "obstacle_on_plan"
        near, points = _look_in_c(planner)
        end = min(progress + horizon, last) + spacing
        if near == -1:  # more points than the scratch holds: Python's to look
            assert len(np.arange(progress, end, spacing)) > state.ahead_capacity, case
            found["Python"] += 1
            continue
        assert near == int(expected), case
        assert points[: len(expected_points)].tobytes() == expected_points.tobytes(), case
        found[expected] += 1
    assert found[True] > 5 and found[False] > 5 and found["Python"] > 0, found
