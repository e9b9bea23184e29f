"""`cosim log info`, `export` and `diff` on String and Binary signals (`/text_signals/<component>`):
a log written by the every-type FMU fixture with text values set between steps; the truth is the
values set (and the fixture's output = input + parameter)."""

from __future__ import annotations

import csv

import pytest
from fixtures.build_fixtures import build_fixture_fmu

from cosim.logs.diff import diff_logs, format_report
from cosim.logs.export import export_signals
from cosim.logs.info import format_info
from cosim.logs.reader import open_log


@pytest.fixture(scope="module")
def every_type(tmp_path_factory):
    return build_fixture_fmu("types_fmi3", tmp_path_factory.mktemp("logtext"))


def _log(fmu, path, second: str, binary: bytes = b"\x00\xff"):
    from cosim.core.master import Master
    from cosim.core.system import System
    from cosim.fmi.component import FmuComponent
    from cosim.record.recorder import Recorder
    from cosim.record.text_signals import TextRecording

    system = System(0.5)
    component = system.add(FmuComponent(fmu, "tt", parameters={"String_parameter": "!"}))
    with Master(system) as master, Recorder(path) as recorder:
        master.initialize()
        text = TextRecording(recorder, system)
        master.run(2)
        component.set_text("String_input", second)
        component.set_text("Binary_input", binary)
        master.run(2)
        text.finish(master.time_ns)
    return path


def test_info_lists_the_text_channels(every_type, tmp_path):
    with open_log(_log(every_type, tmp_path / "a.mcap", "bye")) as log:
        info = format_info(log)
    assert "/text_signals/tt" in info
    assert "text      tt (4)" in info.splitlines()


def test_csv_export_writes_the_text_signals_as_set_binary_as_hex(every_type, tmp_path):
    with open_log(_log(every_type, tmp_path / "a.mcap", 'bye, "quoted"\nline')) as log:
        paths = export_signals(log, tmp_path / "out", "csv")
        t_ns = log.text_signals("tt").t
    text_path = tmp_path / "out" / "a-tt-text.csv"
    assert text_path in paths
    with open(text_path, newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["t_ns", "t", "String_input", "Binary_input", "String_output", "Binary_output"]
    assert [int(row[0]) for row in rows[1:]] == [round(t * 1e9) for t in t_ns.tolist()] == [0, 1e9, 15e8, 2e9]
    # set at t = 1 s; the outputs follow one step later
    assert rows[2][2:4] == ['bye, "quoted"\nline', "00ff"]
    assert rows[3][4] == 'bye, "quoted"\nline!'
    assert (
        bytes.fromhex(rows[3][5]) == b"\x00\xff" + bytes.fromhex(rows[1][5])[len(bytes.fromhex(rows[1][3])) :]
    )


def test_diff_compares_text_signals(every_type, tmp_path):
    a = _log(every_type, tmp_path / "a.mcap", "bye")
    same = _log(every_type, tmp_path / "same.mcap", "bye")
    other = _log(every_type, tmp_path / "other.mcap", "bye!")
    with open_log(a) as log_a, open_log(same) as log_b:
        assert not diff_logs(log_a, log_b, 0.0).differs
    with open_log(a) as log_a, open_log(other) as log_b:
        report = diff_logs(log_a, log_b, 0.0)
        text = format_report(report, log_a, log_b)
    assert report.differs
    assert [name for name, _ in report.text_differences] == ["tt.String_input", "tt.String_output"]
    assert dict(report.text_differences)["tt.String_input"] == 1.0
    assert dict(report.text_differences)["tt.String_output"] == 1.5
    assert "text tt.String_input: differs from t = 1.000 s" in text
    assert text.splitlines()[-1] == "result: DIFFERENT (text)"
