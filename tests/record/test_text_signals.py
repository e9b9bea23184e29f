"""String and Binary values set from a scenario's TOML and recorded in the log: a string sets a
String parameter or held input, hex digits a Binary one; `/text_signals/<component>` holds them,
read back by `Log.text_signals` and by the `mcap` reader's ROS 2 decoder (an independent one)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from fixtures.build_fixtures import build_fixture_fmu

from cosim.errors import CosimError
from cosim.logs.reader import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.compose import describe_system
from cosim.scenario.load import load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scenario"))
from test_compose import write_scenario  # noqa: E402

BASE = "warehouse_diff_drive_one_obstacle.toml"
SHORT = {r"^stop_time = .*$": "stop_time = 0.3"}


@pytest.fixture(scope="module")
def every_type(tmp_path_factory):
    return build_fixture_fmu("types_fmi3", tmp_path_factory.mktemp("text"))


def _scenario(tmp_path, fmu, values: str, name: str = "text") -> Path:
    extra = f'[components.tt]\nfmu = "{fmu}"\nisolation = "none"\n{values}\n'
    extra += '[[connections]]\nfrom = "vehicle.x"\nto = "tt.Float64_input"\n'
    return write_scenario(tmp_path, name, BASE, extra, SHORT)


VALUES = 'String_parameter = " world"\nString_input = "hi"\nBinary_parameter = "0c"\nBinary_input = "ff01"\n'


def test_toml_strings_set_string_and_binary_variables_and_the_log_records_them(every_type, tmp_path):
    log_path = tmp_path / "run.mcap"
    result = run_scenario(load_scenario(_scenario(tmp_path, every_type, VALUES)), log_path)
    assert result.failure is None
    with open_log(log_path) as log:
        assert log.text_components == ["tt"]
        text = log.text_signals("tt")
        numbers = log.signals("tt")
    assert text.names == ["String_input", "Binary_input", "String_output", "Binary_output"]
    assert text.types == ["String", "Binary", "String", "Binary"]
    # The first record (the first step) holds the outputs of initialisation, already computed from
    # the values set; nothing changes afterwards but the last record at the end time.
    assert text.rows[0] == ["hi", b"\xff\x01", "hi world", b"\xff\x01\x0c"]
    assert all(row == text.rows[0] for row in text.rows)
    assert text.t[0] == numbers.t[0] and text.t[-1] == numbers.t[-1] and len(text.rows) == 2

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(log_path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = list(reader.iter_decoded_messages(topics=["/text_signals/tt"]))
    assert len(decoded) == 2
    message = decoded[0].decoded_message
    # ROS 2 field names are lower case (`cosim.record.rosmsg.field_name`).
    assert message.string_input == "hi" and message.string_output == "hi world"
    assert bytes(message.binary_input) == b"\xff\x01" and bytes(message.binary_output) == b"\xff\x01\x0c"
    assert decoded[-1].message.log_time == numbers.t_ns[-1]


@pytest.mark.parametrize(
    ("values", "problem"),
    [
        (
            'Binary_input = "zz"',
            "tt].Binary_input: the FMU's Binary takes a string of hex digits, two a byte",
        ),
        ("String_parameter = 3", "tt].String_parameter: the FMU's String takes a string of text, got 3"),
        (
            'Float64_parameter = "x"',
            "tt].Float64_parameter: must be a number (the FMU's Float64), got a string",
        ),
    ],
)
def test_a_value_of_the_wrong_kind_is_one_line_naming_the_key(every_type, tmp_path, values, problem):
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(_scenario(tmp_path, every_type, values)))
    (line,) = str(raised.value).splitlines()
    assert problem in line


def test_a_text_record_is_written_when_a_value_changes_stamped_as_the_numbers(every_type, tmp_path):
    """An input set between steps: the record at the next step's start t holds it with the outputs
    at t (those before the step), the record one step later the outputs computed from it."""
    from cosim.core.master import Master
    from cosim.core.system import System
    from cosim.fmi.component import FmuComponent
    from cosim.record.recorder import Recorder
    from cosim.record.text_signals import TextRecording

    system = System(0.5)
    component = system.add(FmuComponent(every_type, "tt", parameters={"String_parameter": "!"}))
    with Master(system) as master, Recorder(tmp_path / "text.mcap") as recorder:
        master.initialize()
        text = TextRecording(recorder, system)
        master.run(2)
        component.set_text("String_input", "bye")
        master.run(2)
        text.finish(master.time_ns)
    with open_log(tmp_path / "text.mcap") as log:
        signals = log.text_signals("tt")
    strings = [(row[0], row[2]) for row in signals.rows]
    assert signals.t.tolist() == [0.0, 1.0, 1.5, 2.0]
    assert strings == [("hello", "hello!"), ("bye", "hello!"), ("bye", "bye!"), ("bye", "bye!")]
