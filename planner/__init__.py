"""Occupancy grids and the A* family (grid A* of the thesis, bidirectional, hybrid A*).

This package never imports `cosim`.
"""

from planner.errors import NavcosimError, PlannerError

__all__ = ["NavcosimError", "PlannerError"]
