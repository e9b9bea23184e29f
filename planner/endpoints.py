"""The arguments of a query, checked: the grid, and start and goal points that must lie in a free cell.

The grid planners and hybrid A* raise the same PlannerError messages for the same bad endpoint.
"""

from __future__ import annotations

import math

import numpy as np

from planner.errors import PlannerError
from planner.grid import OccupancyGrid
from planner.searchspace import SearchMap


def _describe(grid: OccupancyGrid, point, cell) -> str:
    return f"({point[0]:g}, {point[1]:g}) m = cell (row {cell[0]}, col {cell[1]})"


def endpoint_node(space: SearchMap, point, role: str) -> int:
    """Padded node of a start/goal point [m]; PlannerError when it is outside, on an obstacle or inflated."""
    grid = space.grid
    try:
        x, y = float(point[0]), float(point[1])
        col = math.floor((x - grid.origin[0]) / grid.resolution)
        row = space.rows - 1 - math.floor((y - grid.origin[1]) / grid.resolution)
    except (TypeError, ValueError, IndexError, OverflowError):
        col = row = -1  # the checks below name the problem
    else:
        if 0 <= row < space.rows and 0 <= col < space.cols:
            node = (row + 1) * space.width + col + 1
            if space.blocked[node] != 1:  # the common case: a free cell, one test
                return node
    return endpoint_error(space, point, role)


def check_endpoint_cell(
    grid: OccupancyGrid, inflated: np.ndarray, expansion_distance: float, point, role: str
) -> tuple[int, int]:
    """The (row, col) of a start/goal point (x, y) [m]; PlannerError when it is outside the map, on
    an obstacle, or inside the inflation (`inflated`, bool [row, col], by `expansion_distance` m)."""
    row, col = grid.world_to_cell((point[0], point[1]))
    where = f"{role} {_describe(grid, point, (row, col))}"
    if not grid.contains_cell((row, col)):
        width, height = grid.size_m
        raise PlannerError(
            f"{where} is outside the map (x in [{grid.origin[0]:g}, {grid.origin[0] + width:g}), "
            f"y in [{grid.origin[1]:g}, {grid.origin[1] + height:g}) m)"
        )
    if grid.occupied[row, col]:
        raise PlannerError(f"{where} is on an obstacle")
    if inflated[row, col]:
        raise PlannerError(
            f"{where} is inside the inflation (expansion_distance {expansion_distance:g} m) "
            "around an obstacle"
        )
    return row, col


def endpoint_error(space: SearchMap, point, role: str) -> int:
    """The padded node of `point` by the thorough path: raises the PlannerError that says why the point
    cannot be an endpoint (the fast checks found that it cannot)."""
    grid = space.grid
    try:
        x, y = float(point[0]), float(point[1])
    except (TypeError, ValueError, IndexError):
        raise PlannerError(f"{role} must be (x, y) in metres, got {point!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlannerError(f"{role} must be finite (x, y) in metres, got {point!r}")
    row, col = check_endpoint_cell(grid, space.inflated, space.expansion_distance, (x, y), role)
    return space.node(row, col)


def check_grid(grid, caller: str = "plan()") -> OccupancyGrid:
    """`grid` itself when it is an OccupancyGrid; PlannerError otherwise."""
    if not isinstance(grid, OccupancyGrid):
        raise PlannerError(f"{caller} needs an OccupancyGrid, got {type(grid).__name__}")
    return grid
