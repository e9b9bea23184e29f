"""Shortest grid distance from every cell to a goal: the obstacle-aware heuristic of hybrid A*.

A compiled Dijkstra: the grid A* kernel with the zero heuristic and no goal, run until OPEN is
empty; the distances are the g values it leaves in the workspace.
"""

from __future__ import annotations

import numpy as np

from planner.astar import (
    HEAP_FULL,
    HEURISTICS,
    NO_COST,
    TIE_BREAKERS,
    astar_search,
    search_parameters,
)
from planner.endpoints import check_grid
from planner.errors import PlannerError
from planner.grid import OccupancyGrid
from planner.options import choice, flag
from planner.searchspace import search_map, workspace


def distance_to_goal(
    grid: OccupancyGrid, goal_cell: tuple[int, int], connectivity: int = 8, corner_cutting: bool = False
) -> np.ndarray:
    """Shortest grid distance [m] from every cell to `goal_cell` (row, col): a compiled Dijkstra.

    Steps cost resolution (straight) and sqrt(2) * resolution (diagonal); inf on obstacles and
    where the goal cannot be reached. Used as an obstacle-aware heuristic by hybrid A*.
    """
    check_grid(grid, "distance_to_goal()")
    choice("connectivity", connectivity, (4, 8))
    corner_cutting = flag("corner_cutting", corner_cutting)
    space = search_map(grid, 0.0)
    row, col = int(goal_cell[0]), int(goal_cell[1])
    if not grid.contains_cell((row, col)):
        raise PlannerError(f"goal cell (row {row}, col {col}) is outside the {space.rows}x{space.cols} map")
    if grid.occupied[row, col]:
        return np.full(grid.shape, np.inf)
    moves = space.moves(connectivity, corner_cutting, False)
    parameters = search_parameters(space.width, HEURISTICS["zero"], TIE_BREAKERS["none"], True, 1.0, 0.0)
    work = workspace(len(space.blocked))
    while True:
        generation = work.next_generation()
        status, _ = astar_search(moves, NO_COST, parameters, space.node(row, col), -1, generation, work.g,
                                 work.nodes, work.heap)  # fmt: skip
        if status != HEAP_FULL:
            break
        work.grow_heap()
    # The closed cells' g, unpadded, in metres (NumPy: one less kernel to compile on a cold cache).
    padded = (space.rows + 2, space.width)
    inner = (slice(1, -1), slice(1, -1))
    g = work.g.reshape(padded)[inner]
    closed = work.nodes[1].reshape(padded)[inner] == generation + 1
    # (masked before scaling: an open cell's g is whatever an earlier search left, NaN included,
    # and NumPy warned "invalid value encountered in multiply" for it)
    return np.where(closed, g, np.inf) * grid.resolution
