"""Errors a user can cause in the orchestrator; see `planner.errors.NavcosimError`."""

from planner.errors import NavcosimError


class CosimError(NavcosimError):
    """Bad scenario, bad FMU, a failed FMU, a bad log file. One-line message."""


QUOTE_LIMIT = 80  # characters of a user's value quoted in an error message
PATH_LIMIT = 200  # characters of a path quoted in an error message


def shorten(text: object, limit: int = QUOTE_LIMIT) -> str:
    """`text` on one line, cut to `limit` characters with an ellipsis (a value or path in a message)."""
    text = str(text).replace("\n", "\\n").replace("\r", "\\r")
    return text if len(text) <= limit else text[: limit - 1] + "…"
