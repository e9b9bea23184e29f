"""The local cluster's fork server warms up on the sweep's first run (`cosim.sweep.engine.first_run`,
laid out from its own bundle as a worker lays it out) and says whether it builds
(`cosim.sweep.warm.first_run_checked`): then no worker checks that run again. Truth: the run
`plan` lists first, and the check a worker makes (`adapter.check_builds` on the bundle's files)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import cosim.sweep.adapter as adapter
from cosim.errors import CosimError
from cosim.sweep import build
from cosim.sweep.engine import first_run, plan
from cosim.sweep.warm import warm_up
from cosim.sweep.worker import redirects

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
GOOD = ["lidar.seed=0:3:4", "lidar.noise=0.02,0.05"]
BAD = ["vfh.robot_radus=0.4,0.5"]  # loads (the name is the FMU's to know), but does not build


def _spec(vary: list[str], tmp_path: Path, replicates: int | None = None):
    return build(SCENARIO, vary, None, None, None, ("simulation.stop_time=5",), tmp_path / "out", None, None,
                 False, replicates)[0]  # fmt: skip


def _worker_check(bundle, run, folder: Path) -> None:
    """What `cosim.sweep.worker.check_task` does on a worker: raises `CosimError` when it fails."""
    files = folder / "files"
    bundle.materialize(files)
    adapter.check_builds(adapter.load(files / bundle.scenario, [*run.overrides, *redirects(run, files)]))


CASES = [(GOOD, None), (["lidar.noise=0.02,0.05"], 3), (["lidar.noise=0.05"], None)]


@pytest.mark.parametrize("vary, replicates", CASES)
def test_the_first_run_is_the_one_plan_lists_first(vary, replicates, tmp_path):
    spec = _spec(vary, tmp_path, replicates)
    bundle, run = first_run(spec)
    _, runs, _ = plan(spec)
    assert run == runs[0]
    assert bundle.files[bundle.scenario] == SCENARIO.read_bytes()


def test_a_sweep_plan_refuses_has_no_first_run(tmp_path):
    spec = _spec(["lidar.noise=0.02"], tmp_path)
    spec = type(spec)(**{**spec.__dict__, "scenario": tmp_path / "missing.toml"})
    assert first_run(spec) is None
    with pytest.raises(CosimError, match="no such scenario file"):
        plan(spec)


def test_the_warm_up_on_the_first_run_builds_what_the_worker_check_builds(tmp_path):
    good = first_run(_spec(GOOD, tmp_path))
    _worker_check(*good, tmp_path / "good")  # builds
    assert warm_up(str(SCENARIO), [], first=good) is True
    bad = first_run(_spec(BAD, tmp_path))
    with pytest.raises(CosimError, match="robot_radus") as truth:
        _worker_check(*bad, tmp_path / "bad")
    with pytest.raises(CosimError, match="robot_radus") as warm:
        warm_up(str(SCENARIO), [], first=bad)
    assert str(warm.value).split(": ")[-1] == str(truth.value).split(": ")[-1]
    assert warm_up(str(SCENARIO), ["lidar.seed=1"]) is False  # no first run: nothing checked


SERVER = """
import sys, time
from multiprocessing import get_context
from pathlib import Path
from cosim.sweep import build
from cosim.sweep.engine import first_run
from cosim.sweep.warm import first_run_checked, start_fork_server, stop_fork_server

def served(vary):
    spec = build(Path(sys.argv[1]), vary, None, None, None, ("simulation.stop_time=5",), None, None,
                 None, False)[0]
    first = first_run(spec)
    start_fork_server(spec.scenario, spec.overrides, first=first)
    worker = get_context("forkserver").Process(target=time.sleep, args=(0,))
    worker.start()  # served once the warm-up is over: the answer is there
    worker.join()
    return first[1].run_id

good, bad = ["lidar.seed=0,1"], ["vfh.robot_radus=0.4,0.5"]
run_id = served(good)
print("good", first_run_checked(run_id))
stop_fork_server()
run_id = served(good)
print("another run", first_run_checked("0" * 16), "then", first_run_checked(run_id))
stop_fork_server()
print("bad", first_run_checked(served(bad)))
stop_fork_server()
"""


@pytest.mark.slow
def test_the_fork_server_answers_once_for_its_own_first_run():
    result = subprocess.run(
        [sys.executable, "-c", SERVER, str(SCENARIO)], capture_output=True, text=True, timeout=300, cwd=REPO
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["good True", "another run False then False", "bad False"]


@pytest.mark.slow
def test_a_first_run_the_fork_server_could_not_build_is_checked_on_a_worker(tmp_path):
    """`cosim sweep` forks its fork server, which finds that the first run does not build: the
    workers start with the runs already queued, and the check then made on a worker stops the
    sweep with its own one-line error (exit 2), before any row is kept."""
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "cosim", "sweep", str(SCENARIO), "--vary", *BAD, "--out", str(out), "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )  # fmt: skip
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cosim: error: "), result.stderr
    assert "no parameter 'robot_radus' (did you mean 'robot_radius'?)" in lines[0]
    assert lines[0].endswith("(checked on the run with vfh.robot_radus=0.4)")
    assert not out.exists(), "a refused sweep leaves nothing behind"
