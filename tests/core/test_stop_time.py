"""The stop time: every FMU is told it, and the last step ends exactly there, also where the stop
time is no whole number of macro steps (or of a component's period) after the start: in the
Python loop, in the compiled kernel and in `cosim fmu simulate` (against fmpy's simulate_fmu,
which cuts its last step the same way for an FMU that can take variable steps). The `gain_fmi2`
fixture keeps the stop time it was told (`stop_time`) and the end t + h of its last step
(`end_time`)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.cli import main
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent
from cosim.logs.reader import open_log
from cosim.ssp.run import run_ssp
from cosim.ssp.simulate import prepare, simulate


def _master(macro_step: float, stop_time: float, period: float = 0.0, start_time: float = 0.0):
    system = System(macro_step)
    gain = system.add(FmuComponent(fixture_fmu("gain_fmi2"), "gain", period=period))
    return Master(system, start_time=start_time, stop_time=stop_time), gain


def _end(gain) -> tuple[float, float]:
    return tuple(gain.output_buffer[[gain.output_index["stop_time"], gain.output_index["end_time"]]])


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize(
    ("macro_step", "stop_time", "period", "start_time", "steps"),
    [
        (0.3, 1.0, 0.0, 0.0, 4),  # 0.3, 0.6, 0.9, then 0.1
        (0.25, 1.0, 0.0, 0.0, 4),  # a whole number of steps: none cut
        (0.3, 1.0, 0.6, 0.0, 4),  # period 0.6: [0, 0.6], then [0.6, 1.0]
        (0.1, 1.05, 0.0, 0.5, 6),  # from 0.5: five steps of 0.1, then 0.05
    ],
)
def test_the_last_step_ends_at_the_stop_time(compiled, macro_step, stop_time, period, start_time, steps):
    master, gain = _master(macro_step, stop_time, period, start_time)
    with master:
        master.initialize()
        assert master.steps_to_stop == steps
        master.run(steps, compiled=compiled)
        assert master.time == stop_time and master.time_ns == round(stop_time * 1e9)
        assert _end(gain) == (stop_time, stop_time)


def test_kernel_and_python_loop_record_the_same_cut_steps():
    histories = {}
    for compiled in (False, True):
        master, _ = _master(0.3, 1.0, period=0.6)
        rows = []
        with master:
            master.initialize()
            master.run_recorded(
                4, lambda first, count, h, rows=rows: rows.append(h[0].copy()), compiled=compiled
            )
        histories[compiled] = np.concatenate(rows)
    np.testing.assert_array_equal(histories[False], histories[True])
    np.testing.assert_array_equal(histories[True][:, -1], [0.6, 1.0])  # end_time after each step


def test_no_step_passes_the_stop_time():
    master, _ = _master(0.3, 1.0)
    with master:
        master.initialize()
        master.run(3)
        with pytest.raises(CosimError, match=r"pass the stop time 1 s \(1 steps remain\)"):
            master.run(2)
        master.step()
        with pytest.raises(CosimError, match="pass the stop time"):
            master.step()


def test_a_stop_time_before_the_start_is_refused():
    with pytest.raises(CosimError, match="is not after the start time"):
        _master(0.1, 1.0, start_time=1.0)


def test_fmu_simulate_cuts_the_last_step_as_fmpy_does(tmp_path):
    path = fixture_fmu("diffdrive_fmi2")
    start = {"x0": 1.0, "theta0": 0.3, "v": 0.8, "omega": -0.4}
    result = simulate(
        prepare(path, stop_time=1.05, step=0.1, start_values=start), tmp_path / "r.mcap", tmp_path / "r.csv"
    )
    assert (result.reason, result.steps, result.end_time) == ("stop_time", 11, 1.05)
    ours = np.genfromtxt(tmp_path / "r.csv", delimiter=",", names=True)
    reference = fmpy.simulate_fmu(str(path), stop_time=1.05, output_interval=0.1, start_values=start)
    assert ours["time"][-1] == reference["time"][-1] == 1.05
    for name in ("time", "x", "y", "theta"):
        np.testing.assert_allclose(ours[name], reference[name], rtol=0, atol=1e-12)


def test_an_ssp_run_ends_at_its_stop_time_with_its_parameters(tmp_path):
    """An SSP of the FMI 2.0 gain fixture (which resets gain and offset in fmi2SetupExperiment),
    its parameters from an .ssv, stop time 1 s at a 0.3 s macro step."""
    ssd = """<ssd:SystemStructureDescription
      xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="g">
      <ssd:System name="g"><ssd:ParameterBindings>
        <ssd:ParameterBinding source="resources/g.ssv"/></ssd:ParameterBindings>
        <ssd:Elements><ssd:Component name="gain" source="resources/gain.fmu"/></ssd:Elements>
      </ssd:System><ssd:DefaultExperiment stopTime="1.0"/></ssd:SystemStructureDescription>"""
    values = {"gain.gain": 3.0, "gain.offset": 0.5, "gain.u": 2.0}
    parameters = "".join(
        f'<ssv:Parameter name="{name}"><ssv:Real value="{value}"/></ssv:Parameter>'
        for name, value in values.items()
    )
    ssv = (
        '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"'
        f' version="1.0" name="g"><ssv:Parameters>{parameters}</ssv:Parameters></ssv:ParameterSet>'
    )
    path = tmp_path / "g.ssp"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("SystemStructure.ssd", ssd)
        archive.writestr("resources/g.ssv", ssv)
        archive.write(fixture_fmu("gain_fmi2"), "resources/gain.fmu")
    result = run_ssp(path, tmp_path / "g.mcap", ["simulation.macro_step=0.3"])
    assert (result.reason, result.steps, result.end_time) == ("stop_time", 4, 1.0)
    with open_log(tmp_path / "g.mcap") as log:
        gain = log.signals("gain")
        assert set(gain["y"].tolist()) == {3.0 * 2.0 + 0.5}
        assert set(gain["stop_time"].tolist()) == {1.0}
        assert gain.t[-1] == 1.0 and gain["end_time"][-1] == 1.0


@pytest.mark.parametrize("loop", ["kernel", "python"])
def test_a_scenario_ends_at_a_stop_time_between_macro_steps(loop, tmp_path, monkeypatch):
    """2.015 s at a 0.01 s macro step: the last step (0.005 s) ends at the stop time, and so does
    every record of the log, the pose of that step included (on the pose grid of 2 steps)."""
    monkeypatch.setenv("NAVCOSIM_LOOP", loop)
    root = Path(__file__).resolve().parents[2]
    scenario = root / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    argv = ["run", str(scenario), "--out", str(tmp_path / "run.mcap"), "--no-plot", "--quiet"]
    monkeypatch.chdir(root)
    assert main([*argv, "--set", "simulation.stop_time=2.015"]) == 1  # the goal is farther
    with open_log(tmp_path / "run.mcap") as log:
        assert log.end_time == 2.015 and log.outcome["time"] == 2.015
        assert log.signals("vehicle").t[-1] == 2.015


def test_fmu_simulate_refuses_a_cut_step_an_fmu_cannot_take():
    path = fixture_fmu("gain_fixed_step_fmi2")
    with pytest.raises(CosimError, match="cannot take a shorter last step") as error:
        prepare(path, stop_time=1.05, step=0.1)
    assert "\n" not in str(error.value)
    assert prepare(path, stop_time=1.0, step=0.1).steps == 10


@pytest.mark.parametrize(("macro_step", "period"), [(0.1, 0.0), (0.05, 0.1)])
def test_a_stop_time_that_cuts_the_step_of_an_fmu_that_cannot_vary_it_is_refused(macro_step, period):
    """gain_fixed_step_fmi2 lacks canHandleVariableCommunicationStepSize: a stop time 1.05 s after
    the start would give it a last step of 0.05 s, which it cannot take (its own step, or its
    period of two macro steps); 1.0 s and, for the macro step alone, 1.1 s end on its steps."""
    system = System(macro_step)
    system.add(FmuComponent(fixture_fmu("gain_fixed_step_fmi2"), "gain", period=period))
    with pytest.raises(CosimError) as error:
        Master(system, stop_time=1.05)
    message = str(error.value)
    assert "\n" not in message
    assert "component 'gain' (0.1 s)" in message and "canHandleVariableCommunicationStepSize" in message
    assert "give a stop time of 1 or 1.1 s" in message
    with Master(system, stop_time=1.1) as master:
        master.initialize()
        master.run(master.steps_to_stop)
        assert master.time == 1.1


def test_an_fmi1_fmu_that_declares_variable_steps_takes_the_cut_step():
    """gain_fmi1 declares canHandleVariableCommunicationStepSize in its FMI 1.0 Capabilities (which
    fmpy does not read): its last step is cut to end at the stop time."""
    system = System(0.1)
    gain = system.add(FmuComponent(fixture_fmu("gain_fmi1"), "gain"))
    assert gain.can_vary_step()
    with Master(system, stop_time=1.05) as master:
        master.initialize()
        master.run(master.steps_to_stop)
        assert gain.output_buffer[gain.output_index["end_time"]] == pytest.approx(1.05, abs=1e-12)
