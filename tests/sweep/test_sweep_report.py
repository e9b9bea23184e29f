"""A sweep's report is what its runs did: counts by outcome, metrics of the goal-reached runs only,
the other endings listed, per-point mean and spread over replicates, a plot that marks collided
and failed points. The truth is computed here from the rows themselves (`collections.Counter`,
`statistics`), independently of `cosim.sweep.results`."""

from __future__ import annotations

import csv
import random
import re
import statistics
from collections import Counter
from pathlib import Path

import pytest

from cosim.sweep.adapter import outcome_keys
from cosim.sweep.plot import sweep_figure
from cosim.sweep.results import SummaryInput, format_summary, group_points, write_aggregate

KEYS = ("vfh.safety_distance", "pure_pursuit.desired_linear_velocity")
A_VALUES, B_VALUES = ("0.1", "0.3", "0.5"), ("1.0", "1.5", "2.0")
OUTCOME = outcome_keys()
REASONS = ("goal_reached", "goal_reached", "collision", "stop_time", "failed")


def _rows(replicates: int = 1, seed: int = 0, reasons=REASONS) -> list[dict[str, str]]:
    """Rows as a sweep writes them, over a 3 x 3 grid, with outcomes drawn at random."""
    rng = random.Random(seed)
    rows = []
    for a in A_VALUES:
        for b in B_VALUES:
            for replicate in range(replicates):
                reason = rng.choice(reasons)
                row = {"run_id": f"{len(rows):016x}", KEYS[0]: a, KEYS[1]: b, "replicate": str(replicate)}
                if reason == "failed":
                    row.update(status="failed", error="the worker failed: KilledWorker: boom", log="")
                else:
                    clearance = -rng.uniform(0.001, 0.02) if reason == "collision" else rng.uniform(0.1, 0.8)
                    row.update(
                        status="completed",
                        reached="true" if reason == "goal_reached" else "false",
                        reason=reason,
                        time=f"{rng.uniform(10, 120):.6f}",
                        distance=f"{rng.uniform(20, 115):.6f}",
                        min_clearance=f"{clearance:.6f}",
                        vfh_interventions=str(rng.randint(0, 20)),
                        recovery_time="0.000000",
                        replans="1",
                        log=f"runs/{len(rows):016x}.mcap",
                        error="",
                    )
                rows.append(row)
    return rows


def _outcome(row: dict[str, str]) -> str:
    return row["reason"] if row["status"] == "completed" else "failed"


def _summary(rows, replicates: int = 1) -> str:
    return format_summary(
        SummaryInput(
            "test", rows, KEYS, OUTCOME, 10.0, len(rows), 2, [("results", Path("r.csv"))], replicates
        )
    )


def test_the_summary_counts_runs_by_outcome_and_times_only_goal_reached_runs():
    rows = _rows(seed=6)
    truth = Counter(_outcome(row) for row in rows)
    assert truth["collision"] and truth["goal_reached"] and truth["failed"]  # the draw covers them
    text = _summary(rows)
    completed = re.search(r"^completed\s+(\d+) of (\d+): (.*)$", text, re.M)
    assert int(completed[1]) == len(rows) - truth["failed"] and int(completed[2]) == len(rows)
    said = {reason: int(count) for reason, count in re.findall(r"(\w+) (\d+)", completed[3])}
    assert said == {reason: count for reason, count in truth.items() if reason != "failed"}
    assert re.search(r"^failed\s+(\d+)$", text, re.M)[1] == str(truth["failed"])
    reached = [float(row["time"]) for row in rows if _outcome(row) == "goal_reached"]
    line = re.search(r"^time\s+(\S+)\s+(\S+)\s+(\S+)$", text, re.M)
    assert [float(value) for value in line.groups()] == pytest.approx(
        [min(reached), statistics.mean(reached), max(reached)], rel=1e-3
    )
    assert f"metric ({len(reached)} goal-reached runs)" in text
    # Every collided run is listed under its outcome, with its values and where it ended.
    section = text.split(f"collision ({truth['collision']} run")[1].split("\n\n")[0]
    for row in rows:
        if _outcome(row) == "collision":
            assert f"{row['run_id']}  {KEYS[0]}={row[KEYS[0]]} {KEYS[1]}={row[KEYS[1]]}" in section
            assert f"time {float(row['time']):.4g} s" in section
    for row in rows:
        if _outcome(row) == "failed":
            assert f"failed {row['run_id']}: {row['error']}" in text


def test_the_aggregate_holds_counts_mean_and_spread_of_each_point(tmp_path):
    rows = _rows(replicates=5, seed=1)
    points = group_points(rows, KEYS, OUTCOME)
    write_aggregate(tmp_path / "aggregate.csv", points, KEYS, OUTCOME)
    with open(tmp_path / "aggregate.csv", newline="") as stream:
        table = list(csv.DictReader(stream))
    assert [(line[KEYS[0]], line[KEYS[1]]) for line in table] == [(a, b) for a in A_VALUES for b in B_VALUES]
    for line in table:
        runs = [row for row in rows if (row[KEYS[0]], row[KEYS[1]]) == (line[KEYS[0]], line[KEYS[1]])]
        assert int(line["runs"]) == len(runs) == 5
        truth = Counter(_outcome(row) for row in runs)
        for reason in ("goal_reached", "collision", "stop_time", "failed"):
            assert int(line[reason]) == truth[reason], reason
        for metric in ("time", "min_clearance", "vfh_interventions"):
            values = [float(row[metric]) for row in runs if _outcome(row) == "goal_reached"]
            if not values:
                assert line[f"{metric}_mean"] == line[f"{metric}_min"] == ""
                continue
            assert float(line[f"{metric}_mean"]) == pytest.approx(statistics.mean(values), rel=1e-5)
            assert float(line[f"{metric}_min"]) == pytest.approx(min(values), rel=1e-5)
            assert float(line[f"{metric}_max"]) == pytest.approx(max(values), rel=1e-5)
            if len(values) > 1:
                assert float(line[f"{metric}_std"]) == pytest.approx(statistics.stdev(values), rel=1e-5)
            else:
                assert line[f"{metric}_std"] == ""


def test_the_summary_of_replicates_gives_each_point_its_outcomes_and_spread():
    rows = _rows(replicates=4, seed=2)
    text = _summary(rows, replicates=4)
    for a in A_VALUES:
        for b in B_VALUES:
            runs = [row for row in rows if (row[KEYS[0]], row[KEYS[1]]) == (a, b)]
            line = next(
                line for line in text.splitlines() if line.startswith(f"{KEYS[0]}={a} {KEYS[1]}={b} ")
            )
            counts = Counter(_outcome(row) for row in runs)
            for reason, count in counts.items():
                assert (f"failed {count}" if reason == "failed" else f"{reason} {count}") in line
            times = [float(row["time"]) for row in runs if _outcome(row) == "goal_reached"]
            if len(times) > 1:
                assert f"{statistics.mean(times):.4g} ± {statistics.stdev(times):.3g}" in line
                assert f"[{min(times):.4g}, {max(times):.4g}]" in line


def _marks(axis, marker: str) -> set[tuple[int, int]]:
    """Cells (column, line) of a map panel holding a mark drawn with `marker`."""
    return {
        (round(line.get_xdata()[0]), round(line.get_ydata()[0]))
        for line in axis.get_lines()
        if line.get_marker() == marker
    }


def test_the_plot_is_titled_marks_collided_and_failed_points_and_leaves_constant_metrics_out():
    rows = _rows(seed=6)
    figure = sweep_figure(rows, KEYS, OUTCOME, grid=True, title="warehouse: grid sweep")
    title = figure._suptitle.get_text()
    truth = Counter(_outcome(row) for row in rows)
    assert title.startswith("warehouse: grid sweep\n9 runs: ")
    for reason, count in truth.items():
        assert f"{count} {reason.replace('_', ' ')}" in title
    panels = [axis.get_title() for axis in figure.axes if axis.get_title()]
    assert panels[0] == "share of runs that reached the goal"
    assert {"time [s]", "distance [m]", "min_clearance [m]", "vfh_interventions"} <= set(panels)
    # recovery_time and replans are the same in every run: no panel, no colour bar, named in the title
    assert not any(panel.startswith(("recovery_time", "replans")) for panel in panels)
    assert "not drawn: recovery_time = 0, replans = 1" in title
    cell = {(B_VALUES.index(row[KEYS[1]]), A_VALUES.index(row[KEYS[0]])): _outcome(row) for row in rows}
    for axis in (axis for axis in figure.axes if axis.get_title()):
        assert _marks(axis, "X") == {place for place, outcome in cell.items() if outcome == "collision"}
        assert _marks(axis, "s") == {place for place, outcome in cell.items() if outcome == "failed"}
        assert _marks(axis, "^") == {place for place, outcome in cell.items() if outcome == "stop_time"}


def test_a_one_key_plot_is_laid_out_in_lines_of_panels_not_a_strip():
    rows = _rows(seed=6)
    for index, row in enumerate(rows):
        row["lidar.noise"] = f"{0.01 * index:g}"
    figure = sweep_figure(rows, ["lidar.noise"], OUTCOME, grid=True)
    drawn = [axis for axis in figure.axes if axis.get_title()]
    assert len(drawn) == 5  # outcome + time, distance, min_clearance, vfh_interventions
    width, height = figure.get_size_inches()
    assert width > height
    collided = {float(row["lidar.noise"]) for row in rows if _outcome(row) == "collision"}
    for axis in drawn:
        assert {line.get_xdata()[0] for line in axis.get_lines() if line.get_marker() == "X"} == collided


def test_with_three_keys_each_key_has_its_column():
    rows = _rows(seed=4)
    for index, row in enumerate(rows):
        row["lidar.noise"] = str(index % 2 * 0.05)
    figure = sweep_figure(rows, (*KEYS, "lidar.noise"), OUTCOME, grid=True)
    labels = [axis.get_xlabel() for axis in figure.axes if axis.get_xlabel()]
    assert labels == [*KEYS, "lidar.noise"]
