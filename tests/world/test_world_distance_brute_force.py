"""`WorldDistance.distance` (world_distance of world.c: a window around the point, its rows scanned
outward until no square can be nearer) against a brute force over every occupied cell square of
the grid, the map edges and every shape, bit for bit."""

from __future__ import annotations

import ctypes
import ctypes.util
import math

import numpy as np
import pytest

from cosim.world.distance import WorldDistance, distance_to_obstacle
from cosim.world.shapes import Circle, Rectangle
from planner.grid import OccupancyGrid

# The C library's hypot, which world.c's circle distance calls (Python's math.hypot differs from it
# in the last bit for about one pair in 200).
_LIBM = ctypes.CDLL(ctypes.util.find_library("m"))
_LIBM.hypot.restype, _LIBM.hypot.argtypes = ctypes.c_double, (ctypes.c_double, ctypes.c_double)


def _brute_force(world: WorldDistance, x: float, y: float) -> float:
    """The minimum over every occupied square (point-to-square distance, the same operations),
    the distance to the map edge and to every shape."""
    best = min(x - world.x_min, world.x_max - x, y - world.y_min, world.y_max - y)
    rows, cols = np.nonzero(world.occupied)
    if len(rows):
        res, half = world.resolution, world.resolution / 2.0
        centre_x = world.x_min + (cols.astype(np.float64) + 0.5) * res
        centre_y = world.y_min + ((world.rows - 1 - rows).astype(np.float64) + 0.5) * res
        dx = np.maximum(np.abs(centre_x - x) - half, 0.0)
        dy = np.maximum(np.abs(centre_y - y) - half, 0.0)
        best = min(best, math.sqrt(float(np.min(dx * dx + dy * dy))))
    for obstacle in world.obstacles:
        if isinstance(obstacle, Circle):
            gap = _LIBM.hypot(x - obstacle.center[0], y - obstacle.center[1]) - obstacle.radius
            best = min(best, max(0.0, gap))
        else:
            best = min(best, distance_to_obstacle(x, y, obstacle))
    return best


def _points(rng, world: WorldDistance, n: int) -> list[tuple[float, float]]:
    """Random points of the map, a third of them on or next to a cell boundary."""
    res = world.resolution
    points = []
    for _ in range(n):
        x = rng.uniform(world.x_min, world.x_max)
        y = rng.uniform(world.y_min, world.y_max)
        if rng.random() < 0.33:
            x = world.x_min + round((x - world.x_min) / res) * res + rng.choice([0.0, 1e-12, -1e-12])
            y = world.y_min + round((y - world.y_min) / res) * res + rng.choice([0.0, 1e-12, -1e-12])
        if world.inside_map(x, y):
            points.append((x, y))
    return points


@pytest.mark.parametrize("seed", range(12))
def test_world_distance_is_the_brute_force_minimum_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    rows, cols = int(rng.integers(1, 60)), int(rng.integers(1, 60))
    density = [0.0, 0.002, 0.02, 0.1, 0.4, 0.9][seed % 6]
    occupied = rng.random((rows, cols)) < density
    resolution = float(rng.choice([0.05, 0.1, 0.25, 0.5, 1.0, 0.3]))
    origin = (float(rng.uniform(-20, 20)), float(rng.uniform(-20, 20)))
    obstacles = ()
    if seed % 3 == 1:
        width, height = cols * resolution, rows * resolution
        obstacles = (
            Circle((origin[0] + rng.uniform(0, width), origin[1] + rng.uniform(0, height)), 0.3),
            Rectangle(
                (origin[0] + rng.uniform(0, width), origin[1] + rng.uniform(0, height)), (0.8, 0.4), 0.7
            ),
        )
    world = WorldDistance(OccupancyGrid(occupied, resolution, origin), obstacles)
    for x, y in _points(rng, world, 400):
        got, want = world.distance(x, y), _brute_force(world, x, y)
        assert got.hex() == want.hex(), (x, y, got, want)


def test_world_distance_in_a_large_sparse_map_bit_for_bit():
    """A warehouse-like map (long racks, wide aisles): the window holds many rows the scan skips."""
    rng = np.random.default_rng(7)
    occupied = np.zeros((160, 300), dtype=bool)
    occupied[0, :] = occupied[-1, :] = True
    for top in range(20, 150, 25):
        occupied[top : top + 3, 30:270] = True
    occupied[rng.integers(0, 160, 40), rng.integers(0, 300, 40)] = True
    world = WorldDistance(OccupancyGrid(occupied, 0.5, (0.0, 0.0)))
    for x, y in _points(rng, world, 3000):
        got, want = world.distance(x, y), _brute_force(world, x, y)
        assert got.hex() == want.hex(), (x, y, got, want)
