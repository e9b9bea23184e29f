"""Inflation (expansion distance): exact Euclidean rule, against a brute-force distance computation."""

import numpy as np
import pytest

import planner
from planner import OccupancyGrid, PlannerError
from planner.inflation import cost_gradient


def _brute_force_inflation(occupied, resolution, radius):
    rows, cols = np.indices(occupied.shape)
    obstacles = np.argwhere(occupied)
    distance = np.sqrt(
        (rows[..., None] - obstacles[:, 0]) ** 2 + (cols[..., None] - obstacles[:, 1]) ** 2
    ).min(axis=-1)
    return distance * resolution <= radius + 1e-9


@pytest.mark.parametrize("radius", [0.0, 0.3, 0.5, 0.75, 1.0, 1.4])
def test_inflation_matches_brute_force(radius):
    occupied = np.random.default_rng(4).random((20, 25)) < 0.05
    grid = OccupancyGrid(occupied, resolution=0.25)
    inflated = planner.inflate(grid, radius)
    assert np.array_equal(inflated.occupied, _brute_force_inflation(occupied, 0.25, radius))
    assert np.array_equal(grid.inflate(radius).occupied, inflated.occupied)
    assert inflated.resolution == grid.resolution and inflated.origin == grid.origin


def test_exact_radius_counts_as_inside():
    occupied = np.zeros((9, 9), bool)
    occupied[4, 4] = True
    inflated = OccupancyGrid(occupied, resolution=0.5).inflate(1.0)  # 2 cells
    assert inflated.occupied[4, 6] and inflated.occupied[4, 2] and not inflated.occupied[4, 7]
    assert not inflated.occupied[6, 6]  # sqrt(8) * 0.5 m = 1.41 m > 1 m


def test_bad_radius():
    grid = OccupancyGrid(np.zeros((3, 3), bool))
    for radius in (-0.1, float("inf"), "x"):
        with pytest.raises(PlannerError, match="expansion_distance"):
            grid.inflate(radius)


def test_cost_gradient_decays():
    occupied = np.zeros((1, 12), bool)
    occupied[0, 0] = True
    cost = cost_gradient(
        OccupancyGrid(occupied, resolution=0.5), expansion_distance=1.0, cost_scaling_factor=2.0
    )
    distance = np.arange(12) * 0.5
    expected = np.exp(-2.0 * np.maximum(distance - 1.0, 0.0))
    assert np.allclose(cost[0], expected)


def test_inflated_paths_keep_the_expansion_distance():
    """Every cell of a path planned with an expansion distance is farther than it from every obstacle."""
    rng = np.random.default_rng(7)
    occupied = rng.random((60, 60)) < 0.04
    occupied[:3, :3] = occupied[-3:, -3:] = False
    grid = OccupancyGrid(occupied, resolution=0.2)
    obstacles = np.argwhere(occupied)
    checked = 0
    for radius in (0.2, 0.35, 0.5):
        free = np.argwhere(~grid.inflate(radius).occupied)
        for _ in range(8):
            start, goal = free[rng.integers(len(free), size=2)]
            try:
                result = planner.plan(
                    grid, grid.cell_to_world(start), grid.cell_to_world(goal), expansion_distance=radius
                )
            except PlannerError as error:
                assert "no path" in str(error)
                continue
            cells = result.cells
            distance = np.sqrt(((cells[:, None, :] - obstacles[None, :, :]) ** 2).sum(-1)).min(1) * 0.2
            assert (distance > radius).all()
            checked += 1
    assert checked >= 10
