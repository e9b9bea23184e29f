"""FMI 1.0 co-simulation FMUs (`diffdrive_fmi1`, functions prefixed by the model identifier, no
setup step, fmiInitializeSlave taking the start time) as components, checked against fmpy's own
FMI 1.0 simulation, in a scenario and under `cosim fmu simulate`."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.master import Master
from cosim.core.system import System
from cosim.fmi.component import FmuComponent
from cosim.logs.reader import open_log

ROOT = Path(__file__).resolve().parents[2]
START = {"x0": 0.5, "theta0": 0.25, "v": 1.0, "omega": 0.5}


def _reference():
    return fmpy.simulate_fmu(
        str(fixture_fmu("diffdrive_fmi1")), stop_time=2, output_interval=0.05, start_values=START
    )


def test_an_fmi1_fmu_runs_as_fmpy_runs_it():
    system = System(0.05)
    vehicle = system.add(
        FmuComponent(fixture_fmu("diffdrive_fmi1"), "vehicle", parameters={"x0": 0.5, "theta0": 0.25})
    )
    vehicle.input_buffer[:] = [START["v"], START["omega"]]
    with Master(system) as master:
        master.initialize()
        master.run(40)
        assert vehicle.describe()["fmi_version"] == "1.0"
    outputs = dict(zip([p.name for p in vehicle.outputs], vehicle.output_buffer.tolist(), strict=True))
    last = _reference()[-1]
    for name in ("x", "y", "theta"):
        assert outputs[name] == pytest.approx(last[name], rel=0, abs=1e-12), name
    assert outputs["steps"] == last["steps"] == 40 and outputs["moving"] == 1.0


@pytest.mark.slow
def test_an_fmi1_fmu_runs_under_fmu_simulate(tmp_path):
    command = [sys.executable, "-m", "cosim", "fmu", "simulate", str(fixture_fmu("diffdrive_fmi1"))]
    command += [
        "--stop-time",
        "2",
        "--step",
        "0.05",
        "--start-values",
        *(f"{k}={v}" for k, v in START.items()),
    ]
    command += ["--csv", str(tmp_path / "out.csv"), "--out", str(tmp_path / "out.mcap"), "--quiet"]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert completed.returncode == 0, completed.stderr
    ours = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    reference = _reference()
    assert len(ours) == len(reference) == 41
    for name in ("time", "x", "y", "theta"):
        np.testing.assert_allclose(ours[name], reference[name], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_an_fmi1_fmu_runs_in_a_scenario(tmp_path):
    """A [components.twin] FMI 1.0 differential drive fed the mixer's commands tracks the vehicle
    (the project's FMI 2.0 DifferentialDrive, the same kinematics) to rounding."""
    text = (ROOT / "scenarios" / "warehouse_diff_drive_no_obstacle.toml").read_text()
    text = text.replace('"maps/warehouse.yaml"', f'"{ROOT / "scenarios" / "maps" / "warehouse.yaml"}"')
    text += (
        f'\n[components.twin]\nfmu = "{fixture_fmu("diffdrive_fmi1")}"\nx0 = 6.0\ny0 = 6.0\n'
        '\n[[connections]]\nfrom = "mixer.v"\nto = "twin.v"\n'
        '\n[[connections]]\nfrom = "mixer.omega"\nto = "twin.omega"\n'
    )
    scenario = tmp_path / "fmi1.toml"
    scenario.write_text(text)
    command = [sys.executable, "-m", "cosim", "run", str(scenario), "--out", str(tmp_path / "run.mcap")]
    command += ["--no-plot", "--quiet", "--set", "simulation.stop_time=5"]
    completed = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert completed.returncode in (0, 1), completed.stderr  # goal reached or not: no failure
    with open_log(tmp_path / "run.mcap") as log:
        assert log.fmus["twin"]["fmi_version"] == "1.0"
        twin, vehicle = log.signals("twin"), log.signals("vehicle")
        assert twin["steps"][-1] == 500 and abs(twin["x"][-1] - 6.0) > 5  # it drove
        np.testing.assert_allclose(twin["x"], vehicle["x"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(twin["y"], vehicle["y"], rtol=0, atol=1e-9)


def test_an_fmi1_fmu_of_reals_steps_in_the_compiled_kernel_as_in_python():
    def run(compiled: bool) -> list[float]:
        system = System(0.05)
        vehicle = system.add(FmuComponent(fixture_fmu("diffdrive_plain_fmi1"), "vehicle"))
        vehicle.input_buffer[:] = [START["v"], START["omega"]]
        with Master(system) as master:
            master.initialize()
            if compiled:
                assert all(native is not None for native in master.kernel_tables().native)
            master.run(40, compiled=compiled)
        return vehicle.output_buffer.tolist()

    assert run(True) == run(False)
