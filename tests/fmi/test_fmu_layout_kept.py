"""A project FMU's layout (`cosim.fmi.layout.fmu_layout`: its ports through a port map) and its files
for the instances are kept beside it in the FMU build cache for the next process: the kept layout
read back is the layout made from the description (the truth: `_make_layout`, and the archive's
variables), its variables those of the description read in this process; a kept copy made for
another file version, another port map or that cannot be read is not used; the extraction is made
once and stays."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from cosim.fmi import layout as layouts
from cosim.fmi.archive import unpack_instance
from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.description import checked_description, file_key, kept_unpacked


def _ports(layout) -> tuple:
    ports = [(p.name, p.type, p.unit, p.description, repr(p.start), p.fmi_type, p.array_name, p.array_index)
             for p in (*layout.inputs, *layout.outputs, *layout.parameters)]  # fmt: skip
    variables = {port: (mapped.variable.name, mapped.scale) for port, mapped in layout.variables.items()}
    return ports, variables, dict(layout.feedthrough), layout.documented_nan, layout.fmi_version


def _fresh(fmu: Path, port_map: dict):
    """`fmu_layout` in a process that has made no layout yet (the in-process cache emptied)."""
    layouts._LAYOUTS.clear()
    return layouts.fmu_layout(fmu, "pure_pursuit", port_map)


@pytest.mark.parametrize("port_map", [{}, {"east": {"name": "x", "scale": 2.0}}])
def test_the_kept_layout_is_the_layout(fmu_cache: Path, port_map: dict):
    fmu = fmu_cache / "PurePursuit.fmu"
    description, version = checked_description(fmu, None, file_key(fmu, None))
    mapping = layouts._parse_port_map(port_map, fmu)
    made = layouts._make_layout(fmu, "pure_pursuit", description, version, mapping)
    first = _fresh(fmu, port_map)
    assert len(list(fmu_cache.glob(".PurePursuit.layout-*.pickle"))) == 1
    again = _fresh(fmu, port_map)
    assert again is not first
    assert _ports(again) == _ports(first) == _ports(made)
    assert again.model_description is description
    assert all(
        any(mapped.variable is v for v in description.modelVariables) for mapped in again.variables.values()
    )
    names = {v.name for v in description.modelVariables if v.causality == "input"}
    assert {p.name for p in again.inputs} == names - {"x"} | ({"east"} if port_map else {"x"})


def test_another_port_map_or_a_damaged_copy_makes_the_layout_again(fmu_cache: Path):
    fmu = fmu_cache / "PurePursuit.fmu"
    plain = _fresh(fmu, {})
    mapped = _fresh(fmu, {"east": "x"})
    kept = sorted(fmu_cache.glob(".PurePursuit.layout-*.pickle"))
    assert len(kept) == 2 and "east" in {p.name for p in mapped.inputs} - {p.name for p in plain.inputs}
    for path in kept:
        path.write_bytes(path.read_bytes()[:-100])  # cut short: cannot be read
    assert _ports(_fresh(fmu, {})) == _ports(plain)
    key_line, _, rest = kept[0].read_bytes().partition(b"\n")
    kept[0].write_bytes(key_line + b"x\n" + rest)  # made from something else
    assert _ports(_fresh(fmu, {})) == _ports(plain)


def test_a_users_fmu_keeps_nothing_beside_it(tmp_path: Path):
    fmu = tmp_path / "PurePursuit.fmu"
    shutil.copy2(builtin_fmu("PurePursuit"), fmu)
    _fresh(fmu, {})
    assert kept_unpacked(fmu) is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["PurePursuit.fmu"]


def test_the_extraction_is_kept_for_the_next_process(fmu_cache: Path):
    fmu = fmu_cache / "PurePursuit.fmu"
    kept = kept_unpacked(fmu)
    assert kept is not None and kept.parent == fmu_cache and not kept.exists()
    folder, release = unpack_instance(fmu, lambda member: not member.startswith("sources/"), "t-", True, kept)
    assert Path(folder) == kept
    assert (kept / "binaries").is_dir() and (kept / "modelDescription.xml").is_file()
    assert not (kept / "sources").exists()
    written = (kept / "modelDescription.xml").stat().st_mtime_ns
    release()
    again, release_again = unpack_instance(fmu, lambda member: True, "t-", True, kept)
    assert Path(again) == kept and (kept / "modelDescription.xml").stat().st_mtime_ns == written
    release_again()
    assert kept.is_dir()
    assert [p.name for p in fmu_cache.iterdir() if p.name.startswith(kept.name)] == [
        kept.name
    ]  # no leftovers
    shutil.copy2(fmu, fmu_cache / "copy.fmu")
    (fmu_cache / "copy.fmu").replace(fmu)  # a rebuilt FMU: another version, extracted anew
    assert kept_unpacked(fmu) != kept
