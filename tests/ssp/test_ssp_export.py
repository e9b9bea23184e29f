"""`cosim ssp export`: what it writes is valid SSP 1.0 (the normative schemas, and fmpy's reader),
and `cosim run` of the archive reproduces the scenario's log exactly (`cosim log diff` at
tolerance 0); the SSV is what the run uses; each component carries its own binding with the same
values under its variables' own names (what libcosim and ecos read), and every unit the SSD names
is defined with the SI exponents of the FMU's own UnitDefinitions; an SSD the scenario does not
describe is an error; without the navcosim annotation the archive runs FMU-only.
"""

from __future__ import annotations

import io
import re
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
import xmlschema

from cosim.cli import main
from cosim.errors import CosimError
from cosim.logs import open_log
from cosim.scenario.load import load_scenario
from cosim.ssp.export import export_scenario, scenario_of
from cosim.ssp.read import open_ssp
from cosim.ssp.run import SspRunResult, run_ssp

REPO = Path(__file__).resolve().parents[2]
SCHEMAS = Path(__file__).resolve().parents[1] / "data" / "ssp-1.0.1"
# Short runs keep the test fast; both sides of each comparison run the same settings.
SCENARIOS = {
    "warehouse_diff_drive_one_obstacle": ["simulation.stop_time=12"],
    "warehouse_bicycle_one_obstacle": ["simulation.stop_time=12"],
}


@pytest.fixture(scope="module", params=sorted(SCENARIOS))
def exported(request, tmp_path_factory):
    """(scenario path, overrides, archive) of an exported shipped scenario."""
    directory = tmp_path_factory.mktemp("export")
    path = REPO / "scenarios" / f"{request.param}.toml"
    archive = directory / f"{request.param}.ssp"
    argv = ["ssp", "export", str(path), "--out", str(archive)]
    for override in SCENARIOS[request.param]:
        argv += ["--set", override]
    assert main(argv) == 0
    return path, SCENARIOS[request.param], archive


def test_written_ssd_and_ssv_are_valid_against_the_normative_schemas(exported):
    _, _, archive = exported
    with zipfile.ZipFile(archive) as zipped:
        ssd, ssv = zipped.read("SystemStructure.ssd"), zipped.read("resources/parameters.ssv")
        names = zipped.namelist()
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureDescription.xsd").validate(io.BytesIO(ssd))
    xmlschema.XMLSchema(SCHEMAS / "SystemStructureParameterValues.xsd").validate(io.BytesIO(ssv))
    for role in ("vehicle", "pure_pursuit", "vfh", "mixer"):
        assert f"resources/{role}.fmu" in names
    assert "resources/navcosim/scenario.toml" in names and "resources/navcosim/warehouse.pgm" in names


def test_a_second_reader_sees_the_fmus_and_their_connections(exported):
    from fmpy.ssp.ssd import read_ssd, read_ssv

    path, _, archive = exported
    lookahead = load_scenario(path).components["pure_pursuit"].parameters["lookahead_distance"]
    ssd = read_ssd(str(archive))  # validates against fmpy's own copy of the schemas
    names = [element.name for element in ssd.system.elements]
    assert names == ["pure_pursuit", "vfh", "mixer", "vehicle"]
    pairs = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections}
    assert ("vehicle", "x", "pure_pursuit", "x") in pairs and (
        "vfh",
        "steering_dir",
        "mixer",
        "steering_dir",
    ) in pairs
    parameters = {p.name: p.value for p in read_ssv(str(archive), "resources/parameters.ssv").parameters}
    assert float(parameters["pure_pursuit.lookahead_distance"]) == lookahead
    assert parameters["vehicle.x0"] == "6.0"  # derived from [start], as the run sets it


SSD_NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}


def _values(parameter_set: ET.Element) -> dict[str, tuple[str, str]]:
    """name -> (value type, value text) of an ssv:ParameterSet."""
    values = {}
    for parameter in parameter_set.iterfind("ssv:Parameters/ssv:Parameter", SSD_NS):
        (value,) = list(parameter)
        values[parameter.get("name")] = (value.tag.rpartition("}")[2], value.get("value"))
    return values


def test_each_component_has_its_own_binding_with_the_systems_values(exported):
    """The same numbers as the root's parameters.ssv, named without the component prefix, in a
    set named as the system (ecos selects parameter sets by name); each set valid SSP 1.0."""
    _, _, archive = exported
    with zipfile.ZipFile(archive) as zipped:
        ssd = ET.fromstring(zipped.read("SystemStructure.ssd"))
        root_values = _values(ET.fromstring(zipped.read("resources/parameters.ssv")))
    ssv_schema = xmlschema.XMLSchema(SCHEMAS / "SystemStructureParameterValues.xsd")
    from_components = {}
    for component in ssd.iterfind("ssd:System/ssd:Elements/ssd:Component", SSD_NS):
        bindings = component.findall("ssd:ParameterBindings/ssd:ParameterBinding", SSD_NS)
        assert len(bindings) == 1 and bindings[0].get("source") is None
        parameter_set = bindings[0].find("ssd:ParameterValues/ssv:ParameterSet", SSD_NS)
        ssv_schema.validate(parameter_set)
        assert parameter_set.get("name") == ssd.get("name")
        for name, value in _values(parameter_set).items():
            assert "." not in name
            from_components[f"{component.get('name')}.{name}"] = value
    assert from_components == root_values and len(root_values) >= 15
    assert from_components["vehicle.x0"] == ("Real", "6.0")


def test_every_unit_the_ssd_names_is_defined_with_the_fmus_si_exponents(exported):
    _, _, archive = exported
    with zipfile.ZipFile(archive) as zipped:
        ssd = ET.fromstring(zipped.read("SystemStructure.ssd"))
        fmus = [
            ET.fromstring(zipfile.ZipFile(io.BytesIO(zipped.read(n))).read("modelDescription.xml"))
            for n in zipped.namelist()
            if n.endswith(".fmu")
        ]
    referenced = {element.get("unit") for element in ssd.iter() if element.get("unit") is not None}
    defined = {}
    for unit in ssd.iterfind("ssd:Units/ssc:Unit", SSD_NS):
        (base,) = unit.findall("ssc:BaseUnit", SSD_NS)
        defined[unit.get("name")] = {key: float(value) for key, value in base.attrib.items()}
    assert referenced == set(defined) and {"m", "rad", "m/s", "rad/s"} <= referenced
    # The FMUs' own definitions (FMI's BaseUnit attributes, the same names as SSP's).
    for description in fmus:
        for unit in description.iterfind("UnitDefinitions/Unit"):
            base = unit.find("BaseUnit")
            if unit.get("name") in defined and base is not None:
                expected = {key: float(value) for key, value in base.attrib.items() if float(value) != 0}
                expected = {k: v for k, v in expected.items() if not (k == "factor" and v == 1.0)}
                assert defined[unit.get("name")] == expected, unit.get("name")
    assert defined["m/s"] == {"m": 1.0, "s": -1.0} and defined["rad"] == {"rad": 1.0}


def test_the_component_bindings_alone_give_the_run_its_values(exported, tmp_path):
    """Without the root binding (as libcosim and ecos see it) the reader finds the same values."""
    _, _, archive = exported
    edited = tmp_path / "components_only.ssp"
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(edited, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "SystemStructure.ssd":
                root = b'<ssd:ParameterBinding source="resources/parameters.ssv" />'
                assert data.count(root) == 1
                data = data.replace(root, b"")
                data = data.replace(b"<ssd:ParameterBindings>\n      \n    </ssd:ParameterBindings>\n", b"")
            target.writestr(item, data)
    with open_ssp(archive) as full, open_ssp(edited) as alone:
        for a, b in zip(full.components, alone.components, strict=True):
            assert (a.name, a.parameters, a.inputs) == (b.name, b.parameters, b.inputs)
            assert a.parameters or a.inputs


def test_running_the_ssp_reproduces_the_scenario_log_exactly(exported, tmp_path, capsys):
    path, overrides, archive = exported
    direct, again = tmp_path / "direct.mcap", tmp_path / "from_ssp.mcap"
    sets = [item for override in overrides for item in ("--set", override)]
    codes = [main(["run", str(path), "--out", str(direct), "--no-plot", "--quiet", *sets])]
    codes.append(main(["run", str(archive), "--out", str(again), "--no-plot", "--quiet"]))
    assert codes[0] == codes[1]
    capsys.readouterr()
    assert main(["log", "diff", str(direct), str(again), "--tolerance", "0"]) == 0
    report = capsys.readouterr().out
    assert "EQUAL within tolerance" in report and "(largest deviation 0)" in report
    a, b = open_log(direct), open_log(again)
    # Five FMUs and lidar plus the replanning planner (its pose and VFH-direction inputs).
    assert sorted(a.components) == sorted(b.components) and len(a.components) == 6
    assert a.scenario_text == b.scenario_text and a.outcome == b.outcome


def test_two_runs_of_the_archive_write_the_same_bytes(exported, tmp_path):
    """The log names each FMU by its archive member, not the folder each run unpacked it to."""
    _, _, archive = exported
    logs = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    for log in logs:
        assert main(["run", str(archive), "--out", str(log), "--no-plot", "--quiet"]) in (0, 1)
    assert logs[0].read_bytes() == logs[1].read_bytes()
    metadata = open_log(logs[0]).metadata
    assert [metadata[f"fmu/{name}"]["fmu"] for name in ("vehicle", "mixer")] == [
        "resources/vehicle.fmu",
        "resources/mixer.fmu",
    ]


def test_the_ssv_is_what_the_run_uses(exported, tmp_path):
    _, _, archive = exported
    edited = tmp_path / "edited.ssp"
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(edited, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "resources/parameters.ssv":
                data = re.sub(
                    rb'(name="pure_pursuit.lookahead_distance">\s*<ssv:Real value=")[^"]*', rb"\g<1>4.5", data
                )
            target.writestr(item, data)
    with open_ssp(edited) as ssp:
        scenario = scenario_of(ssp, {})
        assert scenario.components["pure_pursuit"].parameters["lookahead_distance"] == 4.5
        assert Path(scenario.components["vehicle"].fmu).parent == ssp.directory / "resources"


def test_the_archive_runs_each_fmu_where_the_scenario_ran_it(exported, tmp_path):
    """The project FMUs in-process (on the compiled kernel), though the archive gives them by path
    (which alone would isolate them in child processes); an isolation chosen in the scenario stays."""
    path, overrides, archive = exported
    scenario = load_scenario(path, overrides)
    with open_ssp(archive) as ssp:
        again = scenario_of(ssp, {})
        for name, spec in again.components.items():
            assert not spec.is_builtin and again.isolation(spec) == "none"
            assert scenario.isolation(scenario.components[name]) == "none"
    isolated = export_scenario(
        load_scenario(path, [*overrides, 'vfh.isolation="process"']), tmp_path / "i.ssp"
    )
    with open_ssp(isolated) as ssp:
        again = scenario_of(ssp, {})
        assert [n for n, spec in again.components.items() if again.isolation(spec) == "process"] == ["vfh"]


def test_an_ssd_the_scenario_does_not_describe_is_an_error(exported, tmp_path, capsys):
    _, _, archive = exported
    edited = tmp_path / "rewired.ssp"
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(edited, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "SystemStructure.ssd":  # the avoidance direction, doubled on its way
                wire = b'startConnector="steering_dir" endElement="mixer" endConnector="steering_dir" />'
                assert wire in data
                scaled = wire[:-3] + b'><ssc:LinearTransformation factor="2.0" /></ssd:Connection>'
                data = data.replace(wire, scaled)
            target.writestr(item, data)
    assert main(["run", str(edited), "--out", str(tmp_path / "x.mcap"), "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "rewired.ssp: SystemStructure.ssd: the connections differ" in error


def test_without_the_navcosim_annotation_the_archive_runs_fmu_only(exported, tmp_path):
    _, _, archive = exported
    stripped = tmp_path / "fmus_only.ssp"
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(stripped, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "SystemStructure.ssd":
                start = data.index(b'  <ssd:Annotations>\n    <ssc:Annotation type="org.navcosim.scenario">')
                data = data[:start] + data[data.index(b"</ssd:SystemStructureDescription>") :]
            target.writestr(item, data)
    result = run_ssp(stripped, tmp_path / "fmus.mcap", ["simulation.stop_time=0.5"])
    assert isinstance(result, SspRunResult) and result.exit_code == 0 and result.steps == 50
    log = open_log(result.log_path)
    assert sorted(log.components) == ["mixer", "pure_pursuit", "vehicle", "vfh"]
    # The controllers step at their exported period (20 Hz), the vehicle every macro step; each
    # has a last record at the end (t = 0.5 s) with its final outputs.
    assert len(log.signals("vehicle").t) == 51 and len(log.signals("mixer").t) == 11


def test_export_errors_are_one_line(tmp_path, capsys):
    argv = ["ssp", "export", str(REPO / "scenarios" / "nope.toml"), "--out", str(tmp_path / "x.ssp")]
    assert main(argv) == 2 and "nope.toml: no such scenario file" in capsys.readouterr().err
    with pytest.raises(CosimError, match="simulation.start_time is not allowed"):
        scenario = load_scenario(REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml")
        export_scenario(scenario, tmp_path / "w.ssp")
        run_ssp(tmp_path / "w.ssp", tmp_path / "w.mcap", ["simulation.start_time=1"])
