"""`cosim log plot` of a log that is not a robot run (here `cosim fmu simulate`'s): every signal
over time, titled by the system; a robot run's log still gets the robot picture, byte for byte."""

from __future__ import annotations

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu
from log_synthetic import write_log
from PIL import Image

from cosim.cli import main
from cosim.logs import plot, signal_plot
from cosim.logs.reader import open_log
from cosim.ssp.simulate import prepare, simulate

NAME = "fixture_diffdrive_fmi2"  # the fixture's model name: the component and the system


@pytest.fixture(scope="module")
def fmu_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("simulate") / "alone.mcap"
    start = {"v": 1.0, "omega": 0.5}
    simulate(prepare(fixture_fmu("diffdrive_fmi2"), stop_time=2.0, step=0.01, start_values=start), path)
    return path


@pytest.fixture(scope="module")
def robot_log(tmp_path_factory):
    return write_log(tmp_path_factory.mktemp("robot") / "robot.mcap").path


def test_a_lone_fmu_log_is_not_a_robot_run_and_a_robot_log_is(fmu_log, robot_log):
    with open_log(fmu_log) as log:
        assert not signal_plot.is_robot_log(log)
    with open_log(robot_log) as log:
        assert signal_plot.is_robot_log(log)


def test_every_signal_is_a_panel_with_the_logs_values(fmu_log):
    with open_log(fmu_log) as log:
        panels = signal_plot.signal_panels(log)
        recorded = log.signals(NAME)
        assert [p.label for p in panels] == [f"{NAME}.{n}" for n in log.signal_names(NAME)]
        assert [p.label.split(".")[1] for p in panels] == ["v", "omega", "x", "y", "theta", "steps", "moving"]
        for panel in panels:
            name = panel.label.split(".")[1]
            np.testing.assert_array_equal(panel.values, recorded[name])
            np.testing.assert_array_equal(panel.t, recorded.t)
        title = signal_plot.signal_title(log, len(panels))
    assert title == f"{NAME}\nalone.mcap, ended at t = 2 s: stop_time"
    assert "goal" not in title


def test_plot_command_draws_all_or_the_chosen_signals(fmu_log, tmp_path, capsys):
    every, chosen = tmp_path / "every.png", tmp_path / "chosen.png"
    assert main(["log", "plot", str(fmu_log), "--png", str(every)]) == 0
    assert main(["log", "plot", str(fmu_log), "--png", str(chosen), "--signals", f"{NAME}.x,{NAME}.y"]) == 0
    tall, short = Image.open(every), Image.open(chosen)
    # Seven signals in two columns (four rows) against two in one: the picture grows with them.
    assert tall.size[1] > short.size[1] and tall.size[0] > short.size[0]
    # Each panel draws its line in matplotlib's first colour (C0, #1f77b4).
    blue = (np.abs(np.asarray(short.convert("RGB"), dtype=int) - (31, 119, 180)).sum(axis=2) < 30).sum()
    assert blue > 500


@pytest.mark.parametrize(
    ("signals", "message"),
    [
        (f"{NAME}.thet", f"no signal 'thet' of {NAME}; signals: theta"),
        ("vehicle.x", f"no component 'vehicle' in alone.mcap; components: {NAME}"),
        ("x", "expected COMPONENT.VARIABLE"),
    ],
)
def test_an_unknown_signal_is_one_line_and_exit_2(fmu_log, tmp_path, capsys, signals, message):
    assert main(["log", "plot", str(fmu_log), "--png", str(tmp_path / "x.png"), "--signals", signals]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_a_robot_log_gets_the_robot_picture_unchanged(robot_log, tmp_path, capsys):
    with open_log(robot_log) as log:
        plot.plot_log(log, tmp_path / "before.png")
    assert main(["log", "plot", str(robot_log), "--png", str(tmp_path / "now.png")]) == 0
    assert (tmp_path / "now.png").read_bytes() == (tmp_path / "before.png").read_bytes()
