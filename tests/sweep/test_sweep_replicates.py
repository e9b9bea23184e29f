"""Replicates, kept logs and keys without effect: seeds derived from the point, outcome records that
--resume checks as it checks logs, and warnings decided from the scenario (a seed without noise,
checked against real runs) or from the outcomes."""

from __future__ import annotations

import json
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import build_parser
from cosim.cli.sweep import resume_command
from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.navigation.outcome import outcome_metadata
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from cosim.sweep.adapter import noise_levels, outcome_keys
from cosim.sweep.effect import outcome_warnings, seed_warnings
from cosim.sweep.engine import _row, kept_row_problem, kept_text, plan, record_name
from cosim.sweep.spec import MAX_POINTS, SEED_LIMIT, make_spec, parse_vary, replicate_seeds
from cosim.sweep.worker import TaskResult, keeps_log

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SHORT = "simulation.stop_time=0.3"  # [s]: three lidar scans


def _spec(*vary: str, replicates: int = 1, overrides=(SHORT,)):
    return make_spec(
        SCENARIO, [parse_vary(text) for text in vary], overrides=overrides, replicates=replicates
    )


def test_each_point_gets_distinct_seeds_derived_from_the_point_alone():
    spec = _spec("pure_pursuit.desired_linear_velocity=1.0,1.5", "lidar.noise=0.05", replicates=3)
    _, runs, _ = plan(spec)
    assert len(runs) == 6 and [run.point for run in runs] == [0, 0, 0, 1, 1, 1]
    assert spec.table_keys == (
        "pure_pursuit.desired_linear_velocity",
        "lidar.noise",
        "replicate",
        "lidar.seed",
    )
    for run in runs:
        varied = tuple(o for o in run.overrides if o != SHORT and not o.startswith("lidar.seed="))
        seed = replicate_seeds(varied, 3)[run.values[2]]
        assert f"lidar.seed={seed}" in run.overrides and run.values[3] == seed and 0 <= seed < SEED_LIMIT
    seeds = [run.values[3] for run in runs]
    assert len(set(seeds[:3])) == 3 and len(set(seeds[3:])) == 3 and seeds[:3] != seeds[3:]
    # The same point in another sweep (other base overrides, other points) gets the same seeds.
    _, again, _ = plan(
        _spec("pure_pursuit.desired_linear_velocity=1.5", "lidar.noise=0.05", replicates=3, overrides=())
    )
    assert [run.values[3] for run in again] == seeds[3:]
    assert len({run.run_id for run in runs}) == 6


def test_replicates_refuse_a_varied_seed_and_count_against_the_limit():
    with pytest.raises(CosimError, match="vary it or replicate, not both"):
        _spec("lidar.seed=0,1", replicates=2)
    with pytest.raises(CosimError, match=r"x 3 replicates"):
        _spec(f"lidar.noise=0:0.1:{MAX_POINTS // 2}", replicates=3)
    with pytest.raises(CosimError, match="--replicates 0: must be >= 1"):
        _spec("lidar.noise=0.1", replicates=0)


def _scans(overrides: list[str], path: Path) -> np.ndarray:
    result = run_scenario(load_scenario(SCENARIO, [SHORT, *overrides]), path, progress=False)
    assert result.failure is None
    with open_log(path) as log:
        return np.array([message.message.ranges for message in log.messages("/scan")])


def test_the_lidar_seed_changes_a_run_only_through_its_noise(tmp_path):
    """The fact behind the warning, from real runs: without noise two seeds scan alike, with noise not."""
    quiet = [_scans([f"lidar.seed={seed}"], tmp_path / f"quiet{seed}.mcap") for seed in (1, 2)]
    np.testing.assert_array_equal(quiet[0], quiet[1])
    noisy = [
        _scans(["lidar.noise=0.05", f"lidar.seed={seed}"], tmp_path / f"noisy{seed}.mcap") for seed in (1, 2)
    ]
    assert not np.array_equal(noisy[0], noisy[1])


@pytest.mark.parametrize(
    ("vary", "replicates", "overrides", "warned"),
    [
        (["lidar.seed=0:3:4"], 1, (), ["--vary lidar.seed: lidar.noise is 0 in every run"]),
        (["lidar.seed=0:3:4", "lidar.noise=0.0,0.05"], 1, (), []),
        (["lidar.seed=0:3:4", "lidar.noise=0.0,0.0"], 1, (), ["--vary lidar.seed: lidar.noise is 0"]),
        (["lidar.seed=0:3:4"], 1, ("lidar.noise=0.02",), []),
        (["vfh.safety_distance=0.1,0.3"], 4, (), ["--replicates 4: lidar.noise is 0 in every run"]),
        (["vfh.safety_distance=0.1,0.3"], 4, ("lidar.noise=0.02",), []),
        (["vfh.safety_distance=0.1,0.3"], 1, (), []),
    ],
)
def test_a_seed_without_noise_is_warned_before_anything_runs(vary, replicates, overrides, warned):
    spec = _spec(*vary, replicates=replicates, overrides=overrides)
    base = load_scenario(SCENARIO, list(overrides), check_world=False)
    warnings = seed_warnings(spec, noise_levels(base))
    assert len(warnings) == len(warned)
    for warning, start in zip(warnings, warned, strict=True):
        assert warning.startswith(start), warning


def _row_of(values: dict[str, str], time: str, reason: str = "goal_reached") -> dict[str, str]:
    return {**values, "status": "completed", "reason": reason, "time": time, "distance": "3.0"}


def test_a_key_whose_values_gave_the_same_outcomes_is_warned_after_the_runs():
    keys, outcome = ("scenario.description", "vfh.safety_distance"), ("reason", "time", "distance")
    rows = [
        _row_of({keys[0]: text, keys[1]: distance}, time)
        for distance, time in (("0.1", "10.0"), ("0.3", "12.0"))
        for text in ("a", "b", "c")
    ]
    warnings = outcome_warnings(rows, keys, keys, outcome)
    assert len(warnings) == 1 and warnings[0].startswith(
        "--vary scenario.description: its 3 values gave the same"
    )
    rows[0]["time"] = "10.5"  # one group differs: the key changed something
    assert outcome_warnings(rows, keys, keys, outcome) == []
    rows[0]["status"] = "failed"  # a failed run is not an outcome
    assert len(outcome_warnings(rows, keys, keys, outcome)) == 1
    assert outcome_warnings(rows, keys, keys, outcome, skip=keys[:1]) == []


@pytest.mark.parametrize(
    ("policy", "reason", "error", "kept"),
    [
        ("all", "goal_reached", None, True),
        ("failed", "goal_reached", None, False),
        ("failed", "collision", None, True),
        ("failed", "stop_time", None, True),
        ("failed", None, "an FMU failed", True),
        ("none", "collision", None, False),
        ("none", None, "an FMU failed", False),
    ],
)
def test_which_logs_a_sweep_keeps(policy, reason, error, kept):
    assert keeps_log(policy, {"reason": reason} if reason else None, error) is kept


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A sweep folder whose two completed runs kept an outcome record instead of a log."""
    out = tmp_path_factory.mktemp("sweep")
    (out / "runs").mkdir()
    spec = _spec("lidar.noise=0.0,0.1")
    _, runs, _ = plan(spec)
    rows = []
    for run in runs:
        log = out / f"{run.run_id}.mcap"
        result = run_scenario(load_scenario(SCENARIO, list(run.overrides)), log, progress=False)
        with open_log(log) as opened:
            assert opened.metadata["outcome"] == outcome_metadata(result.outcome)
        log.unlink()  # as --keep-logs none does: the worker's log goes once the row is recorded
        task = TaskResult(run.run_id, outcome_metadata(result.outcome), None, 0.5, "tcp://w", None, ".mcap")
        rows.append(_row(run, spec.table_keys, task, out))
    return out, runs, rows


def test_a_row_without_its_log_is_kept_when_its_outcome_record_agrees(recorded):
    out, runs, rows = recorded
    assert sorted(path.name for path in (out / "runs").iterdir()) == sorted(
        Path(record_name(run.run_id)).name for run in runs
    )
    assert all(row["log"] == "" for row in rows)
    assert [kept_row_problem(row, run, out) for row, run in zip(rows, runs, strict=True)] == [None, None]
    record = json.loads((out / record_name(runs[0].run_id)).read_text())
    assert record["overrides"] == list(runs[0].overrides)
    assert {key: rows[0][key] for key in outcome_keys()} == record["outcome"]


def test_a_row_whose_outcome_record_is_missing_other_or_differs_runs_again(recorded, tmp_path):
    out, runs, rows = recorded
    assert (
        kept_row_problem(dict(rows[0], distance="0.5"), runs[0], out)
        == "row differing from its outcome record"
    )
    assert kept_row_problem(rows[1], runs[0], out) == "outcome record of another run"
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    record = copy / record_name(runs[0].run_id)
    record.write_text(json.dumps(dict(json.loads(record.read_text()), overrides=[SHORT])))
    assert kept_row_problem(rows[0], runs[0], copy) == "outcome record of another run"
    record.write_text("{not json")
    assert kept_row_problem(rows[0], runs[0], copy) == "outcome record unreadable"
    record.unlink()
    assert kept_row_problem(rows[0], runs[0], copy) == "no log and no outcome record"


def test_an_interrupted_sweep_says_what_it_kept_and_the_command_that_resumes_it(tmp_path):
    argv = ["sweep", str(SCENARIO), "--vary", "lidar.noise=0.0,0.1", "--set", "simulation.stop_time=2"]
    argv += ["--replicates", "3", "--keep-logs", "failed", "--workers", "2", "--quiet"]
    args = build_parser("sweep").parse_args(argv)
    command = resume_command(args, tmp_path / "my sweep")
    again = build_parser("sweep").parse_args(shlex.split(command)[1:])
    assert shlex.split(command)[0] == "cosim" and again.resume and again.out == tmp_path / "my sweep"
    assert {k: v for k, v in vars(again).items() if k not in ("resume", "out")} == {
        k: v for k, v in vars(args).items() if k not in ("resume", "out")
    }
    rows = [{"status": "completed"}] * 4 + [{"status": "failed"}]
    text = kept_text(rows, 12, tmp_path, "failed")
    assert (
        "kept 5 of 12 rows" in text
        and "(4 completed, 1 failed" in text
        and str(tmp_path / "results.csv") in text
    )
