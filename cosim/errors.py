"""Errors a user can cause in the orchestrator; see `planner.errors.NavcosimError`."""

import re

from planner.errors import NavcosimError


class CosimError(NavcosimError):
    """Bad scenario, bad FMU, a failed FMU, a bad log file. One-line message."""


class SimulationEnded(CosimError):
    """An FMU asked to end the simulation (FMI 3.0 terminateSimulation, FMI 2.0 Discard with
    fmi2Terminated): the run ends cleanly at the last communication point every component reached.
    A `CosimError`, so a caller that does not expect it stops as at a failure; `component` names
    the FMU, `time` [s] the start of the step in which it asked."""

    def __init__(self, message: str, component: str, time: float) -> None:
        super().__init__(message)
        self.component = component
        self.time = time


QUOTE_LIMIT = 80  # characters of a user's value quoted in an error message
PATH_LIMIT = 200  # characters of a path quoted in an error message
WHERE_LIMIT = 120  # characters of the key path an error names, e.g. [components.lag].ports.u
WORD_LIMIT = 120  # characters of a name, value or path without spaces in a message (see shorten_words)


def shorten(text: object, limit: int = QUOTE_LIMIT) -> str:
    """`text` on one line, cut to `limit` characters with an ellipsis (a value or path in a message)."""
    text = str(text).replace("\n", "\\n").replace("\r", "\\r")
    return text if len(text) <= limit else text[: limit - 1] + "…"


_LONG_WORD = re.compile(rf"\S{{{WORD_LIMIT + 1},}}")


def shorten_words(text: str, limit: int = 1000) -> str:
    """`text` with every run of more than `WORD_LIMIT` characters without a space cut (a message
    that quotes names or values the user wrote, which may be megabytes long), and at most `limit`
    characters in all."""
    return shorten(_LONG_WORD.sub(lambda match: shorten(match.group(0), WORD_LIMIT), text), limit)
