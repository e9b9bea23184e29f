"""The results of a sweep: `results.csv`, written a row at a time, `aggregate.csv` and the summary.

Columns of results.csv: `run_id`, one per varied key (the value as the override gave it), with
`--replicates` also `replicate` and each seed key (`lidar.seed`), `status` (`completed` or
`failed`), the log's outcome metadata (`reached`, `reason`, `time` [s], `distance` [m],
`min_clearance` [m], `vfh_interventions`, `recovery_time` [s], `replans`, and any key the run loop
adds), `wall_time` [s] on the worker, `worker` (its address), `log` (relative to the sweep folder;
empty when --keep-logs did not keep it) and `error` (why a failed run did not complete).

A run is *completed* when it ran to an outcome of its own: the goal was reached, the vehicle
collided, or the stop time came. Not reaching the goal is a result, not a failure. A run *failed*
when it could not be loaded or built, an FMU failed, it was interrupted, or its worker died.

The summary and aggregate.csv count the runs by outcome (`outcome_of`: the reason of a completed
run, else `failed`) and take each metric over the goal-reached runs only, so that a collision's
time never mixes into the time to the goal; the runs that ended otherwise are listed.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
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

    def append(self, row: dict[str, str], durable: bool = True) -> None:
        """Add `row` at the end, on the disk (`fsync`) before this returns; not `durable`: only
        handed to the system (kept as well if this process dies), for a row that `rewrite` writes
        again at once, where waiting for the disk (up to tens of ms) would only delay the end."""
        with open(self.path, "a", encoding="utf-8") as stream:
            stream.write(_csv_text(self.header, [row], False))
            stream.flush()
            if durable:
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


def _float(text: str | None) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


# Outcome reasons in the order the summary and the plot name them; a reason the run loop adds later
# comes after these, and `failed` (a run that did not complete) always last.
REASON_ORDER = ("goal_reached", "collision", "stop_time", "no_path", "fmu_terminated")
GOAL = "goal_reached"
NOT_METRICS = ("reached", "reason", "no_path")  # outcome keys that are no numbers


def outcome_of(row: dict[str, str]) -> str:
    """What became of a run: its outcome reason when it completed, else `failed`."""
    return (row.get("reason") or "?") if row.get("status") == COMPLETED else FAILED


def count_outcomes(rows: Sequence[dict[str, str]]) -> dict[str, int]:
    """Runs per outcome (`goal_reached`, `collision`, ..., `failed`), in `REASON_ORDER`."""
    counts: dict[str, int] = {}
    for row in rows:
        counts[outcome_of(row)] = counts.get(outcome_of(row), 0) + 1
    rank = {reason: index for index, reason in enumerate(REASON_ORDER)}
    return dict(
        sorted(counts.items(), key=lambda item: (item[0] == FAILED, rank.get(item[0], len(rank)), item[0]))
    )


def metric_keys(outcome_keys: Sequence[str]) -> list[str]:
    return [key for key in outcome_keys if key not in NOT_METRICS]


@dataclass(frozen=True)
class Stats:
    """Of `n` values: mean, sample standard deviation (NaN for fewer than two), min and max."""

    n: int
    mean: float
    std: float
    low: float
    high: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Stats | None:
        if not values:
            return None
        mean = math.fsum(values) / len(values)
        std = (
            math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1))
            if len(values) > 1
            else math.nan
        )
        return cls(len(values), mean, std, min(values), max(values))


@dataclass
class Point:
    """The runs of one point of the sweep (its replicates: one run without --replicates).

    `outcomes` counts the runs by outcome; `metrics` holds the statistics of each metric over the
    runs that reached the goal only, so a collision's time or clearance never mixes into them."""

    values: dict[str, str]  # varied key -> value as the table shows it
    rows: list[dict[str, str]]
    outcomes: dict[str, int]
    metrics: dict[str, Stats]

    @property
    def runs(self) -> int:
        return len(self.rows)

    def count(self, outcome: str) -> int:
        return self.outcomes.get(outcome, 0)


def group_points(
    rows: Sequence[dict[str, str]], keys: Sequence[str], outcome_keys: Sequence[str]
) -> list[Point]:
    """The rows grouped by the values of the varied `keys` (seeds of replicates are not among
    them), in the order of each point's first row."""
    groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
    for row in rows:
        groups.setdefault(tuple(row.get(key, "") for key in keys), []).append(row)
    points = []
    for values, members in groups.items():
        reached = [row for row in members if outcome_of(row) == GOAL]
        metrics = {}
        for key in metric_keys(outcome_keys):
            stats = Stats.of([v for v in (_float(row.get(key)) for row in reached) if v is not None])
            if stats is not None:
                metrics[key] = stats
        points.append(Point(dict(zip(keys, values, strict=True)), members, count_outcomes(members), metrics))
    return points


AGGREGATE_FILE = "aggregate.csv"


def _number_text(value: float) -> str:
    return "" if math.isnan(value) else f"{value:.6g}"


def write_aggregate(
    path: Path, points: Sequence[Point], keys: Sequence[str], outcome_keys: Sequence[str]
) -> None:
    """`aggregate.csv`: one row per point: the varied keys, `runs`, a count per outcome that occurs
    in the sweep (`goal_reached`, `collision`, ..., `failed`), then `<metric>_mean`, `_std`, `_min`,
    `_max` over the point's goal-reached runs (empty when none reached it; `_std` empty for one)."""
    outcomes = list(count_outcomes([row for point in points for row in point.rows]))
    metrics = metric_keys(outcome_keys)
    header = [*keys, "runs", *outcomes]
    header += [f"{metric}_{stat}" for metric in metrics for stat in ("mean", "std", "min", "max")]
    lines = []
    for point in points:
        line = {**point.values, "runs": str(point.runs)}
        line.update({outcome: str(point.count(outcome)) for outcome in outcomes})
        for metric in metrics:
            stats = point.metrics.get(metric)
            if stats is not None:
                line[f"{metric}_mean"] = _number_text(stats.mean)
                line[f"{metric}_std"] = _number_text(stats.std)
                line[f"{metric}_min"] = _number_text(stats.low)
                line[f"{metric}_max"] = _number_text(stats.high)
        lines.append(line)
    temporary = path.with_name(f".{path.name}.{os.getpid()}")
    temporary.write_text(_csv_text(header, lines, True), encoding="utf-8")
    os.replace(temporary, path)


@dataclass
class SummaryInput:
    """What `format_summary` prints."""

    title: str
    rows: list[dict[str, str]]
    keys: Sequence[str]  # varied keys (not the replicates' seeds)
    outcome_keys: Sequence[str]
    wall_time: float  # [s]
    executed: int  # runs made by this sweep (not kept from an earlier one)
    workers: int | None
    files: list[tuple[str, Path]]  # ("results", path), ("plot", path), ...
    replicates: int = 1
    warnings: list[str] = field(default_factory=list)
    listed_keys: Sequence[str] = ()  # the values that name a listed run (default `keys`)


LISTED = 5  # runs listed per outcome that is not the goal, and failed runs listed
POINTS_LISTED = 20  # points of a replicated sweep in the summary's table


def _outcome_line(counts: dict[str, int]) -> str:
    return ", ".join(f"{reason} {count}" for reason, count in counts.items() if reason != FAILED) or "none"


def _point_name(values: dict[str, str]) -> str:
    return " ".join(f"{key}={value}" for key, value in values.items())


def format_summary(summary: SummaryInput) -> str:
    """The table printed at the end of a sweep: runs by outcome, the rate of the executed runs, the
    metrics of the goal-reached runs (min/mean/max; per point with replicates), the runs that ended
    otherwise listed with where they ended, the failed runs with their errors, and any warning."""
    rows = summary.rows
    counts = count_outcomes(rows)
    failed = [row for row in rows if row.get("status") != COMPLETED]
    completed = len(rows) - len(failed)
    rate = 60.0 * summary.executed / summary.wall_time if summary.wall_time > 0 else 0.0
    workers = f", {summary.workers} workers)" if summary.workers else ")"
    lines = [
        ("sweep", summary.title),
        ("completed", f"{completed} of {len(rows)}: {_outcome_line(counts)}"),
        ("failed", str(len(failed))),
        ("wall time", f"{summary.wall_time:.1f} s ({rate:.1f} runs/min{workers}"),
        *((name, str(path)) for name, path in summary.files),
    ]
    width = max(len(name) for name, _ in lines) + 2
    text = [f"{name:<{width}}{value}" for name, value in lines]
    metrics = metric_keys(summary.outcome_keys)
    reached = [row for row in rows if outcome_of(row) == GOAL]
    if summary.replicates > 1:
        text += _point_table(summary, metrics)
    else:
        table = []
        for key in metrics:
            stats = Stats.of([v for v in (_float(row.get(key)) for row in reached) if v is not None])
            if stats is not None:
                table.append((key, stats))
        if table:
            text.append("")
            name = f"metric ({len(reached)} goal-reached runs)"
            metric_width = max(width, len(name) + 2)
            text.append(f"{name:<{metric_width}}{'min':>12}{'mean':>12}{'max':>12}")
            text += [f"{k:<{metric_width}}{s.low:>12.4g}{s.mean:>12.4g}{s.high:>12.4g}" for k, s in table]
    for reason, count in counts.items():
        if reason in (GOAL, FAILED):
            continue
        ended = [row for row in rows if outcome_of(row) == reason]
        text.append("")
        text.append(f"{reason} ({count} run{'s' if count != 1 else ''}):")
        for row in ended[:LISTED]:
            where = ", ".join(
                f"{key} {_float(row.get(key)):.4g}{unit}"
                for key, unit in (("time", " s"), ("distance", " m"), ("min_clearance", " m"))
                if _float(row.get(key)) is not None
            )
            values = _point_name({key: row.get(key, "") for key in summary.listed_keys or summary.keys})
            text.append(f"  {row['run_id']}  {values}  ({where})")
        if len(ended) > LISTED:
            text.append(f"  ... and {len(ended) - LISTED} more (see {RESULTS_FILE})")
    if failed:
        text.append("")
    for row in failed[:LISTED]:
        text.append(f"failed {row['run_id']}: {row.get('error') or '?'}")
    if len(failed) > LISTED:
        text.append(f"... and {len(failed) - LISTED} more failed runs (see {RESULTS_FILE})")
    if summary.warnings:
        text.append("")
        text += [f"warning: {warning}" for warning in summary.warnings]
    rule = "-" * min(120, max(len(line) for line in text))
    return "\n".join([rule, *text, rule])


def _point_table(summary: SummaryInput, metrics: list[str]) -> list[str]:
    """Per point: runs by outcome and mean ± std [min, max] of the goal-reached runs' time and
    minimum clearance (every metric is in aggregate.csv)."""
    points = group_points(summary.rows, summary.keys, summary.outcome_keys)
    shown = [metric for metric in ("time", "min_clearance") if metric in metrics]
    names = [_point_name(point.values) for point in points[:POINTS_LISTED]]
    name_width = max([len("point"), *map(len, names)]) + 2
    outcomes = [_outcome_line(point.outcomes | {FAILED: 0}) for point in points[:POINTS_LISTED]]
    outcome_width = max([len("outcomes"), *map(len, outcomes)]) + 2
    header = f"{'point':<{name_width}}{'runs':>5}  {'outcomes':<{outcome_width}}"
    header += "".join(f"  {metric + ' mean ± std [min, max]':<34}" for metric in shown)
    text = ["", f"per point, over {summary.replicates} replicates (goal-reached runs only):", header]
    for name, outcome, point in zip(names, outcomes, points, strict=False):
        failed = f", failed {point.count(FAILED)}" if point.count(FAILED) else ""
        line = f"{name:<{name_width}}{point.runs:>5}  {outcome + failed:<{outcome_width}}"
        for metric in shown:
            stats = point.metrics.get(metric)
            cell = "-"
            if stats is not None:
                spread = f" ± {stats.std:.3g}" if not math.isnan(stats.std) else ""
                cell = f"{stats.mean:.4g}{spread} [{stats.low:.4g}, {stats.high:.4g}]"
            line += f"  {cell:<34}"
        text.append(line.rstrip())
    if len(points) > POINTS_LISTED:
        text.append(f"... and {len(points) - POINTS_LISTED} more points (see {AGGREGATE_FILE})")
    return text
