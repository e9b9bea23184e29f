"""FMU state in both FMI versions of every project FMU: step to t1, save, step to t2, restore, step to
t2 again gives bit-identical outputs at every step, also from a state serialised and deserialised
(into the same instance and into a fresh one); foreign or damaged states are refused with a message."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmu_harness import NAMES, FmuInstance, fmu_path

FMI_ERROR = 3
STEP = 0.05
T1_STEPS, T2_STEPS = 12, 25


def _layout(name: str) -> tuple[list[str], dict[str, list[int]]]:
    """(scalar inputs, array inputs with their dimensions) of `name`, read from its FMI 3.0 form
    (the FMI 2.0 form has the same names, arrays as `name[i]` scalars)."""
    scalars, arrays = [], {}
    for variable in read_model_description(str(fmu_path(name, 3))).modelVariables:
        if variable.causality != "input":
            continue
        if variable.dimensions:
            arrays[variable.name] = [int(d.start) for d in variable.dimensions]
        else:
            scalars.append(variable.name)
    return scalars, arrays


def _array_input(name: str, shape: list[int], k: int) -> np.ndarray:
    """Inputs that make each model work: a scan with obstacles that move, a fixed path."""
    if name == "angles":
        return np.linspace(-math.pi, math.pi, shape[0], endpoint=False)
    if name == "ranges":
        values = np.full(shape, np.nan)
        values[(np.arange(shape[0]) + 7 * k) % 11 == 0] = 0.6 + 0.02 * k
        return values
    if name == "waypoints":
        values = np.full(shape, np.nan)
        s = np.linspace(0.0, 6.0, 25)
        values[:25] = np.column_stack([s, 0.8 * np.sin(s)])
        return values
    return np.sin(0.3 * k + np.arange(math.prod(shape)).reshape(shape))


def _drive(slave: FmuInstance, name: str, k: int) -> None:
    scalars, arrays = _layout(name)
    for array, shape in arrays.items():
        slave.set_array(array, _array_input(array, shape, k))
    values = {}
    for i, scalar in enumerate(scalars):
        kind = slave.variables[scalar].type
        values[scalar] = False if kind == "Boolean" else 0.4 + 0.3 * math.sin(0.37 * k + i)
    slave.set(**values)


def _run(slave: FmuInstance, name: str, first: int, last: int) -> list[dict[str, np.ndarray]]:
    """Outputs after each step k in first..last-1 (time t = k * STEP)."""
    history = []
    for k in range(first, last):
        _drive(slave, name, k)
        slave.fmu.doStep(k * STEP, STEP)
        history.append({n: np.array(v, dtype=float) for n, v in slave.outputs().items()})
    return history


def _assert_identical(a: list[dict[str, np.ndarray]], b: list[dict[str, np.ndarray]]) -> None:
    assert len(a) == len(b)
    for step, (first, second) in enumerate(zip(a, b, strict=True)):
        for output in first:
            x, y = first[output], second[output]
            same = np.array_equal(x.view(np.uint64), y.view(np.uint64))  # bit for bit, NaN and -0.0 included
            assert same, f"step {step}: {output} {x} != {y}"


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("name", NAMES)
def test_state_round_trip_is_bit_identical(name, fmi_version):
    slave = FmuInstance(name, fmi_version)
    slave.initialize()
    _run(slave, name, 0, T1_STEPS)
    state = slave.fmu.getFMUState()
    reference = _run(slave, name, T1_STEPS, T2_STEPS)
    moved = any(not np.array_equal(reference[0][o], reference[-1][o], equal_nan=True) for o in reference[0])
    assert moved, "the outputs must change between t1 and t2 for the test to mean anything"

    slave.fmu.setFMUState(state)
    _assert_identical(_run(slave, name, T1_STEPS, T2_STEPS), reference)

    serialized = slave.fmu.serializeFMUState(state)
    slave.fmu.freeFMUState(state)
    restored = slave.fmu.deserializeFMUState(serialized)
    slave.fmu.setFMUState(restored)
    _assert_identical(_run(slave, name, T1_STEPS, T2_STEPS), reference)
    slave.fmu.freeFMUState(restored)

    # Into an instance that never stepped: the state carries everything, the instance nothing.
    fresh = FmuInstance(name, fmi_version, instance_name="fresh")
    fresh.initialize()
    state = fresh.fmu.deserializeFMUState(serialized)
    fresh.fmu.setFMUState(state)
    _assert_identical(_run(fresh, name, T1_STEPS, T2_STEPS), reference)
    fresh.fmu.freeFMUState(state)
    fresh.free()
    slave.free()


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_get_state_into_an_existing_state_overwrites_it(fmi_version):
    drive = FmuInstance("DifferentialDrive", fmi_version)
    drive.initialize(v=1.0)
    state = drive.fmu.getFMUState()
    drive.step(1.0)
    getter = drive.fmu.fmi2GetFMUstate if fmi_version == 2 else drive.fmu.fmi3GetFMUState
    getter(drive.fmu.component, ctypes.byref(state))  # reuse: the saved pose is now x = 1
    drive.step(1.0)
    drive.fmu.setFMUState(state)
    assert drive.values("x") == [pytest.approx(1.0, abs=1e-15)]
    drive.fmu.freeFMUState(state)
    drive.free()


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_restoring_a_state_restores_time_and_lifecycle(fmi_version):
    drive = FmuInstance("DifferentialDrive", fmi_version)
    drive.initialize(v=1.0)
    for _ in range(4):
        drive.step(0.25)
    state = drive.fmu.getFMUState()
    drive.step(0.25)
    drive.fmu.terminate()
    drive.fmu.setFMUState(state)  # back to stepping at t = 1 s
    drive.fmu.doStep(1.0, 0.5)
    assert drive.values("x") == [pytest.approx(1.5, abs=1e-15)]
    if fmi_version == 3:
        assert drive.values("time") == [1.5]
    else:
        assert drive.fmu.getRealStatus(2) == 1.5  # fmi2LastSuccessfulTime
    drive.fmu.freeFMUState(state)
    drive.free()


def _deserialize_fails(slave: FmuInstance, data: bytes, message: str) -> None:
    with pytest.raises(FMICallException) as error:
        slave.fmu.deserializeFMUState(data) if slave.fmi_version == 3 else slave.fmu.deSerializeFMUstate(data)
    assert error.value.status == FMI_ERROR
    assert message in slave.messages[-1], slave.messages


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_foreign_or_damaged_serialized_states_are_refused(fmi_version):
    drive = FmuInstance("DifferentialDrive", fmi_version)
    drive.initialize()
    state = drive.fmu.getFMUState()
    serialized = drive.fmu.serializeFMUState(state)
    drive.fmu.freeFMUState(state)
    _deserialize_fails(drive, serialized[:-1], "wrong size")
    _deserialize_fails(drive, b"x" * len(serialized), "not a serialized navcosim FMU state")

    other = FmuInstance("DifferentialDrive", 5 - fmi_version)  # the model's other FMI version
    other.initialize()
    state = other.fmu.getFMUState()
    _deserialize_fails(drive, other.fmu.serializeFMUState(state), "the other FMI version")
    other.fmu.freeFMUState(state)
    other.free()

    bicycle = FmuInstance("Bicycle", fmi_version)
    bicycle.initialize()
    state = bicycle.fmu.getFMUState()
    foreign = bicycle.fmu.serializeFMUState(state)
    bicycle.fmu.freeFMUState(state)
    bicycle.free()
    if len(foreign) == len(serialized):
        _deserialize_fails(drive, foreign, "another model")
    else:
        _deserialize_fails(drive, foreign, "wrong size")

    with pytest.raises(FMICallException):
        drive.fmu.setFMUState(None)
    assert "the FMU state is NULL" in drive.messages[-1]
    drive.step()  # refusals leave the instance working
    drive.free()


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_live_state_of_another_model_is_refused_when_its_data_size_differs(fmi_version):
    """A state object (not its bytes) of another FMU carries its data size: setting it is refused
    instead of copying the other model's bytes over this one's."""
    drive, bicycle = FmuInstance("DifferentialDrive", fmi_version), FmuInstance("Bicycle", fmi_version)
    drive.initialize()
    bicycle.initialize()
    own, foreign = drive.fmu.getFMUState(), bicycle.fmu.getFMUState()
    assert len(drive.fmu.serializeFMUState(own)) != len(bicycle.fmu.serializeFMUState(foreign))
    with pytest.raises(FMICallException) as error:
        drive.fmu.setFMUState(foreign)
    assert error.value.status == FMI_ERROR
    assert "not from this FMU" in drive.messages[-1], drive.messages
    drive.fmu.setFMUState(own)  # its own state still restores
    drive.step()
    drive.fmu.freeFMUState(own)
    bicycle.fmu.freeFMUState(foreign)
    drive.free()
    bicycle.free()
