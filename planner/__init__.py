"""Occupancy grids and the A* family (grid A* of the thesis, bidirectional, hybrid A*).

This package never imports `cosim`.
"""

from planner.errors import NavcosimError, PlannerError
from planner.grid import OccupancyGrid
from planner.inflation import cost_gradient, inflate
from planner.plan import distance_to_goal, plan
from planner.result import PlanResult

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
