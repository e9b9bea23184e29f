"""The FMI 2.0 glue: state machine, misuse answered by fmi2Error plus a logged message, independence."""

from __future__ import annotations

import pytest
from fmpy.fmi1 import FMICallException
from fmu_harness import FmuInstance

FMI2_ERROR = 3


@pytest.fixture
def drive():
    instance = FmuInstance("DifferentialDrive")
    yield instance
    instance.free()


def _expect_error(instance: FmuInstance, call, *args, message: str) -> None:
    with pytest.raises(FMICallException) as error:
        call(*args)
    assert error.value.status == FMI2_ERROR
    assert message in instance.errors()


def test_do_step_before_initialisation(drive):
    _expect_error(
        drive, drive.fmu.doStep, 0.0, 0.1, message="fmi2DoStep is not allowed in state 'instantiated'"
    )


def test_get_before_initialisation(drive):
    _expect_error(
        drive, drive.fmu.getReal, [drive.value_reference("x")], message="fmi2GetReal is not allowed"
    )


def test_unknown_value_references(drive):
    drive.initialize()
    _expect_error(drive, drive.fmu.getReal, [999], message="unknown Real value reference 999")
    _expect_error(drive, drive.fmu.setReal, [0], [1.0], message="unknown Real value reference 0")
    _expect_error(drive, drive.fmu.getInteger, [1], message="unknown Integer value reference 1")
    _expect_error(drive, drive.fmu.getBoolean, [0], message="unknown Boolean value reference 0")
    _expect_error(drive, drive.fmu.getString, [0], message="unknown String value reference 0")
    drive.fmu.doStep(0.0, 0.1)  # misuse does not break the instance


def test_lifecycle_order_is_enforced(drive):
    _expect_error(
        drive, drive.fmu.exitInitializationMode, message="fmi2ExitInitializationMode is not allowed"
    )
    drive.initialize()
    _expect_error(drive, drive.fmu.enterInitializationMode, message="not allowed in state 'step complete'")
    drive.fmu.terminate()
    _expect_error(drive, drive.fmu.doStep, 0.0, 0.1, message="not allowed in state 'terminated'")
    assert drive.values("x") == [0.0]  # outputs stay readable after terminate


def test_invalid_step_size(drive):
    drive.initialize()
    _expect_error(drive, drive.fmu.doStep, 0.0, -0.1, message="invalid step")


def test_unsupported_functions_return_error_with_a_message(drive):
    drive.initialize()
    _expect_error(
        drive,
        drive.fmu.getDirectionalDerivative,
        [drive.value_reference("x")],
        [drive.value_reference("v")],
        [1.0],
        message="fmi2GetDirectionalDerivative is not supported",
    )


def test_model_error_enters_the_error_state_and_reset_recovers(drive):
    drive.fmu.setupExperiment(startTime=0.0)
    drive.set(wheel_radius=-0.05)
    drive.fmu.enterInitializationMode()
    _expect_error(drive, drive.fmu.exitInitializationMode, message="wheel_radius")
    _expect_error(drive, drive.fmu.doStep, 0.0, 0.1, message="not allowed in state 'error'")
    drive.fmu.reset()
    drive.initialize(v=1.0)
    drive.fmu.doStep(0.0, 0.5)
    assert drive.values("x") == pytest.approx([0.5], abs=1e-15)


def test_last_successful_time(drive):
    drive.initialize()
    for k in range(3):
        drive.fmu.doStep(k * 0.25, 0.25)
    assert drive.fmu.getRealStatus(2) == 0.75  # fmi2LastSuccessfulTime


def test_two_instances_step_independently():
    first, second = (
        FmuInstance("DifferentialDrive", instance_name="first"),
        FmuInstance("DifferentialDrive", instance_name="second"),
    )
    first.initialize(x0=1.0, v=1.0)
    second.initialize(theta0=1.5707963267948966, v=2.0)
    for k in range(4):
        first.fmu.doStep(k * 0.1, 0.1)
        if k % 2 == 0:
            second.fmu.doStep(k * 0.1, 0.1)
    assert first.values("x", "y") == pytest.approx([1.4, 0.0], abs=1e-12)
    assert second.values("x", "y") == pytest.approx([0.0, 0.4], abs=1e-12)
    first.free()
    second.fmu.doStep(0.4, 0.1)  # still alive after the other one's freeInstance
    assert second.values("y") == pytest.approx([0.6], abs=1e-12)
    second.free()
