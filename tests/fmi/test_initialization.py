"""FMI initialisation in the order of libcosim and ecos (instantiate, set up the experiment, then
parameters and start values, initialization mode with connected values exchanged) and the stop
time told to every FMU, checked on the `gain_fmi*` fixtures (y = gain * u + offset, direct on u; the
FMI 2.0 one resets gain and offset in fmi2SetupExperiment, as 20-sim's FMUs do).

The truths: fmpy reading the FMU's variables after an initialisation in the same order (and, as a
control that the fixture can catch the fault, after one with the parameters set first), and the
analytic value of a chain of gains."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import fmpy
import pytest
from fixtures.conftest_helpers import fixture_fmu
from fmpy.fmi1 import FMU1Slave
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.component import FmuComponent
from cosim.fmi.isolated import IsolatedFmuComponent
from cosim.logs.reader import open_log

PARAMETERS = {"gain": 3.0, "offset": 0.5}
U = 2.0
# Value references of the fixture: gain, offset, u, y, stop_time, end_time.
GAIN, OFFSET, INPUT, Y, STOP_TIME, END_TIME = range(6)


def _fmpy_after_init(version: int, parameters_first: bool = False, stop_time: float | None = 1.0):
    """fmpy's reading of gain, offset, y, stop_time after initialising the fixture by hand."""
    path = fixture_fmu(f"gain_fmi{version}")
    description = fmpy.read_model_description(str(path))
    directory = fmpy.extract(str(path))
    slave_class = {1: FMU1Slave, 2: FMU2Slave, 3: FMU3Slave}[version]
    token = description.guid if version < 3 else description.instantiationToken
    identifier = description.coSimulation.modelIdentifier
    slave = slave_class(guid=token, unzipDirectory=directory, modelIdentifier=identifier, instanceName="x")
    slave.instantiate()
    get = slave.getReal if version < 3 else slave.getFloat64
    put = slave.setReal if version < 3 else slave.setFloat64

    def set_values():
        put([GAIN, OFFSET, INPUT], [PARAMETERS["gain"], PARAMETERS["offset"], U])

    if parameters_first:
        set_values()
    if version == 2:
        slave.setupExperiment(startTime=0.0, stopTime=stop_time)
    if not parameters_first:
        set_values()
    if version == 1:
        slave.initialize(0.0, stop_time)
    else:
        slave.enterInitializationMode(*(() if version == 2 else (None, 0.0, stop_time)))
        slave.exitInitializationMode()
    values = get([GAIN, OFFSET, Y, STOP_TIME])
    slave.terminate()
    slave.freeInstance()
    return values


def _initialised(component_class, version: int, stop_time: float | None = 1.0):
    system = System(0.25)
    gain = system.add(component_class(fixture_fmu(f"gain_fmi{version}"), "gain", parameters=PARAMETERS))
    gain.input_buffer[:] = [U]
    master = Master(system, stop_time=stop_time)
    master.initialize()
    return master, gain


@pytest.mark.parametrize("version", [1, 2, 3])
def test_parameters_survive_an_fmu_that_resets_them_in_setup(version):
    master, gain = _initialised(FmuComponent, version)
    with master:
        ours = (gain._slave.getReal if version < 3 else gain._slave.getFloat64)([GAIN, OFFSET, Y, STOP_TIME])
        outputs = dict(zip([p.name for p in gain.outputs], gain.output_buffer.tolist(), strict=True))
    reference = _fmpy_after_init(version)
    assert ours == reference == [3.0, 0.5, 3.0 * U + 0.5, 1.0]
    assert outputs == {"y": 3.0 * U + 0.5, "stop_time": 1.0, "end_time": 0.0}


def test_the_fixture_loses_parameters_set_before_setup_experiment():
    """The control: set first (the order navcosim used), the FMI 2.0 fixture is back at its defaults."""
    assert _fmpy_after_init(2, parameters_first=True) == [1.0, 0.0, U, 1.0]


@pytest.mark.parametrize("version", [1, 2, 3])
def test_an_open_run_tells_no_stop_time(version):
    master, gain = _initialised(FmuComponent, version, stop_time=None)
    with master:
        assert gain.output_buffer[gain.output_index["stop_time"]] == -1.0
    assert _fmpy_after_init(version, stop_time=None)[3] == -1.0


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
def test_an_isolated_fmu_initialises_in_the_same_order(version):
    master, gain = _initialised(IsolatedFmuComponent, version)
    with master:
        outputs = gain.output_buffer.tolist()
    assert outputs == [3.0 * U + 0.5, 1.0, 0.0]


def _chain(version: int, connect_out: bool, component_class=FmuComponent):
    """B first in the system, fed by A: B.y = 0.5 * A.y - 1 with A.y = 2 * 3 + 1 = 7 at t = 0."""
    path = fixture_fmu(f"gain_fmi{version}")
    system = System(0.1)
    system.add(component_class(path, "b", parameters={"gain": 0.5, "offset": -1.0}))
    a = system.add(component_class(path, "a", parameters={"gain": 2.0, "offset": 1.0}))
    a.input_buffer[:] = [3.0]
    system.connect("a.y", "b.u")
    if connect_out:
        system.add(component_class(path, "c", parameters={"gain": 10.0}))
        system.connect("b.y", "c.u")
    with Master(system, stop_time=1.0) as master:
        master.initialize()
        values = {name: system.component(name).output_buffer[0] for name in system.components}
        inputs = {name: system.component(name).input_buffer[0] for name in system.components}
    return values, inputs


@pytest.mark.parametrize("version", [1, 2, 3])
@pytest.mark.parametrize("connect_out", [False, True])
def test_outputs_at_the_start_reflect_connected_inputs(version, connect_out):
    values, inputs = _chain(version, connect_out)
    assert values["a"] == 7.0
    assert inputs["b"] == 7.0 and values["b"] == 0.5 * 7.0 - 1.0
    if connect_out:
        assert inputs["c"] == 2.5 and values["c"] == 25.0


def test_a_feedback_through_a_state_output_is_exchanged():
    """A feeds B.u directly; B.end_time (a state output, the start time at t = 0) feeds A.u: A comes
    after B in initialisation (A's output depends on A.u), B's direct y needs A: B gets A's value
    once more after both are initialised."""
    path = fixture_fmu("gain_fmi2")
    system = System(0.1)
    a = system.add(FmuComponent(path, "a", parameters={"gain": 2.0, "offset": 1.0}))
    b = system.add(FmuComponent(path, "b", parameters={"gain": 0.5, "offset": -1.0}))
    system.connect("a.y", "b.u")
    system.connect("b.end_time", "a.u", offset=3.0)  # a.u = 0 + 3
    with Master(system, start_time=0.0, stop_time=1.0) as master:
        master.initialize()
        assert [c.name for c in system.initialization_order()] == ["b", "a"]
        assert a.input_buffer[0] == 3.0 and a.output_buffer[0] == 7.0
        assert b.input_buffer[0] == 7.0 and b.output_buffer[0] == 2.5


@pytest.mark.slow
@pytest.mark.parametrize("connect_out", [False, True])
def test_isolated_fmus_exchange_at_the_start_as_in_process(connect_out):
    assert _chain(2, connect_out, IsolatedFmuComponent) == _chain(2, connect_out)


@pytest.mark.slow
def test_a_scenario_component_keeps_its_parameters_and_sees_its_input_at_the_start(tmp_path):
    """[components.gain] (the FMI 2.0 fixture that resets gain and offset in fmi2SetupExperiment)
    fed the mixer's v: y = 3 v + 0.5 from t = 0 on; it is told the stop time, which is no whole
    number of macro steps (0.01 s) and where the run ends."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "scenarios" / "warehouse_diff_drive_no_obstacle.toml").read_text()
    text = text.replace('"maps/warehouse.yaml"', f'"{root / "scenarios" / "maps" / "warehouse.yaml"}"')
    text += (
        f'\n[components.gain]\nfmu = "{fixture_fmu("gain_fmi2")}"\ngain = 3.0\noffset = 0.5\n'
        '\n[[connections]]\nfrom = "mixer.v"\nto = "gain.u"\n'
    )
    scenario = tmp_path / "gain.toml"
    scenario.write_text(text)
    command = [sys.executable, "-m", "cosim", "run", str(scenario), "--out", str(tmp_path / "run.mcap")]
    command += ["--no-plot", "--quiet", "--set", "simulation.stop_time=2.005"]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=root, timeout=600)
    assert completed.returncode in (0, 1), completed.stderr
    with open_log(tmp_path / "run.mcap") as log:
        gain, mixer = log.signals("gain"), log.signals("mixer")
        assert gain.t[0] == 0.0 and mixer.t[0] == 0.0
        assert gain["u"][0] == mixer["v"][0] != 0.0
        assert gain["y"][0] == 3.0 * mixer["v"][0] + 0.5
        assert set(gain["stop_time"].tolist()) == {2.005}
        assert gain.t[-1] == 2.005 and gain["end_time"][-1] == 2.005
