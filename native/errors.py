"""The base of the project's errors a user can cause.

`planner.errors.PlannerError` and `cosim.errors.CosimError` derive from it, so `except
NavcosimError` catches every user-facing error of the project; `planner` and `cosim` re-export it.
"""


class NavcosimError(Exception):
    """An error the user can cause and fix (bad input, bad file, no path). One-line message."""
