"""The replanning planner's C step (`PlannerComponent.kernel_step`, native/costmap.c's
`planner_step`), which the compiled kernel calls, and which hands a step to the Python `step`
where a replan may follow: a planner stepped that way keeps the state, makes the replans and gives
the outputs of one stepped by its Python `step` alone (the truth), step for step, through every
trigger (no free direction, stalled, a new mark on the plan ahead) and a look that finds nothing."""

from __future__ import annotations

import ctypes
import math

import numpy as np

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


def test_the_c_step_and_python_step_make_the_same_run():
    truth, stepped = _planner(), _planner()
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
        own = {"costmap", "scan", "inputs", "points", "arc", "marks_at_plan"}
        assert set(differing) <= own, (k, differing)
        assert np.array_equal(stepped.costmap.marked, truth.costmap.marked)
    reasons = [replan.reason for replan in truth.replans]
    assert [(r.time, r.reason, r.length) for r in stepped.replans] == [
        (r.time, r.reason, r.length) for r in truth.replans
    ]
    # Every trigger fired, and the C step handed over both kinds of step.
    assert {"obstacle_on_plan", "no_free_direction", "stalled"} <= set(reasons), reasons
    assert handed[PENDING_MARKS] > 0 and handed[PENDING_REPLAN] > 0, handed


def _both_nan(a, b) -> bool:
    return isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)


def test_no_c_step_without_replanning_or_when_told():
    planner = _planner()
    assert planner.kernel_step() is not None
    planner.kernel_steps = False  # a run that polls goals after each planner step
    assert planner.kernel_step() is None
