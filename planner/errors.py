"""The one exception type for errors a user can cause.

It lives in `planner` because `planner` never imports `cosim`; `cosim.errors.CosimError`
derives from it, so `except NavcosimError` catches every user-facing error of the project.
"""


class NavcosimError(Exception):
    """An error the user can cause and fix (bad input, bad file, no path). One-line message."""


class PlannerError(NavcosimError):
    """Bad map, bad start/goal, bad option, or no path."""
