"""What a sweep's worker keeps from one run to the next (`cosim.scenario.compose`): the same inputs
give the remembered answer, changed inputs a new one, checked against fmpy's own reading of the file
and against graphs whose loops are known. That a sweep's logs stay byte-identical to `cosim run`
with the same overrides is `test_sweep_cluster.test_every_log_equals_a_run_without_dask`."""

from __future__ import annotations

import os
import shutil

import fmpy

from cosim.fmi.builtin import builtin_fmu
from cosim.scenario import compose

LIMIT = 1 << 30


def _causality(path, causality: str) -> set[str]:
    description = fmpy.read_model_description(str(path))
    return {v.name for v in description.modelVariables if v.causality == causality}


def test_an_fmu_interface_is_read_again_when_its_file_changes(tmp_path):
    path = tmp_path / "robot.fmu"
    shutil.copyfile(builtin_fmu("DifferentialDrive", 2), path)
    first = compose._fmu_interface(path, "vehicle", {}, LIMIT)
    assert compose._fmu_interface(path, "vehicle", {}, LIMIT) is first
    assert set(first.inputs) == _causality(path, "input")
    assert set(first.outputs) == _causality(path, "output")

    # Another FMU at the same path: a new modification time (set ahead, as a coarse clock might not).
    before = path.stat().st_mtime_ns
    shutil.copyfile(builtin_fmu("PurePursuit", 2), path)
    os.utime(path, ns=(before + 2_000_000_000, before + 2_000_000_000))
    second = compose._fmu_interface(path, "vehicle", {}, LIMIT)
    assert second is not first
    assert set(second.inputs) == _causality(path, "input") != set(first.inputs)
    assert set(second.parameters) == _causality(path, "parameter")


def test_an_fmu_interface_follows_its_port_map(tmp_path):
    path = tmp_path / "robot.fmu"
    shutil.copyfile(builtin_fmu("DifferentialDrive", 2), path)
    outputs = _causality(path, "output")
    assert {"x", "y"} <= outputs
    on_x = compose._fmu_interface(path, "vehicle", {"east": {"name": "x", "scale": 1.0}}, LIMIT)
    on_y = compose._fmu_interface(path, "vehicle", {"east": {"name": "y", "scale": 1.0}}, LIMIT)
    assert set(on_x.outputs) == (outputs - {"x"}) | {"east"}
    assert set(on_y.outputs) == (outputs - {"y"}) | {"east"}
    # Another name or another size limit is another component.
    assert compose._fmu_interface(path, "robot", {}, LIMIT) is not compose._fmu_interface(
        path, "vehicle", {}, LIMIT
    )
    assert compose._fmu_interface(path, "vehicle", {}, LIMIT + 1) is not compose._fmu_interface(
        path, "vehicle", {}, LIMIT
    )


def test_a_missing_fmu_is_never_remembered(tmp_path):
    path = tmp_path / "gone.fmu"
    for _ in range(2):
        try:
            compose._fmu_interface(path, "vehicle", {}, LIMIT)
        except compose.CosimError as error:
            assert "not found" in str(error)
        else:
            raise AssertionError("a missing FMU must fail")
    shutil.copyfile(builtin_fmu("DifferentialDrive", 2), path)
    assert set(compose._fmu_interface(path, "vehicle", {}, LIMIT).inputs) == _causality(path, "input")


def test_the_algebraic_loop_is_searched_again_for_another_graph():
    pairs = [("a.y", "b.u"), ("b.v", "a.w")]
    looping = {"a": {"y": ("w",)}, "b": {"v": ("u",)}}
    loop = compose._algebraic_loop(pairs, looping)
    assert loop is not None and loop[0] == loop[-1] and set(loop) == {"a.y", "b.u", "b.v", "a.w"}
    loop.append("changed by the caller")
    assert compose._algebraic_loop(pairs, looping)[-1] != "changed by the caller"
    # b.v a state: no loop; the same pairs with other feedthrough are another graph.
    assert compose._algebraic_loop(pairs, {"a": {"y": ("w",)}, "b": {"v": ()}}) is None
    assert compose._algebraic_loop(pairs[:1], looping) is None
    assert compose._algebraic_loop(pairs, looping) is not None


def test_a_component_built_after_describing_shares_its_ports(tmp_path):
    """Describing a system and building it read each FMU's ports once (`fmu_layout`); every component
    keeps its own buffers, and a new version of the file is read again."""
    from cosim.fmi.component import FmuComponent

    path = tmp_path / "robot.fmu"
    shutil.copyfile(builtin_fmu("DifferentialDrive", 2), path)
    interface = compose._fmu_interface(path, "vehicle", {}, LIMIT)
    built = FmuComponent(path, "vehicle", max_unpacked_size=LIMIT)
    again = FmuComponent(path, "vehicle", max_unpacked_size=LIMIT)
    assert tuple(port.name for port in built.inputs) == interface.inputs
    assert all(
        a is b for a, b in zip(built.inputs + built.outputs, again.inputs + again.outputs, strict=True)
    )
    assert built.input_buffer is not again.input_buffer
    assert {port: tuple(depends) for port, depends in built.feedthrough.items()} == interface.feedthrough
    starts = {v.name: v.start for v in fmpy.read_model_description(str(path)).modelVariables}
    assert [port.start for port in built.parameters] == [
        float(starts[port.name]) for port in built.parameters
    ]

    before = path.stat().st_mtime_ns
    shutil.copyfile(builtin_fmu("PurePursuit", 2), path)
    os.utime(path, ns=(before + 2_000_000_000, before + 2_000_000_000))
    changed = FmuComponent(path, "vehicle", max_unpacked_size=LIMIT)
    assert {port.name for port in changed.inputs} == _causality(path, "input")
    assert changed.model_description.modelName == "PurePursuit"
