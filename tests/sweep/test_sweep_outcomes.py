"""`cosim sweep` end to end on a local Dask cluster, with runs that end in every way: goal reached,
collision and stop time, replicated, keeping only the logs of the runs that missed the goal. The
printed counts, aggregate.csv and the kept files are checked against the rows and the logs."""

from __future__ import annotations

import csv
import re
import statistics
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from cosim.logs import open_log

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
# The goal 4 m ahead of the start: reached at about 2 s, unless the stop time comes first (1 s) or
# the obstacle stands between them (a collision at about 0.7 s).
BASE = ["--set", "goal.x=10.0", "--set", "goal.y=6.0", "--set", "lidar.noise=0.05"]
VARY = ["--vary", "obstacles.0.center=[60.0, 19.25],[8.5, 6.0]", "--vary", "simulation.stop_time=1.0,4.0"]
OPTIONS = ["--replicates", "2", "--keep-logs", "failed", "--workers", "2"]
OUTCOME = ("reached", "reason", "time", "distance", "min_clearance", "vfh_interventions", "recovery_time")


def _sweep(*arguments: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), *arguments]
    return subprocess.run(command, capture_output=True, text=True, cwd=REPO, timeout=600)


def _table(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("outcomes") / "sweep"
    result = _sweep(*BASE, *VARY, *OPTIONS, "--out", str(out))
    assert result.returncode == 0, result.stderr
    return out, result


@pytest.mark.slow
def test_the_summary_and_aggregate_say_what_the_runs_did(swept):
    out, result = swept
    rows = _table(out / "results.csv")
    assert len(rows) == 8 and [row["replicate"] for row in rows] == ["0", "1"] * 4
    assert all(row["status"] == "completed" for row in rows)
    reasons = Counter(row["reason"] for row in rows)
    assert reasons == {"goal_reached": 2, "collision": 4, "stop_time": 2}  # as the scenario is built
    said = re.search(r"^completed\s+8 of 8: (.*)$", result.stdout, re.M)[1]
    assert dict(re.findall(r"(\w+) (\d+)", said)) == {reason: str(n) for reason, n in reasons.items()}
    for row in rows:
        if row["reason"] == "collision":
            assert row["run_id"] in result.stdout.split("collision (4 runs):")[1]
    aggregate = _table(out / "aggregate.csv")
    assert len(aggregate) == 4
    for line in aggregate:
        runs = [
            row
            for row in rows
            if (row["obstacles.0.center"], row["simulation.stop_time"])
            == (line["obstacles.0.center"], line["simulation.stop_time"])
        ]
        assert int(line["runs"]) == len(runs) == 2
        assert {reason: int(line[reason]) for reason in reasons} == {
            reason: sum(row["reason"] == reason for row in runs) for reason in reasons
        }
        times = [float(row["time"]) for row in runs if row["reason"] == "goal_reached"]
        if times:
            assert float(line["time_mean"]) == pytest.approx(statistics.mean(times), rel=1e-5)
            assert float(line["time_std"]) == pytest.approx(statistics.stdev(times), rel=1e-5, abs=1e-9)
        else:
            assert line["time_mean"] == ""
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_replicates_get_their_own_seeds_and_only_the_missed_goals_keep_a_log(swept):
    out, _ = swept
    rows = _table(out / "results.csv")
    for first, second in zip(rows[::2], rows[1::2], strict=True):
        assert first["lidar.seed"] != second["lidar.seed"]
    expected = set()
    for row in rows:
        if row["reason"] == "goal_reached":
            assert row["log"] == ""
            expected.add(f"{row['run_id']}.outcome.json")
        else:
            assert row["log"] == f"runs/{row['run_id']}.mcap"
            expected.add(f"{row['run_id']}.mcap")
            with open_log(out / row["log"]) as log:
                assert {key: row[key] for key in OUTCOME} == {
                    key: log.metadata["outcome"][key] for key in OUTCOME
                }
                assert f"lidar.seed={row['lidar.seed']}" in log.metadata["navcosim"]["overrides"].split()
    assert {path.name for path in (out / "runs").iterdir()} == expected


@pytest.mark.slow
def test_resume_keeps_every_row_with_its_log_or_outcome_record(swept):
    out, _ = swept
    before = _table(out / "results.csv")
    result = _sweep(*BASE, *VARY, *OPTIONS, "--out", str(out), "--resume")
    assert result.returncode == 0, result.stderr
    assert "8 from an earlier sweep" in result.stdout and "run again" not in result.stderr
    assert _table(out / "results.csv") == before


@pytest.mark.slow
def test_a_seed_sweep_without_noise_is_warned(tmp_path):
    result = _sweep(
        "--set", "simulation.stop_time=0.3", "--vary", "lidar.seed=0,1", "--out", str(tmp_path / "s")
    )
    assert result.returncode == 0, result.stderr
    assert "warning: --vary lidar.seed: lidar.noise is 0 in every run" in result.stderr
    assert "warning: --vary lidar.seed: lidar.noise is 0 in every run" in result.stdout  # in the summary too
