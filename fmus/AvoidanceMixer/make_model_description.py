"""Generate `modelDescription.xml` of the AvoidanceMixer FMU.

Run `python3 fmus/AvoidanceMixer/make_model_description.py` after changing the table and commit
both; the XML writer is fmus/common/model_description.py.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

# The shared writer sits in fmus/common/, beside the C glue; generators run as scripts.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "common"))
from model_description import Variable, model_description, write_model_description  # noqa: E402


def variables() -> list[Variable]:
    """AvoidanceMixer's variables; value references as in config.h."""
    return [
        Variable(
            "vehicle_type",
            0,
            "Integer",
            "parameter",
            "0: differential drive (outputs v, omega); 1: bicycle (outputs v, steering_angle)",
            None,
            0,
            minimum=0,
            maximum=1,
        ),
        Variable("wheelbase", 0, "Real", "parameter", "Bicycle wheelbase L", "m", 1.0, minimum=1e-9),
        Variable(
            "max_steering_angle",
            1,
            "Real",
            "parameter",
            "Bicycle steering lock, in (0, pi/2)",
            "rad",
            math.pi / 4,
            minimum=1e-9,
            maximum=math.nextafter(math.pi / 2, 0.0),
        ),
        Variable(
            "direction_tolerance",
            2,
            "Real",
            "parameter",
            "Avoid when |steering_dir - target_dir| exceeds this",
            "rad",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "avoid_gain",
            3,
            "Real",
            "parameter",
            "While avoiding, omega = avoid_gain * steering_dir",
            "1/s",
            0.5,
        ),
        Variable(
            "avoid_speed_factor",
            4,
            "Real",
            "parameter",
            "While avoiding, v = avoid_speed_factor * v_in (1 keeps v, as MATLAB's example)",
            None,
            1.0,
        ),
        Variable(
            "recovery_angular_velocity",
            5,
            "Real",
            "parameter",
            "Differential drive recovery: turn on the spot at this rate toward the side last free",
            "rad/s",
            0.5,
            minimum=0.0,
        ),
        Variable(
            "recovery_linear_velocity",
            6,
            "Real",
            "parameter",
            "Bicycle recovery: reverse at this speed with full lock, nose swinging toward the side last free",
            "m/s",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "avoid_steering_gain",
            7,
            "Real",
            "parameter",
            "Bicycle, while avoiding: steering_angle = avoid_steering_gain * steering_dir (1: the thesis's "
            "car steers at the VFH direction)",
            None,
            1.0,
        ),
        Variable(
            "recovery_min_duration",
            8,
            "Real",
            "parameter",
            "Once recovering, keep recovering at least this long [s] (0: until a direction is free)",
            "s",
            0.0,
            minimum=0.0,
        ),
        Variable(
            "avoid_hold_time",
            9,
            "Real",
            "parameter",
            "Keep heading at the last avoidance offset from target_dir this long [s] after VFH frees "
            "the target (0: follow at once)",
            "s",
            0.0,
            minimum=0.0,
        ),
        Variable("v_in", 10, "Real", "input", "Linear velocity of the path follower", "m/s", 0.0),
        Variable("omega_in", 11, "Real", "input", "Angular velocity of the path follower", "rad/s", 0.0),
        Variable(
            "target_dir",
            12,
            "Real",
            "input",
            "Target direction of the path follower, vehicle frame",
            "rad",
            0.0,
        ),
        Variable(
            "steering_dir", 13, "Real", "input", "VFH steering direction (NaN: nothing free)", "rad", 0.0
        ),
        Variable(
            "goal_reached", 0, "Boolean", "input", "The path follower reached the goal: stop", None, False
        ),
        Variable("v", 20, "Real", "output", "Linear velocity command", "m/s"),
        Variable(
            "omega",
            21,
            "Real",
            "output",
            "Angular velocity command (bicycle: the yaw rate of steering_angle at v)",
            "rad/s",
        ),
        Variable(
            "steering_angle",
            22,
            "Real",
            "output",
            "Bicycle steering angle command (0 for the differential drive)",
            "rad",
        ),
        Variable("mode", 10, "Integer", "output", "0 follow, 1 avoid, 2 recover, 3 stopped at the goal"),
    ]


def generate() -> str:
    """The modelDescription.xml text of AvoidanceMixer."""
    return model_description(
        "AvoidanceMixer",
        "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d03}",
        "Fuses the pure-pursuit command with the VFH steering direction: follow, avoid, recover "
        "(thesis section 4.3.3, Figure 4.12), for a differential drive or a bicycle",
        variables(),
        0.05,
    )


if __name__ == "__main__":
    write_model_description(Path(__file__).with_name("modelDescription.xml"), generate())
