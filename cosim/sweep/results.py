"""The results table of a sweep: `results.csv`, written a row at a time, and its summary.

Columns: `run_id`, one per varied key (the value as the override gave it), `status` (`completed`
or `failed`), the log's outcome metadata (`reached`, `reason`, `time` [s], `distance` [m],
`min_clearance` [m], `vfh_interventions`, `recovery_time` [s], and any key the run loop adds, such
as replans), `wall_time` [s] on the worker, `worker` (its address), `log` (relative to the sweep
folder) and `error` (why a failed run did not complete; empty otherwise).

A run is *completed* when it ran to an outcome of its own: the goal was reached, the vehicle
collided, or the stop time came. Not reaching the goal is a result, not a failure. A run *failed*
when it could not be loaded or built, an FMU failed, it was interrupted, or its worker died.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from cosim.errors import CosimError

COMPLETED, FAILED = "completed", "failed"
RESULTS_FILE = "results.csv"
TIMING_COLUMNS = ("wall_time", "worker")  # differ between two runs of the same sweep


def columns(keys: Sequence[str], outcome_keys: Sequence[str]) -> list[str]:
    return ["run_id", *keys, "status", *outcome_keys, "wall_time", "worker", "log", "error"]


def _csv_text(header: list[str], rows: list[dict[str, str]], with_header: bool) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=header, extrasaction="ignore", lineterminator="\n")
    if with_header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


class ResultsFile:
    """`results.csv`: rows appended (and flushed) as runs finish, so an interrupted sweep keeps
    every finished row; `rewrite` puts them in sweep order at the end."""

    def __init__(self, path: Path, header: list[str]) -> None:
        self.path = path
        self.header = header

    def rewrite(self, rows: list[dict[str, str]]) -> None:
        temporary = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        temporary.write_text(_csv_text(self.header, rows, True), encoding="utf-8")
        os.replace(temporary, self.path)

    def append(self, row: dict[str, str]) -> None:
        with open(self.path, "a", encoding="utf-8") as stream:
            stream.write(_csv_text(self.header, [row], False))
            stream.flush()
            os.fsync(stream.fileno())


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of an existing `results.csv` (none when there is no file)."""
    if not path.is_file():
        return []
    try:
        with open(path, encoding="utf-8", newline="") as stream:
            return list(csv.DictReader(stream))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise CosimError(f"{path}: cannot read the results of the earlier sweep: {error}") from None


def read_table(path: Path):
    """`results.csv` as a pandas DataFrame (text columns as strings, the rest parsed)."""
    import pandas as pd

    text = {"run_id": str, "status": str, "reason": str, "worker": str, "log": str, "error": str}
    return pd.read_csv(path, dtype=text)


def _float(text: str) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if not math.isnan(value) else None


def format_summary(
    title: str,
    rows: list[dict[str, str]],
    outcome_keys: Sequence[str],
    wall_time: float,
    executed: int,
    workers: int | None,
    results_path: Path,
    plot_path: Path | None,
) -> str:
    """The table printed at the end of a sweep: counts, the rate of the `executed` runs over
    `wall_time` [s], and min/mean/max of each metric over the completed runs."""
    completed = [row for row in rows if row.get("status") == COMPLETED]
    failed = [row for row in rows if row.get("status") != COMPLETED]
    reached = sum(row.get("reached") == "true" for row in completed)
    rate = 60.0 * executed / wall_time if wall_time > 0 else 0.0
    lines = [
        ("sweep", title),
        ("completed", f"{len(completed)} of {len(rows)} (goal reached in {reached})"),
        ("failed", str(len(failed))),
        (
            "wall time",
            f"{wall_time:.1f} s ({rate:.1f} runs/min" + (f", {workers} workers)" if workers else ")"),
        ),
        ("results", str(results_path)),
    ]
    if plot_path is not None:
        lines.append(("plot", str(plot_path)))
    width = max(len(name) for name, _ in lines) + 2
    text = [f"{name:<{width}}{value}" for name, value in lines]
    metrics = [key for key in outcome_keys if key not in ("reached", "reason")]
    table = []
    for key in metrics:
        values = [v for v in (_float(row.get(key)) for row in completed) if v is not None]
        if values:
            table.append((key, min(values), sum(values) / len(values), max(values)))
    if table:
        text.append("")
        text.append(f"{'metric':<{width}}{'min':>12}{'mean':>12}{'max':>12}")
        text.extend(f"{key:<{width}}{low:>12.4g}{mean:>12.4g}{high:>12.4g}" for key, low, mean, high in table)
    for row in failed[:5]:
        text.append(f"failed {row['run_id']}: {row.get('error') or '?'}")
    if len(failed) > 5:
        text.append(f"... and {len(failed) - 5} more failed runs (see {results_path.name})")
    rule = "-" * max(len(line) for line in text)
    return "\n".join([rule, *text, rule])
