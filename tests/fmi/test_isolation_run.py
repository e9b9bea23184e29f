"""Each fault of the fault-injection FMU, as the vehicle of a short scenario (an FMU given by path,
so it runs in a child process by default): `cosim run` exits 2 with one line naming the FMU, the
call, the simulation time and what happened, and the log is finalised up to the last completed
step: rosbags (a second MCAP/CDR reader) reads /odom up to the fault and the outcome records it.

The fault FMU is a differential drive with the project's port names, so the scenario's [vehicle]
needs no port map; the run derives x0, y0, theta0 from [start]. Its fault is due at the first doStep
starting at or after fault_time = 2 s, i.e. the step [2.00, 2.01] s; the pose of every step before
it is the project DifferentialDrive's kinematics (an exact arc), so until then the run is the
shipped scenario's, as the in-process comparison below checks.
"""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from rosbags.highlevel import AnyReader

from cosim.cli import main
from cosim.logs import open_log

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
FAULT_TIME = 2.0  # [s]
POSE_PERIOD = 0.02  # [s] /odom at the default 50 Hz
TIMEOUT = 1.0  # [s] fmu_timeout of these runs: how long the hang fault is given

HAPPENED = {
    "segfault": rf"crashed with signal {int(signal.SIGSEGV)} \(SIGSEGV, Segmentation fault\) in fmi2DoStep",
    "abort": rf"crashed with signal {int(signal.SIGABRT)} \(SIGABRT, Aborted\) in fmi2DoStep",
    "exit": r"ended its process with exit status 0 \(exit\(\) inside the FMU\) in fmi2DoStep",
    "hang": r"did not return from fmi2DoStep",
    "nan": r"output 'x' is NaN after fmi2DoStep",
    "error": r"returned fmi2Error from fmi2DoStep",
    "fatal": r"returned fmi2Fatal from fmi2DoStep",
    "discard": r"returned fmi2Discard from fmi2DoStep",
}


def scenario(tmp_path: Path, fault: str, simulation: str = "", stop_time: float = 4.0) -> Path:
    """The shipped one-obstacle scenario, `stop_time` [s] long, with the fault FMU as its vehicle."""
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    start = text.index("[vehicle]")
    end = text.index("\n[", start + 1)
    section = f"""[vehicle]
fmu = "{fixture_fmu("fault_fmi2")}"
type = "differential"
radius = 0.5
fault = {FAULTS.index(fault)}
fault_time = {FAULT_TIME}
"""
    text = text[:start] + section + text[end:]
    text = re.sub(r"(?m)^stop_time = .*$", f"stop_time = {stop_time}", text)
    text = text.replace("[simulation]", f"[simulation]\nfmu_timeout = {TIMEOUT}\n{simulation}", 1)
    path = tmp_path / f"{fault}.toml"
    path.write_text(text)
    return path


def odom_stamps(log_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps [s] and x [m] of every /odom message, read with rosbags alone."""
    stamps, xs = [], []
    with AnyReader([log_path]) as reader:
        connections = [c for c in reader.connections if c.topic == "/odom"]
        for connection, _, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            stamps.append(message.header.stamp.sec + message.header.stamp.nanosec * 1e-9)
            xs.append(message.pose.pose.position.x)
    return np.array(stamps), np.array(xs)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[np.ndarray, np.ndarray]:
    """/odom of the same scenario with the fault FMU in this process and no fault."""
    tmp_path = tmp_path_factory.mktemp("reference")
    log_path = tmp_path / "none.mcap"
    path = scenario(tmp_path, "none", simulation='fmu_isolation = "none"')
    assert main(["run", str(path), "--out", str(log_path), "--quiet", "--no-plot"]) == 1  # stop time
    return odom_stamps(log_path)


@pytest.mark.parametrize(
    "fault", [pytest.param(f, marks=pytest.mark.slow) if f == "hang" else f for f in FAULTS if f != "none"]
)
def test_each_fault_exits_2_with_one_line_and_a_log_up_to_the_fault(tmp_path, capfd, reference, fault):
    path = scenario(tmp_path, fault)
    log_path = tmp_path / f"{fault}.mcap"
    code = main(["run", str(path), "--out", str(log_path), "--quiet", "--no-plot"])
    lines = capfd.readouterr().err.splitlines()
    assert code == 2
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("cosim: error: FMU 'vehicle' (model fixture_fault_fmi2"), line
    assert re.search(HAPPENED[fault] + r" at t = 2 s", line), line
    assert line.endswith(f"; log (up to the failure): {log_path}")
    if fault == "hang":
        assert f"within {TIMEOUT:g} s (fmu_timeout); its process was killed" in line

    stamps, xs = odom_stamps(log_path)
    assert np.all(np.diff(stamps) > 0)  # one message per stamp, in order
    assert stamps[-1] == pytest.approx(FAULT_TIME, abs=1e-9)  # the pose after the last completed step
    assert np.all(np.isfinite(xs))
    expected_stamps, expected_xs = reference
    count = len(stamps)
    assert count == round(FAULT_TIME / POSE_PERIOD) + 1
    np.testing.assert_array_equal(stamps, expected_stamps[:count])
    np.testing.assert_array_equal(xs, expected_xs[:count])  # the same run until the fault
    assert xs[-1] - xs[0] > 1.0  # and it drove [m]

    log = open_log(log_path)
    assert log.outcome["reason"] == "fmu_failed"
    assert log.outcome["failure"] == line.removeprefix("cosim: error: ").split("; log (up to")[0]
    assert float(log.outcome["time"]) == pytest.approx(FAULT_TIME, abs=1e-9)
    assert log.metadata["fmu/vehicle"]["isolation"] == "process"
    vehicle = log.signals("vehicle")
    # Values at their stamps: the last record is the pose after the last completed step, at the
    # fault time, the same as the last /odom.
    assert vehicle.t[-1] == pytest.approx(FAULT_TIME, abs=1e-9) and vehicle["x"][-1] == xs[-1]


def test_isolated_run_equals_the_in_process_run(tmp_path, capfd, reference):
    log_path = tmp_path / "none.mcap"
    path = scenario(tmp_path, "none")
    assert main(["run", str(path), "--out", str(log_path), "--quiet", "--no-plot"]) == 1
    assert capfd.readouterr().err == ""
    stamps, xs = odom_stamps(log_path)
    np.testing.assert_array_equal(stamps, reference[0])
    np.testing.assert_array_equal(xs, reference[1])
    assert open_log(log_path).metadata["fmu/vehicle"]["isolation"] == "process"


@pytest.mark.slow
def test_cosim_run_process_exits_2_on_a_segfaulting_fmu(tmp_path):
    """The whole command in its own process: exit status 2, one line on stderr, no traceback."""
    log_path = tmp_path / "segfault.mcap"
    path = scenario(tmp_path, "segfault")
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(path), "--out", str(log_path), "--quiet", "--no-plot"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert completed.returncode == 2
    lines = completed.stderr.splitlines()
    assert len(lines) == 1 and "SIGSEGV" in lines[0] and "Traceback" not in completed.stderr
    assert odom_stamps(log_path)[0][-1] == pytest.approx(FAULT_TIME, abs=1e-9)


@pytest.mark.slow
def test_ctrl_c_ends_an_isolated_run_cleanly(tmp_path):
    """Ctrl-C at a terminal signals the whole foreground process group; the child (in a session of
    its own, ignoring SIGINT) keeps serving, and the run ends "interrupted" (exit 1) with its log."""
    log_path = tmp_path / "interrupted.mcap"
    path = scenario(tmp_path, "none", stop_time=100.0)
    host = subprocess.Popen(
        [sys.executable, "-m", "cosim", "run", str(path), "--out", str(log_path), "--quiet", "--no-plot"],
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        start_new_session=True,  # its own process group, as a shell gives a foreground job
    )
    child = None
    for _ in range(6000):  # until the run is stepping: its log exists and the child is up
        children = Path(f"/proc/{host.pid}/task/{host.pid}/children").read_text().split()
        child = next((int(pid) for pid in children if _is_isolated_child(int(pid))), None)
        if child is not None and log_path.exists() and host.poll() is None:
            break
        time.sleep(0.01)
    assert child is not None and host.poll() is None
    os.kill(child, signal.SIGINT)  # as if it were in the terminal's process group too
    os.killpg(host.pid, signal.SIGINT)
    _, stderr = host.communicate()
    assert host.returncode == 1, stderr
    assert stderr == ""
    log = open_log(log_path)
    assert log.outcome["reason"] == "interrupted"
    assert 0.0 < float(log.outcome["time"]) < 100.0
    assert math.isfinite(float(log.outcome["distance"]))


def _is_isolated_child(pid: int) -> bool:
    try:
        return b"cosim.fmi.isolated_child" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except FileNotFoundError:
        return False
