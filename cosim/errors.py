"""Errors a user can cause in the orchestrator; `NavcosimError` (`native.errors`) is their base."""

import re
import sys

from native.errors import NavcosimError


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


# The first bytes of the files a user may hand to the wrong command.
_MCAP_MAGIC = b"\x89MCAP0\r\n"  # the MCAP format's magic (cosim.record.mcap_format.MAGIC)
_ZIP_MAGIC = b"PK\x03\x04"  # a zip archive's first local file header: an FMU or an SSP


def file_kind(path) -> str:
    """What `path` holds, judged from its first bytes and, for a zip archive, its member names:
    "mcap" (a log), "ssp", "fmu", "zip" (another archive), "text" (a scenario or any text file),
    "binary", or "missing" (cannot be read)."""
    import zipfile

    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except (OSError, ValueError):
        return "missing"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    if head.startswith(_ZIP_MAGIC):
        try:
            with zipfile.ZipFile(path) as archive:
                names = set(archive.namelist())
        except (OSError, zipfile.BadZipFile, ValueError):
            return "zip"
        if "SystemStructure.ssd" in names:
            return "ssp"
        return "fmu" if "modelDescription.xml" in names else "zip"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as error:
        if error.start < len(head) - 4:  # not merely a character cut by the 4 kB window
            return "binary"
    return "text" if b"\0" not in head else "binary"


_WHAT = {
    "mcap": ("an MCAP log", "`cosim log info {path}` describes it, `cosim log plot {path}` draws it"),
    "ssp": ("an SSP archive", "`cosim run {path}` runs it, `cosim system {path}` shows its system"),
    "fmu": ("an FMU", "`cosim fmu inspect {path}` describes it, `cosim fmu simulate {path}` runs it"),
    "scenario": ("a scenario file", "`cosim run {path}` runs it, `cosim system {path}` shows its system"),
}


def wrong_file_message(path, wanted: str) -> str | None:
    """The one-line error for a file of another kind than a command expects ("… is an MCAP log,
    not a scenario; did you mean `cosim log info …`?"), or None when it is no kind we know."""
    kind = file_kind(path)
    if kind == "text" and str(path).lower().endswith(".toml"):
        kind = "scenario"
    if kind not in _WHAT:
        return None
    what, hint = _WHAT[kind]
    return f"{path}: this is {what}, not {wanted}; {hint.format(path=path)}"


def say(line: str) -> None:
    """Print `line` on stderr without writing it into a progress bar that is showing: through
    `tqdm.write` (which clears the bars on stderr, prints, and draws them again) once tqdm is
    loaded, a plain print otherwise."""
    tqdm_module = sys.modules.get("tqdm")
    if tqdm_module is None:
        print(line, file=sys.stderr, flush=True)
        return
    tqdm_module.tqdm.write(line, file=sys.stderr)
    sys.stderr.flush()
