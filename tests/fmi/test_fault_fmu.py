"""The fault-injection fixture FMU (`fault_fmi2`, tests/fixtures): each fault does what it says.

A vehicle with DifferentialDrive's ports that, at the first doStep reaching `fault_time`, crashes,
aborts, exits, hangs, outputs NaN or returns an error status. The faults that end the process run
in a child Python stepping the FMU through fmpy; the others run here, where fmpy's exception can
be inspected.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

STEP = 0.1
FAULT_TIME = 0.3  # the 4th doStep (t = 3 x 0.1) is the first to reach it
V, OMEGA = 1.0, 0.5
START = (0.5, -1.0, 0.25)

# Child: step the FMU with fmpy, announcing each doStep before the call and after it (flushed,
# since exit() inside the FMU skips Python's own buffers). argv: unzipped dir, fault index,
# fault_time, v, omega, step size.
CHILD = """
import sys
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
directory, fault = sys.argv[1], int(sys.argv[2])
fault_time, v, omega, step = map(float, sys.argv[3:])
description = read_model_description(directory)
vr = {variable.name: variable.valueReference for variable in description.modelVariables}
fmu = FMU2Slave(guid=description.guid, unzipDirectory=directory,
                modelIdentifier=description.coSimulation.modelIdentifier, instanceName="child")
fmu.instantiate()
fmu.setupExperiment(startTime=0.0)
fmu.enterInitializationMode()
fmu.setReal([vr["fault_time"], vr["v"], vr["omega"]], [fault_time, v, omega])
fmu.setInteger([vr["fault"]], [fault])
fmu.exitInitializationMode()
t = 0.0
for _ in range(10):
    print("before", repr(t), flush=True)
    fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
    t += step
    print("after", repr(t), flush=True)
print("done", flush=True)
"""


@pytest.fixture(scope="module")
def unzipped(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp("fault_fmu")
    extract(str(fixture_fmu("fault_fmi2")), str(directory))
    return directory


def pose_at(t: float) -> tuple[float, float, float]:
    """Closed-form pose of the unicycle after t seconds at constant V, OMEGA from START."""
    x0, y0, theta0 = START
    theta = theta0 + OMEGA * t
    return (
        x0 + V / OMEGA * (math.sin(theta) - math.sin(theta0)),
        y0 - V / OMEGA * (math.cos(theta) - math.cos(theta0)),
        theta,
    )


class Vehicle:
    """The fault FMU in this process, started at START with constant V, OMEGA; `fault` is a name of
    FAULTS or the raw enumeration value."""

    def __init__(self, directory: Path, fault: str | int) -> None:
        description = read_model_description(str(directory))
        self.vr = {v.name: v.valueReference for v in description.modelVariables}
        self.fmu = FMU2Slave(
            guid=description.guid,
            unzipDirectory=str(directory),
            modelIdentifier=description.coSimulation.modelIdentifier,
            instanceName="vehicle",
        )
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        names = ["x0", "y0", "theta0", "v", "omega", "fault_time"]
        self.fmu.setReal([self.vr[n] for n in names], [*START, V, OMEGA, FAULT_TIME])
        self.fmu.setInteger([self.vr["fault"]], [FAULTS.index(fault) if isinstance(fault, str) else fault])
        self.fmu.exitInitializationMode()
        self.time = 0.0

    def step(self) -> None:
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=STEP)
        self.time += STEP

    def pose(self) -> tuple[float, float, float]:
        return tuple(self.fmu.getReal([self.vr["x"], self.vr["y"], self.vr["theta"]]))

    def close(self) -> None:
        self.fmu.freeInstance()


def test_model_description_validates_and_lists_every_fault():
    path = fixture_fmu("fault_fmi2")
    assert validate_fmu(str(path)) == []
    description = read_model_description(str(path))
    fault = next(v for v in description.modelVariables if v.name == "fault")
    assert fault.type == "Enumeration" and fault.causality == "parameter"
    assert [item.name for item in fault.declaredType.items] == list(FAULTS)
    assert {v.name for v in description.modelVariables} >= {
        "x0",
        "y0",
        "theta0",
        "v",
        "omega",
        "x",
        "y",
        "theta",
    }


def test_no_fault_drives_the_exact_arc(unzipped):
    vehicle = Vehicle(unzipped, "none")
    for _ in range(10):
        vehicle.step()
    assert vehicle.pose() == pytest.approx(pose_at(1.0), abs=1e-12)
    vehicle.close()


def test_nan_fault_outputs_nan_from_fault_time_on(unzipped):
    vehicle = Vehicle(unzipped, "nan")
    for _ in range(3):
        vehicle.step()
    assert vehicle.pose() == pytest.approx(pose_at(0.3), abs=1e-12)
    vehicle.step()  # t = 0.3: the fault
    assert all(math.isnan(value) for value in vehicle.pose())
    vehicle.step()
    assert all(math.isnan(value) for value in vehicle.pose())
    vehicle.close()


@pytest.mark.parametrize(("fault", "status"), [("error", 3), ("fatal", 4), ("discard", 2)])
def test_status_faults_make_fmpy_raise_with_that_status(unzipped, fault, status):
    vehicle = Vehicle(unzipped, fault)
    for _ in range(3):
        vehicle.step()
    moved = vehicle.pose()
    assert moved == pytest.approx(pose_at(0.3), abs=1e-12)
    with pytest.raises(FMICallException) as error:
        vehicle.step()
    assert error.value.function == "fmi2DoStep" and error.value.status == status
    assert vehicle.pose() == moved  # a failed step does not move the vehicle
    vehicle.close()


def test_unknown_fault_fails_initialisation(unzipped):
    with pytest.raises(FMICallException) as error:
        Vehicle(unzipped, len(FAULTS))
    assert error.value.function == "fmi2ExitInitializationMode" and error.value.status == 3


def _start_child(unzipped: Path, fault: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, str(unzipped), str(FAULTS.index(fault))]
        + [repr(value) for value in (FAULT_TIME, V, OMEGA, STEP)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.slow
def test_process_ending_faults_in_a_child(unzipped):
    """segfault, abort and exit end the child at the fault step; hang keeps it in that doStep,
    deaf to SIGTERM, until SIGKILL. The four children run at once."""
    children = {fault: _start_child(unzipped, fault) for fault in ("segfault", "abort", "exit", "hang")}
    expected_lines = ["before 0.0", "after 0.1", "before 0.1", "after 0.2", "before 0.2"]
    expected_lines += ["after 0.30000000000000004", "before 0.30000000000000004"]

    hang = children.pop("hang")
    seen = [hang.stdout.readline().strip() for _ in expected_lines]
    assert seen == expected_lines, hang.stderr.read()
    time.sleep(0.3)  # inside the faulting doStep: it does not come back
    assert hang.poll() is None
    hang.send_signal(signal.SIGTERM)
    time.sleep(0.2)
    assert hang.poll() is None  # SIGTERM is ignored
    hang.kill()
    rest, _ = hang.communicate()
    assert hang.returncode == -signal.SIGKILL and rest == ""

    outcomes = {}
    for fault, child in children.items():
        out, err = child.communicate()
        outcomes[fault] = child.returncode
        assert out.split("\n")[:-1] == expected_lines, (fault, out, err)  # ended in the 4th doStep
    assert outcomes == {"segfault": -signal.SIGSEGV, "abort": -signal.SIGABRT, "exit": 0}
