"""Bad input to `cosim run`: one line naming the problem, exit 2, no traceback, no log left behind.

The corpus in `tests/scenario_corpus/` holds one malformed scenario per file; its first line says
what the error must contain (`# expect: ...`). FMU-file cases (corrupt zip, no binary for this
platform, model-exchange only, unknown variable names) are made from a project FMU at test time.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cosim.cli import main

CORPUS = Path(__file__).resolve().parents[1] / "scenario_corpus"
CASES = sorted(CORPUS.glob("*.toml"))
REPO = Path(__file__).resolve().parents[2]


def expected_message(path: Path) -> str:
    first = path.read_text().splitlines()[0]
    assert first.startswith("# expect: "), path
    return first[len("# expect: ") :]


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_bad_input(code: int, err: str, expect: str, scenario: Path, log: Path) -> None:
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("cosim: error: "), err
    assert str(scenario) in lines[0], err
    assert expect in lines[0], err
    assert "Traceback" not in err
    assert not log.exists()
    assert not list(log.parent.glob("*.mcap")), "no log, marked or not, is left for bad input"


def test_corpus_is_large_enough():
    assert len(CASES) >= 30


@pytest.mark.parametrize("scenario", CASES, ids=[path.stem for path in CASES])
def test_malformed_scenario(scenario: Path, tmp_path: Path, capsys):
    log = tmp_path / "run.mcap"
    code, _, err = run_cli(["run", str(scenario), "--out", str(log), "--quiet", "--no-plot"], capsys)
    assert_bad_input(code, err, expected_message(scenario), scenario, log)


def _rewrite_fmu(source: Path, target: Path, drop_prefix: str | None = None, edit_xml=None) -> Path:
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(target, "w") as copy:
        for item in original.infolist():
            if drop_prefix and item.filename.startswith(drop_prefix):
                continue
            data = original.read(item.filename)
            if item.filename == "modelDescription.xml" and edit_xml is not None:
                data = edit_xml(data.decode()).encode()
            copy.writestr(item, data)
    return target


def _model_exchange_only(xml: str) -> str:
    start = xml.index("<CoSimulation")
    end = xml.index("/>", start) + 2
    return xml[:start] + '<ModelExchange modelIdentifier="DifferentialDrive"/>' + xml[end:]


def _scenario_with_vehicle(tmp_path: Path, fmu: Path, ports: str = "") -> Path:
    base = (CORPUS / "stop_time_zero.toml").read_text().split("\n", 1)[1]
    base = base.replace("stop_time = 0.0", "stop_time = 5.0").replace(
        "../../scenarios", str(REPO / "scenarios")
    )
    base = base.replace('fmu = "DifferentialDrive"', f'fmu = "{fmu}"\ntype = "differential"{ports}')
    path = tmp_path / f"{fmu.stem}.toml"
    path.write_text(base)
    return path


@pytest.fixture(scope="module")
def project_fmu() -> Path:
    from cosim.fmi.builtin import builtin_fmu

    return builtin_fmu("DifferentialDrive")


@pytest.mark.parametrize(
    "case, expect",
    [
        ("corrupt_zip", "[vehicle].fmu"),
        ("no_platform_binary", "[vehicle].fmu"),
        ("model_exchange_only", "[vehicle].fmu"),
        ("unknown_variable", "has no variable 'speed_command' (mapped to port 'v')"),
    ],
)
def test_bad_fmu_file(case: str, expect: str, project_fmu: Path, tmp_path: Path, capsys):
    fmu_dir = tmp_path / "fmus"
    fmu_dir.mkdir()
    ports = ""
    if case == "corrupt_zip":
        fmu = fmu_dir / "corrupt.fmu"
        fmu.write_bytes(b"PK\x03\x04 this is not a zip archive")
    elif case == "no_platform_binary":
        fmu = _rewrite_fmu(project_fmu, fmu_dir / "nobinary.fmu", drop_prefix="binaries/")
    elif case == "model_exchange_only":
        fmu = _rewrite_fmu(project_fmu, fmu_dir / "me_only.fmu", edit_xml=_model_exchange_only)
    else:
        fmu = fmu_dir / "renamed.fmu"
        shutil.copy(project_fmu, fmu)
        ports = '\nports = { v = "speed_command" }'
    scenario = _scenario_with_vehicle(tmp_path, fmu, ports)
    log = tmp_path / "logs" / "run.mcap"
    code, _, err = run_cli(["run", str(scenario), "--out", str(log), "--quiet", "--no-plot"], capsys)
    assert_bad_input(code, err, expect, scenario, log)


def test_bad_override_names_the_key(tmp_path: Path, capsys):
    scenario = REPO / "scenarios" / "example_commented.toml"
    log = tmp_path / "run.mcap"
    code, _, err = run_cli(
        ["run", str(scenario), "--out", str(log), "--quiet", "--set", "vfh.robot_radius=-0.6"], capsys
    )
    assert_bad_input(code, err, "[vfh].robot_radius: must be >= 0, got -0.6", scenario, log)


@pytest.mark.slow
def test_bad_input_subprocess_has_no_traceback(tmp_path: Path):
    """The installed entry point, as a user runs it."""
    scenario = CORPUS / "histogram_thresholds_order.toml"
    log = tmp_path / "run.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(scenario), "--out", str(log)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 2
    assert completed.stderr.strip().splitlines() == [
        f"cosim: error: {scenario}: [vfh].histogram_thresholds: low 12 > high 10"
    ]
    assert not log.exists()


def test_override_sets_an_item_of_a_list(tmp_path: Path, capsys):
    # Found by the scenario mutator: `--set vfh.distance_limits.1=2` once said "give an item index".
    scenario = REPO / "scenarios" / "example_commented.toml"
    log = tmp_path / "run.mcap"
    code, _, err = run_cli(
        ["run", str(scenario), "--out", str(log), "--quiet", "--set", "vfh.distance_limits.1=2"], capsys
    )
    assert_bad_input(code, err, "[vfh].distance_limits: low 3.5 > high 2", scenario, log)


def test_override_of_a_list_item_out_of_range(tmp_path: Path, capsys):
    scenario = REPO / "scenarios" / "example_commented.toml"
    code, _, err = run_cli(["system", str(scenario), "--set", "vfh.distance_limits.2=25"], capsys)
    assert code == 2
    assert err.splitlines() == [
        "cosim: error: --set vfh.distance_limits.2=25: no item 2 in vfh.distance_limits (items 0 to 1)"
    ]


def test_the_world_check_comes_apart_from_the_file():
    """`load_scenario(check_world=False)` accepts a start inside the unknown obstacle;
    `check_scenario_world` then says what `load_scenario` says of it."""
    from cosim.errors import CosimError
    from cosim.scenario.load import check_scenario_world, load_scenario

    path = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
    overrides = ["start.x=60.0", "start.y=19.25"]  # the centre of its [[obstacles]] box
    with pytest.raises(CosimError) as whole:
        load_scenario(path, overrides)
    scenario = load_scenario(path, overrides, check_world=False)
    with pytest.raises(CosimError) as apart:
        check_scenario_world(scenario)
    assert str(apart.value) == str(whole.value) and "[start]" in str(whole.value)


def test_project_fmus_come_in_the_order_a_run_reads_them():
    """A first run builds the project FMUs in the order the system description reads them."""
    from cosim.scenario.compose import describe_system
    from cosim.scenario.load import load_scenario

    scenario = load_scenario(REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml")
    described = [name for name in describe_system(scenario).components if name in scenario.components]
    assert scenario.project_fmus == [scenario.components[name].fmu for name in described]
    assert scenario.project_fmus[-1] == "DifferentialDrive"
