"""String -> String and Binary -> Binary connections: in a `System` and in a scenario's
`[[connections]]`, from the start time on, with the FMUs in this process or in child processes
(`cosim.fmi.isolated`); a text end wired to a number is refused naming both ends.

Truth: the every-type fixture (`types_fmi2/3`): a String or Binary output is its input followed by
its parameter, at initialisation too, so a consumer fed by a producer shows both parameters
appended to the producer's input start value ("hello", bytes 0a 0b)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.cli import main
from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.component import FmuComponent
from cosim.fmi.isolated import IsolatedFmuComponent

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scenario"))
from test_compose import write_scenario  # noqa: E402


@pytest.mark.parametrize(("consumer_first", "isolated"), [
    (False, ()),
    (True, ()),
    pytest.param(False, ("one", "two"), marks=pytest.mark.slow),  # child processes
])  # fmt: skip
@pytest.mark.parametrize(("version", "kind", "suffix", "expected"), [
    (2, "String", "-two", "hello-one-two"),
    (3, "Binary", b"\x02", b"\x0a\x0b\x01\x02"),
])  # fmt: skip
def test_a_text_connection_holds_from_the_start_time(
    consumer_first, isolated, version, kind, suffix, expected
):
    system = System(0.1)
    fmu = fixture_fmu(f"types_fmi{version}")
    parameters = {"one": b"\x01" if kind == "Binary" else "-one", "two": suffix}
    for name in ("two", "one") if consumer_first else ("one", "two"):
        made = IsolatedFmuComponent if name in isolated else FmuComponent
        system.add(made(fmu, name, {f"{kind}_parameter": parameters[name]}))
    system.connect(f"one.{kind}_output", f"two.{kind}_input")
    two = system.components["two"]
    with Master(system, stop_time=0.3) as master:
        master.initialize()
        # At t = 0 the consumer's output reflects the producer's, whichever was added first.
        assert two.text_values[f"{kind}_input"] == expected[: len(expected) - len(suffix)]
        assert two.text_values[f"{kind}_output"] == expected
        master.run(3)
        assert two.text_values[f"{kind}_output"] == expected


TEXT_SCENARIO = """
[components.one]
fmu = "{fmu}"
isolation = "{isolation}"
String_parameter = "-one"
String_input = "hi"

[components.two]
fmu = "{fmu}"
isolation = "{isolation}"
String_parameter = "-two"

[[connections]]
from = "one.{source}"
to = "two.{target}"
"""


def _scenario(tmp_path, source="String_output", target="String_input", isolation="none"):
    extra = TEXT_SCENARIO.format(
        fmu=fixture_fmu("types_fmi2"), source=source, target=target, isolation=isolation
    )
    return write_scenario(tmp_path, "text", "warehouse_diff_drive_one_obstacle.toml", extra)


@pytest.mark.parametrize(("source", "target", "shown"), [
    ("String_output", "Real_input", "one.String_output (String) -> two.Real_input (a number)"),
    ("Real_output", "String_input", "one.Real_output (a number) -> two.String_input (String)"),
])  # fmt: skip
def test_a_scenario_connection_of_text_and_a_number_is_refused_naming_both_ends(
    tmp_path, capsys, source, target, shown
):
    assert main(["system", str(_scenario(tmp_path, source, target))]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "[[connections]][0]" in err and f"connection {shown} cannot convert" in err


@pytest.mark.slow
@pytest.mark.parametrize("isolation", ["none", "process"])
def test_a_scenario_text_connection_runs_and_is_logged_from_the_start(tmp_path, capsys, isolation):
    from cosim.logs import open_log

    scenario = _scenario(tmp_path, isolation=isolation)
    assert main(["system", str(scenario)]) == 0
    assert "one.String_output" in capsys.readouterr().out
    log_path = tmp_path / "text.mcap"
    args = ["run", str(scenario), "--out", str(log_path), "--quiet", "--no-plot"]
    assert main([*args, "--set", "simulation.stop_time=0.05"]) == 1  # ran to the stop time
    with open_log(log_path) as log:
        two = log.text_signals("two")
        assert two.t[0] == 0.0
        assert set(log.text_signals("one")["String_output"]) == {"hi-one"}  # its input held at "hi"
        assert set(two["String_input"]) == {"hi-one"}
        assert set(two["String_output"]) == {"hi-one-two"}  # at t = 0 too
