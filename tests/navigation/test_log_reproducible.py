"""A run's log: the same bytes for the same scenario, and each signal stamped at the time it holds.

Truth: the file bytes of a second run (sha256), the /odom poses of the same log (written from the
vehicle's outputs, independently of /signals), the scenario's start pose, and the exact arc of a
differential drive (eqs 4.4/4.5 integrated with constant inputs over a step) from the inputs
stamped at the step's start to the pose stamped at its end.
"""

from __future__ import annotations

import hashlib
import math
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.record import rosmsg
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
STOP_TIME = 2.0  # [s]


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """One run in this process, one by `cosim run` in another (another PID, another wall time)."""
    folder = tmp_path_factory.mktemp("same")
    override = f"simulation.stop_time={STOP_TIME}"
    scenario = load_scenario(SCENARIO, [override])
    paths = [folder / "a.mcap", folder / "b.mcap"]
    run_scenario(scenario, paths[0])
    command = [sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(paths[1]), "--no-plot"]
    completed = subprocess.run([*command, "--set", override], capture_output=True, text=True, check=False)
    assert completed.returncode == 1 and "real-time factor" in completed.stdout  # stop time: not reached
    return scenario, paths


@pytest.mark.slow
def test_the_same_scenario_writes_the_same_bytes(two_runs):
    _, (a, b) = two_runs
    assert hashlib.sha256(a.read_bytes()).hexdigest() == hashlib.sha256(b.read_bytes()).hexdigest()
    with open(a, "rb") as stream:
        reader = make_reader(stream)
        attachments = list(reader.iter_attachments())
        assert attachments and all(item.create_time == item.log_time == 0 for item in attachments)
        metadata = {record.name: record.metadata for record in reader.iter_metadata()}
    text = " ".join(f"{key}={value}" for record in metadata.values() for key, value in record.items())
    assert "wall" not in text and "real_time" not in text and f"={socket.gethostname()} " not in text + " "


@pytest.mark.slow
def test_signals_hold_the_values_at_their_stamps(two_runs):
    scenario, (path, _) = two_runs
    log = open_log(path)
    vehicle = log.signals("vehicle")
    h_ns = round(scenario.macro_step * 1e9)
    steps = round(STOP_TIME * 1e9 / h_ns)
    assert np.array_equal(vehicle.t_ns, np.arange(steps + 1) * h_ns)  # every step and the end
    start_x, start_y, start_theta = scenario.start
    assert (vehicle["x"][0], vehicle["y"][0], vehicle["theta"][0]) == (start_x, start_y, start_theta)
    odom = [
        (
            item.t_ns,
            item.message.pose.pose.position.x,
            item.message.pose.pose.position.y,
            item.message.pose.pose,
        )
        for item in log.messages("/odom")
    ]
    stamps = np.array([row[0] for row in odom])
    at = np.searchsorted(vehicle.t_ns, stamps)
    assert np.array_equal(vehicle.t_ns[at], stamps) and stamps[0] == 0 and stamps[-1] == steps * h_ns
    assert np.array_equal(vehicle["x"][at], [row[1] for row in odom])
    assert np.array_equal(vehicle["y"][at], [row[2] for row in odom])
    yaw = np.array([rosmsg.yaw_of(row[3].orientation) for row in odom])
    wrapped = np.angle(np.exp(1j * (vehicle["theta"][at] - yaw)))
    assert np.max(np.abs(wrapped)) < 1e-12
    # The inputs at t_k move the pose at t_k to the pose at t_k+1 along the exact arc.
    x, y, theta, v, omega = (vehicle[name] for name in ("x", "y", "theta", "v", "omega"))
    h = scenario.macro_step
    v, omega, theta0 = v[:-1], omega[:-1], theta[:-1]
    turning = np.abs(omega) > 1e-12
    radius = v / np.where(turning, omega, 1.0)
    arc_x = np.where(turning, radius * (np.sin(theta0 + omega * h) - np.sin(theta0)), v * h * np.cos(theta0))
    arc_y = np.where(turning, -radius * (np.cos(theta0 + omega * h) - np.cos(theta0)), v * h * np.sin(theta0))
    assert np.max(np.abs(x[1:] - x[:-1] - arc_x)) < 1e-9
    assert np.max(np.abs(y[1:] - y[:-1] - arc_y)) < 1e-9
    assert np.max(np.abs(theta[1:] - theta0 - omega * h)) < 1e-12
    assert np.max(np.hypot(np.diff(x), np.diff(y))) > 0.5 * 1.5 * h  # it drove
    held = vehicle["v"]
    assert not math.isnan(held[-1]) and held[-1] == held[-2]  # the last record: inputs last applied


@pytest.mark.slow
def test_signal_units_are_those_of_the_fmu_model_description(two_runs):
    from fmpy import read_model_description

    from cosim.fmi.builtin import builtin_fmu

    _, (path, _) = two_runs
    log = open_log(path)
    description = read_model_description(str(builtin_fmu("DifferentialDrive")))
    declared = {variable.name: variable.unit or "" for variable in description.modelVariables}
    names, units = log.signal_names("vehicle"), log.signal_units("vehicle")
    assert units == [declared[name] for name in names]
    assert dict(zip(names, units, strict=True))["theta"] == "rad" and "m" in units
