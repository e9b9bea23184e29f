"""`[simulation] algebraic_loops = "iterate"`: fixed-point iteration of an algebraic loop within each
macro step, rolling the FMUs back with their FMU state (`cosim.core.loops`).

Truth: two linear feedthrough FMUs (the `gain_state_fmi2/3` fixtures, y = gain * u + offset + w,
with canGetAndSetFMUstate) fed into each other, y1 = a u1 + b + w, y2 = c u2 + d, u1 = y2, u2 = y1,
whose coupled solution is known analytically: y1 = (a d + b + w) / (1 - a c). w is a ramp (the end
time t + h of a third FMU's step, `gain_fmi2`'s `end_time`), so the solution moves every step and
the one-step delay of "delay" lags behind it. The fixture's `integral` (of u over the steps it took)
shows that rejected iterations were rolled back. The iteration counts are checked against the
documented scheme worked through here: Gauss-Seidel sweeps from the previous step's values until
every loop connection's value changes by at most tolerance * (1 + |value|)."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.component import FmuComponent

A_GAIN, B_OFFSET, C_GAIN, D_OFFSET = 0.5, 1.0, -0.8, 2.0
H = 0.1
STEPS = 12
TOLERANCE = 1e-10


def coupled(w):
    """(y1, y2) of the loop for input w."""
    y1 = (A_GAIN * D_OFFSET + B_OFFSET + w) / (1 - A_GAIN * C_GAIN)
    return y1, C_GAIN * y1 + D_OFFSET


def expected_iterations(to_one, one, to_two, two, y2: float, tolerance: float) -> int:
    """Iterations of one macro step as `cosim.core.loops` documents them: members in the order
    one, two, the first iteration from the outputs before the step (two's output `y2`). `to_one`,
    `to_two` are the connections (value -> input), `one`, `two` the models (input -> output)."""
    iterations = 0
    while True:
        iterations += 1
        u1 = to_one(y2)  # one gathers from two: the previous iteration's output
        y2 = two(to_two(one(u1)))  # two gathers from one: this iteration's
        if abs(to_one(y2) - u1) <= tolerance * (1 + abs(to_one(y2))):  # the other connection agrees
            return iterations


def loop_system(version: int, loops: str = "iterate", offsets=(B_OFFSET, D_OFFSET), **settings) -> System:
    system = System(H, loops=loops, **settings)
    system.add(FmuComponent(fixture_fmu("gain_fmi2"), "ramp"))  # end_time: t + h of its last step
    kind = fixture_fmu(f"gain_state_fmi{version}")
    system.add(FmuComponent(kind, "one", {"gain": A_GAIN, "offset": offsets[0]}))
    system.add(FmuComponent(kind, "two", {"gain": C_GAIN, "offset": offsets[1]}))
    system.add(FmuComponent(fixture_fmu("gain_fmi2"), "three"))  # y = u: downstream of the loop
    system.connect("ramp.end_time", "one.w")
    system.connect("two.y", "one.u")
    system.connect("one.y", "two.u")
    system.connect("one.y", "three.u")
    return system


def value(master: Master, reference: str) -> float:
    name, port = reference.split(".")
    component = master.system.components[name]
    direction, index = component.port(port)
    buffer = component.output_buffer if direction == "output" else component.input_buffer
    return float(buffer[index])


@pytest.mark.parametrize("version", [2, 3])
def test_iterate_reaches_the_coupled_solution_at_every_step(version):
    with Master(loop_system(version, loop_tolerance=TOLERANCE), stop_time=STEPS * H) as master:
        master.initialize()
        assert [c.name for c in master.order] == ["ramp", "one", "two", "three", "master"]
        y1, y2 = coupled(0.0)  # the ramp's end_time is the start time before its first step
        assert value(master, "one.y") == pytest.approx(y1, abs=1e-8)
        assert value(master, "two.y") == pytest.approx(y2, abs=1e-8)
        integral = 0.0
        for k in range(STEPS):
            previous_y2 = value(master, "two.y")
            master.step()
            t = (k + 1) * H
            y1, y2 = coupled(t)
            assert value(master, "one.w") == pytest.approx(t, abs=1e-12)
            assert value(master, "one.y") == pytest.approx(y1, abs=1e-8)
            assert value(master, "two.y") == pytest.approx(y2, abs=1e-8)
            assert value(master, "three.y") == value(master, "one.y")  # after the loop, this step
            iterations = expected_iterations(
                lambda y: y,
                lambda u, w=t: A_GAIN * u + B_OFFSET + w,
                lambda y: y,
                lambda u: C_GAIN * u + D_OFFSET,
                previous_y2,
                TOLERANCE,
            )
            assert iterations > 1
            assert value(master, "master.loop_iterations") == iterations
            # Only the accepted iteration's step counts: the rejected ones were rolled back.
            integral += value(master, "one.u") * H
            assert value(master, "one.integral") == pytest.approx(integral, rel=1e-12)


def test_delay_lags_behind_the_coupled_solution():
    with Master(loop_system(2, loops="delay"), stop_time=STEPS * H) as master:
        master.initialize()
        assert "master" not in master.system.components
        errors = []
        for k in range(STEPS):
            master.step()
            errors.append(abs(value(master, "one.y") - coupled((k + 1) * H)[0]))
    # The delayed loop follows the moving solution one communication point late: its error never
    # falls below the change of the solution over a step, as iterate's stays within 1e-8.
    step_change = coupled(H)[0] - coupled(0.0)[0]
    assert min(errors) > 0.1 * step_change > 1e-3


def test_an_fmu_without_fmu_state_is_refused_naming_it():
    system = System(H, loops="iterate")
    system.add(FmuComponent(fixture_fmu("gain_state_fmi2"), "one"))
    system.add(FmuComponent(fixture_fmu("gain_fmi2"), "two"))
    system.connect("two.y", "one.u")
    system.connect("one.y", "two.u")
    with pytest.raises(CosimError) as error:
        Master(system)
    message = str(error.value)
    assert "\n" not in message
    assert "component 'two'" in message and "does not declare canGetAndSetFMUstate" in message
    assert 'simulation.algebraic_loops = "delay"' in message


def test_a_loop_that_does_not_converge_is_an_error_naming_it_and_its_change():
    # Offsets 0: the start values (all 0) are the loop's solution at t = 0, so initialisation
    # agrees at once; the ramp then moves it, which one iteration cannot follow.
    system = loop_system(2, offsets=(0.0, 0.0), loop_max_iterations=1)
    with Master(system, stop_time=STEPS * H) as master:
        master.initialize()
        assert value(master, "master.loop_iterations") == 1
        with pytest.raises(CosimError) as error:
            master.step()
    message = str(error.value)
    # Iteration 1: u1 = y2 before the step = 0, y1 = w = h, y2 = c h; two.y -> one.u changed
    # by |c h| / (1 + |c h|).
    change = abs(C_GAIN * H) / (1 + abs(C_GAIN * H))
    assert "algebraic loop (two.y -> one.u, one.y -> two.u) did not converge" in message
    assert "from t = 0 s in 1 iterations" in message
    assert f"two.y -> one.u still changed by {change:.3g}" in message
    assert "\n" not in message


def test_initialisation_that_does_not_converge_is_an_error():
    system = loop_system(3, loop_max_iterations=3)
    with pytest.raises(CosimError, match=r"did not converge at initialisation in 3 iterations"):
        with Master(system, stop_time=1.0) as master:
            master.initialize()


def test_loop_settings_are_checked():
    with pytest.raises(CosimError, match="loop_tolerance must be a number > 0"):
        System(H, loops="iterate", loop_tolerance=0.0)
    with pytest.raises(CosimError, match="loop_max_iterations must be a whole number >= 1"):
        System(H, loops="iterate", loop_max_iterations=0)


def _ssp(tmp_path):
    ssd = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="loop">
  <ssd:System name="root">
    <ssd:Elements>
      <ssd:Component name="ramp" source="resources/gain.fmu"><ssd:Connectors>
        <ssd:Connector name="end_time" kind="output"><ssc:Real/></ssd:Connector>
      </ssd:Connectors></ssd:Component>
      <ssd:Component name="one" source="resources/gain_state.fmu"><ssd:Connectors>
        <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
        <ssd:Connector name="w" kind="input"><ssc:Real/></ssd:Connector>
        <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
      </ssd:Connectors></ssd:Component>
      <ssd:Component name="two" source="resources/gain_state.fmu"><ssd:Connectors>
        <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
        <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
      </ssd:Connectors></ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="ramp" startConnector="end_time" endElement="one" endConnector="w"/>
      <ssd:Connection startElement="two" startConnector="y" endElement="one" endConnector="u">
        <ssc:LinearTransformation factor="{C_GAIN}" offset="{D_OFFSET}"/></ssd:Connection>
      <ssd:Connection startElement="one" startConnector="y" endElement="two" endConnector="u">
        <ssc:LinearTransformation factor="{A_GAIN}" offset="{B_OFFSET}"/></ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{STEPS * H}"/>
</ssd:SystemStructureDescription>
"""
    archive = tmp_path / "loop.ssp"
    with zipfile.ZipFile(archive, "w") as zipped:
        zipped.writestr("SystemStructure.ssd", ssd)
        zipped.write(fixture_fmu("gain_fmi2"), "resources/gain.fmu")
        zipped.write(fixture_fmu("gain_state_fmi2"), "resources/gain_state.fmu")
    return archive


@pytest.mark.slow
def test_an_ssp_run_logs_the_iterations_on_signals_master(tmp_path, capsys):
    """The same loop in an SSP (the FMUs' own gain 1 and offset 0: the connections carry a, b, c, d,
    so y1 = c y2 + d + w, y2 = a y1 + b), its FMUs in child processes (`fmu_isolation` "auto"),
    iterated by `--set`: every record of one.y is the coupled solution, and /signals/master holds
    the iteration counts of the scheme."""
    from cosim.cli import main
    from cosim.logs import open_log
    from cosim.ssp.run import run_ssp

    archive = _ssp(tmp_path)
    overrides = ["simulation.macro_step=0.1", "simulation.algebraic_loops=iterate"]
    overrides += [f"simulation.loop_tolerance={TOLERANCE}", "simulation.loop_max_iterations=80"]
    result = run_ssp(archive, tmp_path / "loop.mcap", overrides)
    assert result.exit_code == 0, result.failure
    log = open_log(result.log_path)
    one, master = log.signals("one"), log.signals("master")
    assert np.allclose(one.t, np.arange(STEPS + 1) * H)
    # The record at t holds the input applied over the step from t (the ramp's t + h, the ramp
    # stepping first) and the outputs at t, which the step that ended at t made with w = t.
    assert np.allclose(one["w"][:-1], one.t[1:], atol=1e-12)
    w = one.t
    # Here y1 = c y2 + d + w and y2 = a y1 + b, so y1 = (c b + d + w) / (1 - a c).
    exact = (C_GAIN * B_OFFSET + D_OFFSET + w) / (1 - A_GAIN * C_GAIN)
    assert np.max(np.abs(one["y"] - exact)) < 1e-8
    iterations = master["loop_iterations"]
    assert iterations[0] > 1  # initialisation's passes from the start values
    two_y = log.signals("two")["y"]
    for k in range(1, len(iterations)):
        count = expected_iterations(
            lambda y: C_GAIN * y + D_OFFSET,
            lambda u, w=w[k]: u + w,
            lambda y: A_GAIN * y + B_OFFSET,
            lambda u: u,
            two_y[k - 1],
            TOLERANCE,
        )
        assert iterations[k] == count > 1, k
    assert main(["system", str(archive), "--set", "simulation.macro_step=0.1", "--set",
                 "simulation.algebraic_loops=iterate"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "handled by iteration" in out and "one, two iterate to a fixed point" in out


LOOP_SCENARIO = """
[components.ramp]
fmu = "{gain}"

[components.one]
fmu = "{gain_state}"
gain = {a}
offset = {b}

[components.two]
fmu = "{gain_state}"
gain = {c}
offset = {d}

[[connections]]
from = "ramp.end_time"
to = "one.w"

[[connections]]
from = "two.y"
to = "one.u"

[[connections]]
from = "one.y"
to = "two.u"
"""


@pytest.fixture
def loop_scenario(tmp_path):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scenario"))
    from test_compose import write_scenario

    extra = LOOP_SCENARIO.format(
        gain=fixture_fmu("gain_fmi2"), gain_state=fixture_fmu("gain_state_fmi2"), a=A_GAIN, b=B_OFFSET,
        c=C_GAIN, d=D_OFFSET,
    )  # fmt: skip
    return write_scenario(tmp_path, "looped", "warehouse_diff_drive_one_obstacle.toml", extra)


def test_scenario_keys_are_read_and_checked(loop_scenario, capsys):
    from cosim.cli import main
    from cosim.scenario.load import load_scenario

    iterate = ["simulation.algebraic_loops=iterate", "simulation.loop_tolerance=1e-6"]
    scenario = load_scenario(loop_scenario, [*iterate, "simulation.loop_max_iterations=7"])
    assert (scenario.algebraic_loops, scenario.loop_tolerance, scenario.loop_max_iterations) == (
        "iterate",
        1e-6,
        7,
    )
    defaults = load_scenario(loop_scenario)
    assert (defaults.loop_tolerance, defaults.loop_max_iterations) == (1e-8, 50)
    for bad, key in (
        ("loop_tolerance=0", "loop_tolerance"),
        ("loop_max_iterations=0", "loop_max_iterations"),
    ):
        with pytest.raises(CosimError, match=rf"\[simulation\]\.?{key}"):
            load_scenario(loop_scenario, [f"simulation.{bad}"])
    assert main(["system", str(loop_scenario), "--set", "simulation.algebraic_loops=iterate"]) == 0
    out = capsys.readouterr().out
    assert 'handled by iteration (simulation.algebraic_loops = "iterate")' in out


@pytest.mark.slow
def test_a_scenario_run_iterates_the_loop_and_logs_the_iterations(loop_scenario, tmp_path):
    from cosim.cli import main
    from cosim.logs import open_log

    log_path = tmp_path / "looped.mcap"
    args = ["run", str(loop_scenario), "--out", str(log_path), "--quiet", "--no-plot"]
    args += ["--set", "simulation.stop_time=0.5", "--set", "simulation.algebraic_loops=iterate"]
    assert main(args) == 1  # ran to the stop time (the goal is far)
    log = open_log(log_path)
    one, master = log.signals("one"), log.signals("master")
    # The records at t: outputs the step that ended at t made, with w = t (as the SSP run's).
    assert np.max(np.abs(one["y"] - coupled(one.t)[0])) < 1e-7
    assert np.array_equal(master.t, one.t)
    assert master["loop_iterations"][0] > 1 and np.all(master["loop_iterations"][1:] >= 2)
