"""`cosim fmu info` and `cosim fmu validate` on an FMI 3.0 co-simulation FMU built outside our build."""

from fixtures.conftest_helpers import fixture_fmu

from cosim.cli import main


def test_info_lists_an_fmi3_fmus_variables(capsys):
    path = fixture_fmu("diffdrive_fmi3")
    assert main(["fmu", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "FMI version:     3.0" in out
    rows = {line.split()[0]: line.split()[1:4] for line in out.splitlines()[1:] if line.strip()}
    assert rows["v"] == ["input", "continuous", "Float64"]
    assert rows["x"] == ["output", "continuous", "Float64"]
    assert rows["steps"] == ["output", "discrete", "Int32"]
    assert rows["moving"] == ["output", "discrete", "Boolean"]


def test_validate_accepts_a_valid_fmi3_fmu(capsys):
    assert main(["fmu", "validate", str(fixture_fmu("diffdrive_fmi3"))]) == 0
    assert "problem" not in capsys.readouterr().out


def test_validate_reports_an_fmi3_fmu_with_a_broken_structure(tmp_path, capsys):
    """The check is real: drop the InitialUnknowns from a valid FMU and validation fails (exit 1)."""
    import zipfile

    source = fixture_fmu("diffdrive_fmi3")
    broken = tmp_path / "broken_fmi3.fmu"
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(broken, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                text = "\n".join(line for line in text.splitlines() if "<InitialUnknown " not in line)
                data = text.encode()
            zout.writestr(item, data)
    assert main(["fmu", "validate", str(broken)]) == 1
    assert "InitialUnknowns" in capsys.readouterr().out
