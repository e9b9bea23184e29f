"""What a search needs besides the options: the padded blocked map of a grid and reusable work arrays.

Both are cached, so a query on a map already seen allocates nothing of the map's size:
the blocked map per (grid, expansion distance) on the grid itself, the work arrays per padded
size in this module (the C kernels hold the GIL, so sharing them is safe).
"""

from __future__ import annotations

import weakref

import numpy as np

from planner.astar import HEAP_SLACK, WorkState
from planner.grid import OccupancyGrid
from planner.inflation import cost_gradient, dilate_square, inflation_mask

_STAMP_LIMIT = 2**31 - 8
_PATH_ROWS = 1024  # first size of a workspace's path buffers; grown when a path is longer
# (row, col) step of each move, in the bit order of SearchMap.moves and planner.astar.neighbour_tables.
MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


class SearchMap:
    """A grid prepared for the compiled search.

    blocked: uint8, (rows + 2) * (cols + 2), 0 free, 1 obstacle/inflated/border, 2 untrusted point.
    inflated: bool [rows, cols], the cells added by the expansion distance.
    grid: the grid, held weakly: the grid's cache holds this map, and a strong reference back
        would make a cycle that only the cyclic collector frees (a one-off grid's arrays would stay
        until it ran).
    """

    __slots__ = (
        "_grid",
        "rows",
        "cols",
        "width",
        "blocked",
        "inflated",
        "expansion_distance",
        "_costs",
        "_moves",
    )

    def __init__(self, grid: OccupancyGrid, expansion_distance: float) -> None:
        rows, cols = grid.shape
        self._grid = weakref.ref(grid)
        self.rows, self.cols, self.width = rows, cols, cols + 2
        self.expansion_distance = expansion_distance
        self.inflated = inflation_mask(grid, expansion_distance)
        obstacle = grid.occupied | self.inflated
        # Untrusted points (first improvement): free cells whose 3x3 neighbourhood holds an obstacle
        # of the map the search sees (inflated cells count as obstacles).
        untrusted = dilate_square(obstacle) & ~obstacle
        padded = np.ones((rows + 2, cols + 2), dtype=np.uint8)
        inner = padded[1:-1, 1:-1]
        inner[:] = 0
        inner[untrusted] = 2
        inner[obstacle] = 1
        self.blocked = padded.ravel()
        self._costs: dict = {}
        self._moves: dict = {}

    @property
    def grid(self) -> OccupancyGrid:
        return self._grid()

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

    def moves(self, connectivity: int, corner_cutting: bool, untrusted: bool) -> np.ndarray:
        """Padded flat uint8 move masks: bit k set when move k (MOVES) may leave the cell.

        A move needs its target free (with `untrusted`, an untrusted point is not free) and, for a
        diagonal without `corner_cutting`, both orthogonally adjacent cells not obstacles (untrusted
        points do not block a corner). With 4-connectivity only the straight bits are set. Computed
        once per option set, so the search loop tests one bit per neighbour; the endpoints' exemption
        from the untrusted points is added per query by `open_endpoints`.
        """
        key = (connectivity, corner_cutting, untrusted)
        cached = self._moves.get(key)
        if cached is not None:
            return cached
        rows, cols = self.rows, self.cols
        padded = self.blocked.reshape(rows + 2, self.width)
        enterable = padded == 0 if untrusted else padded != 1
        not_obstacle = padded != 1
        masks = np.zeros((rows + 2, self.width), dtype=np.uint8)
        for bit, (d_row, d_col) in enumerate(MOVES[:connectivity]):
            allowed = enterable[1 + d_row : rows + 1 + d_row, 1 + d_col : cols + 1 + d_col].copy()
            if d_row and d_col and not corner_cutting:
                allowed &= not_obstacle[1 + d_row : rows + 1 + d_row, 1 : cols + 1]
                allowed &= not_obstacle[1 : rows + 1, 1 + d_col : cols + 1 + d_col]
            masks[1:-1, 1:-1] |= allowed.astype(np.uint8) << bit
        masks[padded == 1] = 0  # never expanded; keeps the masks of blocked cells out of the way
        cached = self._moves[key] = masks.ravel()
        return cached

    def open_endpoints(
        self, moves: np.ndarray, nodes: tuple[int, ...], connectivity: int, corner_cutting: bool
    ) -> list[tuple[int, int]]:
        """Let the moves into `nodes` (start and goal, exempt from the untrusted points) in `moves`;
        returns what to give `restore` after the search."""
        saved = []
        width, blocked = self.width, self.blocked
        for node in nodes:
            for bit, (d_row, d_col) in enumerate(MOVES[:connectivity]):
                source = node - d_row * width - d_col
                if blocked[source] == 1:
                    continue
                if d_row and d_col and not corner_cutting:
                    if blocked[source + d_row * width] == 1 or blocked[source + d_col] == 1:
                        continue
                saved.append((source, int(moves[source])))
                moves[source] |= 1 << bit
        return saved

    @staticmethod
    def restore(moves: np.ndarray, saved: list[tuple[int, int]]) -> None:
        """Undo `open_endpoints` (in reverse, so a cell saved twice gets its first value back)."""
        for source, value in reversed(saved):
            moves[source] = value


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
    heap int64 [2, capacity + HEAP_SLACK]: keys and nodes of OPEN (the kernel keeps HEAP_SLACK spare
    slots after the last entry), room for one entry per cell at first, doubled if OPEN ever outgrows
    it (decrease-keys push a node again, so OPEN can in theory hold up to 8 entries per cell); path
    float64 and cells int64 [C, 2]: the last path, (x, y) [m] and (row, col) per node, which the
    caller copies out.
    """

    __slots__ = ("g", "nodes", "heap", "path", "cells", "state")

    def __init__(self, size: int) -> None:
        self.g = np.empty(size)
        self.nodes = np.zeros((3, size), dtype=np.int32)
        self.heap = np.empty((2, size + HEAP_SLACK), dtype=np.int64)
        self.path = np.empty((_PATH_ROWS, 2))
        self.cells = np.empty((_PATH_ROWS, 2), dtype=np.int64)
        # The arrays' addresses and the generation, for the C kernel (planner.astar.WorkState): a
        # prepared search hands the kernel this one structure, which stays valid as the arrays grow.
        self.state = WorkState(
            self.g.ctypes.data, self.nodes.ctypes.data, size, self.heap.ctypes.data, self.heap.shape[1],
            self.path.ctypes.data, self.cells.ctypes.data, _PATH_ROWS, 0,
        )  # fmt: skip

    @property
    def generation(self) -> int:
        """The generation of the last search (the C kernel advances it itself)."""
        return self.state.generation

    def grow_path(self, count: int) -> None:
        """Path buffers of at least `count` rows (a search's path did not fit)."""
        rows = max(count, 2 * len(self.path))
        self.path = np.empty((rows, 2))
        self.cells = np.empty((rows, 2), dtype=np.int64)
        self.state.path = self.path.ctypes.data
        self.state.cells = self.cells.ctypes.data
        self.state.path_rows = rows

    def grow_heap(self) -> None:
        """Double the heap arrays (a search returned HEAP_FULL: OPEN outgrew them)."""
        self.heap = np.empty((2, 2 * (self.heap.shape[1] - HEAP_SLACK) + HEAP_SLACK), dtype=np.int64)
        self.state.heap = self.heap.ctypes.data
        self.state.capacity = self.heap.shape[1]

    def next_generation(self) -> int:
        """A fresh generation (OPEN = generation, CLOSED = generation + 1) with no stale stamps."""
        generation = self.state.generation + 2
        if generation >= _STAMP_LIMIT:
            self.nodes[1] = 0
            generation = 2
        self.state.generation = generation
        return generation


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
