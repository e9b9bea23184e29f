"""The costmap's C kernel (cosim/navigation/native/costmap.c) against a plain traversal in Python.

The kernel traverses a beam only when it passes near the box of the marks (only marked cells can
be cleared). The reference below traverses every beam, cell by cell, with the same arithmetic, so
the marks and change counts must be equal exactly, scan after scan, while marks come and go."""

from __future__ import annotations

import copy
import math
import pickle

import numpy as np
import pytest

from cosim.navigation.costmap import Costmap
from planner.grid import OccupancyGrid


def _reference_integrate(marked, known, origin, resolution, x, y, theta, angles, ranges, clear_to):
    """Every beam: clear the marked cells it crosses before its return (or up to clear_to without
    one), then mark the return's cell; cells of [row, col] with row 0 at the top."""
    rows, cols = marked.shape
    gx, gy = (x - origin[0]) / resolution, (y - origin[1]) / resolution
    changed = 0
    for angle, distance in zip(angles, ranges, strict=True):
        hit = math.isfinite(distance)
        if not hit:
            distance = clear_to
            if distance <= 0.0:
                continue
        dx, dy = math.cos(theta + angle), math.sin(theta + angle)
        limit = distance / resolution
        ix, iy = math.floor(gx), math.floor(gy)
        step_x, step_y = (1 if dx > 0 else -1), (1 if dy > 0 else -1)
        next_x = ((ix + 1) - gx) / dx if dx > 0 else ((gx - ix) / -dx if dx < 0 else math.inf)
        next_y = ((iy + 1) - gy) / dy if dy > 0 else ((gy - iy) / -dy if dy < 0 else math.inf)
        delta_x = 1.0 / abs(dx) if dx != 0 else math.inf
        delta_y = 1.0 / abs(dy) if dy != 0 else math.inf
        while True:
            leaving = min(next_x, next_y)
            if hit and leaving >= limit:
                break
            if (
                0 <= ix < cols
                and 0 <= iy < rows
                and marked[rows - 1 - iy, ix]
                and not known[rows - 1 - iy, ix]
            ):
                marked[rows - 1 - iy, ix] = False
                changed += 1
            if leaving >= limit:
                break
            if next_x < next_y:
                next_x, ix = next_x + delta_x, ix + step_x
            else:
                next_y, iy = next_y + delta_y, iy + step_y
        if hit:
            cx = math.floor(gx + dx * (limit + 1e-6))
            cy = math.floor(gy + dy * (limit + 1e-6))
            if (
                0 <= cx < cols
                and 0 <= cy < rows
                and not marked[rows - 1 - cy, cx]
                and not known[rows - 1 - cy, cx]
            ):
                marked[rows - 1 - cy, cx] = True
                changed += 1
    return changed


@pytest.mark.parametrize("range_min", [0.0, 0.2])
def test_integrate_equals_a_full_traversal_while_marks_come_and_go(range_min):
    rng = np.random.default_rng(7)
    occupied = np.zeros((30, 44), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[10:14, 20:23] = True
    grid = OccupancyGrid(occupied, 0.25, (-1.0, 2.0))
    angles = np.linspace(-math.pi, math.pi, 37)
    range_max = 6.0
    costmap = Costmap(grid, angles, range_min, range_max)
    marked = np.zeros_like(occupied)
    clear_to = range_max if range_min == 0.0 else 0.0
    changes = 0
    for _ in range(120):
        x, y = rng.uniform(-1.5, 10.5), rng.uniform(1.5, 10.0)  # sometimes off the map
        theta = rng.uniform(-4.0, 4.0)
        ranges = rng.uniform(0.0, range_max, len(angles))
        ranges[rng.random(len(angles)) < 0.3] = np.nan  # no return: clears when range_min is 0
        if rng.random() < 0.2:
            ranges[:] = np.nan  # an empty scan clears every beam's ray
        expected = _reference_integrate(
            marked, occupied, grid.origin, grid.resolution, x, y, theta, angles, ranges, clear_to
        )
        assert costmap.integrate(x, y, theta, ranges) == expected
        assert np.array_equal(costmap.marked, marked)
        changes += expected
    assert changes > 500 and marked.any()  # marks were set and cleared all along


def _disc_ranges(x, y, theta, angles, discs, range_max):
    """Ranges [m] from (x, y) at heading theta to the nearest of `discs` (cx, cy, r) (NaN: none
    within range_max): returns on obstacles that move a little from scan to scan."""
    ranges = np.full(len(angles), np.nan)
    for k, angle in enumerate(angles):
        dx, dy = math.cos(theta + angle), math.sin(theta + angle)
        for cx, cy, r in discs:
            b = dx * (x - cx) + dy * (y - cy)
            c = (x - cx) ** 2 + (y - cy) ** 2 - r * r
            if b * b - c >= 0 and -b - math.sqrt(b * b - c) >= 0:
                near = -b - math.sqrt(b * b - c)
                if near <= range_max and not near >= ranges[k]:
                    ranges[k] = near
    return ranges


@pytest.mark.parametrize("count", [360, 64])
def test_a_full_turn_of_even_beams_equals_a_full_traversal_among_moving_discs(count):
    """Beams evenly spread round the full turn: the kernel finds the beams near each mark once a
    scan and traverses a beam only there. Discs that drift from scan to scan leave marks that later
    rays cross (cleared), returns on marks already there, marks set and cleared in one scan."""
    from cosim.world.lidar import evenly_spaced_beams

    rng = np.random.default_rng(11)
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    angles = evenly_spaced_beams(-math.pi, math.pi, count)
    range_max = 12.0
    costmap = Costmap(grid, angles, 0.0, range_max)
    assert costmap._uniform
    marked = np.zeros_like(occupied)
    discs = [(rng.uniform(3, 27), rng.uniform(3, 17), rng.uniform(0.3, 1.2)) for _ in range(12)]
    x, y, theta = 15.0, 10.0, 0.3
    changes = 0
    for scan in range(60):
        discs = [(cx + rng.normal(0, 0.3), cy + rng.normal(0, 0.3), r) for cx, cy, r in discs]
        x, y = x + rng.normal(0, 0.4), y + rng.normal(0, 0.4)
        theta += rng.normal(0, 0.5) + (2 * math.pi if scan == 30 else 0.0)
        ranges = _disc_ranges(x, y, theta, angles, discs, range_max)
        expected = _reference_integrate(
            marked, occupied, grid.origin, grid.resolution, x, y, theta, angles, ranges, range_max
        )
        assert costmap.integrate(x, y, theta, ranges) == expected
        assert np.array_equal(costmap.marked, marked)
        changes += expected
    assert changes > 200 and marked.sum() > 20


def test_marks_change_only_through_integrate():
    grid = OccupancyGrid(np.zeros((8, 8), dtype=bool), 0.5, (0.0, 0.0))
    costmap = Costmap(grid, np.array([0.0]), 0.0, 3.0)
    with pytest.raises(ValueError):
        costmap.marked[2, 2] = True  # the kernel keeps counts of the marks: no writes from outside
    with pytest.raises(ValueError, match="needs 1 ranges"):
        costmap.integrate(1.0, 1.0, 0.0, np.array([]))


def test_a_copy_has_its_own_marks():
    """The kernel's struct holds the addresses of the costmap's arrays: a copy binds to its own."""
    grid = OccupancyGrid(np.zeros((20, 20), dtype=bool), 0.5, (0.0, 0.0))
    costmap = Costmap(grid, np.array([0.0]), 0.0, 8.0)
    costmap.integrate(1.25, 5.1, 0.0, np.array([3.0]))
    for twin in (copy.deepcopy(costmap), pickle.loads(pickle.dumps(costmap))):
        assert twin.integrate(1.25, 5.1, 0.0, np.array([6.0])) == 2  # clears the mark, marks a new one
        assert costmap.marked.sum() == 1 and twin.marked.sum() == 1
        assert not np.array_equal(costmap.marked, twin.marked)


def _progress_numpy(points, arc, first, stop, x, y):
    """The planner's progress as NumPy computed it before native/costmap.c took it over."""
    a, b = points[first:stop], points[first + 1 : stop + 1]
    edge = b - a
    length_sq = (edge * edge).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        fraction = np.clip(((x - a[:, 0]) * edge[:, 0] + (y - a[:, 1]) * edge[:, 1]) / length_sq, 0.0, 1.0)
    fraction = np.nan_to_num(fraction)
    nearest = a + fraction[:, None] * edge
    best = int(np.argmin(np.hypot(nearest[:, 0] - x, nearest[:, 1] - y)))
    return first + best, arc[first + best] + fraction[best] * math.sqrt(length_sq[best])


def test_path_progress_is_the_numpy_description_bit_for_bit():
    import ctypes

    from cosim.navigation.costmap import path_progress

    function = path_progress()
    rng = np.random.default_rng(7)
    segment = ctypes.c_int64()
    for trial in range(400):
        n = int(rng.integers(2, 80))
        points = np.cumsum(rng.normal(0.0, 1.0, (n, 2)), axis=0)
        if trial % 3 == 0:  # repeated points: zero-length segments
            points[rng.integers(1, n, size=n // 4)] = points[0]
        if trial % 5 == 0:  # a grid-like plan: ties between segments at equal distances
            points = np.round(points)
        points = np.ascontiguousarray(points)
        arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))))
        first = int(rng.integers(0, n - 1))
        stop = min(first + int(rng.integers(1, 70)), n - 1)
        x, y = (float(v) for v in rng.normal(points[first], 2.0))
        if trial % 7 == 0:
            x, y = float(points[first][0]), float(points[first][1])  # on a point exactly
        progress = function(points.ctypes.data, arc.ctypes.data, first, stop, x, y, ctypes.byref(segment))
        expected_segment, expected = _progress_numpy(points, arc, first, stop, x, y)
        assert (segment.value, progress) == (expected_segment, expected)


def test_the_look_round_the_plan_never_misses_a_new_mark_near_its_points():
    """`new_marks_maybe_near` says "no" only when `new_marks_near` on the planner's points ahead
    (np.interp every half cell along the plan, as `PlannerComponent._plan_ahead` makes them) is
    False; and it does say "no" for marks away from the plan."""
    rng = np.random.default_rng(5)
    grid = OccupancyGrid(np.zeros((40, 50), dtype=bool), 0.5, (1.0, -2.0))
    costmap = Costmap(grid, evenly_spaced_beams_full(90), 0.0, 10.0)
    answers = set()
    for _ in range(300):
        waypoints = np.cumsum(rng.normal(0.0, 1.2, (rng.integers(2, 12), 2)), axis=0) + (13.0, 8.0)
        waypoints[rng.random(len(waypoints)) < 0.1] = waypoints[0]  # repeated points: zero-length segments
        waypoints = np.ascontiguousarray(waypoints)
        arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(waypoints, axis=0).T))))
        since = costmap.snapshot()
        x, y, theta = rng.uniform(2, 24), rng.uniform(-1, 17), rng.uniform(-4, 4)
        ranges = rng.uniform(0.3, 10.0, 90)
        ranges[rng.random(90) < 0.5] = np.nan
        costmap.integrate(x, y, theta, ranges)
        segment = int(rng.integers(0, len(waypoints) - 1))
        progress = arc[segment] + rng.uniform(0.0, 1.0) * (arc[segment + 1] - arc[segment])
        horizon, spacing, radius = rng.uniform(0.5, 4.0), 0.25, rng.uniform(0.2, 1.0)
        along = np.arange(progress, min(progress + horizon, arc[-1]) + spacing, spacing)
        along = along[along <= arc[-1]]
        points = np.column_stack(
            (np.interp(along, arc, waypoints[:, 0]), np.interp(along, arc, waypoints[:, 1]))
        )
        exact = costmap.new_marks_near(points, radius, since)
        high = min(progress + horizon, arc[-1]) + 2.0 * spacing
        plan = (waypoints.ctypes.data, arc.ctypes.data, len(waypoints))
        maybe = costmap.new_marks_maybe_near(since, plan, segment, progress, high, radius)
        assert maybe or not exact
        answers.add((maybe, exact))
    assert answers == {(False, False), (True, False), (True, True)}


def evenly_spaced_beams_full(count):
    return np.linspace(-math.pi, math.pi, count, endpoint=False)


def test_the_costmap_grids_obstacle_distance_is_the_full_transform_bit_for_bit():
    """`Costmap.grid()` carries its obstacle distance, made from the known map's transform lowered
    round each mark: equal to the exact transform of the whole grid (known cells and marks) as
    marks come and go, and whatever the known map (a fresh one each time: not the shared one)."""
    from cosim.world.lidar import evenly_spaced_beams
    from planner.inflation import distance_to_nearest, obstacle_distance

    rng = np.random.default_rng(5)
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[0, :] = occupied[:, -1] = True
    occupied[rng.integers(0, 40, 300), rng.integers(0, 60, 300)] = True  # near everywhere: small squares
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    angles = evenly_spaced_beams(-math.pi, math.pi, 90)
    costmap = Costmap(grid, angles, 0.0, 12.0)
    discs = [(rng.uniform(3, 27), rng.uniform(3, 17), rng.uniform(0.3, 1.2)) for _ in range(12)]
    x, y, theta = 15.0, 10.0, 0.3
    for _ in range(20):
        discs = [(cx + rng.normal(0, 0.3), cy + rng.normal(0, 0.3), r) for cx, cy, r in discs]
        x, y, theta = x + rng.normal(0, 0.4), y + rng.normal(0, 0.4), theta + rng.normal(0, 0.5)
        costmap.integrate(x, y, theta, _disc_ranges(x, y, theta, angles, discs, 12.0))
        seen = costmap.grid()
        assert "obstacle_distance" in seen._cache  # made from the marks, not transformed
        expected = distance_to_nearest(seen.occupied) * seen.resolution
        assert np.array_equal(obstacle_distance(seen), expected)
    assert costmap.marked.sum() > 10
