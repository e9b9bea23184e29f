"""Generate `modelDescription.xml` of the VectorFieldHistogram FMU (720 ranges and angles).

Run `python3 fmus/VectorFieldHistogram/make_model_description.py` after changing the table and
commit both; the XML writer is fmus/common/model_description.py.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

# The shared writer sits in fmus/common/, beside the C glue; generators run as scripts.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "common"))
from model_description import Variable, model_description, write_model_description  # noqa: E402

MAX_READINGS = 720  # VFH_MAX_READINGS in config.h
MAX_SECTORS = 720  # VFH_MAX_SECTORS in config.h


def variables() -> list[Variable]:
    """VectorFieldHistogram's variables; value references as in config.h. Defaults are MATLAB's."""
    parameters = [
        Variable(
            "num_angular_sectors",
            0,
            "Integer",
            "parameter",
            "Number of histogram sectors over [-pi, pi], 1..720 (MATLAB NumAngularSectors)",
            None,
            180,
            minimum=1,
            maximum=MAX_SECTORS,
        ),
        Variable(
            "distance_limit_min",
            0,
            "Real",
            "parameter",
            "Readings closer than this are ignored (MATLAB DistanceLimits(1))",
            "m",
            0.05,
            minimum=0.0,
        ),
        Variable(
            "distance_limit_max",
            1,
            "Real",
            "parameter",
            "Readings farther than this are ignored; also the weight constant a (MATLAB DistanceLimits(2))",
            "m",
            2.0,
            minimum=1e-9,
        ),
        Variable(
            "robot_radius",
            2,
            "Real",
            "parameter",
            "Radius of the circle around the vehicle (MATLAB RobotRadius)",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "safety_distance",
            3,
            "Real",
            "parameter",
            "Clearance added to robot_radius (MATLAB SafetyDistance)",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "min_turning_radius",
            4,
            "Real",
            "parameter",
            "Turning radius at the current speed, for the masked histogram (MATLAB MinTurningRadius)",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "target_direction_weight",
            5,
            "Real",
            "parameter",
            "Cost weight mu1 of the target direction",
            None,
            5.0,
            minimum=0.0,
        ),
        Variable(
            "current_direction_weight",
            6,
            "Real",
            "parameter",
            "Cost weight mu2 of the current direction (0)",
            None,
            2.0,
            minimum=0.0,
        ),
        Variable(
            "previous_direction_weight",
            7,
            "Real",
            "parameter",
            "Cost weight mu3 of the previous direction",
            None,
            2.0,
            minimum=0.0,
        ),
        Variable(
            "histogram_threshold_low",
            8,
            "Real",
            "parameter",
            "Density below this frees a sector (MATLAB HistogramThresholds(1))",
            None,
            3.0,
            minimum=0.0,
        ),
        Variable(
            "histogram_threshold_high",
            9,
            "Real",
            "parameter",
            "Density above this occupies a sector (MATLAB HistogramThresholds(2))",
            None,
            10.0,
            minimum=0.0,
        ),
        Variable(
            "narrow_opening_threshold",
            10,
            "Real",
            "parameter",
            "Valleys narrower than this give their bisector, wider ones two edge candidates",
            "rad",
            0.8,
            minimum=1e-9,
        ),
    ]
    inputs = [
        Variable(
            f"ranges[{k}]",
            1000 + k - 1,
            "Real",
            "input",
            f"Range of reading {k} (NaN: no reading)",
            "m",
            math.nan,
        )
        for k in range(1, MAX_READINGS + 1)
    ]
    inputs += [
        Variable(
            f"angles[{k}]",
            2000 + k - 1,
            "Real",
            "input",
            f"Angle of reading {k}, counter-clockwise from the vehicle's x axis",
            "rad",
            math.nan,
        )
        for k in range(1, MAX_READINGS + 1)
    ]
    inputs.append(
        Variable("target_dir", 20, "Real", "input", "Direction to steer toward, vehicle frame", "rad", 0.0)
    )
    outputs = [
        Variable(
            "steering_dir",
            30,
            "Real",
            "output",
            "Obstacle-free steering direction (NaN when nothing is free)",
            "rad",
        ),
        Variable("free_sectors", 10, "Integer", "output", "Number of free sectors in the masked histogram"),
        Variable("num_valleys", 11, "Integer", "output", "Number of runs of free sectors (valleys)"),
        Variable("target_dir_free", 0, "Boolean", "output", "The target direction lies in a free sector"),
    ]
    return parameters + inputs + outputs


def generate() -> str:
    """The modelDescription.xml text of VectorFieldHistogram."""
    return model_description(
        "VectorFieldHistogram",
        "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d02}",
        "VFH+ obstacle avoidance as MATLAB controllerVFH: polar density with enlargement angle, hysteresis, "
        "turning-radius mask, valley candidates, three-weight cost",
        variables(),
        0.05,
    )


if __name__ == "__main__":
    write_model_description(Path(__file__).with_name("modelDescription.xml"), generate())
