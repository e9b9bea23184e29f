"""Generate `modelDescription.xml` of the PurePursuit FMU (thousands of waypoint elements).

The XML stays the single source of the variable list (the build reads it); this script only
writes it. Run `python3 fmus/PurePursuit/make_model_description.py` after changing the table and
commit both; the XML writer is fmus/common/model_description.py.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

# The shared writer sits in fmus/common/, beside the C glue; generators run as scripts.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "common"))
from model_description import Variable, model_description, write_model_description  # noqa: E402

MAX_WAYPOINTS = 1000  # PP_MAX_WAYPOINTS in config.h


def variables() -> list[Variable]:
    """PurePursuit's variables; value references as in config.h."""
    parameters = [
        Variable(
            "desired_linear_velocity",
            0,
            "Real",
            "parameter",
            "Constant linear velocity v (MATLAB DesiredLinearVelocity)",
            "m/s",
            0.1,
        ),
        Variable(
            "max_angular_velocity",
            1,
            "Real",
            "parameter",
            "|omega| is clipped to this (MATLAB MaxAngularVelocity)",
            "rad/s",
            1.0,
            minimum=0.0,
        ),
        Variable(
            "lookahead_distance",
            2,
            "Real",
            "parameter",
            "Arc length from the projection point to the lookahead point (MATLAB LookaheadDistance)",
            "m",
            1.0,
            minimum=1e-9,
        ),
        Variable(
            "goal_tolerance",
            3,
            "Real",
            "parameter",
            "goal_reached when the distance to the last waypoint is at most this; then v = omega = 0",
            "m",
            0.1,
            minimum=0.0,
        ),
        Variable(
            "angular_velocity_law",
            0,
            "Integer",
            "parameter",
            "0: omega = 2 sin(alpha)/L as MATLAB (independent of v); 1: nav2 omega = v * 2 sin(alpha)/L",
            None,
            0,
            minimum=0,
            maximum=1,
        ),
    ]
    inputs = [
        Variable("x", 10, "Real", "input", "Vehicle x in the map frame", "m", 0.0),
        Variable("y", 11, "Real", "input", "Vehicle y in the map frame", "m", 0.0),
        Variable("theta", 12, "Real", "input", "Vehicle heading, counter-clockwise from x", "rad", 0.0),
    ]
    for column, axis, first in ((1, "x", 1000), (2, "y", 2000)):
        inputs += [
            Variable(
                f"waypoints[{k},{column}]",
                first + k - 1,
                "Real",
                "input",
                f"Waypoint {k} {axis} (rows with NaN are ignored)",
                "m",
                math.nan,
            )
            for k in range(1, MAX_WAYPOINTS + 1)
        ]
    outputs = [
        Variable(
            "v", 20, "Real", "output", "Linear velocity command (0 without waypoints or at the goal)", "m/s"
        ),
        Variable("omega", 21, "Real", "output", "Angular velocity command, counter-clockwise", "rad/s"),
        Variable(
            "target_dir",
            22,
            "Real",
            "output",
            "Bearing alpha of the lookahead point in the vehicle frame (MATLAB TargetDir)",
            "rad",
        ),
        Variable(
            "lookahead_x", 23, "Real", "output", "x of the lookahead point (the pose without waypoints)", "m"
        ),
        Variable(
            "lookahead_y", 24, "Real", "output", "y of the lookahead point (the pose without waypoints)", "m"
        ),
        Variable(
            "goal_distance",
            25,
            "Real",
            "output",
            "Distance from the pose to the last waypoint (NaN without waypoints)",
            "m",
        ),
        Variable("goal_reached", 0, "Boolean", "output", "goal_distance <= goal_tolerance"),
    ]
    return parameters + inputs + outputs


def generate() -> str:
    """The modelDescription.xml text of PurePursuit."""
    return model_description(
        "PurePursuit",
        "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d01}",
        "Pure-pursuit path follower, MATLAB controllerPurePursuit compatible (NaN-padded waypoints, "
        "forward-only projection, arc-length lookahead), with a goal check",
        variables(),
        0.05,
    )


if __name__ == "__main__":
    write_model_description(Path(__file__).with_name("modelDescription.xml"), generate())
