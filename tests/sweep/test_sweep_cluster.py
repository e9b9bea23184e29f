"""Sweeps on real Dask clusters: a LocalCluster, and a `dask scheduler` with `dask worker`s started
here (on 127.0.0.1, in other working directories). Each row is checked against its own log, one
run against a run made without Dask, and the two clusters' tables against each other."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import pytest

import cosim
from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.navigation.outcome import outcome_metadata
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from cosim.sweep.adapter import outcome_keys
from cosim.sweep.plot import plot_sweep
from cosim.sweep.results import TIMING_COLUMNS
from cosim.sweep.warm import WARM_ENV, warm_up

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
BASE = ["--set", "simulation.stop_time=4"]  # [s] simulated: 400 macro steps a run
VARY = ["--vary", "pure_pursuit.desired_linear_velocity=1.0,1.5", "--vary", "lidar.noise=0.0,0.2"]
OUTCOME = (
    "reached",
    "reason",
    "time",
    "distance",
    "min_clearance",
    "vfh_interventions",
    "recovery_time",
    "replans",
)


def _sweep(out: Path, *options: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), *BASE, *VARY, "--out", str(out)]
    return subprocess.run([*command, *options], capture_output=True, text=True, cwd=cwd, timeout=600)


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv", newline="") as stream:
        return list(csv.DictReader(stream))


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "sweep"
    result = _sweep(out, "--workers", "2")
    assert result.returncode == 0, result.stderr
    return out, result


@pytest.mark.slow
def test_each_row_matches_its_log(local_sweep):
    out, result = local_sweep
    rows = _rows(out)
    assert len(rows) == 4 and len({row["run_id"] for row in rows}) == 4
    assert [(row["pure_pursuit.desired_linear_velocity"], row["lidar.noise"]) for row in rows] == [
        ("1.0", "0.0"),
        ("1.0", "0.2"),
        ("1.5", "0.0"),
        ("1.5", "0.2"),
    ]
    for row in rows:
        assert row["status"] == "completed" and row["error"] == ""
        assert row["log"] == f"runs/{row['run_id']}.mcap"
        with open_log(out / row["log"]) as log:
            assert log.is_complete
            assert {key: row[key] for key in OUTCOME} == log.metadata["outcome"]
            overrides = log.metadata["navcosim"]["overrides"].split()
        assert overrides == [
            "simulation.stop_time=4",
            f"lidar.noise={row['lidar.noise']}",
            f"pure_pursuit.desired_linear_velocity={row['pure_pursuit.desired_linear_velocity']}",
        ]
        assert row["worker"].startswith("tcp://127.0.0.1:") and float(row["wall_time"]) > 0
    # Kinematic driving at the commanded speed from rest: the two speeds drive different distances,
    # so rows and logs cannot be paired up wrongly without the check above failing.
    assert float(rows[0]["distance"]) < float(rows[2]["distance"]) <= 1.5 * 4 + 1e-9
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(path.name for path in (out / "runs").iterdir()) == sorted(
        f"{r['run_id']}.mcap" for r in rows
    )
    assert "completed  4 of 4" in result.stdout


@pytest.mark.slow
def test_every_log_equals_a_run_without_dask(local_sweep, tmp_path):
    # The workers fork from a server that made a short run of the first point (cosim.sweep.warm),
    # and a worker makes its runs one after the other: whatever it keeps from a run to the next
    # must not change a log. A log holds no path, PID or wall time, so the same run gives the same bytes.
    out, _ = local_sweep
    for index, row in enumerate(_rows(out)):
        overrides = [
            "simulation.stop_time=4",
            f"lidar.noise={row['lidar.noise']}",
            f"pure_pursuit.desired_linear_velocity={row['pure_pursuit.desired_linear_velocity']}",
        ]
        direct = tmp_path / f"direct{index}.mcap"
        result = run_scenario(load_scenario(SCENARIO, overrides), direct)
        assert outcome_metadata(result.outcome) == {key: row[key] for key in OUTCOME}
        assert (
            hashlib.sha256(direct.read_bytes()).digest()
            == hashlib.sha256((out / row["log"]).read_bytes()).digest()
        )


@pytest.mark.slow
def test_the_plot_process_draws_the_png_this_process_draws(local_sweep, tmp_path):
    # `cosim sweep` draws sweep.png in a plot process forked before the cluster starts, from the rows
    # it sends there; drawn here from the rows results.csv kept, it is the same file, byte for byte.
    out, _ = local_sweep
    keys = ["pure_pursuit.desired_linear_velocity", "lidar.noise"]
    title = f"{load_scenario(SCENARIO, []).name}: grid sweep"
    here = plot_sweep(_rows(out), keys, outcome_keys(), tmp_path / "sweep.png", grid=True, title=title)
    assert here is not None and here.read_bytes() == (out / "sweep.png").read_bytes()


@pytest.mark.slow
def test_the_python_api_returns_the_table(local_sweep):
    out, _ = local_sweep
    rows = _rows(out)
    # In 4 s no obstacle comes near enough for the noise to matter, or it does: the API warns
    # exactly when the two noise levels gave the same outcomes at each speed.
    outcome = [tuple(row[key] for key in OUTCOME) for row in rows]  # noise fastest
    same = outcome[0] == outcome[1] and outcome[2] == outcome[3]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # Every run is in DIR already: resume answers from DIR without starting a cluster.
        table = cosim.sweep(
            SCENARIO,
            {"pure_pursuit.desired_linear_velocity": [1.0, 1.5], "lidar.noise": "0.0:0.2:2"},
            overrides=["simulation.stop_time=4"],
            out=out,
            resume=True,
            progress=False,
            plot=False,
        )
    said = [
        str(w.message) for w in caught if "--vary lidar.noise: its 2 values gave the same" in str(w.message)
    ]
    assert len(said) == same
    assert list(table["run_id"]) == [row["run_id"] for row in rows]
    assert list(table["distance"]) == [float(row["distance"]) for row in rows]
    assert table["reached"].dtype == bool
    assert table["pure_pursuit.desired_linear_velocity"].tolist() == [1.0, 1.0, 1.5, 1.5]


def _stop(process: subprocess.Popen) -> None:
    """End a service we started, by its PID: SIGTERM to its process group, SIGKILL if it lingers."""
    if process.poll() is not None:
        return
    os.killpg(process.pid, signal.SIGTERM)
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=30)


@pytest.fixture(scope="module")
def dask_scheduler(tmp_path_factory):
    """`dask scheduler` on a random port of 127.0.0.1 and `dask worker` (2 processes, 1 thread each),
    each in a working directory of its own; stopped by PID however the tests end."""
    scheduler_dir, worker_dir = tmp_path_factory.mktemp("scheduler"), tmp_path_factory.mktemp("worker")
    scheduler_file = scheduler_dir / "scheduler.json"
    dask = [sys.executable, "-m", "dask"]
    services = []
    try:
        services.append(
            subprocess.Popen(
                [*dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"]
                + ["--scheduler-file", str(scheduler_file)],
                cwd=scheduler_dir,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        deadline = time.monotonic() + 120
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            assert time.monotonic() < deadline and services[0].poll() is None, "the scheduler did not start"
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        services.append(
            subprocess.Popen(
                [*dask, "worker", address, "--nworkers", "2", "--nthreads", "1", "--host", "127.0.0.1"]
                + ["--no-dashboard", "--local-directory", str(worker_dir)],
                cwd=worker_dir,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        yield address
    finally:
        for process in reversed(services):
            _stop(process)


def _comparable(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{key: value for key, value in row.items() if key not in TIMING_COLUMNS} for row in rows]


@pytest.mark.slow
def test_a_sweep_on_a_dask_scheduler_gives_the_same_table(local_sweep, dask_scheduler, tmp_path):
    local_out, _ = local_sweep
    client_dir = tmp_path / "client"
    client_dir.mkdir()
    # From another folder too: the sweep's files reach the workers through Dask, not paths.
    result = _sweep(tmp_path / "remote", "--scheduler", dask_scheduler, cwd=client_dir)
    assert result.returncode == 0, result.stderr
    remote = _rows(tmp_path / "remote")
    assert _comparable(remote) == _comparable(_rows(local_out))
    assert all(row["worker"].startswith("tcp://127.0.0.1:") for row in remote)
    for row in remote:
        with open_log(tmp_path / "remote" / row["log"]) as log:
            assert {key: row[key] for key in OUTCOME} == log.metadata["outcome"]


@pytest.mark.slow
def test_failed_runs_are_rows_interrupt_keeps_rows_and_resume_finishes(dask_scheduler, tmp_path):
    """A run whose start lies inside an obstacle fails on its worker; Ctrl-C (SIGINT to the process
    group, as a terminal sends it) keeps the finished rows and logs; --resume runs what is missing,
    and the failed runs again."""
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--set", "simulation.stop_time=10"]
    command += ["--vary", "simulation.macro_step=0.01,0.001"]
    command += ["--vary", "obstacles.0.center=[60.0, 19.25],[6.0, 6.0]"]
    command += ["--scheduler", dask_scheduler, "--out", str(out)]
    process = subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 300
        while process.poll() is None and time.monotonic() < deadline:
            if (out / "results.csv").exists() and len(_rows(out)) >= 2:
                break
            time.sleep(0.05)
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGINT)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode in (130, 1), stderr  # interrupted, or it had already finished
    assert "Traceback" not in stderr
    before = {row["run_id"]: row for row in _rows(out)}
    assert len(before) >= 2
    if "cosim: interrupted" in stderr:  # not when the sweep had already finished
        completed = sum(row["status"] == "completed" for row in before.values())
        assert f"cosim sweep: interrupted: kept {len(before)} of 4 rows in {out / 'results.csv'}" in stderr
        assert f"({completed} completed, {len(before) - completed} failed" in stderr
        resume = next(
            line for line in stderr.splitlines() if line.startswith("cosim sweep: to run the rest: ")
        )
        assert resume.endswith(f"--out {out} --resume") and "--scheduler" in resume
    for row in before.values():
        assert (out / row["log"]).is_file() if row["log"] else row["status"] == "failed"
    result = subprocess.run([*command, "--resume"], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 1, result.stderr  # some runs failed
    rows = _rows(out)
    assert [row["obstacles.0.center"] for row in rows] == ["[60.0, 19.25]", "[6.0, 6.0]"] * 2
    for row in rows:
        if row["obstacles.0.center"] == "[6.0, 6.0]":
            assert row["status"] == "failed" and row["log"] == ""
            assert str(SCENARIO) in row["error"] and "[start]" in row["error"], row["error"]
        else:
            assert row["status"] == "completed" and row["reason"] == "stop_time"
            with open_log(out / row["log"]) as log:
                assert log.metadata["outcome"] == {key: row[key] for key in OUTCOME}
    for run_id, row in before.items():
        if row["status"] == "completed":  # skipped by resume: the very same row
            assert next(r for r in rows if r["run_id"] == run_id) == row


def _import_warm(request: str | None, tmp_path: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "TMPDIR": str(tmp_path)}
    if request is not None:
        environment[WARM_ENV] = request
    command = [
        sys.executable,
        "-c",
        "import cosim.sweep.warm, os; print(os.environ.get('NAVCOSIM_SWEEP_WARM'))",
    ]
    return subprocess.run(command, capture_output=True, text=True, env=environment, timeout=300)


@pytest.mark.slow
def test_the_fork_server_warm_up_runs_quietly_and_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    warm_up(str(SCENARIO), ["lidar.seed=3"])  # raises if the short run fails
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(CosimError, match="robot_radus"):
        warm_up(str(SCENARIO), ["vfh.robot_radus=0.5"])
    assert list(tmp_path.iterdir()) == []
    # In the fork server: nothing printed, and the request is out of the environment it passes on.
    request = json.dumps({"scenario": str(SCENARIO), "overrides": ["lidar.seed=3"]})
    result = _import_warm(request, tmp_path)
    assert result.returncode == 0 and result.stdout == "None\n" and result.stderr == "", result
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "request_text",
    [
        "not json",
        json.dumps({"scenario": "/no/such/scenario.toml", "overrides": []}),
        json.dumps({"scenario": str(SCENARIO), "overrides": ["vfh.robot_radus=0.5"]}),
    ],
)
def test_a_failed_warm_up_never_stops_the_fork_server(request_text, tmp_path):
    result = _import_warm(request_text, tmp_path)
    assert result.returncode == 0 and result.stdout == "None\n" and result.stderr == "", result
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_quiet_local_sweep_says_nothing_when_port_8787_is_taken(tmp_path):
    # Dask's scheduler serves HTTP even without a dashboard, by default on port 8787; where another
    # program holds that port, Dask warned on stderr that it bound another, through --quiet.
    with socket.socket() as holder:
        try:
            holder.bind(("127.0.0.1", 8787))
            holder.listen()
        except OSError:  # taken already, by someone else: the case to check all the same
            pass
        result = _sweep(tmp_path / "sweep", "--workers", "2", "--quiet", "--no-plot")
    assert result.returncode == 0, result.stderr
    assert result.stderr == "" and result.stdout == ""
    assert len(_rows(tmp_path / "sweep")) == 4
