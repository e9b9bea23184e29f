"""Smoothing never lengthens a path and never crosses an obstacle or inflated cell (checked by
dense sampling of every segment against the inflated grid); curvature blends are G2."""

import numpy as np
import pytest

import planner
from planner import OccupancyGrid


def _dense_points(path, per_metre=200):
    points = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        count = max(2, int(np.hypot(*(b - a)) * per_metre))
        points.append(a + (b - a) * np.linspace(0, 1, count)[:, None])
    return np.vstack(points)


@pytest.mark.parametrize("method", ["line_of_sight", "curvature"])
@pytest.mark.parametrize("expansion", [0.0, 0.3])
def test_smoothing_shorter_and_clear(method, expansion):
    rng = np.random.default_rng(11)
    occupied = rng.random((50, 50)) < (0.015 if expansion else 0.08)
    grid = OccupancyGrid(occupied, resolution=0.1, origin=(1.0, 1.0))
    inflated = grid.inflate(expansion) if expansion else grid
    free = np.argwhere(~inflated.occupied)
    checked = 0
    for _ in range(30):
        start, goal = (grid.cell_to_world(cell) for cell in free[rng.integers(len(free), size=2)])
        try:
            raw = planner.plan(grid, start, goal, expansion_distance=expansion)
        except planner.PlannerError:
            continue
        smooth = planner.plan(grid, start, goal, expansion_distance=expansion, smoothing=method)
        assert smooth.length <= raw.length + 1e-9
        assert smooth.info["raw_length"] == pytest.approx(raw.length)
        assert np.allclose(smooth.path[0], raw.path[0]) and np.allclose(smooth.path[-1], raw.path[-1])
        cells = inflated.world_to_cells(_dense_points(smooth.path))
        assert not inflated.occupied[cells[:, 0], cells[:, 1]].any()
        checked += 1
    assert checked >= 15


def test_line_of_sight_on_open_map_is_straight():
    grid = OccupancyGrid(np.zeros((20, 30), bool), resolution=0.5)
    start, goal = grid.cell_to_world((18, 1)), grid.cell_to_world((2, 27))
    result = planner.plan(grid, start, goal, smoothing="line_of_sight")
    assert result.path_nodes == 2
    assert result.length == pytest.approx(np.hypot(*(np.array(goal) - np.array(start))))


def _curvature(path):
    first = np.gradient(path, axis=0)
    second = np.gradient(first, axis=0)
    cross = first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]
    return cross / np.hypot(*first.T) ** 3


def test_curvature_blend_is_continuous():
    """One 90-degree corner: curvature starts at 0 on the straight legs and has no jump."""
    from planner.smoothing import corner_blend

    blend = corner_blend(np.array([0.0, 0.0]), np.array([4.0, 0.0]), np.array([4.0, 4.0]), 2.0, 0.001)
    kappa = _curvature(blend)[2:-2]
    assert abs(kappa[0]) < 0.01 and abs(kappa[-1]) < 0.01
    assert np.abs(np.diff(kappa)).max() < 0.01  # dense samples: no step in curvature
    assert (kappa > 0).all()  # a left turn throughout: convex
    assert np.hypot(*np.diff(blend, axis=0).T).sum() < 4.0
