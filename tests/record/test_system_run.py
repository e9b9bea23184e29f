"""The base of every run (`cosim.record.system_run`): any System stepped to its stop with every
signal in the log, and how a run's loop ended.

Truth: the components' outputs written out by hand here (a clock whose output after a step is the
step's end time, a doubler at half the rate), and the stamping rule of the recorder's docstring:
the record at t holds the inputs applied at t and the outputs at t, a last record at the end.
"""

from __future__ import annotations

import numpy as np
import pytest

from cosim.core import interrupt
from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master, System
from cosim.errors import CosimError, SimulationEnded
from cosim.logs.reader import open_log
from cosim.record.system_run import RunEnd, SystemRun, open_recorder, run_guarded

H = 0.25  # [s] macro step
STOP = 2.0  # [s]


class Clock(PythonComponent):
    """Output `t`: the time at the end of its last step [s] (its start time before any step)."""

    def __init__(self) -> None:
        super().__init__("clock", outputs=[Port("t", unit="s")], feedthrough={"t": []})

    def on_setup(self, t0, parameters) -> None:
        self.output_buffer[0] = t0

    def step(self, t, h) -> None:
        self.output_buffer[0] = t + h


class Doubler(PythonComponent):
    """Output `y` = 2 u, every other macro step."""

    def __init__(self) -> None:
        super().__init__("doubler", inputs=[Port("u")], outputs=[Port("y")], feedthrough={"y": ["u"]})
        self.period = 2 * H

    def step(self, t, h) -> None:
        self.output_buffer[0] = 2.0 * self.input_buffer[0]


def _run(tmp_path, total_steps=None, loop_error=None):
    system = System(H)
    system.add(Clock())
    system.add(Doubler())
    system.connect("clock.t", "doubler.u")
    master = Master(system, stop_time=STOP)
    master.initialize()
    recorder = open_recorder(tmp_path / "run.mcap", False, "unused: a path is given", trace=False)
    steps = SystemRun(master, recorder)
    steps.write_header("two", {"note": "test"}, master.order)
    steps.begin()
    steps.signal_channels()
    reason, end = steps.record_steps(total_steps or master.steps_to_stop, lambda error: f"failed: {error}")
    failure = steps.close_master(end.failure, lambda error: f"closing: {error}")
    steps.end_steps()
    recorder.close({"reason": reason})
    return reason, end, failure, recorder.path


def test_every_signal_of_every_component_is_recorded_at_its_steps(tmp_path):
    reason, end, failure, path = _run(tmp_path)
    assert (reason, end, failure) == ("stop_time", RunEnd(), None)
    with open_log(path) as log:
        assert log.metadata["navcosim"]["scenario_name"] == "two"
        assert log.metadata["navcosim"]["note"] == "test"
        clock = log.signals("clock")
        doubler = log.signals("doubler")
    steps = round(STOP / H)
    # The clock: a record at each step's start holding its output there (= that time), and a last
    # one at the stop time.
    np.testing.assert_array_equal(clock.t, np.arange(steps + 1) * H)
    np.testing.assert_array_equal(clock.values[:, 0], np.arange(steps + 1) * H)
    assert clock.names == ["t"] and clock.unit("t") == "s"
    # The doubler: every other step, and at the end. Gauss-Seidel: the clock steps first, so the
    # input applied at t is the clock's output after its step at t (t + H); the record at t holds
    # the outputs at t, those of its step before (twice that step's input; 0 at first).
    np.testing.assert_array_equal(doubler.t, np.arange(0, steps + 1, 2) * H)
    assert doubler.names == ["u", "y"]
    u, y = doubler.values[:, 0], doubler.values[:, 1]
    np.testing.assert_array_equal(u[:-1], doubler.t[:-1] + H)
    assert u[-1] == u[-2]  # the end: the input last applied, held
    np.testing.assert_array_equal(y, [0.0, *(2.0 * u[:-1])])


def test_a_run_told_fewer_steps_ends_there_with_its_last_records(tmp_path):
    reason, _, _, path = _run(tmp_path, total_steps=3)
    assert reason == "stop_time"
    with open_log(path) as log:
        clock, doubler = log.signals("clock"), log.signals("doubler")
    np.testing.assert_array_equal(clock.t, [0.0, H, 2 * H, 3 * H])
    # The doubler stepped at 0 and 2H; its last record, at the end (3H), holds the input last
    # applied and the output of its last step.
    np.testing.assert_array_equal(doubler.t, [0.0, 2 * H, 3 * H])
    np.testing.assert_array_equal(doubler.values, [[H, 0.0], [3 * H, 2 * H], [3 * H, 6 * H]])


@pytest.mark.parametrize(
    "raised, expected",
    [
        (None, RunEnd()),
        (
            SimulationEnded("fmu 'x' asked to end at t = 1 s", "x", 1.0),
            RunEnd(ended="fmu 'x' asked to end at t = 1 s"),
        ),
        (CosimError("status error"), RunEnd(failure="described: status error")),
        (interrupt.Interrupted("SIGTERM"), RunEnd(interrupted=True)),
    ],
    ids=["normal", "ended", "failed", "interrupted"],
)
def test_run_guarded_tells_how_a_loop_ended(raised, expected):
    def loop() -> None:
        if raised is not None:
            raise raised

    assert run_guarded(loop, lambda error: f"described: {error}") == expected


def test_an_error_that_is_no_run_end_goes_through():
    def loop() -> None:
        raise ValueError("a bug")

    with pytest.raises(ValueError, match="a bug"):
        run_guarded(loop, str)
