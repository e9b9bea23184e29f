"""A project FMU's parsed modelDescription.xml is kept beside it in the FMU build cache
(`cosim.fmi.description._parsed_description`): read back, it is the parse; any other file version,
or a kept copy that cannot be read, means a fresh parse; nothing is written beside a user's FMU."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import fmpy
from fmpy.model_description import ModelVariable

from cosim.fmi import description

FIELDS = ("name", "valueReference", "type", "causality", "variability", "start", "unit", "description")


def _summary(parsed) -> tuple:
    variables = [tuple(getattr(v, f) for f in FIELDS) for v in parsed.modelVariables]
    outputs = [(u.variable.name, [d.name for d in u.dependencies or []]) for u in parsed.outputs]
    return parsed.guid, parsed.coSimulation.modelIdentifier, variables, outputs


def _parse(path: Path):
    return description._parsed_description.__wrapped__(str(path.resolve()), *description.file_identity(path))


def test_the_kept_parse_is_the_parse(fmu_cache: Path):
    fmu = fmu_cache / "PurePursuit.fmu"
    first = _parse(fmu)
    kept = fmu_cache / ".PurePursuit.description.pickle"
    assert kept.is_file()
    again = _parse(fmu)
    assert again is not first
    assert _summary(again) == _summary(first) == _summary(fmpy.read_model_description(str(fmu)))
    # Every field of every variable, each a fmpy ModelVariable (kept in the compact form).
    fields = list(description._variable_defaults())
    for kept_variable, variable in zip(again.modelVariables, first.modelVariables, strict=True):
        assert isinstance(kept_variable, ModelVariable)
        for name in fields:
            kept_value, value = getattr(kept_variable, name), getattr(variable, name)
            assert type(kept_value) is type(value) and (kept_value == value or name == "declaredType"), name
    dependency = again.outputs[0].variable
    assert any(dependency is variable for variable in again.modelVariables)  # shared, not copied


def test_another_file_version_is_parsed_again(fmu_cache: Path, monkeypatch):
    fmu = fmu_cache / "PurePursuit.fmu"
    _parse(fmu)
    kept = fmu_cache / ".PurePursuit.description.pickle"
    calls = []
    monkeypatch.setattr(
        fmpy, "read_model_description", lambda path, validate=True: calls.append(validate) or "parsed"
    )
    assert _parse(fmu) != "parsed" and calls == []  # the kept one
    os.utime(fmu, ns=(fmu.stat().st_atime_ns, fmu.stat().st_mtime_ns + 1))  # "rebuilt"
    assert _parse(fmu) == "parsed" and calls == [False]  # a project FMU: no schema validation
    key, _, payload = kept.read_bytes().partition(b"\n")
    assert key == description._kept_key(str(fmu.resolve()))
    kept.write_bytes(key + b"\n" + payload[: len(payload) // 2])  # cut short
    assert _parse(fmu) == "parsed" and len(calls) == 2


def test_nothing_is_kept_beside_a_users_fmu(fmu_cache: Path, tmp_path: Path, monkeypatch):
    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copy2(fmu_cache / "PurePursuit.fmu", mine / "PurePursuit.fmu")
    validated = []
    parse = fmpy.read_model_description
    monkeypatch.setattr(
        fmpy, "read_model_description", lambda path, validate=True: validated.append(validate) or parse(path)
    )
    _parse(mine / "PurePursuit.fmu")
    assert sorted(p.name for p in mine.iterdir()) == ["PurePursuit.fmu"]
    assert validated == [True]  # a user's FMU is checked against the FMI schema
