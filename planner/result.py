"""What a planner returns: the path and the metrics of the thesis's Tables 3.1-3.4."""

from __future__ import annotations

import numpy as np


def expanded_mask(nodes: np.ndarray, width: int, shape: tuple[int, int]) -> np.ndarray:
    """bool [rows, cols] mask of expanded cells given as flat indices `nodes` of the padded map (one
    blocked border cell around the grid, `width` = cols + 2)."""
    rows, cols = shape
    nodes = nodes.astype(np.int64)
    mask = np.zeros(rows * cols, dtype=bool)
    mask[(nodes // width - 1) * cols + nodes % width - 1] = True
    return mask.reshape(rows, cols)


class PlanResult:
    """A planned path with its metrics.

    path: N x 2 (x, y) [m] for grid planners, N x 3 (x, y, theta) [m, m, rad] for hybrid A*.
    cells: N x 2 (row, col) grid cells of the path (grid planners; for hybrid, the cells under
        the poses).
    length: path length [m] (sum of segment lengths of `path`).
    path_nodes: number of nodes (poses) in the path.
    searched_nodes: number of nodes expanded (popped from OPEN and closed).
    elapsed: wall-clock time of the search [s] (excludes map loading and JIT compilation).
    explored: bool array of the grid's shape, True where a cell was expanded (for plots); given as
        that array, or by a grid search as (expanded padded nodes, padded width, grid shape), which
        becomes the array on first access (most callers never look at it).
    directions: for hybrid A*, +1 forward / -1 reverse per pose; None for grid planners.
    planner: the configuration's name, e.g. "astar", "bidirectional", "hybrid".
    info: planner-specific details (resolved options, timings).

    A plain class with slots, not a dataclass: construction is on every plan() call's path, and the
    explored mask is made lazily so that a query does not allocate an array of the map's size.
    """

    __slots__ = (
        "path",
        "cells",
        "length",
        "path_nodes",
        "searched_nodes",
        "elapsed",
        "_explored",
        "directions",
        "planner",
        "info",
    )

    def __init__(
        self,
        path: np.ndarray,
        cells: np.ndarray,
        length: float,
        path_nodes: int,
        searched_nodes: int,
        elapsed: float,
        explored: np.ndarray | tuple[np.ndarray, int, tuple[int, int]],
        directions: np.ndarray | None = None,
        planner: str = "astar",
        info: dict | None = None,
    ) -> None:
        self.path = path
        self.cells = cells
        self.length = length
        self.path_nodes = path_nodes
        self.searched_nodes = searched_nodes
        self.elapsed = elapsed
        self._explored = explored
        self.directions = directions
        self.planner = planner
        self.info = {} if info is None else info

    @property
    def explored(self) -> np.ndarray:
        """bool [rows, cols], True where a cell was expanded."""
        if isinstance(self._explored, tuple):
            self._explored = expanded_mask(*self._explored)
        return self._explored

    @explored.setter
    def explored(self, value: np.ndarray) -> None:
        self._explored = value

    def __repr__(self) -> str:
        return (
            f"PlanResult(planner={self.planner!r}, length={self.length:.3f} m, path_nodes={self.path_nodes}, "
            f"searched_nodes={self.searched_nodes}, elapsed={self.elapsed:.6f} s)"
        )
