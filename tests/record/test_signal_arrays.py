"""`[output] signal_arrays`: array outputs in `/signals/<component>` (off by default).

Off, `/signals/lidar` holds the scan pose only and the planner (all array outputs) has no channel;
on, the lidar's every beam is there at each scan (its float32 rounding is what `/scan` carries, its
angles those of `[lidar]`), and the planner's waypoints are one message at t = 0 equal to `/plan`
(up to the last waypoint, which is the goal itself).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _log(tmp_path: Path, arrays: bool):
    # A plan fixed for the run (a replanning planner also has scalar inputs, so always a channel).
    overrides = [
        "simulation.stop_time=3.0",
        f"output.signal_arrays={str(arrays).lower()}",
        "planner.replan=false",
    ]
    scenario = load_scenario(SCENARIO, overrides)
    assert scenario.signal_arrays is arrays
    result = run_scenario(scenario, tmp_path / f"{arrays}.mcap")
    assert result.failure is None
    return scenario, open_log(tmp_path / f"{arrays}.mcap")


def test_arrays_left_out_by_default(tmp_path):
    _, log = _log(tmp_path, False)
    assert log.signals("lidar").names == ["x", "y", "theta"]
    assert "planner" not in log.components


def test_arrays_recorded_on_request(tmp_path):
    scenario, log = _log(tmp_path, True)
    lidar = log.signals("lidar")
    beams = len(scenario.lidar.angles)
    assert lidar.names == ["x", "y", "theta"] + [f"ranges[{k}]" for k in range(1, beams + 1)] + [
        f"angles[{k}]" for k in range(1, beams + 1)
    ]
    ranges, angles = lidar.values[:, 3 : 3 + beams], lidar.values[:, 3 + beams :]
    np.testing.assert_array_equal(angles, np.broadcast_to(scenario.lidar.angles, angles.shape))
    scans = list(log.messages("/scan"))
    # 10 Hz for 3 s. /scan at t is the sweep taken at t, the lidar's outputs after its step at t,
    # which /signals/lidar (values at the time they hold: the end of that step) has at t + 0.1 s.
    assert len(scans) == len(lidar.t) - 1 == 30
    # The initial outputs (at t = 0) are a sweep from the start pose, as the first /scan is.
    # /scan follows REP-117: the lidar's NaN (no return) is +inf there.
    on_scan = np.where(np.isnan(ranges), np.inf, ranges).astype(np.float32)
    np.testing.assert_array_equal(np.asarray(scans[0].message.ranges), on_scan[0])
    for scan, row in zip(scans, on_scan[1:], strict=True):
        np.testing.assert_array_equal(np.asarray(scan.message.ranges, dtype=np.float32), row)
    assert np.isfinite(ranges).sum() > beams  # the beams hit something
    planner = log.signals("planner")
    np.testing.assert_array_equal(planner.t_ns, [0])
    waypoints = planner.values[0].reshape(-1, 2)
    plan = log.plan()
    # /plan is the planner's path; the waypoints end exactly at the goal instead of its cell centre.
    np.testing.assert_array_equal(waypoints[: len(plan) - 1], plan[:-1])
    np.testing.assert_array_equal(waypoints[len(plan) - 1], scenario.goal)
    assert np.all(np.isnan(waypoints[len(plan) :]))


@pytest.mark.parametrize("value", ["1", '"yes"'])
def test_signal_arrays_must_be_a_boolean(value):
    from cosim.errors import CosimError

    with pytest.raises(CosimError, match=r"\[output\]\.signal_arrays: must be true or false"):
        load_scenario(SCENARIO, [f"output.signal_arrays={value}"])
