"""A sweep trusts nothing it reads back or reaches: resume re-checks every kept row against its
log, a scheduler address that is no Dask scheduler gives one line, and limits come before work."""

from __future__ import annotations

import shutil
import socket
import threading
from pathlib import Path

import pytest

from cosim.errors import CosimError
from cosim.navigation.outcome import outcome_metadata
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from cosim.sweep.engine import kept_row_problem, plan, probe_scheduler
from cosim.sweep.spec import MAX_POINTS, make_spec, parse_vary

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


@pytest.fixture(scope="module")
def earlier_sweep(tmp_path_factory):
    """A sweep folder as a finished sweep leaves it: two runs' logs and their rows."""
    out = tmp_path_factory.mktemp("sweep")
    spec = make_spec(SCENARIO, [parse_vary("lidar.noise=0.0,0.1")], overrides=["simulation.stop_time=1"])
    _, runs, _ = plan(spec)
    (out / "runs").mkdir()
    rows = []
    for run in runs:
        log = out / "runs" / f"{run.run_id}.mcap"
        result = run_scenario(load_scenario(SCENARIO, list(run.overrides)), log)
        rows.append({"run_id": run.run_id, "status": "completed", "log": f"runs/{log.name}"})
        rows[-1].update(outcome_metadata(result.outcome))
    return out, runs, rows


def test_a_whole_row_with_its_own_log_is_kept(earlier_sweep):
    out, runs, rows = earlier_sweep
    assert [kept_row_problem(row, run, out) for row, run in zip(rows, runs, strict=True)] == [None, None]


def test_a_cut_log_is_run_again(earlier_sweep, tmp_path):
    out, runs, rows = earlier_sweep
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    log = copy / rows[0]["log"]
    log.write_bytes(log.read_bytes()[: log.stat().st_size // 2])
    assert kept_row_problem(rows[0], runs[0], copy) == "log incomplete"


def test_a_log_of_another_run_or_outside_the_folder_is_not_kept(earlier_sweep):
    out, runs, rows = earlier_sweep
    assert kept_row_problem(dict(rows[1]), runs[0], out) == "log of another run"
    assert (
        kept_row_problem(dict(rows[0], log="../../etc/passwd"), runs[0], out)
        == "log outside the sweep folder"
    )
    assert kept_row_problem(dict(rows[0], log="runs"), runs[0], out) == "log outside the sweep folder"
    assert kept_row_problem(dict(rows[0], log="runs/none.mcap"), runs[0], out) == "log missing"


def test_a_row_that_differs_from_its_log_or_holds_a_nul_is_not_kept(earlier_sweep):
    out, runs, rows = earlier_sweep
    assert kept_row_problem(dict(rows[0], distance="0.5"), runs[0], out) == "row differing from its log"
    assert kept_row_problem(dict(rows[0], reason="goal\x00"), runs[0], out) == "row with control characters"


def _server(answer: bytes | None):
    """A TCP server on 127.0.0.1 that accepts and sends `answer` (None: stays silent)."""
    listener = socket.create_server(("127.0.0.1", 0))
    accepted = []

    def serve():
        try:
            connection, _ = listener.accept()
        except OSError:
            return
        accepted.append(connection)
        if answer is not None:
            connection.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    return listener, accepted


@pytest.mark.parametrize(
    ("answer", "message"),
    [(None, "no Dask handshake within 0.5 s"), (b"SSH-2.0-OpenSSH_9.6\r\n", "not a Dask scheduler")],
)
def test_a_server_that_is_no_dask_scheduler_gives_one_line(answer, message):
    listener, accepted = _server(answer)
    try:
        with pytest.raises(CosimError, match=message) as error:
            probe_scheduler(f"tcp://127.0.0.1:{listener.getsockname()[1]}", 0.5)
        assert "\n" not in str(error.value)
    finally:
        listener.close()
        for connection in accepted:
            connection.close()


def test_a_dask_like_handshake_passes_the_probe():
    # A scheduler's first frame: an 8-byte little-endian length, then the message.
    listener, accepted = _server((58).to_bytes(8, "little") + bytes(58))
    try:
        probe_scheduler(f"tcp://127.0.0.1:{listener.getsockname()[1]}", 5.0)
    finally:
        listener.close()
        for connection in accepted:
            connection.close()


@pytest.mark.parametrize(
    ("vary", "options", "message"),
    [
        (["lidar.noise=0:0.1:10000000000"], {}, "COUNT 10000000000 is more than a sweep runs"),
        (["lidar.noise=0:0.1:1000", "lidar.seed=0:999:1000"], {}, "the grid has 1000000 points"),
        (["lidar.noise=0:0.1"], {"method": "lhs", "samples": MAX_POINTS + 1}, "more than a sweep runs"),
        (["lidar.noise=" + "[" * 500 + "1" + "]" * 500], {}, "nested too deeply"),
    ],
)
def test_limits_come_before_any_point_is_made(vary, options, message):
    with pytest.raises(CosimError, match=message):
        make_spec(SCENARIO, [parse_vary(text) for text in vary], **options)


@pytest.mark.slow
def test_validation_loads_the_scenario_per_key_not_per_value(monkeypatch):
    import cosim.sweep.adapter as adapter

    loads = []
    real = adapter.load
    monkeypatch.setattr(adapter, "load", lambda *args, **kwargs: loads.append(args) or real(*args, **kwargs))
    spec = make_spec(SCENARIO, [parse_vary("lidar.noise=0:0.1:200"), parse_vary("lidar.seed=0:99:100")])
    _, runs, _ = plan(spec)
    assert len(runs) == 20_000
    assert len(loads) == 1 + 2 * 2  # the base, then each key's smallest and largest value
