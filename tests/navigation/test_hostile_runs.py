"""Hostile conditions around a run (issue 10): concurrent runs, existing or unwritable logs, and
SIGINT/SIGTERM at every stage. A log is never shared, never overwritten by accident, and always
either finalised or not there; every ending is one line on stderr, never a traceback."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import threading
from datetime import datetime
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cosim.cli import main
from cosim.core import interrupt
from cosim.errors import CosimError
from cosim.navigation import run as run_module
from cosim.navigation.outcome import OutcomeMonitor
from cosim.record.logfile import claim_default_log, claim_log, default_log_path
from cosim.scenario import load as load_module
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "scenarios" / "example_commented.toml"
WAREHOUSE = REPO / "scenarios" / "maps" / "warehouse.yaml"
SHORT = ("--set", "simulation.stop_time=0.5", "--quiet", "--no-plot")  # 50 macro steps
SIGNALS = [signal.SIGINT, signal.SIGTERM]


def finalised_outcome(log: Path) -> dict[str, str]:
    """The outcome metadata of a log that has its summary and footer (a finalised log)."""
    with open(log, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary() is not None, f"{log} is not finalised"
        return {record.name: record.metadata for record in reader.iter_metadata()}["outcome"]


def one_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --- names and concurrency -----------------------------------------------------------------------
def test_default_name_has_milliseconds():
    scenario = load_scenario(EXAMPLE, check_world=False)
    name = default_log_path(
        scenario.log_pattern, scenario.name, datetime(2026, 1, 31, 14, 25, 1, 123456)
    ).name
    assert name == "example_commented-20260131-142501-123.mcap"


def test_a_taken_default_name_gets_a_suffix_from_each_of_four_threads(tmp_path):
    path = tmp_path / "logs" / "run-20260131-142501-123.mcap"
    claimed: list[tuple[Path, object]] = []
    barrier = threading.Barrier(4)

    def claim() -> None:
        barrier.wait()
        claimed.append(claim_default_log(path))

    threads = [threading.Thread(target=claim) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    names = sorted(name.name for name, _ in claimed)
    for _, stream in claimed:
        stream.close()
    assert names == sorted(f"run-20260131-142501-123{suffix}.mcap" for suffix in ("", "-1", "-2", "-3"))


@pytest.mark.slow
def test_four_parallel_default_named_runs_leave_four_complete_logs(tmp_path):
    # A pattern without {timestamp}: all four ask for the same name at the same moment.
    scenario = tmp_path / "parallel.toml"
    text = EXAMPLE.read_text().replace('"maps/warehouse.yaml"', f'"{WAREHOUSE}"')
    scenario.write_text(
        text.replace('log = "logs/{scenario}-{timestamp}.mcap"', 'log = "logs/{scenario}.mcap"')
    )
    command = [sys.executable, "-m", "cosim", "run", str(scenario), *SHORT]
    processes = [
        subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(4)
    ]
    results = [(process.wait(), process.stderr.read()) for process in processes]
    for process in processes:
        process.stdout.close()
        process.stderr.close()
    assert [code for code, _ in results] == [1, 1, 1, 1], results  # stop time, not reached
    assert all(err == "" for _, err in results), results
    logs = sorted((tmp_path / "logs").glob("*.mcap"))
    assert [log.name for log in logs] == [
        "example_commented-1.mcap",
        "example_commented-2.mcap",
        "example_commented-3.mcap",
        "example_commented.mcap",
    ]
    for log in logs:
        outcome = finalised_outcome(log)
        assert outcome["reason"] == "stop_time" and float(outcome["time"]) == 0.5


def test_existing_out_is_refused_and_kept(tmp_path, capsys):
    log = tmp_path / "precious.mcap"
    log.write_bytes(b"an earlier run")
    assert main(["run", str(EXAMPLE), "--out", str(log), *SHORT]) == 2
    assert one_line(capsys.readouterr().err) == (
        f"cosim: error: {log}: already exists; give --force to overwrite it"
    )
    assert log.read_bytes() == b"an earlier run"
    assert main(["run", str(EXAMPLE), "--out", str(log), "--force", *SHORT]) == 1
    assert finalised_outcome(log)["reason"] == "stop_time"


def test_existing_out_refused_at_creation_too(tmp_path):
    """The check before the build is a courtesy; the exclusive create is what holds in a race."""
    log = tmp_path / "raced.mcap"
    log.write_bytes(b"written while we were building")
    with pytest.raises(CosimError, match="already exists; give --force"):
        claim_log(log)
    assert log.read_bytes() == b"written while we were building"


def test_a_live_log_is_never_shared(tmp_path, capsys):
    log = tmp_path / "live.mcap"
    live = claim_log(log)  # as a run that is still writing it holds it
    try:
        assert main(["run", str(EXAMPLE), "--out", str(log), "--force", *SHORT]) == 2
        assert one_line(capsys.readouterr().err) == (
            f"cosim: error: {log}: in use by another run that is still writing it"
        )
    finally:
        live.close()
    assert main(["run", str(EXAMPLE), "--out", str(log), "--force", *SHORT]) == 1
    assert finalised_outcome(log)["reason"] == "stop_time"


def test_out_is_a_directory(tmp_path, capsys):
    assert main(["run", str(EXAMPLE), "--out", str(tmp_path), *SHORT]) == 2
    assert (
        one_line(capsys.readouterr().err)
        == f"cosim: error: {tmp_path}: cannot write the log (Is a directory)"
    )


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_out_dev_full(capsys):
    assert main(["run", str(EXAMPLE), "--out", "/dev/full", *SHORT]) == 2
    assert one_line(capsys.readouterr().err) == (
        "cosim: error: /dev/full: writing the log failed (No space left on device)"
    )
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)  # a device is never renamed to *.failed.mcap


# --- interrupts ----------------------------------------------------------------------------------
def _signal_self(signal_number: int):
    """A wrapper that sends `signal_number` to this process, then calls the wrapped function."""

    def wrap(function):
        def wrapped(*args, **kwargs):
            os.kill(os.getpid(), signal_number)
            return function(*args, **kwargs)

        return wrapped

    return wrap


@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("stage", ["load", "build", "initialise"])
def test_signal_before_the_log_exists(stage, signal_number, tmp_path, capsys, monkeypatch):
    wrap = _signal_self(signal_number)
    if stage == "load":
        monkeypatch.setattr(load_module, "load_scenario", wrap(load_module.load_scenario))
    elif stage == "build":
        monkeypatch.setattr(run_module, "build_run", wrap(run_module.build_run))
    else:
        monkeypatch.setattr(run_module.Master, "initialize", wrap(run_module.Master.initialize))
    log = tmp_path / "run.mcap"
    assert main(["run", str(EXAMPLE), "--out", str(log), *SHORT]) == 1
    name = signal.Signals(signal_number).name
    assert one_line(capsys.readouterr().err) == f"cosim: interrupted ({name})"
    assert list(tmp_path.iterdir()) == []  # nothing written
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # handlers given back


@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_signal_after_the_log_opened_finalises_it(signal_number, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(run_module, "_write_header", _signal_self(signal_number)(run_module._write_header))
    log = tmp_path / "run.mcap"
    assert main(["run", str(EXAMPLE), "--out", str(log), *SHORT]) == 1
    assert capsys.readouterr().err == ""  # an ordinary "not reached" end: the outcome says why
    outcome = finalised_outcome(log)
    assert outcome["reason"] == "interrupted" and float(outcome["time"]) == 0.01  # after one step


@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_signal_while_finalising_keeps_the_complete_log(signal_number, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(OutcomeMonitor, "finish", _signal_self(signal_number)(OutcomeMonitor.finish))
    log = tmp_path / "run.mcap"
    assert main(["run", str(EXAMPLE), "--out", str(log), *SHORT]) == 1
    assert one_line(capsys.readouterr().err) == f"cosim: interrupted ({signal.Signals(signal_number).name})"
    outcome = finalised_outcome(log)
    assert outcome["reason"] == "stop_time" and float(outcome["time"]) == 0.5  # the whole run


@pytest.mark.slow
@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_signal_during_startup_of_a_real_process(signal_number, tmp_path):
    """The process as a user runs it: exit 1, one line; before the fix SIGTERM gave -15 silently."""
    log = tmp_path / "run.mcap"
    script = (
        "import os, sys\n"
        "import cosim.scenario.load as load\n"
        "from cosim.cli import main\n"
        "original = load.load_scenario\n"
        "def interrupted(*a, **k):\n"
        f"    os.kill(os.getpid(), {int(signal_number)})\n"
        "    return original(*a, **k)\n"
        "load.load_scenario = interrupted\n"
        f"sys.exit(main(['run', {str(EXAMPLE)!r}, '--out', {str(log)!r}, '--quiet']))\n"
    )
    completed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert completed.returncode == 1, completed.stderr
    name = signal.Signals(signal_number).name
    assert completed.stderr.splitlines() == [f"cosim: interrupted ({name})"]
    assert not log.exists()


def test_deferred_signal_is_taken_once():
    with interrupt.catching_signals():
        with pytest.raises(interrupt.Interrupted) as caught:
            with interrupt.deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                os.kill(os.getpid(), signal.SIGINT)  # a second one while deferred changes nothing
        assert caught.value.signal_name == "SIGTERM"
        with interrupt.deferred():
            os.kill(os.getpid(), signal.SIGINT)
            assert interrupt.take() == "SIGINT"
            assert interrupt.take() is None


# --- SSP runs claim their log and take signals the same way --------------------------------------
@pytest.fixture()
def convoy_ssp(tmp_path) -> Path:
    import zipfile

    import cosim

    convoy = REPO / "tests" / "data" / "ssp" / "convoy"
    archive = tmp_path / "convoy.ssp"
    with zipfile.ZipFile(archive, "w") as ssp:
        ssp.write(convoy / "SystemStructure.ssd", "SystemStructure.ssd")
        ssp.write(convoy / "resources" / "parameters.ssv", "resources/parameters.ssv")
        ssp.write(cosim.builtin_fmu("DifferentialDrive"), "resources/DifferentialDrive.fmu")
        ssp.write(cosim.builtin_fmu("Bicycle"), "resources/Bicycle.fmu")
    return archive


def test_ssp_run_refuses_an_existing_out(convoy_ssp, tmp_path, capsys):
    log = tmp_path / "precious.mcap"
    log.write_bytes(b"an earlier run")
    assert main(["run", str(convoy_ssp), "--out", str(log), "--quiet"]) == 2
    assert (
        one_line(capsys.readouterr().err)
        == f"cosim: error: {log}: already exists; give --force to overwrite it"
    )
    assert log.read_bytes() == b"an earlier run"


@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_ssp_run_interrupted_after_the_log_opened(signal_number, convoy_ssp, tmp_path, capsys, monkeypatch):
    from cosim.ssp import run as ssp_run

    monkeypatch.setattr(ssp_run, "_write_header", _signal_self(signal_number)(ssp_run._write_header))
    log = tmp_path / "convoy.mcap"
    assert main(["run", str(convoy_ssp), "--out", str(log), "--quiet"]) == 1
    assert capsys.readouterr().err == ""
    outcome = finalised_outcome(log)
    assert outcome["reason"] == "interrupted" and float(outcome["time"]) < 8.0  # before the stop time


@pytest.mark.slow
@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_signal_after_the_command_finished(signal_number, tmp_path):
    """Between the end of the work and the end of the process (interpreter shutdown) a signal still
    means exit 1, never -15 or a traceback; what was printed is not lost."""
    log = tmp_path / "run.mcap"
    script = (
        "import os, sys\n"
        "from cosim.cli import main\n"
        f"sys.argv = ['cosim', 'run', {str(EXAMPLE)!r}, '--out', {str(log)!r}, '--no-plot',\n"
        "            '--set', 'simulation.stop_time=0.5']\n"
        "code = main()\n"
        f"os.kill(os.getpid(), {int(signal_number)})\n"
        "sys.exit(code)\n"
    )
    completed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert completed.returncode == 1, completed.stderr  # was -15 for SIGTERM
    assert "Traceback" not in completed.stderr and "interrupted" not in completed.stderr  # only tqdm's bar
    assert str(log) in completed.stdout  # the summary table came out before the exit
    assert finalised_outcome(log)["reason"] == "stop_time"


@pytest.mark.slow
@pytest.mark.parametrize("signal_number", SIGNALS, ids=["SIGINT", "SIGTERM"])
def test_signal_while_an_fmu_hangs_in_do_step(signal_number, tmp_path):
    """Issue 10: an FMU hung in fmi2DoStep once made cosim ignore SIGINT and SIGTERM for good. In a
    child process (an FMU given by path), the host still takes the signal: exit 1, the log finalised
    with outcome "interrupted" at the last completed step, and the hung child is gone."""
    from test_isolation_run import scenario

    path = scenario(tmp_path, "hang", stop_time=4.0)
    text = path.read_text().replace("fault_time = 2.0", "fault_time = 0.5")
    path.write_text(text.replace("fmu_timeout = 1.0", "fmu_timeout = 3600"))  # only the signal ends it
    log = tmp_path / "hung.mcap"
    host = subprocess.Popen(
        [sys.executable, "-m", "cosim", "run", str(path), "--out", str(log), "--quiet", "--no-plot"],
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    child = None
    try:
        while host.poll() is None:  # until the child hangs: the fault sleeps in nanosleep() for good
            children = Path(f"/proc/{host.pid}/task/{host.pid}/children").read_text().split()
            child = next((int(pid) for pid in children if _is_isolated_child(int(pid))), None)
            if child is not None and log.exists() and "nanosleep" in _wchan(child):
                break
        assert host.poll() is None and child is not None
        host.send_signal(signal_number)
        _, stderr = host.communicate()
    finally:
        if host.poll() is None:  # the test failed: leave no run (and no hung child) behind
            host.kill()
            host.communicate()
    assert host.returncode == 1, stderr
    assert stderr == ""  # an ordinary "not reached" end, as when the loop takes the signal
    outcome = finalised_outcome(log)
    assert outcome["reason"] == "interrupted" and float(outcome["time"]) == 0.5  # the last completed step
    assert not Path(f"/proc/{child}").exists() or "Z" in Path(f"/proc/{child}/stat").read_text().split()[2]


def _is_isolated_child(pid: int) -> bool:
    try:
        return b"cosim.fmi.isolated_child" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:  # gone between the listing and the read (ProcessLookupError, FileNotFoundError)
        return False


def _wchan(pid: int) -> str:
    """The kernel function a process waits in ('' when it runs or is gone)."""
    try:
        return Path(f"/proc/{pid}/wchan").read_text()
    except OSError:
        return ""
