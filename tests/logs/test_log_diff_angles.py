"""`cosim log diff` compares angle-valued signals (unit rad) modulo 2 pi, other signals as numbers."""

from __future__ import annotations

import math

import numpy as np

from cosim.cli import main
from cosim.logs import open_log
from cosim.logs.diff import diff_logs
from cosim.record.recorder import Recorder

STEP_NS = 10_000_000
STEPS = 1000  # 10 s at 1 rad/s: the heading turns past pi and past 2 pi


def _write(path, times_ns, theta, x, units=("rad", "m")) -> None:
    with Recorder(path) as recorder:
        channel = recorder.signal_channel("vehicle", ["theta", "x"], units=list(units) if units else None)
        for t_ns, heading, position in zip(times_ns, theta, x, strict=True):
            recorder.write_signals(channel, int(t_ns), np.array([heading, position]))


def _wrap(angles: np.ndarray) -> np.ndarray:
    """To (-pi, pi]."""
    return -np.remainder(-angles + math.pi, 2 * math.pi) + math.pi


def test_a_wrapped_heading_equals_the_unwrapped_one_but_a_length_off_by_2_pi_does_not(tmp_path, capsys):
    t_ns = np.arange(STEPS) * STEP_NS
    theta = t_ns / 1e9  # [rad], 1 rad/s
    x = np.cos(theta)
    assert np.max(np.abs(_wrap(theta) - theta)) > 6.0  # the wrap really happens
    _write(tmp_path / "a.mcap", t_ns, theta, x)
    _write(tmp_path / "wrapped.mcap", t_ns, _wrap(theta), x)
    _write(tmp_path / "shifted.mcap", t_ns, theta, x + 2 * math.pi)
    a = open_log(tmp_path / "a.mcap")
    assert a.signal_units("vehicle") == ["rad", "m"] and a.signals("vehicle").unit("theta") == "rad"
    report = diff_logs(a, open_log(tmp_path / "wrapped.mcap"), 1e-9)
    heading = next(item for item in report.deviations if item.name == "theta")
    assert heading.angle and heading.max_deviation <= 1e-12 and not report.differs
    assert main(["log", "diff", str(tmp_path / "a.mcap"), str(tmp_path / "wrapped.mcap")]) == 0
    report = diff_logs(a, open_log(tmp_path / "shifted.mcap"), 1e-9)
    assert [item.name for item in report.exceeding] == ["x"]
    assert math.isclose(report.exceeding[0].max_deviation, 2 * math.pi, rel_tol=1e-12)
    capsys.readouterr()
    assert main(["log", "diff", str(tmp_path / "a.mcap"), str(tmp_path / "shifted.mcap")]) == 1
    assert "vehicle.x " in capsys.readouterr().out


def test_exact_angles_stay_exact_and_interpolation_crosses_the_wrap(tmp_path):
    t_ns = np.arange(STEPS) * STEP_NS
    theta = t_ns / 1e9
    _write(tmp_path / "a.mcap", t_ns, theta, theta)
    nudged = theta.copy()
    nudged[500] += 1e-15 * 8  # a few ulps at 5 rad
    _write(tmp_path / "nudged.mcap", t_ns, nudged, theta)
    report = diff_logs(open_log(tmp_path / "a.mcap"), open_log(tmp_path / "nudged.mcap"), 0.0)
    heading = next(item for item in report.deviations if item.name == "theta")
    assert heading.max_deviation == abs(nudged[500] - theta[500]) > 0 and heading.at_time == 5.0
    # B wrapped and sampled between A's times: interpolating B across a jump of 2 pi would give
    # errors of pi; unwrapped first it is linear interpolation of a straight line.
    between = t_ns[:-1] + STEP_NS // 2
    _write(tmp_path / "between.mcap", between, _wrap(between / 1e9), between / 1e9)
    report = diff_logs(open_log(tmp_path / "a.mcap"), open_log(tmp_path / "between.mcap"), 1e-9)
    heading = next(item for item in report.deviations if item.name == "theta")
    assert heading.interpolated and heading.max_deviation < 1e-9


def test_a_log_without_units_compares_plain_numbers(tmp_path):
    t_ns = np.arange(STEPS) * STEP_NS
    theta = t_ns / 1e9
    _write(tmp_path / "a.mcap", t_ns, theta, theta, units=None)
    _write(tmp_path / "wrapped.mcap", t_ns, _wrap(theta), theta, units=None)
    a = open_log(tmp_path / "a.mcap")
    assert a.signal_units("vehicle") == ["", ""]
    report = diff_logs(a, open_log(tmp_path / "wrapped.mcap"), 1e-9)
    assert [item.name for item in report.exceeding] == ["theta"]
