"""The FMI 3.0 export of every project FMU: its description (arrays, not scalars), fmpy's validation,
the vehicles through fmpy's FMU3Slave against closed-form arcs, the controllers equal to their FMI 2.0
build bit for bit, the glue's answers to misuse, and the build against our own minimal header."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu
from fmu_harness import NAMES, FmuInstance, fmu_path, unpacked

from cosim.fmi import builtin as fmus
from cosim.fmi.inspect import validate

FMI_ERROR = 3
TOLERANCE = 1e-9


def test_every_project_fmu_has_an_fmi3_build():
    assert {"DifferentialDrive", "Bicycle", "PurePursuit", "VectorFieldHistogram", "AvoidanceMixer"} <= set(
        NAMES
    )
    for name in NAMES:
        description = read_model_description(str(fmu_path(name, 3)))
        assert description.fmiVersion == "3.0" and description.coSimulation.modelIdentifier == name
        assert description.coSimulation.canGetAndSetFMUstate and description.coSimulation.canSerializeFMUstate
        fmi2 = read_model_description(str(fmu_path(name, 2)))
        assert description.instantiationToken == fmi2.guid


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_fmu_passes_fmpy_validation_and_ours(name):
    path = fmu_path(name, 3)
    assert validate_fmu(str(path)) == []  # fmpy's own entry point: FMI 3.0 arrays keep it fast
    assert validate(path) == []  # plus the binary loads and exports every FMI 3.0 function


def _dimensions(variable) -> list[int]:
    return [int(d.start) for d in variable.dimensions]


def test_waypoints_ranges_and_angles_are_float64_arrays():
    vfh = {v.name: v for v in read_model_description(str(fmu_path("VectorFieldHistogram", 3))).modelVariables}
    for name in ("ranges", "angles"):
        assert (
            vfh[name].type == "Float64" and vfh[name].causality == "input" and _dimensions(vfh[name]) == [720]
        )
        assert vfh[name].start.split() == ["NaN"] * 720
    pursuit = {v.name: v for v in read_model_description(str(fmu_path("PurePursuit", 3))).modelVariables}
    assert pursuit["waypoints"].type == "Float64" and _dimensions(pursuit["waypoints"]) == [1000, 2]
    for name in NAMES:
        variables = read_model_description(str(fmu_path(name, 3))).modelVariables
        references = [v.valueReference for v in variables]
        assert len(set(references)) == len(references)  # FMI 3.0: unique across types
        assert variables[0].name == "time" and variables[0].causality == "independent" and references[0] == 0
        assert not any("[" in v.name for v in variables)  # every FMI 2.0 array became an array variable
        # FMI 2.0 keeps its scalars: as many values as FMI 3.0 elements, same names otherwise.
        fmi2 = read_model_description(str(fmu_path(name, 2))).modelVariables
        assert sum(math.prod(_dimensions(v)) for v in variables[1:]) == len(fmi2)


# ---------------------------------------------------------------- vehicles against closed-form arcs


def unicycle_pose(x0, y0, theta0, v, omega, t):
    """Closed form of x' = v cos(theta), y' = v sin(theta), theta' = omega for constant v, omega."""
    if omega == 0.0:
        return x0 + v * t * math.cos(theta0), y0 + v * t * math.sin(theta0), theta0
    theta = theta0 + omega * t
    return (
        x0 + v / omega * (math.sin(theta) - math.sin(theta0)),
        y0 - v / omega * (math.cos(theta) - math.cos(theta0)),
        theta,
    )


def _assert_pose(slave: FmuInstance, expected) -> None:
    x, y, theta = (slave.values(n)[0] for n in ("x", "y", "theta"))
    assert abs(x - expected[0]) <= TOLERANCE and abs(y - expected[1]) <= TOLERANCE
    assert abs(math.remainder(theta - expected[2], 2 * math.pi)) <= TOLERANCE and -math.pi < theta <= math.pi


@pytest.mark.parametrize(
    ("v", "omega", "theta0", "step_size"),
    [(1.0, 0.5, 0.3, 0.1), (0.7, -2.0, -2.9, 0.05), (-0.4, 0.0, 1.0, 0.2)],
)
def test_fmi3_differential_drive_follows_the_arc(v, omega, theta0, step_size):
    drive = FmuInstance("DifferentialDrive", 3)
    drive.initialize(x0=1.0, y0=-2.0, theta0=theta0, v=v, omega=omega)
    for _ in range(60):
        drive.step(step_size)
    _assert_pose(drive, unicycle_pose(1.0, -2.0, theta0, v, omega, 60 * step_size))
    assert drive.values("time") == [pytest.approx(60 * step_size, abs=1e-12)]
    drive.free()


@pytest.mark.parametrize(("v", "delta"), [(1.5, 0.35), (-0.8, -0.5)])
def test_fmi3_bicycle_rear_axle_follows_the_circle(v, delta):
    """Front steering, rear-axle reference: a circle of radius L / tan(delta), yaw rate v tan(delta) / L."""
    wheelbase = 2.5
    bicycle = FmuInstance("Bicycle", 3)
    bicycle.initialize(wheelbase=wheelbase, x0=0.5, y0=0.25, theta0=0.8, v=v, steering_angle=delta)
    for _ in range(50):
        bicycle.step(0.1)
    omega = v * math.tan(delta) / wheelbase
    _assert_pose(bicycle, unicycle_pose(0.5, 0.25, 0.8, v, omega, 5.0))
    assert bicycle.values("yaw_rate") == [pytest.approx(omega, abs=1e-14)]
    bicycle.free()


# ---------------------------------------------------------------- controllers: FMI 3.0 == FMI 2.0


def _pair(name: str, **parameters) -> tuple[FmuInstance, FmuInstance]:
    pair = FmuInstance(name, 2), FmuInstance(name, 3)
    for slave in pair:
        slave.initialize(**parameters)
    return pair


def _assert_same_outputs(fmi2: FmuInstance, fmi3: FmuInstance) -> None:
    first, second = fmi2.outputs(), fmi3.outputs()
    assert first.keys() == second.keys()
    for name in first:
        a, b = np.array(first[name], dtype=float), np.array(second[name], dtype=float)
        assert np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b)), name


def test_vfh_fmi3_equals_fmi2_with_one_set_per_array():
    rng = np.random.default_rng(7)
    fmi2, fmi3 = _pair(
        "VectorFieldHistogram", num_angular_sectors=90, distance_limit_max=4.0, robot_radius=0.2
    )
    angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    steered = 0
    for k in range(40):
        ranges = rng.uniform(0.3, 6.0, 720)
        ranges[rng.random(720) < 0.9] = np.nan  # a sparse scan: some directions stay free
        ranges[(np.abs(angles) < 0.6) & (k % 3 == 0)] = 0.8  # an obstacle ahead every third scan
        beam_angles = angles + 0.01 * (k % 2)  # the angles change too: the watched-input path
        target_dir = float(rng.uniform(-2.0, 2.0))
        for slave in (fmi2, fmi3):
            slave.set_array("ranges", ranges)
            slave.set_array("angles", beam_angles)
            slave.set(target_dir=target_dir)
            slave.step()
        _assert_same_outputs(fmi2, fmi3)
        steered += not math.isnan(fmi3.values("steering_dir")[0])
    assert steered > 10  # the comparison covered steering, not only blocked scans
    assert fmi3.values("ranges") == pytest.approx(list(ranges), nan_ok=True)  # one get for the array
    fmi2.free(), fmi3.free()


def test_pure_pursuit_fmi3_equals_fmi2_along_a_changing_plan():
    fmi2, fmi3 = _pair("PurePursuit", desired_linear_velocity=0.5, lookahead_distance=0.8)
    plans = [
        np.column_stack([np.linspace(0.0, 8.0, 30), np.sin(np.linspace(0.0, 3.0, 30))]),
        np.column_stack([np.linspace(0.0, 5.0, 12), np.linspace(0.0, -2.0, 12)]),
    ]
    x = y = theta = 0.0
    for k in range(60):
        waypoints = np.full((1000, 2), np.nan)
        plan = plans[k // 30]
        waypoints[: len(plan)] = plan
        for slave in (fmi2, fmi3):
            slave.set_array("waypoints", waypoints)
            slave.set(x=x, y=y, theta=theta)
            slave.step()
        _assert_same_outputs(fmi2, fmi3)
        v, omega = fmi3.values("v")[0], fmi3.values("omega")[0]
        x, y, theta = x + 0.05 * v * math.cos(theta), y + 0.05 * v * math.sin(theta), theta + 0.05 * omega
    assert fmi3.values("v")[0] == 0.5  # still following, the comparison saw a moving robot
    waypoints_back = np.array(fmi3.values("waypoints")).reshape(1000, 2)  # row-major [i, j]
    assert np.array_equal(waypoints_back[: len(plans[1])], plans[1])
    fmi2.free(), fmi3.free()


def test_avoidance_mixer_fmi3_equals_fmi2():
    rng = np.random.default_rng(3)
    for vehicle_type in (0, 1):
        fmi2, fmi3 = _pair("AvoidanceMixer", vehicle_type=vehicle_type, wheelbase=0.8)
        for k in range(60):
            steering = math.nan if k % 7 == 0 else float(rng.uniform(-1.5, 1.5))
            inputs = dict(v_in=0.6, omega_in=float(rng.uniform(-1, 1)), target_dir=float(rng.uniform(-1, 1)))
            for slave in (fmi2, fmi3):
                slave.set(steering_dir=steering, goal_reached=k > 55, **inputs)
                slave.step()
            _assert_same_outputs(fmi2, fmi3)
        fmi2.free(), fmi3.free()


# ---------------------------------------------------------------- misuse


def _fails_with(slave: FmuInstance, call, *args, message: str) -> None:
    with pytest.raises(FMICallException) as error:
        call(*args)
    assert error.value.status == FMI_ERROR
    assert message in slave.messages[-1], slave.messages


def test_fmi3_glue_answers_misuse_naming_the_variable():
    vfh = FmuInstance("VectorFieldHistogram", 3)
    vr = {name: v.valueReference for name, v in vfh.variables.items()}
    _fails_with(vfh, vfh.fmu.doStep, 0.0, 0.05, message="fmi3DoStep is not allowed in state 'instantiated'")
    vfh.initialize()
    references, three_values = (ctypes.c_uint32 * 1)(vr["ranges"]), (ctypes.c_double * 3)(1.0, 2.0, 3.0)
    _fails_with(
        vfh,
        vfh.fmu.fmi3SetFloat64,
        vfh.fmu.component,
        references,
        1,
        three_values,
        3,
        message="fmi3SetFloat64: nValues is 3, the 1 value references have 720 values",
    )
    _fails_with(vfh, vfh.fmu.setFloat64, [vr["steering_dir"]], [1.0], message="Float64 variable steering_dir")
    _fails_with(
        vfh,
        vfh.fmu.setFloat64,
        [vr["robot_radius"]],
        [0.5],
        message="fixed parameter robot_radius (Float64 value reference 4) cannot be set after initialisation",
    )
    _fails_with(vfh, vfh.fmu.setFloat64, [0], [1.0], message="the independent variable time")
    _fails_with(
        vfh, vfh.fmu.getInt32, [vr["ranges"]], message="variable ranges (value reference 13) is Float64"
    )
    _fails_with(vfh, vfh.fmu.getFloat64, [999], message="unknown value reference 999")
    _fails_with(
        vfh,
        vfh.fmu.getUInt8,
        [vr["free_sectors"]],
        message="variable free_sectors (value reference 17) is Int32",
    )
    vfh.step()  # misuse leaves the instance working
    assert vfh.values("free_sectors") == [180]  # no readings: every one of the 180 sectors is free
    vfh.free()


def test_fmi3_wrong_instantiation_token_is_refused():
    directory, description = unpacked("DifferentialDrive", 3)
    slave = FMU3Slave(
        guid="{00000000-0000-0000-0000-000000000000}",
        unzipDirectory=directory,
        modelIdentifier="DifferentialDrive",
    )
    messages: list[bytes] = []
    with pytest.raises(Exception, match="instantiate"):
        slave.instantiate(logMessage=lambda env, status, category, message: messages.append(message))
    assert b"does not match this FMU's" in messages[-1]


def test_fmi3_glue_builds_against_our_minimal_header(tmp_path):
    """pip's isolated wheel build has no fmpy: our fmi3Functions.h must build the same FMUs."""
    build = fmus._build_module(fmus.SOURCE_ROOT)
    own = fmus.SOURCE_ROOT / "common" / "fmi3"
    for name in ("DifferentialDrive", "VectorFieldHistogram"):
        path = build.build_fmu(fmus.SOURCE_ROOT / name, tmp_path, header_dir=own, fmi_version=3)
        assert validate(path) == []
