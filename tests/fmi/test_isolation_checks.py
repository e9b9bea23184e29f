"""What a failed FMU is besides a crash: a NaN or infinite output (unless the output's NaN has a
meaning), and an archive that would unpack to more than the limit (refused before extraction).
Also the scenario keys that choose isolation, the timeout, the size limit and the NaN allowance.
"""

from __future__ import annotations

import math
import re
import tempfile
import zipfile
from pathlib import Path
from types import SimpleNamespace

import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from zip_bomb import write_zip_bomb

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.archive import DEFAULT_MAX_UNPACKED_SIZE, MIB
from cosim.fmi.builtin import builtin_fmu, documented_nan_variables, known_names
from cosim.fmi.component import FmuComponent
from cosim.fmi.isolated import IsolatedFmuComponent
from cosim.navigation.build import build_run
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
GIB = 1 << 30


def fault_system(fault: str, allow: tuple[str, ...] = ()) -> tuple[System, FmuComponent]:
    system = System(0.1)
    vehicle = system.add(FmuComponent(fixture_fmu("fault_fmi2"), "vehicle", nan_outputs=allow))
    return system, vehicle


@pytest.mark.parametrize("compiled", [False, True])
def test_a_nan_output_fails_the_step_in_both_loops(compiled):
    system, vehicle = fault_system("nan")
    parameters = {"vehicle": {"fault": FAULTS.index("nan"), "fault_time": 0.3}}
    with Master(system, parameters=parameters) as master:
        master.initialize()
        vehicle.set_inputs([0, 1], [1.0, 0.5])
        with pytest.raises(CosimError) as error:
            master.run(10, compiled=compiled)
        assert master.step_index == 3  # the step [0.3, 0.4] s produced the NaN
    assert str(error.value) == (
        "FMU 'vehicle' (model fixture_fault_fmi2) output 'x' is NaN after fmi2DoStep at t = 0.3 s "
        "(FMU outputs must be finite; list outputs whose NaN has a meaning in the component's nan_outputs)"
    )


def test_outputs_allowed_nan_pass_but_not_infinity():
    system, vehicle = fault_system("nan", allow=("x", "y", "theta"))
    parameters = {"vehicle": {"fault": FAULTS.index("nan"), "fault_time": 0.3}}
    with Master(system, parameters=parameters) as master:
        master.initialize()
        vehicle.set_inputs([0, 1], [1.0, 0.5])
        master.run(10)
        assert all(math.isnan(value) for value in vehicle.output_buffer[:3])
    # Infinity is never a value: v = inf drives x (heading 0) to +inf, y = 0 + inf * sin(0) is NaN.
    system, vehicle = fault_system("none", allow=("x", "y", "theta"))
    with Master(system) as master:
        master.initialize()
        vehicle.set_inputs([0, 1], [math.inf, 0.0])
        with pytest.raises(CosimError, match=r"output 'x' is \+inf after fmi2DoStep at t = 0 s"):
            master.run(1)


def test_nan_allowance_names_outputs_only():
    with pytest.raises(CosimError, match="'v' is not an output"):
        FmuComponent(fixture_fmu("fault_fmi2"), "vehicle", nan_outputs=("v",))
    vehicle = FmuComponent(fixture_fmu("fault_fmi2"), "vehicle")
    vehicle.instantiate()
    with pytest.raises(CosimError, match=r"allow_nan\(\) called in state instantiated"):
        vehicle.allow_nan("x")  # the check is compiled at instantiate()
    vehicle.free()


def test_the_navigation_template_allows_nan_only_for_the_vfh_steering_direction():
    built = build_run(load_scenario(SHIPPED))
    allowed = {
        name: sorted(getattr(component, "nan_outputs", ()))
        for name, component in built.system.components.items()
        if hasattr(component, "nan_outputs")
    }
    assert allowed == {"vehicle": [], "pure_pursuit": ["goal_distance"], "vfh": ["steering_dir"], "mixer": []}


def test_the_project_fmus_documented_nan_outputs_are_allowed_and_nothing_else():
    """A project FMU's real output may be NaN exactly when its description says when it is NaN
    (read here from the raw XML, not through fmpy); other tools' FMUs get no such allowance."""
    from xml.etree import ElementTree

    allowed = {}
    for name in known_names():
        path = builtin_fmu(name)
        component = FmuComponent(path, "c")
        with zipfile.ZipFile(path) as archive:
            root = ElementTree.fromstring(archive.read("modelDescription.xml"))
        documented = sorted(
            element.get("name")
            for element in root.iter("ScalarVariable")
            if element.get("causality") == "output"
            and element.find("Real") is not None
            and "NaN" in element.get("description", "")
        )
        assert sorted(component.nan_outputs) == documented, name
        allowed[name] = documented
    assert allowed["VectorFieldHistogram"] == ["steering_dir"]
    assert allowed["PurePursuit"] == ["goal_distance"]
    assert allowed["DifferentialDrive"] == allowed["Bicycle"] == allowed["AvoidanceMixer"] == []
    other = SimpleNamespace(generationTool="other tool", modelName="VectorFieldHistogram", modelVariables=[])
    assert documented_nan_variables(other) == ()
    assert FmuComponent(fixture_fmu("fault_fmi2"), "v").nan_outputs == frozenset()


@pytest.fixture(scope="module")
def bomb(tmp_path_factory) -> Path:
    """The diffdrive fixture FMU plus a 2 GiB entry of zeros, about 2 MB on disk."""
    path = tmp_path_factory.mktemp("bomb") / "bomb.fmu"
    write_zip_bomb(path, 2 * GIB)
    with zipfile.ZipFile(fixture_fmu("diffdrive_fmi2")) as source, zipfile.ZipFile(path, "a") as target:
        for info in source.infolist():
            target.writestr(info, source.read(info))
    return path


def test_a_small_fmu_that_unpacks_to_2_gib_is_refused_without_extracting(bomb, monkeypatch, tmp_path):
    assert bomb.stat().st_size < 3 * MIB
    with zipfile.ZipFile(bomb) as archive:
        assert archive.getinfo("resources/padding.bin").file_size == 2 * GIB
    extracted: list[str] = []
    monkeypatch.setattr(zipfile.ZipFile, "extractall", lambda *args, **kwargs: extracted.append("all"))
    monkeypatch.setattr(zipfile.ZipFile, "open", _refuse_reading(zipfile.ZipFile.open))
    # A temporary folder of the test's own: other runs on the machine come and go in /tmp.
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    monkeypatch.setenv("TMPDIR", str(temporary))
    monkeypatch.setattr(tempfile, "tempdir", str(temporary))
    for kind in (FmuComponent, IsolatedFmuComponent):
        with pytest.raises(CosimError) as error:
            kind(bomb, "vehicle")
        assert str(error.value) == (
            f"FMU '{bomb}' would unpack to 2,048 MiB "
            "('resources/padding.bin' alone 2,048 MiB), more than the limit of 1,024 MiB; not extracted "
            "(raise the limit with [simulation] fmu_max_size, in MiB, if you trust it)"
        )
    assert extracted == [] and list(temporary.iterdir()) == []
    assert DEFAULT_MAX_UNPACKED_SIZE == GIB


def _refuse_reading(original):
    """ZipFile.open that refuses the big entry: nothing may inflate it."""

    def guarded(self, name, *args, **kwargs):
        assert "padding" not in str(getattr(name, "filename", name)), "the 2 GiB entry was opened"
        return original(self, name, *args, **kwargs)

    return guarded


def test_a_raised_limit_lets_the_description_load(bomb):
    component = FmuComponent(bomb, "vehicle", max_unpacked_size=3 * GIB)  # reads modelDescription.xml only
    assert [p.name for p in component.inputs] == ["v", "omega"]


def scenario_text(extra: str = "", vehicle: str = "") -> str:
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    if vehicle:
        start = text.index("[vehicle]")
        end = text.index("\n[", start + 1)
        text = text[:start] + vehicle + text[end:]
    return text.replace("[simulation]", f"[simulation]\n{extra}", 1)


FIXTURE_VEHICLE = """[vehicle]
fmu = "{path}"
type = "differential"
radius = 0.5
{extra}
"""


def load(tmp_path: Path, text: str, *overrides: str):
    path = tmp_path / "s.toml"
    path.write_text(text)
    return load_scenario(path, list(overrides))


def test_isolation_defaults_put_fmus_given_by_path_in_a_child(tmp_path):
    vehicle = FIXTURE_VEHICLE.format(path=fixture_fmu("diffdrive_fmi2"), extra="")
    scenario = load(tmp_path, scenario_text(vehicle=vehicle))
    assert scenario.fmu_isolation == "auto" and scenario.fmu_timeout == 10.0 and scenario.fmu_max_size == 1024
    where = {role: scenario.isolation(spec) for role, spec in scenario.components.items()}
    assert where == {"vehicle": "process", "pure_pursuit": "none", "vfh": "none", "mixer": "none"}
    built = build_run(scenario)
    kinds = {name: type(c).__name__ for name, c in built.system.components.items() if name != "planner"}
    assert kinds == {
        "vehicle": "IsolatedFmuComponent",
        "pure_pursuit": "FmuComponent",
        "vfh": "FmuComponent",
        "lidar": "Lidar",
        "mixer": "FmuComponent",
    }
    assert built.system.components["vehicle"].timeout == 10.0
    everything = load(tmp_path, scenario_text(vehicle=vehicle), 'simulation.fmu_isolation="process"')
    assert {everything.isolation(s) for s in everything.components.values()} == {"process"}
    nothing = load(tmp_path, scenario_text(vehicle=vehicle), 'simulation.fmu_isolation="none"')
    assert {nothing.isolation(s) for s in nothing.components.values()} == {"none"}
    own = load(
        tmp_path, scenario_text(vehicle=vehicle), 'vehicle.isolation="none"', 'vfh.isolation="process"'
    )
    assert own.isolation(own.components["vehicle"]) == "none"
    assert own.isolation(own.components["vfh"]) == "process"


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            'vehicle.isolation="thread"',
            r"\[vehicle\]\.isolation: must be one of 'process', 'none', got 'thread'",
        ),
        (
            'simulation.fmu_isolation="yes"',
            r"\[simulation\]\.fmu_isolation: must be one of 'auto', 'process'",
        ),
        ("simulation.fmu_timeout=0", r"\[simulation\]\.fmu_timeout: must be > 0, got 0"),
        ("simulation.fmu_max_size=-1", r"\[simulation\]\.fmu_max_size: must be > 0, got -1"),
        ('vfh.nan_outputs="steering_dir"', r"\[vfh\]\.nan_outputs: must be a list of output port names"),
    ],
)
def test_bad_isolation_keys_name_the_file_and_key(tmp_path, override, message):
    with pytest.raises(CosimError, match=re.escape(str(tmp_path / "s.toml")) + ": " + message):
        load(tmp_path, scenario_text(), override)


def test_nan_outputs_key_reaches_the_component_and_is_checked_against_its_outputs(tmp_path):
    vehicle = FIXTURE_VEHICLE.format(path=fixture_fmu("diffdrive_fmi2"), extra='nan_outputs = ["steps"]')
    built = build_run(load(tmp_path, scenario_text(vehicle=vehicle)))
    assert built.system.components["vehicle"].nan_outputs == {"steps"}
    wrong = FIXTURE_VEHICLE.format(path=fixture_fmu("diffdrive_fmi2"), extra='nan_outputs = ["speed"]')
    with pytest.raises(CosimError, match=r"\[vehicle\]\.nan_outputs: 'speed' is not an output of the FMU"):
        build_run(load(tmp_path, scenario_text(vehicle=wrong)))


def test_fmu_max_size_applies_to_every_fmu_of_the_run(tmp_path):
    """A limit above the fixture vehicle's size and below PurePursuit's (2000 waypoint inputs make
    its description large) refuses the project FMU: the limit is the run's, not per FMU kind."""

    def unpacked(path: Path) -> int:
        with zipfile.ZipFile(path) as archive:
            return sum(info.file_size for info in archive.infolist())

    vehicle_size, pure_pursuit_size = (
        unpacked(fixture_fmu("diffdrive_fmi2")),
        unpacked(builtin_fmu("PurePursuit")),
    )
    assert vehicle_size < pure_pursuit_size
    vehicle = FIXTURE_VEHICLE.format(path=fixture_fmu("diffdrive_fmi2"), extra="")
    below = f"simulation.fmu_max_size={(vehicle_size - 1) / MIB!r}"
    with pytest.raises(
        CosimError, match=r"\[vehicle\]\.fmu: FMU '.*' would unpack to .* more than the limit"
    ):
        build_run(load(tmp_path, scenario_text(vehicle=vehicle), below))
    between = f"simulation.fmu_max_size={(vehicle_size + pure_pursuit_size) / 2 / MIB!r}"
    with pytest.raises(CosimError, match=r"\[pure_pursuit\]\.fmu: FMU '.*PurePursuit.fmu' would unpack to"):
        build_run(load(tmp_path, scenario_text(vehicle=vehicle), between))


@pytest.mark.parametrize(
    ("size", "said"),
    [
        (0.4 * MIB, "0.4 MiB"),
        (0.25 * MIB, "0.25 MiB"),
        (1.5 * MIB, "1.5 MiB"),
        (2 * GIB, "2,048 MiB"),
        (700, "700 bytes"),
    ],
)
def test_limit_messages_never_round_a_size_to_zero(size, said):
    """A limit under 1 MiB ([simulation] fmu_max_size = 0.4) was said as "0 MiB"."""
    from cosim.fmi.archive import mib

    assert mib(int(size)) == said


def test_a_limit_below_one_mib_is_said_as_given(tmp_path):
    size = fixture_fmu("diffdrive_fmi2").stat().st_size
    vehicle = FIXTURE_VEHICLE.format(path=fixture_fmu("diffdrive_fmi2"), extra="")
    with pytest.raises(CosimError, match=r"more than the limit of 0\.001 MiB;") as error:
        build_run(load(tmp_path, scenario_text(vehicle=vehicle), "simulation.fmu_max_size=0.001"))
    assert " 0 MiB" not in str(error.value) and size > 0.001 * MIB
