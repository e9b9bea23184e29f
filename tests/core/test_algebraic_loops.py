"""Algebraic loops under the Gauss-Seidel master (`System.loops`): "delay" steps the loop's
components with their inputs from the previous communication point (Jacobi inside the loop,
Gauss-Seidel elsewhere), "error" refuses the loop naming the keys that run it.

Truth: two affine feedthrough FMUs (the `types_numeric_fmi2` fixture, Real_output = Real_input +
Real_parameter) wired into each other through scaled connections; the one-step-delayed recurrence
is computed here, and it converges to the coupled fixed point known analytically."""

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.component import Port, PythonComponent
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent

A_GAIN, C_GAIN, B_BIAS, D_BIAS = 0.5, -0.8, 1.0, 2.0  # y1 = a*y2 + b, y2 = c*y1 + d


def _loop(loops="delay", downstream=False):
    system = System(0.01, loops=loops)
    kind = fixture_fmu("types_numeric_fmi2")
    system.add(FmuComponent(kind, "one", {"Real_parameter": B_BIAS}))
    system.add(FmuComponent(kind, "two", {"Real_parameter": D_BIAS}))
    # one.Real_input = a * two.Real_output, two.Real_input = c * one.Real_output
    system.connect("two.Real_output", "one.Real_input", scale=A_GAIN)
    system.connect("one.Real_output", "two.Real_input", scale=C_GAIN)
    if downstream:
        system.add(FmuComponent(kind, "three", {"Real_parameter": 0.0}))
        system.connect("one.Real_output", "three.Real_input")
    return system


def _outputs(master, name):
    component = master.system.components[name]
    return component.output_buffer[component.output_index["Real_output"]]


def test_delay_follows_the_one_step_delayed_recurrence_and_reaches_the_fixed_point():
    with Master(_loop(downstream=True)) as master:
        master.initialize()
        y1, y2 = _outputs(master, "one"), _outputs(master, "two")
        for _ in range(60):
            master.step()
            # Both loop members saw the other's output from before the step.
            y1, y2 = A_GAIN * y2 + B_BIAS, C_GAIN * y1 + D_BIAS
            assert _outputs(master, "one") == pytest.approx(y1, abs=1e-12)
            assert _outputs(master, "two") == pytest.approx(y2, abs=1e-12)
            # Outside the loop, Gauss-Seidel: `three` sees `one`'s output of this step.
            assert _outputs(master, "three") == pytest.approx(y1, abs=1e-12)
    fixed = (A_GAIN * D_BIAS + B_BIAS) / (1 - A_GAIN * C_GAIN)
    assert y1 == pytest.approx(fixed, abs=1e-6)
    assert y2 == pytest.approx(C_GAIN * fixed + D_BIAS, abs=1e-6)


def test_delay_equals_the_jacobi_master_on_the_loop():
    runs = []
    for mode in ("gauss-seidel", "jacobi"):
        system = _loop()
        system.mode = mode
        with Master(system) as master:
            master.initialize()
            rows = []
            for _ in range(20):
                master.step()
                rows.append((_outputs(master, "one"), _outputs(master, "two")))
        runs.append(np.array(rows))
    assert np.array_equal(runs[0], runs[1])


def test_error_refuses_the_loop_and_names_the_keys_that_run_it():
    with pytest.raises(
        CosimError, match=r"algebraic loop .*one\.Real_output.*simulation\.algebraic_loops=delay"
    ):
        Master(_loop("error"))


def test_unknown_handling_is_refused():
    with pytest.raises(CosimError, match="not one of delay, iterate, error"):
        System(0.01, loops="solve")


class Echo(PythonComponent):
    def __init__(self, name):
        super().__init__(name, [Port("seen", start=0.0)], [Port("out", start=0.0)])

    def step(self, t, h):
        self.output_buffer[0] = self.input_buffer[0] + 1.0


def test_delay_note_is_said_once_on_stderr(capsys):
    system = System(0.01)
    system.add(Echo("a"))
    system.add(Echo("b"))
    system.connect("a.out", "b.seen")
    system.connect("b.out", "a.seen")
    with Master(system) as master:
        master.initialize()
        master.run(3)
        # a_k+1 = b_k + 1, b_k+1 = a_k + 1 from 0, 0: both 3 after 3 steps.
        assert master.system.components["a"].output_buffer[0] == 3.0
        assert master.system.components["b"].output_buffer[0] == 3.0
    assert capsys.readouterr().err.count("algebraic loop a.out -> b.seen -> b.out -> a.seen -> a.out") == 1


LOOP_SCENARIO = """
[components.one]
fmu = "{fmu}"
Real_parameter = 1.0
Integer_input = 0
Boolean_input = false
Enumeration_input = 1

[components.two]
fmu = "{fmu}"
Real_parameter = 2.0
Integer_input = 0
Boolean_input = false
Enumeration_input = 1

[[connections]]
from = "two.Real_output"
to = "one.Real_input"
scale = 0.5

[[connections]]
from = "one.Real_output"
to = "two.Real_input"
scale = -0.8
"""


@pytest.fixture
def loop_scenario(tmp_path):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scenario"))
    from test_compose import write_scenario

    extra = LOOP_SCENARIO.format(fmu=fixture_fmu("types_numeric_fmi2"))
    return write_scenario(tmp_path, "looped", "warehouse_diff_drive_one_obstacle.toml", extra)


def test_cosim_system_shows_the_loop_and_its_handling(loop_scenario, capsys):
    from cosim.cli import main

    assert main(["system", str(loop_scenario)]) == 0
    out = capsys.readouterr().out
    assert "algebraic loop: " in out and "one.Real_output -> two.Real_input" in out
    assert 'simulation.algebraic_loops = "delay"' in out
    assert main(["system", str(loop_scenario), "--set", "simulation.algebraic_loops=error"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "algebraic loop through components" in err and 'algebraic_loops = "delay"' in err


@pytest.mark.slow
def test_a_scenario_with_a_loop_runs(loop_scenario, tmp_path, capsys):
    from cosim.cli import main

    log = tmp_path / "looped.mcap"
    args = ["run", str(loop_scenario), "--out", str(log), "--quiet", "--no-plot"]
    args += ["--set", "simulation.stop_time=0.5"]
    assert main(args) == 1  # ran to the stop time (the goal is far)
    assert log.exists()
    assert capsys.readouterr().err.count("note: algebraic loop") == 1


SSP1 = "http://ssp-standard.org/SSP1"
LOOP_SSD = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="{SSP1}/SystemStructureDescription"
    xmlns:ssc="{SSP1}/SystemStructureCommon" version="1.0" name="looped">
  <ssd:System name="root">
    <ssd:Elements>
      <ssd:Component name="one" source="resources/affine.fmu"><ssd:Connectors>
        <ssd:Connector name="Real_input" kind="input"><ssc:Real/></ssd:Connector>
        <ssd:Connector name="Real_output" kind="output"><ssc:Real/></ssd:Connector>
      </ssd:Connectors></ssd:Component>
      <ssd:Component name="two" source="resources/affine.fmu"><ssd:Connectors>
        <ssd:Connector name="Real_input" kind="input"><ssc:Real/></ssd:Connector>
        <ssd:Connector name="Real_output" kind="output"><ssc:Real/></ssd:Connector>
      </ssd:Connectors></ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="two" startConnector="Real_output"
          endElement="one" endConnector="Real_input">
        <ssc:LinearTransformation factor="{A_GAIN}" offset="{B_BIAS}"/></ssd:Connection>
      <ssd:Connection startElement="one" startConnector="Real_output"
          endElement="two" endConnector="Real_input">
        <ssc:LinearTransformation factor="{C_GAIN}" offset="{D_BIAS}"/></ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.3"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.slow
def test_an_ssp_with_a_loop_runs_the_delayed_recurrence(tmp_path, capsys):
    import zipfile

    from cosim.logs import open_log
    from cosim.ssp.run import run_ssp

    archive = tmp_path / "looped.ssp"
    with zipfile.ZipFile(archive, "w") as zipped:
        zipped.writestr("SystemStructure.ssd", LOOP_SSD)
        zipped.write(fixture_fmu("types_numeric_fmi2"), "resources/affine.fmu")
    result = run_ssp(archive, tmp_path / "looped.mcap", ["simulation.macro_step=0.01"])
    assert result.exit_code == 0
    log = open_log(result.log_path)
    one, two = log.signals("one")["Real_output"], log.signals("two")["Real_output"]
    # Parameters 0: Real_output = Real_input; the connections carry a*y2 + b and c*y1 + d from
    # the previous communication point.
    for k in range(1, len(one)):
        assert one[k] == pytest.approx(A_GAIN * two[k - 1] + B_BIAS, abs=1e-12)
        assert two[k] == pytest.approx(C_GAIN * one[k - 1] + D_BIAS, abs=1e-12)
    assert len(one) >= 30
    from cosim.cli import main

    assert main(["system", str(archive), "--set", "simulation.macro_step=0.01"]) == 0
    out = capsys.readouterr().out
    assert "algebraic loop: " in out and "one, two step with their inputs from the previous" in out
