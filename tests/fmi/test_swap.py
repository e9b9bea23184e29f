"""Swapping the vehicle FMU: a scenario runs with the project's DifferentialDrive replaced by
(a) the hand-written FMI 3.0 fixture and (b) the FMI 2.0 fixture whose variables have other
names, mapped in the scenario; the driven trajectories agree with the project FMU's within 1e-6.

The fixtures (tests/fixtures/fmu_src, built with `cc` by build_fixtures.py) implement the same
kinematics as the project FMU (exact arcs for constant v, omega) but independently, so agreement
checks both the swap machinery and the two implementations against each other.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.logs import open_log
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
STOP_TIME = 30.0  # [s]: long enough to turn, meet the unknown box and let VFH steer around it


def _scenario_text(vehicle_section: str) -> str:
    """The shipped one-obstacle scenario with an absolute map path and another [vehicle] table."""
    text = SHIPPED.read_text()
    map_file = (SHIPPED.parent / "maps" / "warehouse.yaml").resolve()
    text = re.sub(r'(?m)^file = "maps/warehouse.yaml"', f'file = "{map_file}"', text)
    start = text.index("[vehicle]")
    end = text.index("\n[", start + 1)
    return text[:start] + vehicle_section + text[end:]


PROJECT = """[vehicle]
fmu = "DifferentialDrive"
radius = 0.5
"""

FMI3 = """[vehicle]
fmu = "{path}"
type = "differential"
radius = 0.5
"""

FMI2_RENAMED = """[vehicle]
fmu = "{path}"
type = "differential"
radius = 0.5
ports = {{ x = "pos_x", y = "pos_y", theta = "heading", v = "speed_cmd", omega = "yaw_rate_cmd", \
x0 = "start_x", y0 = "start_y", theta0 = "start_heading" }}
"""


def _run(tmp_path: Path, name: str, vehicle_section: str):
    scenario_path = tmp_path / f"{name}.toml"
    scenario_path.write_text(_scenario_text(vehicle_section))
    scenario = load_scenario(scenario_path, [f"simulation.stop_time={STOP_TIME}", "output.plot=false"])
    log_path = tmp_path / f"{name}.mcap"
    result = run_scenario(scenario, log_path)
    assert result.failure is None
    return result, open_log(log_path)


@pytest.fixture(scope="module")
def project_run(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("swap"), "project", PROJECT)


@pytest.mark.parametrize(
    "kind, section", [("diffdrive_fmi3", FMI3), ("diffdrive_fmi2_renamed", FMI2_RENAMED)]
)
def test_swapped_vehicle_drives_the_same_trajectory(tmp_path, project_run, kind, section):
    reference_result, reference_log = project_run
    result, log = _run(tmp_path, kind, section.format(path=fixture_fmu(kind)))
    expected, actual = reference_log.trajectory(), log.trajectory()
    assert len(actual.t) == len(expected.t) > 1000
    np.testing.assert_array_equal(actual.t, expected.t)
    for axis in ("x", "y", "theta"):
        np.testing.assert_allclose(getattr(actual, axis), getattr(expected, axis), rtol=0, atol=1e-6)
    # The run did something worth comparing: it moved well away from the start.
    assert np.hypot(actual.x[-1] - actual.x[0], actual.y[-1] - actual.y[0]) > 20.0
    assert result.outcome.vfh_interventions == reference_result.outcome.vfh_interventions
    assert result.outcome.distance == pytest.approx(reference_result.outcome.distance, abs=1e-5)
    # The log names the FMU that actually ran.
    assert log.metadata["fmu/vehicle"]["fmu"] == str(fixture_fmu(kind))
