"""Unconnected inputs take their start values, as FMI defines: a third-party-style feedthrough FMU
with inputs of every type, one of them wired, runs in a scenario; its log holds the other inputs at
their start values and every output as fmpy computes it from the same one input; `cosim system`
lists them and the log's metadata keeps them. An input without a start value, and a template input
whose template connection was dropped, stay errors (the latter:
`test_compose_errors.test_replacement_problems_at_once`)."""

from __future__ import annotations

import re
import zipfile

import fmpy
import numpy as np
import pytest
from fixtures.build_fixtures import build_fixture_fmu
from fixtures.conftest_helpers import fixture_fmu
from fixtures.types_fixture import INPUT_STARTS
from test_compose import write_scenario

from cosim.cli import main
from cosim.errors import CosimError
from cosim.logs.reader import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.compose import describe_system
from cosim.scenario.load import load_scenario

BASE = "warehouse_diff_drive_one_obstacle.toml"
SHORT = {r"^stop_time = .*$": "stop_time = 0.5"}
NUMERIC = ("Real", "Integer", "Boolean", "Enumeration")  # FMI 2.0 numeric types of the fixture


@pytest.fixture(scope="module")
def feedthrough(tmp_path_factory):
    return build_fixture_fmu("types_numeric_fmi2", tmp_path_factory.mktemp("feedthrough"))


def _scenario(tmp_path, fmu, extra: str = "", name: str = "third_party"):
    text = f'[components.ft]\nfmu = "{fmu}"\n{extra}\n'
    text += '[[connections]]\nfrom = "vehicle.x"\nto = "ft.Real_input"\n'
    return write_scenario(tmp_path, name, BASE, text, SHORT)


def test_an_every_type_fmu_with_one_input_wired_runs_as_fmpy_runs_it(feedthrough, tmp_path):
    log_path = tmp_path / "run.mcap"
    result = run_scenario(load_scenario(_scenario(tmp_path, feedthrough)), log_path)
    assert result.failure is None
    with open_log(log_path) as log:
        signals = log.signals("ft")
        times = signals.t
        kept = log.metadata["unconnected_inputs"]
    for t in NUMERIC[1:]:
        assert signals[f"{t}_input"].tolist() == [float(INPUT_STARTS[t])] * len(times), t
        assert kept[f"ft.{t}_input"] == str(INPUT_STARTS[t]).lower(), t
    assert "ft.Real_input" not in kept
    # fmpy, given the one input the run fed (sampled at the communication points), computes the
    # outputs from it and the others' start values.
    h = 0.01
    given = np.array(
        list(zip(times, signals["Real_input"], strict=True)), dtype=[("time", float), ("Real_input", float)]
    )
    expected = fmpy.simulate_fmu(
        str(feedthrough), stop_time=float(times[-1]), step_size=h, output_interval=h, input=given
    )
    for t in NUMERIC:
        ours = signals[f"{t}_output"][1:]  # the first record holds the outputs of initialisation
        theirs = np.asarray(expected[f"{t}_output"], dtype=float)[1 : len(ours) + 1]
        assert ours.tolist() == theirs.tolist(), t


def test_cosim_system_lists_the_unconnected_inputs_with_their_values(feedthrough, tmp_path, capsys):
    path = _scenario(tmp_path, feedthrough, extra="Boolean_input = false")
    assert main(["system", str(path)]) == 0
    out = capsys.readouterr().out
    section = out[out.index("unconnected inputs") :]
    assert re.search(r"ft\.Integer_input +-2000000000 +start", section)
    assert re.search(r"ft\.Enumeration_input +2 +start", section)
    assert re.search(r"ft\.Boolean_input +false +held by the scenario", section)
    assert "ft.Real_input" not in section


def _without_start(source, target, variable: str):
    """A copy of the FMU whose `variable` declares no start value."""
    with zipfile.ZipFile(source) as archive, zipfile.ZipFile(target, "w") as copy:
        for item in archive.infolist():
            data = archive.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                at = text.index(f'name="{variable}"')
                end = text.index("/>", text.index("<", text.index(">", at)))
                text = text[:at] + re.sub(r' start="[^"]*"', "", text[at:end], count=1) + text[end:]
                data = text.encode()
            copy.writestr(item, data)
    return target


def test_an_unconnected_input_without_a_start_value_is_one_error_naming_it(feedthrough, tmp_path):
    """FMI 2.0 and 3.0 require a start value on every input (the FMU is refused as it loads, as fmpy
    refuses it); FMI 1.0 does not, and defines no default: unconnected, such an input is an error,
    connected or held it runs."""
    fmu = _without_start(feedthrough, tmp_path / "no_start.fmu", "Integer_input")
    with pytest.raises(CosimError, match='Variable "Integer_input" .* has no start value'):
        describe_system(load_scenario(_scenario(tmp_path, fmu)))
    fmi1 = _without_start(fixture_fmu("diffdrive_plain_fmi1"), tmp_path / "fmi1.fmu", "omega")
    extra = f'[components.dd]\nfmu = "{fmi1}"\n[[connections]]\nfrom = "vehicle.x"\nto = "dd.v"\n'
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(write_scenario(tmp_path, "fmi1", BASE, extra, SHORT)))
    (line,) = str(raised.value).splitlines()
    assert "[components.dd]: input 'omega' is not connected and the FMU gives it no start value" in line
    held = write_scenario(tmp_path, "held", BASE, extra.replace("\n[[", "\nomega = 0.5\n[[", 1), SHORT)
    assert describe_system(load_scenario(held)).components["dd"].held_inputs == {"omega": 0.5}
