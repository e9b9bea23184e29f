"""Files given to the wrong command get one line that says what the file is and which command
takes it; `cosim system X.ssp` prints the system an SSP archive runs.

The truth: the files are made here (a scenario exported as SSP, a log of a run, a two-FMU SSD
written in the test), so what each holds is known."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

import cosim
from cosim.cli import main
from cosim.errors import file_kind

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
SSP1 = "http://ssp-standard.org/SSP1"
SSD = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="{SSP1}/SystemStructureDescription"
    xmlns:ssc="{SSP1}/SystemStructureCommon" version="1.0" name="pair">
  <ssd:System name="root">
    <ssd:Elements>
      <ssd:Component name="robot" source="models/robot.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="omega" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="x" kind="output"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="theta" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="twin" source="models/robot.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="omega" kind="input"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="robot" startConnector="x" endElement="twin"
          endConnector="v"><ssc:LinearTransformation factor="0.5" offset="0.25"/></ssd:Connection>
      <ssd:Connection startElement="robot" startConnector="theta" endElement="twin" endConnector="omega"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("kinds")
    exported = folder / "exported.ssp"
    assert main(["ssp", "export", str(SCENARIO), "--out", str(exported)]) == 0
    log = folder / "run.mcap"
    assert main(
        ["run", str(SCENARIO), "--out", str(log), "--no-plot", "--set", "simulation.stop_time=0.5"]
    ) in (0, 1)
    plain = folder / "pair.ssp"
    with zipfile.ZipFile(plain, "w") as archive:
        archive.writestr("SystemStructure.ssd", SSD)
        archive.write(cosim.builtin_fmu("DifferentialDrive"), "models/robot.fmu")
    return {"exported": exported, "log": log, "plain": plain, "fmu": cosim.builtin_fmu("DifferentialDrive")}


def test_file_kinds_are_told_apart(files):
    assert file_kind(files["log"]) == "mcap"
    assert file_kind(files["exported"]) == "ssp"
    assert file_kind(files["plain"]) == "ssp"
    assert file_kind(files["fmu"]) == "fmu"
    assert file_kind(SCENARIO) == "text"
    assert file_kind(files["log"].parent / "missing") == "missing"


@pytest.mark.parametrize(
    ("command", "given", "says"),
    [
        (["run"], "log", "is an MCAP log, not a scenario; `cosim log info"),
        (["system"], "log", "is an MCAP log, not a scenario; `cosim log info"),
        (["run"], "fmu", "is an FMU, not a scenario; `cosim fmu inspect"),
        (["log", "info"], "exported", "is an SSP archive, not an MCAP log; `cosim run"),
        (["log", "plot"], "fmu", "is an FMU, not an MCAP log"),
        (["log", "info"], "scenario", "is a scenario file, not an MCAP log; `cosim run"),
    ],
)
def test_a_file_of_another_kind_gets_one_line_naming_the_right_command(files, command, given, says, capsys):
    path = SCENARIO if given == "scenario" else files[given]
    assert main([*command, str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and "codec" not in err[0], err


def test_system_of_a_plain_ssp_lists_its_fmus_connections_and_order(files, capsys):
    assert main(["system", str(files["plain"]), "--set", "simulation.macro_step=0.05"]) == 0
    out = capsys.readouterr().out
    assert "system of pair" in out and "SSP 1.0" in out
    assert "macro step 0.05 s" in out
    assert "connections (2; input = output * factor + offset)" in out
    assert any(line.split()[:4] == ["robot.x", "twin.v", "0.5", "0.25"] for line in out.splitlines())
    rows = [line.split() for line in out.splitlines()]
    assert ["robot", "robot", "models/robot.fmu", "2.0", "co-simulation", "every", "step"] in rows
    order = out.split("step order")[1].split("\n\n")[0].splitlines()[1:]  # (unconnected inputs follow)
    assert [line.split()[1] for line in order] == ["robot", "twin"]  # twin reads robot's outputs


def test_system_of_an_exported_ssp_is_its_scenario_named_by_archive_members(files, capsys):
    assert main(["system", str(files["exported"])]) == 0
    exported = capsys.readouterr().out
    assert main(["system", str(SCENARIO)]) == 0
    scenario = capsys.readouterr().out
    assert "exported scenario in" in exported.splitlines()[0]
    assert "navcosim-ssp" not in exported  # the temporary folder it was unpacked to
    # Same components and the same step order as the scenario it came from.
    assert exported.split("step order")[1] == scenario.split("step order")[1]


def test_png_of_a_plain_ssp_is_refused_in_one_line(files, tmp_path, capsys):
    assert main(["system", str(files["plain"]), "--png", str(tmp_path / "d.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no scenario" in err[0]
    assert not (tmp_path / "d.png").exists()
