"""What a planner returns: the path and the metrics of the thesis's Tables 3.1-3.4."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(slots=True)
class PlanResult:
    """A planned path with its metrics.

    path: N x 2 (x, y) [m] for grid planners, N x 3 (x, y, theta) [m, m, rad] for hybrid A*.
    cells: N x 2 (row, col) grid cells of the path (grid planners; for hybrid, the cells under
        the poses).
    length: path length [m] (sum of segment lengths of `path`).
    path_nodes: number of nodes (poses) in the path.
    searched_nodes: number of nodes expanded (popped from OPEN and closed).
    elapsed: wall-clock time of the search [s] (excludes map loading and JIT compilation).
    explored: bool array of the grid's shape, True where a cell was expanded (for plots).
    directions: for hybrid A*, +1 forward / -1 reverse per pose; None for grid planners.
    planner: the configuration's name, e.g. "astar", "bidirectional", "hybrid".

    Not frozen: a frozen dataclass sets each field through object.__setattr__, which cost ~5 us per
    plan, a measurable share of a small map's query.
    """

    path: np.ndarray
    cells: np.ndarray
    length: float
    path_nodes: int
    searched_nodes: int
    elapsed: float
    explored: np.ndarray
    directions: np.ndarray | None = None
    planner: str = "astar"
    info: dict = field(default_factory=dict)
