"""SSP 1.0 import: a hand-written SSP (connections, a .ssv parameter binding, a nested system) run by
navcosim and by a second engine, fmpy's SSP master; nesting against the flat equivalent; the
experiment and its overrides; parameter binding precedence; FMI 3.0 components; one-line errors.

The second engine's conventions (`fmpy.ssp.simulation.simulate_ssp`, fmpy 0.3.32): it steps every
FMU first and then copies the connections (Jacobi), starts every connector at 0.0, and records each
step's outputs stamped with the step's start time, as our log does. The hand-written SSP therefore runs Jacobi
(from its annotation), and every connected output is 0.0 after initialisation, where both
conventions agree; fmpy records inputs after the connections of the step are copied, so its row k
holds the inputs of our step k + 1.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
import xmlschema
from fixtures.conftest_helpers import fixture_fmu

import cosim
from cosim.cli import main
from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.ssp.read import open_ssp
from cosim.ssp.run import run_ssp

DATA = Path(__file__).resolve().parents[1] / "data"
CONVOY = DATA / "ssp" / "convoy"
SCHEMAS = DATA / "ssp-1.0.1"
STEP, STOP = 0.0625, 8.0  # [s] the convoy's DefaultExperiment and annotation
SSD_NS = 'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"'


def pack(path: Path, ssd: str | bytes, files: dict[str, Path | bytes] | None = None) -> Path:
    """An .ssp archive at `path` with `ssd` as SystemStructure.ssd and `files` (name -> file or bytes)."""
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("SystemStructure.ssd", ssd)
        for name, content in (files or {}).items():
            if isinstance(content, Path):
                archive.write(content, name)
            else:
                archive.writestr(name, content)
    return path


def convoy_files() -> dict[str, Path]:
    return {
        "resources/parameters.ssv": CONVOY / "resources" / "parameters.ssv",
        "resources/DifferentialDrive.fmu": cosim.builtin_fmu("DifferentialDrive"),
        "resources/Bicycle.fmu": cosim.builtin_fmu("Bicycle"),
    }


@pytest.fixture(scope="module")
def convoy(tmp_path_factory):
    """The hand-written convoy SSP, run by navcosim: (archive, log)."""
    directory = tmp_path_factory.mktemp("convoy")
    archive = pack(directory / "convoy.ssp", (CONVOY / "SystemStructure.ssd").read_bytes(), convoy_files())
    result = run_ssp(archive, directory / "convoy.mcap")
    assert result.exit_code == 0 and result.reason == "stop_time"
    return archive, open_log(result.log_path)


def test_hand_written_files_are_valid_against_the_normative_schemas():
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureDescription.xsd").validate(CONVOY / "SystemStructure.ssd")
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureParameterValues.xsd").validate(
        CONVOY / "resources" / "parameters.ssv"
    )


def test_the_ssp_flattens_to_two_fmus_with_their_parameters_and_connections(convoy):
    archive, _ = convoy
    with open_ssp(archive) as ssp:
        leader, car = ssp.components
        assert (leader.name, car.name, car.path) == ("leader", "follower_car", "follower.car")
        assert leader.inputs == {"v": 0.8, "omega": 0.25} and leader.parameters == {"track_width": 0.4}
        assert car.parameters == {"wheelbase": 2.5, "max_steering_angle": 0.5, "y0": -3.0}
        assert [(c.source, c.target) for c in ssp.connections] == [
            ("leader.x", "follower_car.v"),
            ("leader.theta", "follower_car.steering_angle"),
        ]
        assert (ssp.start_time, ssp.stop_time, ssp.macro_step, ssp.master) == (0.0, STOP, STEP, "jacobi")


def test_hand_written_ssp_matches_fmpy_ssp_to_1e_9(convoy):
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    archive, log = convoy
    parameters = read_ssv(str(archive), resource="resources/parameters.ssv")
    reference = simulate_ssp(str(archive), stop_time=STOP, step_size=STEP, parameter_set=parameters)
    leader, car = log.signals("leader"), log.signals("follower_car")
    # fmpy.ssp's row k, stamped t_k, holds what step k left: the outputs at t_k+1 and the inputs
    # they feed into step k + 1. Ours stamps each value at the time it holds: record k + 1 (at
    # t_k+1) has the same outputs, and the same inputs except for the last record (held inputs).
    assert len(reference) + 1 == len(leader.t) == len(car.t) == round(STOP / STEP) + 1
    assert np.array_equal(reference["time"] + STEP, leader.t[1:]) and np.array_equal(leader.t, car.t)
    deviations = {}
    for ours, prefix in ((leader, "leader"), (car, "follower.car")):
        for name in ("x", "y", "theta"):
            deviations[f"{prefix}.{name}"] = np.max(np.abs(ours[name][1:] - reference[f"{prefix}.{name}"]))
    for name in ("v", "steering_angle"):
        deviations[f"car.{name}"] = np.max(np.abs(car[name][1:-1] - reference[f"follower.car.{name}"][:-1]))
    print("max |navcosim - fmpy.ssp|:", max(deviations.values()), deviations)
    assert max(deviations.values()) <= 1e-9
    # Not a trivial agreement: both vehicles moved, and the steering hit its bound from the .ssv.
    assert leader["theta"][-1] == pytest.approx(0.25 * STOP)
    assert np.hypot(car["x"][-1], car["y"][-1] + 3.0) > 1.0
    assert np.max(np.abs(car["steering_angle_actual"])) == pytest.approx(0.5)


FLAT_SSD = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {SSD_NS}
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:nc="urn:navcosim:ssp:1" version="1.0" name="flat">
  <ssd:System name="flat">
    <ssd:ParameterBindings>
      <ssd:ParameterBinding><ssd:ParameterValues>
        <ssv:ParameterSet version="1.0" name="inline">
          <ssv:Parameters>
            <ssv:Parameter name="leader.v"><ssv:Real value="0.8"/></ssv:Parameter>
            <ssv:Parameter name="leader.omega"><ssv:Real value="0.25"/></ssv:Parameter>
            <ssv:Parameter name="leader.track_width"><ssv:Real value="0.4"/></ssv:Parameter>
            <ssv:Parameter name="no_such_element.gain"><ssv:Real value="7"/></ssv:Parameter>
          </ssv:Parameters>
        </ssv:ParameterSet>
      </ssd:ParameterValues></ssd:ParameterBinding>
      <ssd:ParameterBinding source="resources/parameters.ssv" prefix="car."/>
    </ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="leader" source="resources/DifferentialDrive.fmu">
        <ssd:Connectors>
          <ssd:Connector name="x" kind="output"/><ssd:Connector name="theta" kind="output"/>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="car" source="resources/Bicycle.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"/><ssd:Connector name="steering_angle" kind="input"/>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="car" startConnector="v" endElement="leader" endConnector="x"/>
      <ssd:Connection startElement="leader" startConnector="theta"
          endElement="car" endConnector="steering_angle"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="{STOP}">
    <ssd:Annotations><ssc:Annotation type="org.navcosim.simulation">
      <nc:Simulation macroStep="{STEP}" master="jacobi"/>
    </ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""
# The car's values of the convoy's .ssv, bare names for the prefixed binding above.
CAR_SSV = b"""<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="car">
  <ssv:Parameters>
    <ssv:Parameter name="wheelbase"><ssv:Real value="2.5"/></ssv:Parameter>
    <ssv:Parameter name="max_steering_angle"><ssv:Real value="0.5"/></ssv:Parameter>
    <ssv:Parameter name="y0"><ssv:Real value="-3.0"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""


def test_nested_system_runs_as_its_flat_equivalent(convoy, tmp_path):
    """The flat system (inline values, a prefixed .ssv, a connection written end to start) gives
    the nested one's signals exactly."""
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureDescription.xsd").validate(FLAT_SSD)
    _, nested = convoy
    files = convoy_files() | {"resources/parameters.ssv": CAR_SSV}
    result = run_ssp(pack(tmp_path / "flat.ssp", FLAT_SSD, files), tmp_path / "flat.mcap")
    flat = open_log(result.log_path)
    for nested_name, flat_name in (("leader", "leader"), ("follower_car", "car")):
        a, b = nested.signals(nested_name), flat.signals(flat_name)
        assert a.names == b.names and np.array_equal(a.t_ns, b.t_ns)
        assert np.array_equal(a.values, b.values)


def test_bindings_higher_in_the_hierarchy_and_later_ones_take_precedence(tmp_path):
    ssd = (CONVOY / "SystemStructure.ssd").read_text()
    # A binding on the car itself (after its connectors, as the schema orders them), and a second
    # binding at the root after the convoy's own.
    car_end = "</ssd:Connectors>\n          </ssd:Component>"
    car_binding = (
        '<ssd:ParameterBindings><ssd:ParameterBinding source="resources/car.ssv"/></ssd:ParameterBindings>'
    )
    ssd = ssd.replace(car_end, car_end.replace("</ssd:Connectors>", "</ssd:Connectors>" + car_binding))
    root_binding = '<ssd:ParameterBinding source="resources/parameters.ssv"/>'
    ssd = ssd.replace(root_binding, root_binding + '<ssd:ParameterBinding source="resources/later.ssv"/>')
    car_values = CAR_SSV.replace(b'"2.5"', b'"9.0"').replace(b'"-3.0"', b'"4.0"')
    later = CAR_SSV.replace(b'name="wheelbase"', b'name="follower.car.wheelbase"').replace(b'"2.5"', b'"3.5"')
    files = convoy_files() | {"resources/car.ssv": car_values, "resources/later.ssv": later}
    with open_ssp(pack(tmp_path / "precedence.ssp", ssd, files)) as ssp:
        car = ssp.component("follower_car")
        # wheelbase: car.ssv 9.0 < root parameters.ssv 2.5 < root later.ssv 3.5 (later wins);
        # y0: car.ssv 4.0, overridden by the root's -3.0; later.ssv's bare names match nothing.
        assert car.parameters == {"wheelbase": 3.5, "max_steering_angle": 0.5, "y0": -3.0}


def test_linear_transformations_compose_through_system_connectors(convoy, tmp_path):
    """leader.x -> follower.v: x 2 - 0.5 on the way in, then x 0.5 + 1 inside the follower:
    car.v = 0.5 (2 x - 0.5) + 1 = x + 0.75 at every step; the steering keeps its plain path."""
    ssd = (CONVOY / "SystemStructure.ssd").read_text()
    outer = 'endElement="follower" endConnector="v"/>'
    inner = 'startConnector="v" endElement="car" endConnector="v"/>'
    ssd = ssd.replace(
        outer, outer[:-2] + '><ssc:LinearTransformation factor="2" offset="-0.5"/></ssd:Connection>'
    )
    ssd = ssd.replace(
        inner, inner[:-2] + '><ssc:LinearTransformation factor="0.5" offset="1"/></ssd:Connection>'
    )
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureDescription.xsd").validate(ssd)
    archive = pack(tmp_path / "scaled.ssp", ssd, convoy_files())
    with open_ssp(archive) as ssp:
        assert ssp.connections[0].factor == 1.0 and ssp.connections[0].offset == 0.75
    log = open_log(run_ssp(archive, tmp_path / "scaled.mcap").log_path)
    leader, car = log.signals("leader"), log.signals("follower_car")
    # Jacobi: the input applied at t_k is the leader's output at t_k, and each record holds both
    # at its stamp (the last record, at the end, holds the inputs last applied).
    assert leader["x"][0] == 0.0 and np.array_equal(car["v"][:-1], leader["x"][:-1] + 0.75)
    assert np.array_equal(car["steering_angle"][:-1], leader["theta"][:-1])


def test_experiment_from_the_command_line_when_the_file_has_none(convoy, tmp_path, capsys):
    ssd = (CONVOY / "SystemStructure.ssd").read_text()
    start, end = ssd.index("<ssd:DefaultExperiment"), ssd.index("</ssd:DefaultExperiment>")
    bare = pack(
        tmp_path / "bare.ssp", ssd[:start] + ssd[end + len("</ssd:DefaultExperiment>") :], convoy_files()
    )
    assert main(["run", str(bare), "--out", str(tmp_path / "a.mcap"), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "bare.ssp: SystemStructure.ssd" in error and "stopTime" in error
    argv = ["run", str(bare), "--out", str(tmp_path / "a.mcap"), "--quiet", "--set", "simulation.stop_time=2"]
    # No annotation gives a macro step: both FMUs' DefaultExperiment stepSize (0.01 s) does.
    assert main(argv) == 0 and len(open_log(tmp_path / "a.mcap").signals("follower_car").t) == 201
    argv += ["--force", "--set", "simulation.macro_step=0.125", "--set", "simulation.master=jacobi"]
    assert main(argv) == 0
    short = open_log(tmp_path / "a.mcap").signals("follower_car")
    assert len(short.t) == 17 and short.t[-1] == 2.0  # 16 steps and the end
    # The convoy's own file with the same overrides runs the same steps.
    argv = ["run", str(convoy[0]), "--out", str(tmp_path / "b.mcap"), "--quiet", "--set"]
    assert main(argv + ["simulation.stop_time=2", "--set", "simulation.macro_step=0.125"]) == 0
    assert np.array_equal(open_log(tmp_path / "b.mcap").signals("follower_car").values, short.values)
    assert main(["run", str(bare), "--set", "vfh.robot_radius=1"]) == 2
    assert "an SSP run takes only simulation." in capsys.readouterr().err


def test_fmi3_fmu_in_an_ssp_follows_the_exact_arc(tmp_path):
    """The FMI 3.0 fixture differential drive, commanded by start values from an .ssv."""
    v, omega = 0.5, 0.4
    ssd = f"""<ssd:SystemStructureDescription {SSD_NS} version="1.0" name="arc">
      <ssd:System name="arc"><ssd:ParameterBindings>
        <ssd:ParameterBinding source="resources/arc.ssv"/></ssd:ParameterBindings>
        <ssd:Elements><ssd:Component name="robot" source="resources/robot.fmu"/></ssd:Elements>
      </ssd:System><ssd:DefaultExperiment stopTime="3.0"/></ssd:SystemStructureDescription>"""
    ssv = f"""<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
      version="1.0" name="arc"><ssv:Parameters>
      <ssv:Parameter name="robot.v"><ssv:Real value="{v}"/></ssv:Parameter>
      <ssv:Parameter name="robot.omega"><ssv:Real value="{omega}"/></ssv:Parameter>
      <ssv:Parameter name="robot.y0"><ssv:Real value="1.0"/></ssv:Parameter>
    </ssv:Parameters></ssv:ParameterSet>"""
    files = {"resources/robot.fmu": fixture_fmu("diffdrive_fmi3"), "resources/arc.ssv": ssv.encode()}
    result = run_ssp(
        pack(tmp_path / "arc.ssp", ssd, files), tmp_path / "arc.mcap", ["simulation.macro_step=0.01"]
    )
    robot = open_log(result.log_path).signals("robot")
    theta = omega * robot.t  # each record holds the outputs at its stamp
    assert np.allclose(robot["theta"], theta, rtol=0, atol=1e-12)
    assert np.allclose(robot["x"], v / omega * np.sin(theta), rtol=0, atol=1e-12)
    assert np.allclose(robot["y"], 1.0 + v / omega * (1 - np.cos(theta)), rtol=0, atol=1e-12)
    assert robot["steps"][0] == 0 and robot["steps"][-1] == 300 and math.isclose(robot.t[-1], 3.0)


CONNECTOR = '<ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>'


@pytest.mark.parametrize(
    "case, expected",
    [
        ("bad_zip", "bad.ssp: not a zip archive"),
        ("no_ssd", "bad.ssp: the archive has no SystemStructure.ssd"),
        ("bad_xml", "bad.ssp: SystemStructure.ssd: bad XML at line"),
        ("schema", "bad.ssp: SystemStructure.ssd: not valid SSP 1.0 (SystemStructureDescription.xsd) at "),
        (
            "connector",
            "element 'leader': connector 'x_position' is not a variable of resources/DifferentialDrive.fmu",
        ),
        ("connection", "connection leader.x -> follower.speed: element 'follower' has no connector 'speed'"),
        (
            "bad_ssv",
            "bad.ssp: resources/parameters.ssv: not valid SSP 1.0 (SystemStructureParameterValues.xsd)",
        ),
        ("missing_fmu", "element 'follower.car': source 'resources/Bicycle.fmu' is not in the archive"),
    ],
)
def test_errors_are_one_line_naming_the_file_and_the_element(case, expected, tmp_path, capsys):
    ssd = (CONVOY / "SystemStructure.ssd").read_text()
    files: dict = convoy_files()
    archive = tmp_path / "bad.ssp"
    if case == "bad_zip":
        archive.write_bytes(b"PK not really a zip")
    elif case == "no_ssd":
        with zipfile.ZipFile(archive, "w") as zipped:
            zipped.writestr("resources/readme.txt", "no ssd")
    else:
        if case == "bad_xml":
            ssd = ssd.replace("</ssd:System>\n  <ssd:DefaultExperiment", "<ssd:DefaultExperiment", 1)
        elif case == "schema":
            ssd = ssd.replace('kind="output"', 'kind="sideways"', 1)
        elif case == "connector":
            ssd = ssd.replace(CONNECTOR, CONNECTOR.replace('"x"', '"x_position"'), 1)
        elif case == "connection":
            ssd = ssd.replace(
                'endElement="follower" endConnector="v"', 'endElement="follower" endConnector="speed"'
            )
        elif case == "bad_ssv":
            files["resources/parameters.ssv"] = (
                b'<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/'
                b'SystemStructureParameterValues" version="1.0"><ssv:Parameters/></ssv:ParameterSet>'
            )
        elif case == "missing_fmu":
            del files["resources/Bicycle.fmu"]
        pack(archive, ssd, files)
    assert main(["run", str(archive), "--out", str(tmp_path / "log.mcap"), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("cosim: error: ") and error.count("\n") == 1, error
    assert expected in error, error
    print(error.strip())
    assert not (tmp_path / "log.mcap").exists()


def test_api_errors_are_cosim_errors(tmp_path):
    with pytest.raises(CosimError, match="no such SSP file"):
        with open_ssp(tmp_path / "missing.ssp"):
            pass
