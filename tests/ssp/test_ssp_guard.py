"""An SSP archive is untrusted input (issue 26): hostile archives built here with zipfile end with
one error line that starts with the archive's name and exit code 2, before anything is extracted
or run; an FMU that crashes, exits or hangs inside an SSP runs in a child process and ends the run
with exit code 2 and a readable log; connected connectors' units convert as SSP's Units say.

The truths: the archive's own central directory (entry sizes and counts, read back with zipfile),
the normative SSP rule for units (the value is converted to the target's unit, SI value =
factor * value + offset, before the LinearTransformation), and a second run of the same system
with the conversion written out as a LinearTransformation.
"""

from __future__ import annotations

import re
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from zip_bomb import write_zip_bomb

import cosim
from cosim.cli import main
from cosim.errors import CosimError
from cosim.fmi.archive import MAX_ENTRIES, MIB
from cosim.logs import open_log
from cosim.ssp.read import MAX_NAME_LENGTH, MAX_SYSTEM_DEPTH, open_ssp
from cosim.ssp.run import run_ssp

SSP1 = "http://ssp-standard.org/SSP1"
NAMESPACES = (
    f'xmlns:ssd="{SSP1}/SystemStructureDescription" xmlns:ssc="{SSP1}/SystemStructureCommon" '
    f'xmlns:ssv="{SSP1}/SystemStructureParameterValues" xmlns:nc="urn:navcosim:ssp:1"'
)
GIB = 1 << 30
STEP = '<ssd:Annotations><ssc:Annotation type="org.navcosim.simulation"><nc:Simulation macroStep="0.1"/>'
STEP += "</ssc:Annotation></ssd:Annotations>"


def ssd(elements: str, connections: str = "", stop: str = "1", step: str = STEP, units: str = "") -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {NAMESPACES} version="1.0" name="guard">
  <ssd:System name="root">
    <ssd:Elements>{elements}</ssd:Elements>
    {f"<ssd:Connections>{connections}</ssd:Connections>" if connections else ""}
  </ssd:System>{units}
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}">{step}</ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def robot(
    name: str = "robot", connectors: str = "", values: str = "", source: str = "models/robot.fmu"
) -> str:
    """A component, with these connectors and parameter values (ssv:Parameter elements)."""
    connectors = f"<ssd:Connectors>{connectors}</ssd:Connectors>" if connectors else ""
    bindings = ""
    if values:
        bindings = f"""<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="values"><ssv:Parameters>{values}</ssv:Parameters>
          </ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>"""
    return f"""
      <ssd:Component name="{name}" source="{source}">
        {connectors}{bindings}
      </ssd:Component>"""


def real(name: str, value: float) -> str:
    return f'<ssv:Parameter name="{name}"><ssv:Real value="{value!r}"/></ssv:Parameter>'


def pack(path: Path, text: str, files: dict[str, Path | bytes] | None = None) -> Path:
    files = {"models/robot.fmu": cosim.builtin_fmu("DifferentialDrive")} if files is None else files
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("SystemStructure.ssd", text)
        for name, content in files.items():
            if isinstance(content, Path):
                archive.write(content, name)
            else:
                archive.writestr(name, content)
    return path


def error_line(capsys, argv: list[str]) -> str:
    """Run `cosim` with `argv`: exit code 2 and one line on stderr, returned without 'cosim: error: '."""
    assert main(argv) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cosim: error: "), lines
    return lines[0].removeprefix("cosim: error: ")


def refuses(capsys, archive: Path, *options: str) -> str:
    """`cosim run archive` fails with one line that starts with the archive's name; the line's rest."""
    line = error_line(capsys, ["run", str(archive), "--out", str(archive.with_suffix(".mcap")), *options])
    assert line.startswith(f"{archive}: ")
    assert not archive.with_suffix(".mcap").exists()
    return line.removeprefix(f"{archive}: ")


def no_extraction(monkeypatch) -> list[str]:
    """Records what would be extracted, or a folder made to extract it to."""
    extracted: list[str] = []
    monkeypatch.setattr(zipfile.ZipFile, "extractall", lambda *args, **kwargs: extracted.append("all"))
    monkeypatch.setattr(tempfile, "mkdtemp", lambda *args, **kwargs: extracted.append("folder"))
    return extracted


# ---- the archive ---------------------------------------------------------------------------------


def test_a_2_gib_entry_beside_the_ssd_is_refused_before_extraction(tmp_path, capsys, monkeypatch):
    archive = tmp_path / "bomb.ssp"
    write_zip_bomb(archive, 2 * GIB)
    with zipfile.ZipFile(archive, "a") as zipped:
        zipped.writestr("SystemStructure.ssd", ssd(robot()))
        zipped.write(cosim.builtin_fmu("DifferentialDrive"), "models/robot.fmu")
    assert archive.stat().st_size < 5 * MIB
    with zipfile.ZipFile(archive) as zipped:
        total = sum(info.file_size for info in zipped.infolist())
    assert total > 2 * GIB
    extracted = no_extraction(monkeypatch)
    line = refuses(capsys, archive)
    assert re.fullmatch(
        r"the SSP archive would unpack to 2,04\d MiB \('resources/padding.bin' alone 2,048 MiB\), more than "
        r"the limit of 1,024 MiB; not extracted; raise the limit with --set simulation.fmu_max_size=MIB "
        r"if you trust it",
        line,
    ), line
    assert extracted == []


def test_fmu_max_size_sets_the_limit_of_the_archive(tmp_path, capsys):
    archive = pack(tmp_path / "padded.ssp", ssd(robot()), {
        "models/robot.fmu": cosim.builtin_fmu("DifferentialDrive"),
        "resources/padding.bin": bytes(2 * MIB),
    })  # fmt: skip
    line = refuses(capsys, archive, "--set", "simulation.fmu_max_size=1.5")
    assert "more than the limit of 1.5 MiB" in line and "'resources/padding.bin' alone 2.0 MiB" in line
    result = run_ssp(archive, tmp_path / "padded.mcap", ["simulation.fmu_max_size=3"])
    assert result.reason == "stop_time" and result.failure is None


def test_an_archive_of_too_many_entries_is_refused_before_extraction(tmp_path, capsys, monkeypatch):
    files: dict[str, Path | bytes] = {"models/robot.fmu": cosim.builtin_fmu("DifferentialDrive")}
    files.update({f"resources/empty/{i}": b"" for i in range(MAX_ENTRIES)})
    archive = pack(tmp_path / "many.ssp", ssd(robot()), files)
    with zipfile.ZipFile(archive) as zipped:
        entries = len(zipped.infolist())
    assert entries == MAX_ENTRIES + 2
    extracted = no_extraction(monkeypatch)
    line = refuses(capsys, archive)
    limit = f"more than the limit of {MAX_ENTRIES:,}"
    assert line == f"the SSP archive has {entries:,} entries, {limit}; not extracted"
    assert extracted == []


@pytest.mark.parametrize("member", ["../outside.txt", "resources/../../outside.txt", "/tmp/absolute.txt"])
def test_a_member_outside_the_archive_is_refused(member, tmp_path, capsys, monkeypatch):
    archive = pack(tmp_path / "slip.ssp", ssd(robot()))
    with zipfile.ZipFile(archive, "a") as zipped:
        zipped.writestr(zipfile.ZipInfo(member), b"x")
    with zipfile.ZipFile(archive) as zipped:
        assert member in zipped.namelist()  # as written: zipfile keeps the name
    extracted = no_extraction(monkeypatch)
    assert refuses(capsys, archive) == f"archive member '{member}' points outside the archive"
    assert extracted == []


@pytest.mark.parametrize("source", ["../robot.fmu", "/etc/hostname", "models/../../robot.fmu"])
def test_a_component_source_outside_the_archive_is_refused(source, tmp_path, capsys):
    archive = pack(tmp_path / "source.ssp", ssd(robot(source=source)))
    line = refuses(capsys, archive)
    assert line.endswith(f"source '{source}' must be a relative path inside the archive"), line


# ---- nesting, names, times -----------------------------------------------------------------------


def nested(depth: int) -> str:
    """`depth` systems inside the root system, the robot in the innermost."""
    inner = robot()
    for level in range(depth):
        inner = f'<ssd:System name="s{level}"><ssd:Elements>{inner}</ssd:Elements></ssd:System>'
    return ssd(inner)


def test_systems_nest_up_to_the_limit(tmp_path):
    archive = pack(tmp_path / "deep.ssp", nested(MAX_SYSTEM_DEPTH))
    with open_ssp(archive) as ssp:
        (component,) = ssp.components
    path = ".".join(f"s{level}" for level in reversed(range(MAX_SYSTEM_DEPTH)))
    assert component.path == f"{path}.robot"


@pytest.mark.parametrize("depth", [MAX_SYSTEM_DEPTH + 1, 100, 1000])
def test_deeper_nesting_is_one_line(depth, tmp_path, capsys):
    archive = pack(tmp_path / f"deep{depth}.ssp", nested(depth))
    line = refuses(capsys, archive)
    if depth == MAX_SYSTEM_DEPTH + 1:
        assert line.startswith("SystemStructure.ssd: element '") and line.endswith(
            f"': systems nest more than {MAX_SYSTEM_DEPTH} deep (the limit of navcosim)"
        ), line
    else:
        xml_depth = 2 * depth + 4  # description, root system, Elements, then System + Elements per level
        assert line == (
            f"SystemStructure.ssd: elements nest {xml_depth} deep, more than the limit of 100 "
            "(systems inside systems: at most 20)"
        )


@pytest.mark.parametrize("where", ["element", "connector"])
def test_a_5_mb_name_is_one_short_line(where, tmp_path, capsys):
    name = "n" * 5_000_000
    connector = f'<ssd:Connector name="{name}" kind="input"/>'
    component = robot(name) if where == "element" else robot(connectors=connector)
    archive = pack(tmp_path / "name.ssp", ssd(component))
    line = refuses(capsys, archive)
    assert len(line) < 300 and f"is 5,000,000 characters long, more than {MAX_NAME_LENGTH}" in line, line
    assert f"{where} name 'nnn" in line


def test_a_component_name_longer_than_the_limit_is_refused(tmp_path, capsys):
    inner = robot("r" * 150)
    inner = f'<ssd:System name="{"s" * 150}"><ssd:Elements>{inner}</ssd:Elements></ssd:System>'
    line = refuses(capsys, pack(tmp_path / "joined.ssp", ssd(inner)))
    assert f"(301 characters, the element path joined by '_') is longer than {MAX_NAME_LENGTH}" in line


@pytest.mark.parametrize(
    "stop, step, expected",
    [
        ("1e300", STEP, "stop time must be a finite number, at most 1e+09 s in magnitude, got 1e+300"),
        ("-1e10", STEP, "stop time must be a finite number, at most 1e+09 s in magnitude, got -1e+10"),
        (
            "120",
            STEP.replace('"0.1"', '"1e-9"'),
            "120 s at macro step 1e-09 s is 1.2e+11 steps, above max_steps = 1e+08 "
            "(give --set simulation.max_steps=N to allow it)",
        ),
    ],
)
def test_times_and_the_number_of_steps_are_limited(stop, step, expected, tmp_path, capsys):
    archive = pack(tmp_path / "time.ssp", ssd(robot(), stop=stop, step=step))
    assert refuses(capsys, archive) == f"SystemStructure.ssd: {expected}"


def test_max_steps_is_a_set_key_and_an_option(tmp_path, capsys):
    archive = pack(tmp_path / "steps.ssp", ssd(robot()))  # 1 s of 0.1 s: 10 steps
    assert "is 10 steps, above max_steps = 9" in refuses(capsys, archive, "--set", "simulation.max_steps=9")
    assert run_ssp(archive, tmp_path / "ten.mcap", ["simulation.max_steps=10"]).steps == 10
    assert "is 10 steps, above max_steps = 9" in refuses(capsys, archive, "--max-steps", "9")


def test_set_errors_and_output_errors_name_the_archive(tmp_path, capsys):
    archive = pack(tmp_path / "plain.ssp", ssd(robot()))
    line = refuses(capsys, archive, "--set", "simulation.fmu_isolation=maybe")
    assert line == "--set simulation.fmu_isolation=maybe: fmu_isolation must be one of auto, process, none"
    if Path("/dev/full").exists():
        line = error_line(capsys, ["run", str(archive), "--out", "/dev/full", "--quiet"])
        assert line == f"{archive}: /dev/full: writing the log failed (No space left on device)"


# ---- units ---------------------------------------------------------------------------------------

UNITS = """
  <ssd:Units>
    <ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>
    <ssc:Unit name="km"><ssc:BaseUnit m="1" factor="1000"/></ssc:Unit>
    <ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>
    <ssc:Unit name="s"><ssc:BaseUnit s="1"/></ssc:Unit>
    <ssc:Unit name="degC"><ssc:BaseUnit K="1" offset="273.15"/></ssc:Unit>
    <ssc:Unit name="K"><ssc:BaseUnit K="1"/></ssc:Unit>
  </ssd:Units>"""


TRANSFORM = '<ssc:LinearTransformation factor="2" offset="3"/>'
SUPPRESS = ' suppressUnitConversion="true"'


def chase(source_unit: str | None, target_unit: str | None, wire: str = "", attributes: str = "") -> str:
    """`lead` drives at 0.5 m/s; its x feeds `chase`'s v, through connectors of these units."""

    def typed(unit):
        return f'<ssc:Real unit="{unit}"/>' if unit else "<ssc:Real/>"

    output = f'<ssd:Connector name="x" kind="output">{typed(source_unit)}</ssd:Connector>'
    lead = robot("lead", output, real("v", 0.5))
    follower = robot("chase", f'<ssd:Connector name="v" kind="input">{typed(target_unit)}</ssd:Connector>')
    connection = (
        '<ssd:Connection startElement="lead" startConnector="x" endElement="chase" '
        f'endConnector="v"{attributes}>{wire}</ssd:Connection>'
    )
    return ssd(lead + follower, connection, units=UNITS)


@pytest.mark.parametrize(
    "source, target, wire, attributes, factor, offset",
    [
        ("m", "m", "", "", 1.0, 0.0),
        (None, "mm", "", "", 1.0, 0.0),  # a connector without a unit is not checked
        ("m", "mm", "", "", 1000.0, 0.0),
        ("mm", "km", "", "", 1e-6, 0.0),
        ("degC", "K", "", "", 1.0, 273.15),
        ("K", "degC", "", "", 1.0, -273.15),
        # SSP: converted to the target's unit first, then transformed: 2 * (1000 x) + 3.
        ("km", "m", TRANSFORM, "", 2000.0, 3.0),
        ("km", "m", TRANSFORM, SUPPRESS, 2.0, 3.0),
        ("m", "s", "", SUPPRESS, 1.0, 0.0),
    ],
)
def test_connected_units_convert_as_ssp_units_say(source, target, wire, attributes, factor, offset, tmp_path):
    archive = pack(tmp_path / "units.ssp", chase(source, target, wire, attributes))
    with open_ssp(archive) as ssp:
        (connection,) = ssp.connections
    assert (connection.source, connection.target) == ("lead.x", "chase.v")
    assert connection.factor == pytest.approx(factor, rel=1e-15) and connection.offset == pytest.approx(
        offset, rel=1e-12
    )


def test_a_converted_run_is_the_run_with_the_conversion_written_out(tmp_path):
    converted = pack(tmp_path / "converted.ssp", chase("m", "mm"))
    written = pack(tmp_path / "written.ssp", chase(None, None, '<ssc:LinearTransformation factor="1000"/>'))
    logs = [open_log(run_ssp(path, path.with_suffix(".mcap")).log_path) for path in (converted, written)]
    (a, b) = (log.signals("chase") for log in logs)
    assert a.names == b.names and np.array_equal(a.values, b.values)
    lead = logs[0].signals("lead")
    assert np.array_equal(a.t, lead.t)
    # Gauss-Seidel: chase takes lead's x after lead's step [t, t + h]; the last record repeats.
    assert a["v"][-1] > 100 and np.allclose(a["v"][:-1], 1000 * lead["x"][1:], rtol=1e-12, atol=0)


@pytest.mark.parametrize(
    "source, target, expected",
    [
        ("m", "s", "units do not agree: 'm' at lead.x and 's' at chase.v have different SI base units"),
        ("m", "furlong", "units differ ('m' at lead.x, 'furlong' at chase.v) and 'furlong' is not defined"),
    ],
)
def test_units_that_do_not_convert_are_one_line_naming_both_ends(source, target, expected, tmp_path, capsys):
    line = refuses(capsys, pack(tmp_path / "mismatch.ssp", chase(source, target)))
    assert line.startswith("SystemStructure.ssd: connection lead.x -> chase.v: " + expected), line


# ---- FMUs in a child process ---------------------------------------------------------------------


def test_only_the_projects_own_build_counts_as_the_projects_fmu(tmp_path):
    own = cosim.builtin_fmu("DifferentialDrive")
    copy = tmp_path / "copy.fmu"
    with zipfile.ZipFile(own) as source, zipfile.ZipFile(copy, "w") as target:
        for info in source.infolist():
            target.writestr(info, source.read(info))
        target.comment = b"not the project's bytes"
    text = ssd(robot("own") + robot("copy", source="models/copy.fmu"))
    archive = pack(tmp_path / "two.ssp", text, {"models/robot.fmu": own, "models/copy.fmu": copy})
    with open_ssp(archive) as ssp:
        assert {c.name: c.project for c in ssp.components} == {"own": True, "copy": False}


HAPPENED = {
    "segfault": r"crashed with signal 11 \(SIGSEGV, Segmentation fault\) in fmi2DoStep",
    "exit": r"ended its process with exit status 0 \(exit\(\) inside the FMU\) in fmi2DoStep",
    "hang": r"did not return from fmi2DoStep at t = 0.5 s within 1 s \(fmu_timeout\)",
}


@pytest.mark.slow
@pytest.mark.parametrize("fault", sorted(HAPPENED))
def test_a_failing_fmu_inside_an_ssp_ends_the_run_with_exit_2_and_a_readable_log(fault, tmp_path, capsys):
    values = f'<ssv:Parameter name="fault"><ssv:Integer value="{FAULTS.index(fault)}"/></ssv:Parameter>'
    values += real("fault_time", 0.5) + real("v", 1.0)
    text = ssd(robot("robot", values=values, source="resources/fault.fmu"))
    archive = pack(tmp_path / f"{fault}.ssp", text, {"resources/fault.fmu": fixture_fmu("fault_fmi2")})
    log_path = tmp_path / f"{fault}.mcap"
    argv = ["run", str(archive), "--out", str(log_path), "--quiet", "--set", "simulation.fmu_timeout=1"]
    line = error_line(capsys, argv)
    assert re.fullmatch(
        rf"{re.escape(str(archive))}: FMU 'robot' \(model fixture_fault_fmi2, process \d+\) "
        rf"{HAPPENED[fault]}.*"
        rf"; log \(up to the failure\): {re.escape(str(log_path))}",
        line,
    ), line
    log = open_log(log_path)
    outcome = log.metadata["outcome"]
    assert outcome["reason"] == "fmu_failed" and outcome["failure"].startswith(f"{archive}: FMU 'robot'")
    signals = log.signals("robot")
    # Steps of 0.1 s up to the one that failed, [0.5, 0.6]: x = v t exactly (a straight line).
    assert signals.t[-1] == pytest.approx(0.5) and np.allclose(signals["x"], signals.t, rtol=0, atol=1e-12)


def test_an_fmu_failure_in_process_names_the_archive_too(tmp_path, capsys):
    values = f'<ssv:Parameter name="fault"><ssv:Integer value="{FAULTS.index("error")}"/></ssv:Parameter>'
    values += real("fault_time", 0.5)
    text = ssd(robot("robot", values=values, source="resources/fault.fmu"))
    archive = pack(tmp_path / "error.ssp", text, {"resources/fault.fmu": fixture_fmu("fault_fmi2")})
    result = run_ssp(archive, tmp_path / "error.mcap", ["simulation.fmu_isolation=none"])
    assert result.failure.startswith(f"{archive}: ")
    assert "returned fmi2Error from fmi2DoStep" in result.failure
    with pytest.raises(CosimError, match=r"^\S+error.ssp: --set simulation.fmu_timeout=0: "):
        run_ssp(archive, tmp_path / "error2.mcap", ["simulation.fmu_timeout=0"])


# ---- an exported SSP: the scenario inside it ----------------------------------------------------

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SCENARIO = "resources/navcosim/scenario.toml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    archive = tmp_path_factory.mktemp("exported") / "exported.ssp"
    assert main(["ssp", "export", str(SHIPPED), "--out", str(archive)]) == 0
    return archive


def rewrite(archive: Path, out: Path, **edits) -> Path:
    """A copy of `archive` with members replaced: name (with '/' as '__') -> function of the text
    (bytes for a .fmu)."""
    replaced = {name.replace("__", "/"): edit for name, edit in edits.items()}
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as target:
        for info in source.infolist():
            data = source.read(info)
            if info.filename in replaced:
                edit = replaced[info.filename]
                data = edit(data) if info.filename.endswith(".fmu") else edit(data.decode()).encode()
            target.writestr(info.filename, data)
    return out


@pytest.mark.parametrize("name", ["../../etc/hostname", "/etc/passwd", "resources/../../../etc/passwd"])
def test_the_scenario_of_an_exported_ssp_must_be_inside_it(name, exported, tmp_path, capsys):
    def edit(text: str) -> str:
        return text.replace(f'scenario="{SCENARIO}"', f'scenario="{name}"')

    archive = rewrite(exported, tmp_path / "outside.ssp", **{"SystemStructure.ssd": edit})
    line = refuses(capsys, archive)
    assert line == (
        "SystemStructure.ssd: annotation org.navcosim.scenario: needs an nc:Scenario whose scenario "
        f"attribute names a file in the archive (got '{name}')"
    )


def test_the_map_of_an_exported_ssp_must_be_inside_it(exported, tmp_path, capsys):
    outside = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()

    def ssd_edit(text: str) -> str:
        return re.sub(r'\s*<nc:Set value="map.file=[^"]*" />', "", text)

    def toml_edit(text: str) -> str:
        return text.replace('file = "maps/warehouse.yaml"', f'file = "{outside}"')

    archive = rewrite(
        exported, tmp_path / "map.ssp", **{"SystemStructure.ssd": ssd_edit, SCENARIO: toml_edit}
    )
    line = refuses(capsys, archive)
    assert line == (
        f"{SCENARIO}: the map file '{outside}' is not in the archive; an archive's scenario may name "
        "only files inside it"
    )


def test_the_image_of_an_exported_ssps_map_must_be_inside_it(exported, tmp_path, capsys):
    def yaml_edit(text: str) -> str:
        return re.sub(r"(?m)^image:.*$", "image: ../../../../etc/hostname", text)

    archive = rewrite(exported, tmp_path / "image.ssp", **{"resources/navcosim/warehouse.yaml": yaml_edit})
    line = refuses(capsys, archive)
    assert line.startswith(
        f"{SCENARIO}: the image of the map 'warehouse.yaml' is not beside it in the archive"
    )


@pytest.mark.slow
def test_the_output_log_of_an_exported_ssp_is_not_followed(exported, tmp_path, monkeypatch):
    elsewhere = tmp_path / "elsewhere" / "chosen.mcap"

    def toml_edit(text: str) -> str:
        return text + f'\n[output]\nlog = "{elsewhere}"\n'

    archive = rewrite(exported, tmp_path / "log.ssp", **{SCENARIO: toml_edit})
    monkeypatch.chdir(tmp_path)
    scenario, result = run_ssp(archive, None, ["simulation.stop_time=0.5"])
    assert not elsewhere.exists() and not elsewhere.parent.exists()
    assert result.log_path.resolve().parent == (tmp_path / "logs").resolve()
    assert open_log(result.log_path).metadata["navcosim"]["scenario_name"] == scenario.name


def test_an_exported_ssp_runs_only_the_projects_own_fmus_in_process(exported, tmp_path):
    from cosim.ssp.export import scenario_of

    def repack(data: bytes) -> bytes:
        import io

        buffer = io.BytesIO()
        with zipfile.ZipFile(io.BytesIO(data)) as source, zipfile.ZipFile(buffer, "w") as target:
            for info in source.infolist():
                target.writestr(info, source.read(info))
            target.comment = b"not the project's bytes"
        return buffer.getvalue()

    archive = rewrite(exported, tmp_path / "foreign.ssp", **{"resources/vehicle.fmu": repack})
    with zipfile.ZipFile(archive) as zipped:
        assert "vehicle.isolation=&quot;none&quot;" in zipped.read("SystemStructure.ssd").decode()
    with open_ssp(archive) as ssp:
        scenario = scenario_of(ssp, {})
        where = {name: scenario.isolation(spec) for name, spec in scenario.components.items()}
        assert where == {"vehicle": "process", "pure_pursuit": "none", "vfh": "none", "mixer": "none"}
        scenario = scenario_of(ssp, {"fmu_isolation": "none"})  # the user's word
        assert {scenario.isolation(spec) for spec in scenario.components.values()} == {"none"}
        scenario = scenario_of(ssp, {"fmu_isolation": "auto"})
        where = {name: scenario.isolation(spec) for name, spec in scenario.components.items()}
        assert where == {"vehicle": "process", "pure_pursuit": "none", "vfh": "none", "mixer": "none"}


def test_an_exported_ssp_cannot_raise_the_limits_of_its_run(exported, tmp_path, capsys):
    from cosim.ssp.export import scenario_of

    def toml_edit(text: str) -> str:
        raised = "fmu_timeout = 1e6\nfmu_max_size = 1e6\nmax_steps = 1_000_000_000_000"
        text = text.replace("[simulation]", f"[simulation]\n{raised}", 1)
        return re.sub(r"(?m)^stop_time = .*$", "stop_time = 1e7", text)

    archive = rewrite(exported, tmp_path / "limits.ssp", **{SCENARIO: toml_edit})
    line = refuses(capsys, archive)
    assert "stop_time" in line and "above max_steps = 1e+08" in line, line
    with open_ssp(archive) as ssp:
        scenario = scenario_of(ssp, {"stop_time": 10})
        assert (scenario.fmu_timeout, scenario.fmu_max_size) == (10.0, 1024.0)
        scenario = scenario_of(ssp, {"stop_time": 10, "fmu_timeout": 60, "fmu_max_size": 2048})
        assert (scenario.fmu_timeout, scenario.fmu_max_size) == (60, 2048)


def test_an_fmu_inside_an_ssp_is_held_to_the_same_limits(tmp_path, capsys):
    own = cosim.builtin_fmu("DifferentialDrive")
    padded, crowded = tmp_path / "padded.fmu", tmp_path / "crowded.fmu"
    for path, extra in ((padded, {"resources/padding.bin": bytes(2 * MIB)}), (crowded, None)):
        extra = extra or {f"resources/{i}": b"" for i in range(MAX_ENTRIES)}
        with zipfile.ZipFile(own) as source, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as target:
            for info in source.infolist():
                target.writestr(info, source.read(info))
            for name, data in extra.items():
                target.writestr(name, data)
    archive = pack(tmp_path / "padded.ssp", ssd(robot()), {"models/robot.fmu": padded})
    assert archive.stat().st_size < MIB  # the archive itself is within 1.5 MiB
    line = refuses(capsys, archive, "--set", "simulation.fmu_max_size=1.5")
    assert line.startswith("SystemStructure.ssd: element 'robot': FMU 'models/robot.fmu' would unpack to "), (
        line
    )
    assert "more than the limit of 1.5 MiB" in line
    assert run_ssp(archive, tmp_path / "padded.mcap", ["simulation.fmu_max_size=3"]).failure is None
    archive = pack(tmp_path / "crowded.ssp", ssd(robot()), {"models/robot.fmu": crowded})
    line = refuses(capsys, archive)
    with zipfile.ZipFile(crowded) as zipped:
        entries = len(zipped.infolist())
    assert line == (
        f"SystemStructure.ssd: element 'robot': FMU 'models/robot.fmu' has {entries:,} entries, more than "
        f"the limit of {MAX_ENTRIES:,}; not extracted"
    )


def fault_scenario(tmp_path: Path, fault: str) -> Path:
    """The shipped one-obstacle scenario, 4 s long, with the fault FMU (a path) as its vehicle, its
    fault due at 2 s."""
    text = SHIPPED.read_text()
    text = text.replace(
        'file = "maps/warehouse.yaml"', f'file = "{SHIPPED.parent / "maps" / "warehouse.yaml"}"'
    )
    start = text.index("[vehicle]")
    end = text.index("\n[", start + 1)
    section = f"""[vehicle]
fmu = "{fixture_fmu("fault_fmi2")}"
type = "differential"
radius = 0.5
fault = {FAULTS.index(fault)}
fault_time = 2.0
"""
    text = re.sub(r"(?m)^stop_time = .*$", "stop_time = 4.0", text[:start] + section + text[end:])
    path = tmp_path / f"{fault}.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_an_exported_ssp_that_says_in_process_runs_a_foreign_fmu_in_a_child_process(tmp_path):
    """A segfault of the vehicle, which the archive (edited) says to run in-process: exit code 2 and
    one line naming the archive and the signal, not a dead process (exit code 139)."""
    import subprocess
    import sys

    exported = tmp_path / "fault.ssp"
    assert main(["ssp", "export", str(fault_scenario(tmp_path, "segfault")), "--out", str(exported)]) == 0

    def in_process(text: str) -> str:
        assert "vehicle.isolation=&quot;process&quot;" in text  # as the scenario ran it
        return text.replace("vehicle.isolation=&quot;process&quot;", "vehicle.isolation=&quot;none&quot;")

    archive = rewrite(exported, tmp_path / "in_process.ssp", **{"SystemStructure.ssd": in_process})
    log_path = tmp_path / "in_process.mcap"
    argv = [
        sys.executable,
        "-m",
        "cosim",
        "run",
        str(archive),
        "--out",
        str(log_path),
        "--quiet",
        "--no-plot",
    ]
    done = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path, check=False)
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, (done.returncode, done.stderr[-2000:])
    assert lines[0].startswith(f"cosim: error: {archive}: ")
    assert "crashed with signal 11 (SIGSEGV, Segmentation fault) in fmi2DoStep at t = 2" in lines[0]
    outcome = open_log(log_path).metadata["outcome"]
    assert outcome["reason"] == "fmu_failed" and "SIGSEGV" in outcome["failure"]
