"""FMUs in a child process (`IsolatedFmuComponent`): the same values and messages as in-process,
and every fault of the fault-injection FMU reported as a `CosimError` that names the FMU, the call,
the simulation time and what happened, with the child gone afterwards.

The truth for "the same" is the in-process `FmuComponent` on the same FMU: isolation must not change
a single bit of a trajectory or a character of an FMU's own error message. The truth for a crash is
the child's wait status as the kernel reports it (the signal number of SIGSEGV/SIGABRT, exit status
0 for exit()).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from fixtures.build_fixtures import FAULTS
from fixtures.conftest_helpers import fixture_fmu

from cosim.core.component import State
from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.fmi.builtin import builtin_fmu
from cosim.fmi.component import FmuComponent
from cosim.fmi.isolated import IsolatedFmuComponent

STEP = 0.1  # [s]
FAULT_TIME = 0.3  # [s]: the doStep starting at t = 0.3 (the 4th) faults
POSE = ("x", "y", "theta")


def closed_loop(kind: type, vehicle_path, controller_kind: type | None = None) -> tuple[System, object]:
    """DifferentialDrive-like vehicle and the go-to-goal controller fixture, 1 ms macro step."""
    system = System(0.001)
    vehicle = system.add(kind(vehicle_path, "vehicle", feedthrough_override={name: [] for name in POSE}))
    controller = (controller_kind or kind)(
        fixture_fmu("controller_fmi2"), "controller", {"goal_x": 5.0, "goal_y": 3.0}
    )
    system.add(controller)
    for name in POSE:
        system.connect(f"vehicle.{name}", f"controller.{name}")
    system.connect("controller.v", "vehicle.v")
    system.connect("controller.omega", "vehicle.omega")
    return system, vehicle


def recorded(system: System, steps: int) -> list[np.ndarray]:
    """Every component's inputs and outputs after each of `steps` steps (Python loop)."""
    rows: list[list[np.ndarray]] = []
    with Master(system) as master:
        master.initialize()
        master.run_recorded(steps, lambda first, count, histories: rows.append(histories), compiled=False)
    return [np.concatenate([block[i] for block in rows]) for i in range(len(rows[0]))]


@pytest.mark.parametrize("split", ["both", "vehicle only"])
def test_isolated_closed_loop_is_bit_identical_to_in_process(split):
    path = builtin_fmu("DifferentialDrive")
    reference = recorded(closed_loop(FmuComponent, path)[0], 3000)
    other = FmuComponent if split == "vehicle only" else IsolatedFmuComponent
    isolated = recorded(closed_loop(IsolatedFmuComponent, path, other)[0], 3000)
    for expected, actual in zip(reference, isolated, strict=True):
        np.testing.assert_array_equal(actual, expected)
    assert reference[0].shape[0] == 3000
    assert max(np.ptp(history, axis=0).max() for history in reference) > 0.5  # it drove [m]


def test_fmi3_integer_and_boolean_outputs_cross_the_process_boundary():
    """FMI 3.0 fixture with Int32 `steps` and Boolean `moving`: lifecycle, set_inputs, states."""
    outputs = []
    for kind in (FmuComponent, IsolatedFmuComponent):
        vehicle = kind(fixture_fmu("diffdrive_fmi3"), "vehicle")
        try:
            vehicle.instantiate()
            vehicle.setup(0.0, {"x0": 1.0, "y0": -2.0, "theta0": 0.4})
            vehicle.set_inputs([0, 1], [0.8, 0.5])  # before initialisation: sent with it
            vehicle.initialize()
            for k in range(25):
                vehicle.do_step(k * 0.01, 0.01)
            vehicle.set_inputs([0], [0.0])
            vehicle.do_step(0.25, 0.01)
            outputs.append(
                dict(zip([p.name for p in vehicle.outputs], vehicle.get_outputs().tolist(), strict=True))
            )
            assert vehicle.state is State.STEPPING
            vehicle.terminate()
        finally:
            vehicle.free()
        assert vehicle.state is State.FREED
    assert outputs[1] == outputs[0]
    assert outputs[0]["steps"] == 26.0 and outputs[0]["moving"] == 0.0


def test_port_map_errors_come_before_any_process():
    with pytest.raises(CosimError, match="has no variable 'speed'") as error:
        IsolatedFmuComponent(fixture_fmu("diffdrive_fmi2"), "vehicle", port_map={"v": "speed"})
    assert "process" not in str(error.value)


def fault_vehicle(kind: type, fault: str, timeout: float = 10.0):
    """The fault FMU at constant v, omega, stepped up to its fault; returns (component, error)."""
    options = {"timeout": timeout} if kind is IsolatedFmuComponent else {}
    vehicle = kind(fixture_fmu("fault_fmi2"), "vehicle", **options)
    vehicle.instantiate()
    vehicle.setup(0.0, {"fault": FAULTS.index(fault), "fault_time": FAULT_TIME})
    vehicle.set_inputs([0, 1], [1.0, 0.5])
    vehicle.initialize()
    try:
        for k in range(10):
            vehicle.do_step(round(k * STEP, 9), STEP)
            vehicle.get_outputs()
    except CosimError as error:
        return vehicle, error
    return vehicle, None


def child_gone(pid: int) -> bool:
    """The child was reaped: no process with that id, or (reused id) not our child any more."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    with open(f"/proc/{pid}/stat") as stat:
        return int(stat.read().rsplit(")", 1)[1].split()[1]) != os.getpid()


@pytest.mark.parametrize(
    ("fault", "happened"),
    [
        ("segfault", f"crashed with signal {int(signal.SIGSEGV)} (SIGSEGV, Segmentation fault)"),
        ("abort", f"crashed with signal {int(signal.SIGABRT)} (SIGABRT, Aborted)"),
        ("exit", "ended its process with exit status 0 (exit() inside the FMU)"),
    ],
)
def test_a_crashing_fmu_ends_its_child_not_the_host(fault, happened):
    vehicle, error = fault_vehicle(IsolatedFmuComponent, fault)
    pid = vehicle.pid
    assert error is not None
    assert vehicle.state is State.FAILED
    assert str(error) == (
        f"FMU 'vehicle' (model fixture_fault_fmi2, process {pid}) {happened} in fmi2DoStep at t = 0.3 s"
    )
    outputs = vehicle.output_buffer.copy()
    vehicle.free()  # safe after the crash
    assert child_gone(pid)
    # The shared outputs still hold the last completed step's: the pose at t = 0.3 s, bit for bit.
    reference = FmuComponent(fixture_fmu("fault_fmi2"), "vehicle")
    reference.instantiate()
    reference.setup(0.0, {"fault_time": FAULT_TIME})
    reference.set_inputs([0, 1], [1.0, 0.5])
    reference.initialize()
    for k in range(3):
        reference.do_step(round(k * STEP, 9), STEP)
    np.testing.assert_array_equal(outputs, reference.get_outputs())
    reference.free()


def test_a_hung_fmu_is_killed_after_the_timeout():
    """The hang fault ignores SIGINT and SIGTERM; the host's timeout kills it anyway (SIGKILL)."""
    vehicle, error = fault_vehicle(IsolatedFmuComponent, "hang", timeout=0.5)
    pid = vehicle.pid
    assert error is not None and vehicle.state is State.FAILED
    assert str(error) == (
        f"FMU 'vehicle' (model fixture_fault_fmi2, process {pid}) did not return from fmi2DoStep "
        "at t = 0.3 s within 0.5 s (fmu_timeout); its process was killed"
    )
    assert child_gone(pid)  # killed and reaped before the error was raised
    vehicle.free()


@pytest.mark.parametrize("fault", ["nan", "error", "fatal", "discard"])
def test_fmu_reported_failures_read_the_same_in_a_child(fault):
    """Status errors and NaN outputs are raised by the child's FmuComponent: the same message, the
    same state (Error and Fatal fail the instance, Discard does not) as in-process."""
    local, local_error = fault_vehicle(FmuComponent, fault)
    isolated, isolated_error = fault_vehicle(IsolatedFmuComponent, fault)
    try:
        assert local_error is not None and str(isolated_error) == str(local_error)
        assert isolated.state is local.state
        assert "at t = 0.3 s" in str(local_error)
        np.testing.assert_array_equal(isolated.output_buffer, local.output_buffer)
    finally:
        pid = isolated.pid
        for component in (local, isolated):
            if component.state in (State.SET_UP, State.STEPPING):
                component.terminate()
            component.free()
    assert child_gone(pid)
    expected = {
        "nan": "output 'x' is NaN after fmi2DoStep",
        "error": "returned fmi2Error from fmi2DoStep",
        "fatal": "returned fmi2Fatal from fmi2DoStep",
        "discard": "returned fmi2Discard from fmi2DoStep",
    }[fault]
    assert expected in str(local_error)


def test_master_stops_on_a_crash_and_closes_the_rest():
    """A segfault inside the master's loop: the step index stays at the failed step, close()
    terminates and frees the healthy component, and both children are gone."""
    system = System(STEP)
    vehicle = system.add(IsolatedFmuComponent(fixture_fmu("fault_fmi2"), "vehicle"))
    driver = system.add(IsolatedFmuComponent(fixture_fmu("diffdrive_fmi2"), "other"))
    parameters = {"vehicle": {"fault": FAULTS.index("segfault"), "fault_time": FAULT_TIME}}
    master = Master(system, parameters=parameters)
    master.initialize()
    pids = vehicle.pid, driver.pid
    with pytest.raises(CosimError, match=r"SIGSEGV.* in fmi2DoStep at t = 0.3 s"):
        master.run(10)
    assert master.step_index == 3
    master.close()
    assert driver.state is State.FREED and vehicle.state is State.FREED
    assert all(child_gone(pid) for pid in pids)


HOST = """
import sys, time
sys.path[:0] = {paths!r}
from cosim.fmi.isolated import IsolatedFmuComponent
vehicle = IsolatedFmuComponent({path!r}, "vehicle", timeout=600)
vehicle.instantiate()
vehicle.setup(0.0, {{"fault": {fault}, "fault_time": 0.0}})
vehicle.initialize()
print(vehicle.pid, flush=True)
vehicle.do_step(0.0, 0.1)  # hangs, deaf to SIGTERM
"""


@pytest.mark.slow
def test_a_hung_child_dies_with_its_host():
    """The host is killed (SIGKILL: no cleanup at all) while its child hangs in doStep: the kernel
    kills the child too (PR_SET_PDEATHSIG), so no hung FMU outlives a run."""
    code = HOST.format(
        paths=[p for p in sys.path if p], path=str(fixture_fmu("fault_fmi2")), fault=FAULTS.index("hang")
    )
    host = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], stdout=subprocess.PIPE, text=True)
    pid = int(host.stdout.readline())
    assert os.path.exists(f"/proc/{pid}")
    host.kill()
    host.wait()
    for _ in range(1000):  # the kernel kills it at once; 10 ms polls leave a loaded machine 10 s
        try:
            with open(f"/proc/{pid}/stat") as stat:
                if stat.read().rsplit(")", 1)[1].split()[0] == "Z":
                    break  # dead, waiting for init to reap it
        except FileNotFoundError:
            break
        time.sleep(0.01)
    else:
        pytest.fail(f"child {pid} still runs after its host was killed")
