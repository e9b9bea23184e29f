"""`writer.metadata_record` writes the bytes the mcap library writes for a Metadata record.

Truth: `mcap.records.Metadata.write` on the library's `RecordBuilder`, and the library's reader."""

import pytest
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import Metadata

from cosim.record.writer import metadata_record


def _library(name: str, data: dict[str, str]) -> bytes:
    builder = RecordBuilder()
    Metadata(name=name, metadata=data).write(builder)
    return builder.end()


@pytest.mark.parametrize(
    "name, data",
    [
        ("unconnected_inputs", {f"vfh.ranges[{k}]": "nan" for k in range(1, 722)}),
        ("navcosim", {"scenario_name": "a", "overrides": "", "start": "6.0,6.0,0.0"}),
        ("empty", {}),
        ("", {"": ""}),
        ("ünïcödé ✓", {"ключ": "значение", "emoji 🤖": "x" * 70000}),
    ],
)
def test_the_record_is_the_libraries_bytes(name, data):
    assert metadata_record(name, data) == _library(name, data)


def test_a_log_with_such_records_reads_back(tmp_path):
    from cosim.record.recorder import Recorder

    path = tmp_path / "m.mcap"
    recorder = Recorder(path)
    recorder.add_metadata("first", {"a": "1", "b": "two"})
    recorder.add_metadata("unconnected_inputs", {f"x[{k}]": "nan" for k in range(300)})
    recorder.close()
    with open(path, "rb") as stream:
        records = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    assert records["first"] == {"a": "1", "b": "two"}
    assert records["unconnected_inputs"] == {f"x[{k}]": "nan" for k in range(300)}
