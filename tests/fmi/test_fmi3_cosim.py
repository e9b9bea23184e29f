"""The orchestrator's side of the FMI 3.0 builds: `cosim.builtin_fmu(name, fmi_version=3)`, `cosim fmu
path/info/validate --fmi 3`, FmuComponent moving each FMI 3.0 array with one get/set (and giving the
FMI 2.0 build's results), the `[simulation] fmi_version` key, and every shipped scenario's log equal
in both versions (`cosim log diff --tolerance 0`)."""

from __future__ import annotations

import dataclasses
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

import cosim
from cosim.cli import main
from cosim.errors import CosimError
from cosim.fmi.builtin import known_names
from cosim.fmi.component import FmuComponent
from cosim.fmi.inspect import array_problems, validate
from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted(
    p for p in (REPO / "scenarios").glob("*.toml") if not p.name.startswith("fleet_")
)  # fleets: tests/fleet
REDUCED = ["simulation.macro_step=0.05", "output.pose_rate=20"]


def test_builtin_fmu_in_both_versions(capsys):
    for name in known_names():
        fmi2, fmi3 = cosim.builtin_fmu(name), cosim.builtin_fmu(name, fmi_version=3)
        assert fmi2 != fmi3 and fmi2.name == fmi3.name == f"{name}.fmu"
        assert read_model_description(str(fmi2)).fmiVersion == "2.0"
        assert read_model_description(str(fmi3)).fmiVersion == "3.0"
    with pytest.raises(CosimError, match="FMI version 4"):
        cosim.builtin_fmu("Bicycle", fmi_version=4)
    assert main(["fmu", "path", "Bicycle", "--fmi", "3"]) == 0
    assert capsys.readouterr().out.strip() == str(cosim.builtin_fmu("Bicycle", fmi_version=3))
    assert main(["fmu", "path", "Bicycle"]) == 0
    assert capsys.readouterr().out.strip() == str(cosim.builtin_fmu("Bicycle"))


def test_cli_info_and_validate_show_fmi3_arrays(capsys):
    assert main(["fmu", "info", "VectorFieldHistogram", "--fmi", "3"]) == 0
    out = capsys.readouterr().out
    assert "FMI version:     3.0" in out
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.strip()}
    assert rows["ranges[720]"][1:6] == ["input", "continuous", "Float64", "m", "NaN"]
    assert "array of 720 elements; Range of reading i" in out
    assert main(["fmu", "info", "PurePursuit", "--fmi", "3"]) == 0
    assert "waypoints[1000][2]" in capsys.readouterr().out
    assert main(["fmu", "validate", "PurePursuit", "--fmi", "3"]) == 0
    assert "valid" in capsys.readouterr().out


def _edited(source: Path, target: Path, edit) -> Path:
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode()).encode()
            zout.writestr(item, data)
    return target


def test_validate_reports_broken_fmi3_arrays(tmp_path, capsys):
    source = cosim.builtin_fmu("VectorFieldHistogram", fmi_version=3)
    short = _edited(
        source, tmp_path / "short.fmu", lambda text: text.replace('start="NaN NaN ', 'start="NaN ', 1)
    )
    assert main(["fmu", "validate", str(short)]) == 1
    assert "array variable 'ranges': 719 start values for 720 elements" in capsys.readouterr().out
    # A dimension sized by an ordinary (non-structural) parameter: num_angular_sectors, value reference 1.
    bad_size = _edited(
        source,
        tmp_path / "size.fmu",
        lambda text: text.replace('<Dimension start="720"/>', '<Dimension valueReference="1"/>', 1),
    )
    problems = validate(bad_size)
    assert any(
        "refers to value reference 1, which is not an integer structural parameter" in p for p in problems
    )
    assert array_problems(read_model_description(str(source))) == []


def _component(name: str, fmi_version: int) -> FmuComponent:
    component = FmuComponent(cosim.builtin_fmu(name, fmi_version), name)
    component.instantiate()
    component.setup(0.0, {})
    component.initialize()
    return component


def test_fmi3_component_has_the_fmi2_ports_and_moves_each_array_with_one_call():
    fmi2, fmi3 = _component("VectorFieldHistogram", 2), _component("VectorFieldHistogram", 3)
    for kind in ("inputs", "outputs", "parameters"):
        assert [p.name for p in getattr(fmi2, kind)] == [p.name for p in getattr(fmi3, kind)], kind
    group, *others = fmi3._input_groups  # one call: the Float64 inputs
    assert not others and group.fmi_type == "Float64" and len(group.slots) == 1441
    assert len(group.references) == 3  # ranges, angles, target_dir: each array is one value reference
    assert len(fmi2._input_groups[0].references) == 1441  # FMI 2.0: one reference per scalar
    rng = np.random.default_rng(5)
    angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    for k in range(30):
        ranges = np.where(rng.random(720) < 0.8, np.nan, rng.uniform(0.2, 3.0, 720))
        for component in (fmi2, fmi3):
            component.input_buffer[:720] = ranges
            component.input_buffer[720:1440] = angles
            component.input_buffer[1440] = math.sin(k)
            component.push_inputs()
            component.do_step(k * 0.05, 0.05)
        a, b = fmi2.get_outputs().copy(), fmi3.get_outputs().copy()
        assert np.array_equal(a, b, equal_nan=True), k
    for component in (fmi2, fmi3):
        component.terminate()
        component.free()


def test_fmi3_component_sends_an_array_whole_when_restricted():
    """restrict_push to one waypoint element still sends the whole waypoints array (one reference)."""
    pursuit = _component("PurePursuit", 3)
    names = [p.name for p in pursuit.inputs]
    pursuit.restrict_push([names.index("waypoints[3,2]")])
    group = pursuit._input_groups[0]
    assert len(group.references) == 1 and len(group.slots) == 2000
    pursuit.input_buffer[[names.index(f"waypoints[{k},1]") for k in (1, 2)]] = [0.0, 4.0]
    pursuit.input_buffer[[names.index(f"waypoints[{k},2]") for k in (1, 2)]] = [0.0, 0.0]
    pursuit.push_inputs()
    pursuit.do_step(0.0, 0.05)
    outputs = dict(zip([p.name for p in pursuit.outputs], pursuit.get_outputs(), strict=True))
    assert outputs["goal_distance"] == pytest.approx(4.0)  # the last waypoint (4, 0) from the origin
    pursuit.terminate()
    pursuit.free()


def test_scenario_fmi_version_key(tmp_path):
    scenario = REPO / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    assert load_scenario(scenario).fmi_version == 2
    assert load_scenario(scenario, ["simulation.fmi_version=3"]).fmi_version == 3
    with pytest.raises(CosimError, match=r"\[simulation\]\.fmi_version: must be 2 or 3") as error:
        load_scenario(scenario, ["simulation.fmi_version=4"])
    assert scenario.name in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenario_log_is_equal_in_fmi3(path: Path, tmp_path: Path):
    logs = {}
    for version in (2, 3):
        scenario = dataclasses.replace(
            load_scenario(path, [*REDUCED, f"simulation.fmi_version={version}"]), plot=False
        )
        logs[version] = tmp_path / f"fmi{version}.mcap"
        result = run_scenario(scenario, logs[version])
        assert result.outcome.reason == "goal_reached"
        versions = {fmu["fmi_version"] for fmu in open_log(logs[version]).fmus.values()}
        assert versions == {f"{version}.0"}  # every role ran the build of that version
    assert main(["log", "diff", str(logs[2]), str(logs[3]), "--tolerance", "0"]) == 0
