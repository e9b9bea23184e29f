"""`OutcomeMonitor.check_positions` (the kernel path's check of a block of steps at once) against
independent truth: the goal step and the clearance computed directly from the scene's geometry,
and the monitor fed one position at a time."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.navigation.outcome import OutcomeMonitor
from cosim.world.distance import WorldDistance
from cosim.world.shapes import Circle
from planner.grid import OccupancyGrid

RADIUS = 0.5
OBSTACLE = Circle((10.0, 7.0), 1.0)  # beside the path y = 5: closest at x = 10, 2 m centre to centre


def _world():
    return WorldDistance(OccupancyGrid(np.zeros((40, 60), dtype=bool), 0.5, (0.0, 0.0)), (OBSTACLE,))


def _path(steps: int):
    """A drive along y = 5 from x = 2, 0.013 m per step (times 0.01 s apart)."""
    times = [(k + 1) / 100 for k in range(steps)]
    xs = [2.0 + 0.013 * (k + 1) for k in range(steps)]
    return times, xs, [5.0] * steps


@pytest.mark.parametrize("block", [1, 7, 1000])
def test_a_block_of_positions_ends_where_the_goal_is_first_reached(block):
    goal, tolerance = (20.0, 5.0), 1.0
    times, xs, ys = _path(2000)
    # Truth: the first step within the tolerance, from the positions alone.
    first = next(k for k, x in enumerate(xs) if abs(x - goal[0]) <= tolerance)
    monitor = OutcomeMonitor(_world(), goal, tolerance, RADIUS, (2.0, 5.0))
    reason, at = None, 0
    while reason is None:
        index, reason = monitor.check_positions(
            times[at : at + block], xs[at : at + block], ys[at : at + block]
        )
        at += index if reason is None else index + 1
    assert reason == "goal_reached" and at - 1 == first
    outcome = monitor.outcome
    assert outcome.reached and outcome.time == times[first]
    assert outcome.distance == pytest.approx(xs[first] - 2.0, abs=1e-9)
    # The clearance: distance from the footprint to the circle, smallest where the path passes it.
    clearance = min(math.hypot(x - 10.0, 5.0 - 7.0) - 1.0 - RADIUS for x in xs[: first + 1])
    assert outcome.min_clearance == pytest.approx(clearance, abs=1e-9)
    assert monitor.last_xy == (xs[first], ys[first])  # no step after the goal was looked at


def test_a_block_gives_what_one_position_at_a_time_gives():
    times, xs, ys = _path(1500)
    ys = [5.0 + 0.4 * math.sin(k / 50) for k in range(len(xs))]
    ys[900] = math.nan  # a position that is not finite ends the run as a collision
    single = OutcomeMonitor(_world(), (40.0, 5.0), 1.0, RADIUS, (2.0, 5.0))
    ended = next(k for k in range(len(xs)) if single.check_position(times[k], xs[k], ys[k]) is not None)
    batched = OutcomeMonitor(_world(), (40.0, 5.0), 1.0, RADIUS, (2.0, 5.0))
    index, reason = batched.check_positions(times, xs, ys)
    assert (index, reason) == (ended, "collision") == (900, "collision")
    assert repr(batched.outcome) == repr(single.outcome)  # NaN distance and point: compared as text
    assert math.isnan(batched.outcome.distance) and batched.outcome.time == times[900]
    assert batched.last_xy[0] == single.last_xy[0] and math.isnan(batched.last_xy[1])
