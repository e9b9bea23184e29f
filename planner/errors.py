"""The planner's error a user can cause; `NavcosimError` (`native.errors`) is the project's base."""

from native.errors import NavcosimError

__all__ = ["NavcosimError", "PlannerError"]


class PlannerError(NavcosimError):
    """Bad map, bad start/goal, bad option, or no path."""
