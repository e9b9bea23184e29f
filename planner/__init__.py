"""Occupancy grids and the A* family (grid A* of the thesis, bidirectional, hybrid A*).

This package never imports `cosim`. Its names are imported on first use, so that
`import planner` (and everything that only needs `planner.errors`) stays fast: the
search modules load their C kernels (`native.load`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from planner.errors import NavcosimError, PlannerError

if TYPE_CHECKING:
    from planner.goal_distance import distance_to_goal
    from planner.grid import OccupancyGrid
    from planner.inflation import cost_gradient, inflate
    from planner.planning import plan
    from planner.result import PlanResult

_LAZY = {
    "OccupancyGrid": "planner.grid",
    "PlanResult": "planner.result",
    "cost_gradient": "planner.inflation",
    "inflate": "planner.inflation",
    "distance_to_goal": "planner.goal_distance",
    "plan": "planner.planning",
}

__all__ = [
    "NavcosimError",
    "OccupancyGrid",
    "PlanResult",
    "PlannerError",
    "cost_gradient",
    "distance_to_goal",
    "inflate",
    "plan",
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'planner' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
