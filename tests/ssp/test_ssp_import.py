"""SSP files as other tools write them: connections with `startElement=""`/`endElement=""` (the
system's own connector, as OMSimulator writes it), the macro step from the OSP and OMS step
annotations or the FMUs' DefaultExperiment, SSP 2.0 archives (checked against the normative SSP 2.0
schemas, with SSP 2.0's value types), and messages and logs that name archive members (`models/X.fmu`)
rather than the folder a run unpacked the archive to.

The files are written here in the style of those tools' annotations (from the SSP 2.0 and OSP
annotation definitions), not copied from any tool's output. The truth they are checked against:
the analytic motion of the differential drive (x = v t for a constant speed and no turn, the arc
of `test_ssp.py` for a turn) and the step counts their experiments imply.
"""

from __future__ import annotations

import re
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
from cosim.ssp import schema
from cosim.ssp.read import open_ssp
from cosim.ssp.run import run_ssp, summary

SSP1 = "http://ssp-standard.org/SSP1"
NAMESPACES = (
    f'xmlns:ssd="{SSP1}/SystemStructureDescription" xmlns:ssc="{SSP1}/SystemStructureCommon" '
    f'xmlns:ssv="{SSP1}/SystemStructureParameterValues" xmlns:nc="urn:navcosim:ssp:1" '
    'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations" '
    'xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"'
)
SCHEMAS_2 = Path(schema.__file__).resolve().parent / "schemas" / "ssp-2.0"
V = 0.5  # [m/s] the robot's commanded speed


def pack(path: Path, ssd: str, files: dict[str, Path | bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("SystemStructure.ssd", ssd)
        for name, content in files.items():
            if isinstance(content, Path):
                archive.write(content, name)
            else:
                archive.writestr(name, content)
    return path


def system_ssd(
    version: str = "1.0",
    empty: str = ' startElement=""',
    experiment: str = "",
    system_annotation: str = "",
    extra_elements: str = "",
    real: str = "Real",
) -> str:
    """A root system with its own input `speed` (given V by an inline binding) wired to the robot's
    `v`, and its own output `position` fed by the robot's `x`. `empty` is how the system's own end
    is written: `startElement=""` (OMSimulator) or nothing (the SSP 1.0 way)."""
    end_empty = empty.replace("startElement", "endElement")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {NAMESPACES} version="{version}" name="line">
  <ssd:System name="root">
    <ssd:Connectors>
      <ssd:Connector name="speed" kind="input"><ssc:{real}/></ssd:Connector>
      <ssd:Connector name="position" kind="output"><ssc:{real} unit="m"/></ssd:Connector>
    </ssd:Connectors>
    <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
      <ssv:ParameterSet version="{version}" name="commands"><ssv:Parameters>
        <ssv:Parameter name="speed"><ssv:{real} value="{V}"/></ssv:Parameter>
      </ssv:Parameters></ssv:ParameterSet>
    </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="robot" source="models/robot.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"><ssc:{real}/></ssd:Connector>
          <ssd:Connector name="x" kind="output"><ssc:{real} unit="m"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>{extra_elements}
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection{empty} startConnector="speed" endElement="robot" endConnector="v"/>
      <ssd:Connection startElement="robot" startConnector="x"{end_empty} endConnector="position"/>
    </ssd:Connections>{system_annotation}
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="2">{experiment}</ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


ROBOT = {"models/robot.fmu": cosim.builtin_fmu("DifferentialDrive")}
NC = """<ssd:Annotations><ssc:Annotation type="org.navcosim.simulation">
      <nc:Simulation macroStep="0.05"/></ssc:Annotation></ssd:Annotations>"""
OSP = """<ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">
      <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="0.04"/></osp:Algorithm>
    </ssc:Annotation></ssd:Annotations>"""
OMS = """
    <ssd:Annotations><ssc:Annotation type="org.openmodelica"><oms:Annotations>
      <oms:SimulationInformation>
        <oms:FixedStepMaster description="oms-ma" stepSize="0.025" absoluteTolerance="1e-4"/>
      </oms:SimulationInformation>
    </oms:Annotations></ssc:Annotation></ssd:Annotations>"""
# A second FMU whose own DefaultExperiment step (0.05 s) is larger than the robot's (0.01 s).
FOLLOWER = '\n      <ssd:Component name="follower" source="models/tracker.fmu"/>'


def test_an_empty_element_name_is_the_systems_own_connector(tmp_path):
    """speed (the root's input, V from its binding) -> robot.v and robot.x -> position, written
    with empty element names, run as the same SSD without them: x = V t exactly."""
    step = ["simulation.macro_step=0.125"]
    logs = []
    for case, empty in (("empty", ' startElement=""'), ("absent", "")):
        ssd = system_ssd(empty=empty)
        xmlschema.XMLSchema(schema.SCHEMA_DIR / "SystemStructureDescription.xsd").validate(ssd)
        archive = pack(tmp_path / f"{case}.ssp", ssd, ROBOT)
        with open_ssp(archive) as ssp:
            assert ssp.components[0].inputs == {"v": V} and ssp.connections == []
        logs.append(open_log(run_ssp(archive, tmp_path / f"{case}.mcap", step).log_path).signals("robot"))
    empty, absent = logs
    assert np.array_equal(empty.values, absent.values) and empty.names == absent.names
    assert np.allclose(empty["x"], V * empty.t, rtol=0, atol=1e-12) and empty.t[-1] == 2.0


@pytest.mark.parametrize(
    "experiment, system_annotation, overrides, step, source",
    [
        (NC + OSP, OMS, ["simulation.macro_step=0.1"], 0.1, "--set simulation.macro_step"),
        (NC + OSP, OMS, [], 0.05, "navcosim annotation nc:Simulation macroStep"),
        (OSP, OMS, [], 0.04, "OSP annotation osp:FixedStepAlgorithm baseStepSize"),
        ("", OMS, [], 0.025, "OMS annotation oms:FixedStepMaster stepSize"),
        ("", "", [], 0.01, "smallest FMU DefaultExperiment stepSize, of models/robot.fmu"),
    ],
)
def test_the_macro_step_comes_from_the_first_source_that_gives_one(
    experiment, system_annotation, overrides, step, source, tmp_path
):
    """--set, then navcosim's annotation, then OSP's, then OMS's, then the FMUs' smallest step."""
    # Two blocks of ssd:Annotations in one DefaultExperiment are not SSP: join them into one.
    experiment = experiment.replace("</ssd:Annotations><ssd:Annotations>", "")
    ssd = system_ssd(experiment=experiment, system_annotation=system_annotation, extra_elements=FOLLOWER)
    xmlschema.XMLSchema(schema.SCHEMA_DIR / "SystemStructureDescription.xsd").validate(ssd)
    files = ROBOT | {"models/tracker.fmu": cosim.builtin_fmu("PurePursuit")}
    archive = pack(tmp_path / "steps.ssp", ssd, files)
    result = run_ssp(archive, tmp_path / "steps.mcap", overrides)
    assert result.exit_code == 0 and (result.macro_step, result.macro_step_source) == (step, source)
    assert f"(macro step from {source})" in summary(result)
    log = open_log(result.log_path)
    robot = log.signals("robot")
    assert result.steps == round(2 / step) and np.allclose(np.diff(robot.t), step, rtol=0, atol=1e-12)
    assert log.metadata["navcosim"]["macro_step_source"] == source


def test_an_ssp_without_any_step_asks_for_one(tmp_path, capsys):
    """The fixture FMU gives no DefaultExperiment step and the file no annotation."""
    files = {"models/robot.fmu": fixture_fmu("diffdrive_fmi2")}
    archive = pack(tmp_path / "nostep.ssp", system_ssd(), files)
    with open_ssp(archive) as ssp:
        assert ssp.macro_step is None
    assert main(["run", str(archive), "--out", str(tmp_path / "x.mcap"), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "osp:FixedStepAlgorithm" in error
    assert "--set simulation.macro_step" in error


ARC_SSV_2 = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="2.0" name="arc"><ssv:Parameters>
  <ssv:Parameter name="robot.v"><ssv:Float64 value="0.5"/></ssv:Parameter>
  <ssv:Parameter name="robot.omega"><ssv:Float32 value="0.25"/></ssv:Parameter>
  <ssv:Parameter name="robot.y0"><ssv:Float64 value="1.0"/></ssv:Parameter>
</ssv:Parameters></ssv:ParameterSet>
"""
ARC_SSD_2 = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {NAMESPACES} version="2.0" name="arc">
  <ssd:System name="arc">
    <ssd:ParameterBindings><ssd:ParameterBinding source="resources/arc.ssv"/></ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="robot" source="resources/robot.fmu" implementation="CoSimulation">
        <ssd:Connectors>
          <ssd:Connector name="x" kind="output"><ssc:Float64 unit="m"/></ssd:Connector>
          <ssd:Connector name="theta" kind="output"><ssc:Float64/></ssd:Connector>
          <ssd:Connector name="steps" kind="output"><ssc:Int32/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment stopTime="4">
    <ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">
      <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="0.01"/></osp:Algorithm>
    </ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def test_ssp_2_archive_runs_the_exact_arc(tmp_path):
    """An SSP 2.0 SSD and SSV (Float64, Float32 values; Float64, Int32 connectors), valid against
    the normative SSP 2.0 schemas, run: the FMI 3.0 robot follows the exact arc."""
    xmlschema.XMLSchema(SCHEMAS_2 / "SystemStructureDescription.xsd").validate(ARC_SSD_2)
    xmlschema.XMLSchema(SCHEMAS_2 / "SystemStructureParameterValues.xsd").validate(ARC_SSV_2)
    files = {"resources/robot.fmu": fixture_fmu("diffdrive_fmi3"), "resources/arc.ssv": ARC_SSV_2.encode()}
    archive = pack(tmp_path / "arc2.ssp", ARC_SSD_2, files)
    with open_ssp(archive) as ssp:
        assert ssp.version == "2.0" and ssp.components[0].inputs == {"v": 0.5, "omega": 0.25}
    result = run_ssp(archive, tmp_path / "arc2.mcap")
    assert result.exit_code == 0 and result.steps == 400
    robot = open_log(result.log_path).signals("robot")
    theta = 0.25 * robot.t
    assert np.allclose(robot["theta"], theta, rtol=0, atol=1e-12)
    assert np.allclose(robot["x"], 0.5 / 0.25 * np.sin(theta), rtol=0, atol=1e-12)
    assert np.allclose(robot["y"], 1.0 + 0.5 / 0.25 * (1 - np.cos(theta)), rtol=0, atol=1e-12)


def test_ssp_2_integer_and_enumeration_values(tmp_path):
    """Int8..UInt64 give integers, an ssv:Enumeration given as an ssv:Value child its item's value."""
    parameters = "".join(
        f'<ssv:Parameter name="{name}"><ssv:{kind} value="{value}"/></ssv:Parameter>'
        for name, kind, value in (("fail_time", "Float64", "0.5"), ("fail_status", "UInt8", "3"))
    )
    ssd = f"""<ssd:SystemStructureDescription {NAMESPACES} version="2.0" name="types">
      <ssd:System name="types"><ssd:Elements>
        <ssd:Component name="failing" source="f.fmu"><ssd:ParameterBindings><ssd:ParameterBinding>
          <ssd:ParameterValues><ssv:ParameterSet version="2.0" name="p"><ssv:Parameters>{parameters}
          </ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>
        </ssd:ParameterBindings></ssd:Component>
        <ssd:Component name="fault" source="g.fmu"><ssd:ParameterBindings><ssd:ParameterBinding>
          <ssd:ParameterValues><ssv:ParameterSet version="2.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="fault"><ssv:Enumeration><ssv:Value value="hang"/></ssv:Enumeration>
            </ssv:Parameter>
            <ssv:Parameter name="fault_time"><ssv:Int64 value="7"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>
        </ssd:ParameterBindings></ssd:Component>
      </ssd:Elements></ssd:System></ssd:SystemStructureDescription>"""
    xmlschema.XMLSchema(SCHEMAS_2 / "SystemStructureDescription.xsd").validate(ssd)
    files = {"f.fmu": fixture_fmu("failing_fmi2"), "g.fmu": fixture_fmu("fault_fmi2")}
    with open_ssp(pack(tmp_path / "types.ssp", ssd, files)) as ssp:
        assert ssp.component("failing").parameters == {"fail_time": 0.5, "fail_status": 3.0}
        assert ssp.component("fault").parameters == {"fault": 4.0, "fault_time": 7.0}  # "hang" is item 4


@pytest.mark.parametrize(
    "version, edit, expected",
    [
        # 2.0's Float64 connector type is no SSP 1.0.
        ("1.0", lambda s: s, "not valid SSP 1.0 (SystemStructureDescription.xsd)"),
        ("2.0", lambda s: s.replace('kind="output"', 'kind="sideways"', 1), "not valid SSP 2.0"),
        ("3.0", lambda s: s, "not valid SSP 1.0"),
    ],
)
def test_each_file_is_checked_against_the_schemas_of_its_version(version, edit, expected, tmp_path, capsys):
    ssd = edit(ARC_SSD_2.replace('version="2.0" name="arc"', f'version="{version}" name="arc"'))
    files = {"resources/robot.fmu": fixture_fmu("diffdrive_fmi3"), "resources/arc.ssv": ARC_SSV_2.encode()}
    archive = pack(tmp_path / "bad.ssp", ssd, files)
    assert main(["run", str(archive), "--out", str(tmp_path / "x.mcap"), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and f"bad.ssp: SystemStructure.ssd: {expected}" in error, error
    with pytest.raises(CosimError, match="resources/arc.ssv: not valid SSP 2.0"):
        broken = ARC_SSV_2.replace('<ssv:Float32 value="0.25"/>', '<ssv:Float32 value="fast"/>')
        with open_ssp(pack(tmp_path / "ssv.ssp", ARC_SSD_2, files | {"resources/arc.ssv": broken.encode()})):
            pass


def test_messages_and_logs_name_archive_members_and_runs_are_byte_equal(tmp_path, capsys):
    """Two runs of one archive write the same bytes (the log names `models/robot.fmu`, not the
    folder each run unpacked it to), and an FMU that cannot load is named by its member."""
    archive = pack(tmp_path / "line.ssp", system_ssd(experiment=OSP), ROBOT)
    first, second = (run_ssp(archive, tmp_path / f"{n}.mcap").log_path for n in ("a", "b"))
    assert first.read_bytes() == second.read_bytes()
    assert open_log(first).metadata["fmu/robot"]["fmu"] == "models/robot.fmu"
    # An FMU without a binary for this platform, and an FMI 1.0 FMU without one.
    member = "models/robot.fmu"
    for fmu in (fixture_fmu("no_binary"), _fmi1(tmp_path)):
        broken = pack(tmp_path / "broken.ssp", system_ssd(experiment=OSP), {member: fmu})
        assert main(["run", str(broken), "--out", str(tmp_path / "c.mcap"), "--quiet", "--force"]) == 2
        error = capsys.readouterr().err
        assert error.count("\n") == 1 and f"'{member}'" in error, error
        assert "navcosim-ssp-" not in error and not re.search(r"/tmp/\S*robot\.fmu", error), error


def _fmi1(tmp_path: Path) -> Path:
    """An FMI 1.0 co-simulation model description with the robot's variables and no binary."""
    variables = "".join(
        f'<ScalarVariable name="{name}" valueReference="{i}" causality="{causality}"><Real/></ScalarVariable>'
        for i, (name, causality) in enumerate((("v", "input"), ("x", "output")))
    )
    description = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="1.0" modelName="Line" modelIdentifier="Line" guid="{{7}}"
    numberOfContinuousStates="0" numberOfEventIndicators="0">
  <ModelVariables>{variables}</ModelVariables>
  <Implementation><CoSimulation_StandAlone><Capabilities/></CoSimulation_StandAlone></Implementation>
</fmiModelDescription>"""
    path = tmp_path / "fmi1.fmu"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("modelDescription.xml", description)
    return path


BALL_SSD = f"""<ssd:SystemStructureDescription {NAMESPACES} version="2.0" name="ball">
  <ssd:System name="ball"><ssd:Elements>
    <ssd:Component name="ball" source="models/ball.fmu"IMPLEMENTATION/>
  </ssd:Elements></ssd:System>
  <ssd:DefaultExperiment stopTime="2"/>
</ssd:SystemStructureDescription>"""


@pytest.mark.parametrize(
    "kind, implementation",
    [
        ("bouncing_ball_me_fmi2", ""),
        ("bouncing_ball_me_fmi3", ""),
        ("bouncing_ball_both_fmi2", "ModelExchange"),
    ],
)
def test_model_exchange_components_are_integrated(kind, implementation, tmp_path):
    """An FMU without co-simulation (implementation "any", the default), or one whose component says
    "ModelExchange", is integrated by CVode: the ball from rest at 1 m bounces at the analytic
    times t1 = sqrt(2 h0 / g), t_k+1 = t_k + 2 e^k sqrt(2 g h0) / g (4 bounces in 2 s)."""
    attribute = f' implementation="{implementation}"' if implementation else ""
    ssd = BALL_SSD.replace("IMPLEMENTATION", attribute)
    xmlschema.XMLSchema(SCHEMAS_2 / "SystemStructureDescription.xsd").validate(ssd)
    archive = pack(tmp_path / "ball.ssp", ssd, {"models/ball.fmu": fixture_fmu(kind)})
    with open_ssp(archive) as ssp:
        assert ssp.components[0].interface == "me"
    result = run_ssp(archive, tmp_path / "ball.mcap", ["simulation.macro_step=0.01"])
    assert result.exit_code == 0
    ball = open_log(result.log_path).signals("ball")
    g, e, h0 = 9.81, 0.7, 1.0
    bounces = [np.sqrt(2 * h0 / g)]
    for k in range(1, 4):
        bounces.append(bounces[-1] + 2 * e**k * np.sqrt(2 * g * h0) / g)
    assert ball["bounces"][-1] == 4
    assert abs(ball["t_bounce"][-1] - bounces[-1]) < 1e-3  # CVode at the FMU's default tolerance


def test_an_fmu_with_both_interfaces_runs_co_simulation_unless_the_ssd_says_otherwise(tmp_path, capsys):
    """The fixture's co-simulation binary is absent: choosing it fails, naming the member."""
    archive = pack(
        tmp_path / "both.ssp",
        BALL_SSD.replace("IMPLEMENTATION", ""),
        {"models/ball.fmu": fixture_fmu("bouncing_ball_both_fmi2")},
    )
    with open_ssp(archive) as ssp:
        assert ssp.components[0].interface == "cs"
    argv = [
        "run",
        str(archive),
        "--out",
        str(tmp_path / "x.mcap"),
        "--quiet",
        "--set",
        "simulation.macro_step=0.01",
    ]
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "'models/ball.fmu'" in error and "navcosim-ssp-" not in error, error


def test_an_fmi1_fmu_in_an_ssp_runs_the_exact_arc(tmp_path):
    """The FMI 1.0 co-simulation fixture; its connectors by SSP's FMI 1.0 rule (a variable of
    variability "parameter" is kind parameter), its values from an SSP 1.0 inline binding."""
    ssd = f"""<ssd:SystemStructureDescription {NAMESPACES} version="1.0" name="arc1">
      <ssd:System name="arc1"><ssd:Elements>
        <ssd:Component name="robot" source="models/robot1.fmu">
          <ssd:Connectors>
            <ssd:Connector name="v" kind="input"/><ssd:Connector name="y0" kind="parameter"/>
            <ssd:Connector name="x" kind="output"/>
          </ssd:Connectors>
          <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
            <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
              <ssv:Parameter name="v"><ssv:Real value="0.5"/></ssv:Parameter>
              <ssv:Parameter name="omega"><ssv:Real value="0.4"/></ssv:Parameter>
              <ssv:Parameter name="y0"><ssv:Real value="1.0"/></ssv:Parameter>
            </ssv:Parameters></ssv:ParameterSet>
          </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
        </ssd:Component>
      </ssd:Elements></ssd:System>
      <ssd:DefaultExperiment stopTime="3"/></ssd:SystemStructureDescription>"""
    xmlschema.XMLSchema(schema.SCHEMA_DIR / "SystemStructureDescription.xsd").validate(ssd)
    archive = pack(tmp_path / "arc1.ssp", ssd, {"models/robot1.fmu": fixture_fmu("diffdrive_fmi1")})
    result = run_ssp(archive, tmp_path / "arc1.mcap", ["simulation.macro_step=0.01"])
    assert result.exit_code == 0 and result.steps == 300
    log = open_log(result.log_path)
    assert log.metadata["fmu/robot"]["fmu"] == "models/robot1.fmu"
    assert log.metadata["fmu/robot"]["fmi_version"] == "1.0"
    robot = log.signals("robot")
    theta = 0.4 * robot.t
    assert np.allclose(robot["theta"], theta, rtol=0, atol=1e-12)
    assert np.allclose(robot["x"], 0.5 / 0.4 * np.sin(theta), rtol=0, atol=1e-12)
    assert np.allclose(robot["y"], 1.0 + 0.5 / 0.4 * (1 - np.cos(theta)), rtol=0, atol=1e-12)
