"""What every project FMU shares: its committed modelDescription.xml is its generator's output, a bad
parameter fails initialisation with fmi2Error and a message naming it, and misuse of a variable is
answered by the glue with a message naming the variable."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest
from fmpy.fmi1 import FMICallException
from fmu_harness import FmuInstance

FMU_DIR = Path(__file__).resolve().parents[2] / "fmus"
FMI2_ERROR = 3
GENERATED = ["PurePursuit", "VectorFieldHistogram", "AvoidanceMixer", "ArtificialPotentialField"]
ALL_FMUS = ["DifferentialDrive", "Bicycle", *GENERATED]


def load_generator(model: str):
    path = FMU_DIR / model / "make_model_description.py"
    spec = importlib.util.spec_from_file_location(f"generator_{model}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("model", GENERATED)
def test_committed_model_description_is_the_generators_output(model):
    committed = (FMU_DIR / model / "modelDescription.xml").read_text()
    assert committed == load_generator(model).generate()


BAD_PARAMETERS = [
    ("DifferentialDrive", {"wheel_radius": -0.05}, "wheel_radius"),
    ("DifferentialDrive", {"track_width": 0.0}, "track_width"),
    ("DifferentialDrive", {"wheel_speed_min": 5.0, "wheel_speed_max": 1.0}, "wheel_speed_min"),
    ("DifferentialDrive", {"input_mode": 3}, "input_mode"),
    ("DifferentialDrive", {"x0": math.nan}, "x0"),
    ("Bicycle", {"wheelbase": 0.0}, "wheelbase"),
    ("Bicycle", {"max_steering_angle": 0.0}, "max_steering_angle"),
    ("Bicycle", {"max_steering_angle": math.pi / 2}, "max_steering_angle"),
    ("Bicycle", {"speed_min": 1.0, "speed_max": -1.0}, "speed_min"),
    ("Bicycle", {"steering_mode": 3}, "steering_mode"),
    ("Bicycle", {"input_mode": 1, "steering_mode": 2}, "input_mode"),
    ("Bicycle", {"theta0": math.inf}, "theta0"),
    ("PurePursuit", {"lookahead_distance": 0.0}, "lookahead_distance"),
    ("PurePursuit", {"lookahead_distance": -1.0}, "lookahead_distance"),
    ("PurePursuit", {"max_angular_velocity": -0.1}, "max_angular_velocity"),
    ("PurePursuit", {"goal_tolerance": -0.5}, "goal_tolerance"),
    ("PurePursuit", {"angular_velocity_law": 2}, "angular_velocity_law"),
    ("VectorFieldHistogram", {"num_angular_sectors": 0}, "num_angular_sectors"),
    ("VectorFieldHistogram", {"num_angular_sectors": 721}, "num_angular_sectors"),
    ("VectorFieldHistogram", {"histogram_threshold_high": 2.0}, "histogram_threshold_high"),  # < low 3
    ("VectorFieldHistogram", {"distance_limit_max": 0.01}, "distance_limit_max"),  # < min 0.05
    ("VectorFieldHistogram", {"distance_limit_min": -0.1}, "distance_limit_min"),
    ("VectorFieldHistogram", {"robot_radius": -0.1}, "robot_radius"),
    ("VectorFieldHistogram", {"safety_distance": -0.1}, "safety_distance"),
    ("VectorFieldHistogram", {"min_turning_radius": -1.0}, "min_turning_radius"),
    ("VectorFieldHistogram", {"narrow_opening_threshold": 0.0}, "narrow_opening_threshold"),
    ("ArtificialPotentialField", {"distance_limit_min": -0.1}, "distance_limit_min"),
    ("ArtificialPotentialField", {"distance_limit_max": 0.01}, "distance_limit_max"),  # < min 0.05
    ("ArtificialPotentialField", {"distance_limit_max": math.inf}, "distance_limit_max"),
    ("ArtificialPotentialField", {"robot_radius": -0.1}, "robot_radius"),
    ("ArtificialPotentialField", {"safety_distance": math.nan}, "safety_distance"),
    ("ArtificialPotentialField", {"influence_distance": 0.0}, "influence_distance"),
    ("ArtificialPotentialField", {"attractive_gain": 0.0}, "attractive_gain"),
    ("ArtificialPotentialField", {"repulsive_gain": -1.0}, "repulsive_gain"),
    ("ArtificialPotentialField", {"max_target_deviation": 0.0}, "max_target_deviation"),
    ("ArtificialPotentialField", {"max_target_deviation": 3.2}, "max_target_deviation"),  # > pi
    ("AvoidanceMixer", {"vehicle_type": 2}, "vehicle_type"),
    ("AvoidanceMixer", {"vehicle_type": 1, "wheelbase": 0.0}, "wheelbase"),
    ("AvoidanceMixer", {"vehicle_type": 1, "max_steering_angle": 1.6}, "max_steering_angle"),
    ("AvoidanceMixer", {"direction_tolerance": -0.1}, "direction_tolerance"),
    ("AvoidanceMixer", {"recovery_angular_velocity": -0.5}, "recovery_angular_velocity"),
    ("AvoidanceMixer", {"recovery_linear_velocity": -0.1}, "recovery_linear_velocity"),
    ("AvoidanceMixer", {"recovery_min_duration": -1.0}, "recovery_min_duration"),
    ("AvoidanceMixer", {"avoid_hold_time": math.inf}, "avoid_hold_time"),
    ("AvoidanceMixer", {"avoid_steering_gain": math.nan}, "avoid_steering_gain"),
]


@pytest.mark.parametrize(("model", "parameters", "name"), BAD_PARAMETERS)
def test_bad_parameter_fails_initialisation_naming_it(model, parameters, name):
    with FmuInstance(model).initialize(parameters, exit=False) as fmu:
        with pytest.raises(FMICallException) as error:
            fmu.exit_initialization()
        assert error.value.status == FMI2_ERROR
        assert any(name in message for message in fmu.messages), fmu.messages


def _set_fails_naming(fmu: FmuInstance, name: str, expected: str) -> None:
    variable = fmu.variables[name]
    value = {"Real": 1.0, "Integer": 1, "Boolean": True}[variable.type]
    with pytest.raises(FMICallException) as error:
        fmu.set({name: value})
    assert error.value.status == FMI2_ERROR
    assert f"{expected} {name} " in fmu.messages[-1], fmu.messages


@pytest.mark.parametrize("model", ALL_FMUS)
def test_setting_an_output_or_a_fixed_parameter_after_initialisation_names_it(model):
    with FmuInstance(model).initialize() as fmu:
        variables = fmu.description.modelVariables
        output = next(v for v in variables if v.causality == "output")
        parameter = next(v for v in variables if v.causality == "parameter" and v.variability == "fixed")
        before = fmu.get(parameter.name)
        _set_fails_naming(fmu, output.name, f"{output.type} variable")
        _set_fails_naming(fmu, parameter.name, "fixed parameter")
        assert fmu.get(parameter.name) == before
        fmu.step()  # misuse does not break the instance
