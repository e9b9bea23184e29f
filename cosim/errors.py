"""Errors a user can cause in the orchestrator; see `planner.errors.NavcosimError`."""

from planner.errors import NavcosimError


class CosimError(NavcosimError):
    """Bad scenario, bad FMU, a failed FMU, a bad log file. One-line message."""
