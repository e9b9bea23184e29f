"""The FMI 2.0 glue: state machine, misuse answered by fmi2Error plus a logged message, independence."""

from __future__ import annotations

import pytest
from fmpy.fmi1 import FMICallException
from fmu_harness import Instance

FMI2_ERROR = 3


@pytest.fixture
def drive():
    instance = Instance("DifferentialDrive")
    yield instance
    instance.free()


def _expect_error(instance: Instance, call, *args, message: str) -> None:
    with pytest.raises(FMICallException) as error:
        call(*args)
    assert error.value.status == FMI2_ERROR
    assert message in instance.errors()


def test_do_step_before_initialisation(drive):
    _expect_error(
        drive, drive.slave.doStep, 0.0, 0.1, message="fmi2DoStep is not allowed in state 'instantiated'"
    )


def test_get_before_initialisation(drive):
    _expect_error(drive, drive.slave.getReal, [drive.vr["x"]], message="fmi2GetReal is not allowed")


def test_unknown_value_references(drive):
    drive.initialize()
    _expect_error(drive, drive.slave.getReal, [999], message="unknown Real value reference 999")
    _expect_error(drive, drive.slave.setReal, [0], [1.0], message="unknown Real value reference 0")
    _expect_error(drive, drive.slave.getInteger, [1], message="unknown Integer value reference 1")
    _expect_error(drive, drive.slave.getBoolean, [0], message="unknown Boolean value reference 0")
    _expect_error(drive, drive.slave.getString, [0], message="unknown String value reference 0")
    drive.slave.doStep(0.0, 0.1)  # misuse does not break the instance


def test_lifecycle_order_is_enforced(drive):
    _expect_error(
        drive, drive.slave.exitInitializationMode, message="fmi2ExitInitializationMode is not allowed"
    )
    drive.initialize()
    _expect_error(drive, drive.slave.enterInitializationMode, message="not allowed in state 'step complete'")
    drive.slave.terminate()
    _expect_error(drive, drive.slave.doStep, 0.0, 0.1, message="not allowed in state 'terminated'")
    assert drive.get("x") == [0.0]  # outputs stay readable after terminate


def test_invalid_step_size(drive):
    drive.initialize()
    _expect_error(drive, drive.slave.doStep, 0.0, -0.1, message="invalid step")


def test_unsupported_functions_return_error_with_a_message(drive):
    drive.initialize()
    _expect_error(
        drive,
        drive.slave.getDirectionalDerivative,
        [drive.vr["x"]],
        [drive.vr["v"]],
        [1.0],
        message="fmi2GetDirectionalDerivative is not supported",
    )


def test_model_error_enters_the_error_state_and_reset_recovers(drive):
    drive.slave.setupExperiment(startTime=0.0)
    drive.set(wheel_radius=-0.05)
    drive.slave.enterInitializationMode()
    _expect_error(drive, drive.slave.exitInitializationMode, message="wheel_radius")
    _expect_error(drive, drive.slave.doStep, 0.0, 0.1, message="not allowed in state 'error'")
    drive.slave.reset()
    drive.initialize(v=1.0)
    drive.slave.doStep(0.0, 0.5)
    assert drive.get("x") == pytest.approx([0.5], abs=1e-15)


def test_last_successful_time(drive):
    drive.initialize()
    for k in range(3):
        drive.slave.doStep(k * 0.25, 0.25)
    assert drive.slave.getRealStatus(2) == 0.75  # fmi2LastSuccessfulTime


def test_two_instances_step_independently():
    first, second = Instance("DifferentialDrive", "first"), Instance("DifferentialDrive", "second")
    first.initialize(x0=1.0, v=1.0)
    second.initialize(theta0=1.5707963267948966, v=2.0)
    for k in range(4):
        first.slave.doStep(k * 0.1, 0.1)
        if k % 2 == 0:
            second.slave.doStep(k * 0.1, 0.1)
    assert first.get("x", "y") == pytest.approx([1.4, 0.0], abs=1e-12)
    assert second.get("x", "y") == pytest.approx([0.0, 0.4], abs=1e-12)
    first.free()
    second.slave.doStep(0.4, 0.1)  # still alive after the other one's freeInstance
    assert second.get("y") == pytest.approx([0.6], abs=1e-12)
    second.free()
