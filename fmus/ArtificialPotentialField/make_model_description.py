"""Generate `modelDescription.xml` of the ArtificialPotentialField FMU.

Run `python3 fmus/ArtificialPotentialField/make_model_description.py` after changing the table and
commit both; the XML writer is fmus/common/model_description.py. The scan and target inputs are
taken from VectorFieldHistogram's generator, so the two stay interchangeable port for port.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

# The shared writer sits in fmus/common/, beside the C glue; generators run as scripts.
FMUS = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(FMUS / "common"))
from model_description import Variable, model_description, write_model_description  # noqa: E402


def _vfh_variables() -> list[Variable]:
    spec = importlib.util.spec_from_file_location(
        "vfh_model_description", FMUS / "VectorFieldHistogram" / "make_model_description.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.variables()


def variables() -> list[Variable]:
    """ArtificialPotentialField's variables; value references as in config.h."""
    parameters = [
        Variable(
            "distance_limit_min",
            0,
            "Real",
            "parameter",
            "Readings closer than this are ignored (as VFH)",
            "m",
            0.05,
            minimum=0.0,
        ),
        Variable(
            "distance_limit_max",
            1,
            "Real",
            "parameter",
            "Readings farther than this are ignored (as VFH)",
            "m",
            2.0,
            minimum=1e-9,
        ),
        Variable(
            "robot_radius",
            2,
            "Real",
            "parameter",
            "Radius of the circle around the vehicle; clearances are measured from it",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "safety_distance",
            3,
            "Real",
            "parameter",
            "A reading within robot_radius + safety_distance blocks the directions within 90 degrees of it",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "influence_distance",
            4,
            "Real",
            "parameter",
            "Clearance rho_0 (range - robot_radius) beyond which a reading does not repel, > 0",
            "m",
            1.0,
            minimum=1e-9,
        ),
        Variable(
            "attractive_gain",
            5,
            "Real",
            "parameter",
            "Strength of the constant pull toward target_dir, > 0",
            None,
            1.0,
            minimum=1e-9,
        ),
        Variable(
            "repulsive_gain",
            6,
            "Real",
            "parameter",
            "Khatib's eta [m^3]: a reading at clearance rho repels with eta (1/rho - 1/rho_0) / rho^2",
            None,
            0.005,
            minimum=0.0,
        ),
        Variable(
            "max_target_deviation",
            7,
            "Real",
            "parameter",
            "Trapped (no direction) when the force points farther than this from target_dir, (0, pi]; "
            "pi: never",
            "rad",
            math.pi,
            minimum=1e-9,
            maximum=math.pi,
        ),
    ]
    inputs = [v for v in _vfh_variables() if v.causality == "input"]
    outputs = [
        Variable(
            "steering_dir",
            30,
            "Real",
            "output",
            "Direction of the resultant force, vehicle frame (NaN when no direction: see direction_status)",
            "rad",
        ),
        Variable("force_x", 31, "Real", "output", "Resultant force along the vehicle's x axis"),
        Variable("force_y", 32, "Real", "output", "Resultant force along the vehicle's y axis"),
        Variable(
            "nearest_distance",
            33,
            "Real",
            "output",
            "Smallest range inside the distance limits (NaN: none)",
            "m",
        ),
        Variable(
            "repelling_readings",
            10,
            "Integer",
            "output",
            "Number of readings within the influence distance",
        ),
        Variable(
            "direction_status",
            11,
            "Integer",
            "output",
            "0 the force's direction, 1 deflected clear of the safety circle, 2 trapped (NaN: zero force or "
            "beyond max_target_deviation), 3 enclosed (NaN: the safety circle blocks every direction)",
        ),
        Variable(
            "target_dir_free",
            0,
            "Boolean",
            "output",
            "No repelling reading lies in the robot_radius + safety_distance corridor along target_dir",
        ),
    ]
    return parameters + inputs + outputs


def generate() -> str:
    """The modelDescription.xml text of ArtificialPotentialField."""
    return model_description(
        "ArtificialPotentialField",
        "{a0764ad2-2fce-4367-acb0-8292e0bec0f1}",
        "Artificial potential field obstacle avoidance (Khatib): constant attraction toward the target "
        "direction plus the repulsion of every lidar reading within the influence distance; VFH's ports",
        variables(),
        0.05,
    )


if __name__ == "__main__":
    write_model_description(Path(__file__).with_name("modelDescription.xml"), generate())
