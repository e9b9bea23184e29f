"""Expansion distance (the thesis's third improvement): inflation and a nav2-style cost gradient.

Rule: a free cell is *inflated* when the Euclidean distance between its centre and the centre of
the nearest occupied cell is <= the radius [m]. Distances come from an exact Euclidean distance
transform (`distance_to_nearest`, C: planner/native/distance.c), so the rule is exact (no chamfer
approximation) at every resolution.
Consequence: a path through cell centres of the inflated grid keeps more than `radius` from every
obstacle *centre*, i.e. more than `radius - resolution / 2` from an obstacle cell's edge.

The functions take a `planner.grid.OccupancyGrid` but do not import it: the grid's `inflate`
method is built on `inflation_mask`, so the grid module sits above this one.
"""

from __future__ import annotations

import ctypes
import functools
import math
from pathlib import Path
from typing import Protocol

import numpy as np

from native.load import bind, load
from planner.errors import PlannerError

KERNEL_SOURCE = Path(__file__).parent / "native" / "distance.c"


@functools.cache
def _kernels() -> ctypes.CDLL:
    """The distance transform and dilation kernels, loaded (built) on first use."""
    pointer, count, real = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double
    return bind(
        load(KERNEL_SOURCE),
        {
            "navcosim_distance_transform": (count, (pointer, count, count, real, real, pointer)),
            "navcosim_dilate_square": (None, (pointer, count, count, pointer)),
        },
    )


def _cells(mask: np.ndarray) -> np.ndarray:
    """`mask` as a C-ordered 2-D array of bytes 0/1 (no copy for a C-ordered bool array)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"expected a 2-D grid, got shape {mask.shape}")
    return np.ascontiguousarray(mask, dtype=bool).view(np.uint8)


def distance_to_nearest(mask: np.ndarray, sampling: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Exact Euclidean distance from every cell of a 2-D grid to the nearest True cell of `mask`
    (0 on them; inf everywhere when there is none), rows `sampling[0]` and columns `sampling[1]`
    apart: `scipy.ndimage.distance_transform_edt(~mask, sampling=sampling)`, equal bit for bit with
    unit sampling (exact integer squared distances) and to rounding otherwise."""
    cells = _cells(mask)
    rows, cols = cells.shape
    distance = np.empty((rows, cols))
    if cells.size and _kernels().navcosim_distance_transform(
        cells.ctypes.data, rows, cols, float(sampling[0]), float(sampling[1]), distance.ctypes.data
    ):
        raise MemoryError("no memory for the distance transform's scratch lines")
    return distance


def dilate_square(mask: np.ndarray) -> np.ndarray:
    """`mask` dilated by a full 3 x 3 square (a cell is True when it or one of its 8 neighbours is;
    nothing beyond the border): `scipy.ndimage.binary_dilation(mask, structure=np.ones((3, 3)))`."""
    cells = _cells(mask)
    dilated = np.empty(cells.shape, dtype=bool)
    if cells.size:
        _kernels().navcosim_dilate_square(cells.ctypes.data, *cells.shape, dilated.ctypes.data)
    return dilated


class Grid(Protocol):
    """What this module reads of a `planner.grid.OccupancyGrid`."""

    occupied: np.ndarray  # bool [row, col]
    resolution: float  # [m/cell]
    _cache: dict  # derived arrays of the grid (read-only), keyed by name

    @property
    def shape(self) -> tuple[int, int]: ...

    def inflate(self, radius_m: float) -> Grid: ...


def obstacle_distance(grid: Grid) -> np.ndarray:
    """Distance [m] from every cell centre to the nearest occupied cell centre (0 on obstacles).

    With no obstacle at all the distance is inf everywhere. Cached on the grid.
    """
    cached = grid._cache.get("obstacle_distance")
    if cached is not None:
        return cached
    if not grid.occupied.any():
        distance = np.full(grid.shape, np.inf)
    else:
        distance = distance_to_nearest(grid.occupied) * grid.resolution
    distance.flags.writeable = False
    grid._cache["obstacle_distance"] = distance
    return distance


def set_obstacle_distance(grid: Grid, cells: np.ndarray) -> None:
    """Give `grid` its `obstacle_distance` from `cells`, the distance (cells) from every cell to the
    nearest occupied one exactly as `distance_to_nearest(grid.occupied)` gives it (the grid must
    have an occupied cell), made more cheaply elsewhere (a costmap's marks on a known map)."""
    distance = cells * grid.resolution
    distance.flags.writeable = False
    grid._cache["obstacle_distance"] = distance


def _check_radius(radius_m: float, name: str = "expansion_distance") -> float:
    try:
        radius = float(radius_m)
    except (TypeError, ValueError):
        raise PlannerError(f"{name} must be a number of metres, got {radius_m!r}") from None
    if not math.isfinite(radius) or radius < 0.0:
        raise PlannerError(f"{name} must be >= 0 m, got {radius_m!r}")
    return radius


def inflation_mask(grid: Grid, radius_m: float) -> np.ndarray:
    """Bool mask of the cells added by inflating `grid` by `radius_m` [m] (occupied cells excluded)."""
    radius = _check_radius(radius_m)
    if radius == 0.0:
        return np.zeros(grid.shape, dtype=bool)
    # A tiny tolerance so a distance of exactly `radius` (e.g. 2 cells at 0.5 m) counts as inside
    # despite the square root's rounding.
    return (obstacle_distance(grid) <= radius * (1.0 + 1e-12)) & ~grid.occupied


def inflate(grid: Grid, radius_m: float) -> Grid:
    """A new grid whose occupied cells are the obstacles plus every cell within `radius_m` [m] of one."""
    return grid.inflate(radius_m)


def cost_gradient(
    grid: Grid, expansion_distance: float = 0.0, cost_scaling_factor: float = 1.0
) -> np.ndarray:
    """nav2-style inflation cost in [0, 1] per cell: 1 at or inside `expansion_distance` [m] of an
    obstacle, exp(-cost_scaling_factor * (d - expansion_distance)) farther out (d: obstacle distance
    [m], cost_scaling_factor [1/m]); obstacles are 1. The search multiplies a step's length by
    (1 + cost_weight * cost of the cell it enters), which pulls paths away from walls.
    """
    radius = _check_radius(expansion_distance)
    scaling = _check_radius(cost_scaling_factor, "cost_scaling_factor")
    distance = obstacle_distance(grid)
    with np.errstate(over="ignore", invalid="ignore"):
        cost = np.exp(-scaling * np.maximum(distance - radius, 0.0))
    cost[~np.isfinite(distance)] = 0.0
    return cost
