"""What a search needs besides the options: the padded blocked map of a grid and reusable work arrays.

Both are cached, so a query on a map already seen allocates nothing of the map's size:
the blocked map per (grid, expansion distance) on the grid itself, the work arrays per padded
size in this module (the GIL serialises compiled searches, so sharing them is safe).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation

from planner.grid import OccupancyGrid
from planner.inflation import cost_gradient, inflation_mask

_STAMP_LIMIT = 2**31 - 8


class SearchMap:
    """A grid prepared for the compiled search.

    blocked: uint8, (rows + 2) * (cols + 2), 0 free, 1 obstacle/inflated/border, 2 untrusted point.
    inflated: bool [rows, cols], the cells added by the expansion distance.
    """

    __slots__ = ("grid", "rows", "cols", "width", "blocked", "inflated", "expansion_distance", "_costs")

    def __init__(self, grid: OccupancyGrid, expansion_distance: float) -> None:
        rows, cols = grid.shape
        self.grid = grid
        self.rows, self.cols, self.width = rows, cols, cols + 2
        self.expansion_distance = expansion_distance
        self.inflated = inflation_mask(grid, expansion_distance)
        obstacle = grid.occupied | self.inflated
        # Untrusted points (first improvement): free cells whose 3x3 neighbourhood holds an obstacle
        # of the map the search sees (inflated cells count as obstacles).
        untrusted = binary_dilation(obstacle, structure=np.ones((3, 3), dtype=bool)) & ~obstacle
        padded = np.ones((rows + 2, cols + 2), dtype=np.uint8)
        inner = padded[1:-1, 1:-1]
        inner[:] = 0
        inner[untrusted] = 2
        inner[obstacle] = 1
        self.blocked = padded.ravel()
        self._costs: dict = {}

    def node(self, row: int, col: int) -> int:
        """Padded flat index of cell (row, col)."""
        return (row + 1) * self.width + col + 1

    def costs(self, cost_scaling_factor: float) -> np.ndarray:
        """Padded flat cost gradient in [0, 1] (see planner.inflation.cost_gradient)."""
        cached = self._costs.get(cost_scaling_factor)
        if cached is None:
            padded = np.zeros((self.rows + 2, self.cols + 2))
            padded[1:-1, 1:-1] = cost_gradient(self.grid, self.expansion_distance, cost_scaling_factor)
            cached = self._costs[cost_scaling_factor] = padded.ravel()
        return cached


def search_map(grid: OccupancyGrid, expansion_distance: float) -> SearchMap:
    """The cached SearchMap of `grid` inflated by `expansion_distance` [m]."""
    key = ("search_map", expansion_distance)
    cached = grid._cache.get(key)
    if cached is None:
        cached = grid._cache[key] = SearchMap(grid, expansion_distance)
    return cached


class Workspace:
    """Reusable arrays of one search direction over a padded map of `size` cells.

    g [cells] per node; nodes int32 [3, size]: parent, stamp, expanded nodes in closing order;
    heap arrays of one entry per cell, doubled if OPEN ever outgrows them (decrease-keys push a node
    again, so OPEN can in theory hold up to 8 entries per cell).
    """

    __slots__ = ("g", "nodes", "generation", "heap_key", "heap_node")

    def __init__(self, size: int) -> None:
        self.g = np.empty(size)
        self.nodes = np.zeros((3, size), dtype=np.int32)
        self.generation = 0
        self.heap_key = np.empty(size, dtype=np.int64)
        self.heap_node = np.empty(size, dtype=np.int32)

    def grow_heap(self) -> None:
        """Double the heap arrays (a search returned status -1: OPEN outgrew them)."""
        self.heap_key = np.empty(2 * len(self.heap_key), dtype=np.int64)
        self.heap_node = np.empty(2 * len(self.heap_node), dtype=np.int32)

    def next_generation(self) -> int:
        """A fresh generation (OPEN = generation, CLOSED = generation + 1) with no stale stamps."""
        self.generation += 2
        if self.generation >= _STAMP_LIMIT:
            self.nodes[1] = 0
            self.generation = 2
        return self.generation


_NO_COST = np.zeros(1)
_workspaces: dict[tuple[int, int], Workspace] = {}


def workspace(size: int, direction: int = 0) -> Workspace:
    """The shared workspace for padded maps of `size` cells (direction 1: bidirectional backward)."""
    key = (size, direction)
    found = _workspaces.get(key)
    if found is None:
        # Keep a few map sizes only, so a long session over many maps does not hoard memory.
        if len(_workspaces) >= 8:
            _workspaces.pop(next(iter(_workspaces)))
        found = _workspaces[key] = Workspace(size)
    return found


def no_cost() -> np.ndarray:
    """A placeholder cost array for searches without a cost gradient (never indexed)."""
    return _NO_COST
