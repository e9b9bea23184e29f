"""Parameters of the project FMUs as a scenario sets them: types, ranges, MATLAB-style pairs.

A component section's keys other than `fmu`, `ports`, `rate` are FMU parameters. For the project
FMUs the known ones are checked here on load (type, range, ordering of pairs); the two MATLAB-style
pairs `distance_limits = [min, max]` and `histogram_thresholds = [low, high]` of the VFH are split
into the FMU's scalar parameters. Whether a name exists in the FMU at all is checked against its
modelDescription.xml when the system is built, so FMUs from other tools are checked the same way.
"""

from __future__ import annotations

import math

from cosim.scenario.schema import TableReader, describe, is_number

# name -> (kind, minimum, maximum); kind "float" accepts integers too, "int" only integers.
_POSE = {"x0": ("float", None, None), "y0": ("float", None, None), "theta0": ("float", None, None)}
KNOWN_PARAMETERS: dict[str, dict[str, tuple[str, float | None, float | None]]] = {
    "DifferentialDrive": {
        "input_mode": ("int", 0, 1),
        "wheel_radius": ("float", 1e-9, None),
        "track_width": ("float", 1e-9, None),
        "wheel_speed_min": ("float", None, None),
        "wheel_speed_max": ("float", None, None),
        **_POSE,
    },
    "Bicycle": {
        "input_mode": ("int", 0, 1),
        "steering_mode": ("int", 0, 2),
        "wheelbase": ("float", 1e-9, None),
        "rear_axle_distance": ("float", 0.0, None),
        "max_steering_angle": ("float", 1e-9, math.pi / 2),
        "speed_min": ("float", None, None),
        "speed_max": ("float", None, None),
        **_POSE,
    },
    "PurePursuit": {
        "desired_linear_velocity": ("float", 0.0, None),
        "max_angular_velocity": ("float", 1e-9, None),
        "lookahead_distance": ("float", 1e-9, None),
        "goal_tolerance": ("float", 1e-9, None),
        "angular_velocity_law": ("int", 0, 1),
    },
    "VectorFieldHistogram": {
        "num_angular_sectors": ("int", 2, 3600),
        "distance_limit_min": ("float", 0.0, None),
        "distance_limit_max": ("float", 1e-9, None),
        "robot_radius": ("float", 0.0, None),
        "safety_distance": ("float", 0.0, None),
        "min_turning_radius": ("float", 0.0, None),
        "target_direction_weight": ("float", 0.0, None),
        "current_direction_weight": ("float", 0.0, None),
        "previous_direction_weight": ("float", 0.0, None),
        "histogram_threshold_low": ("float", 0.0, None),
        "histogram_threshold_high": ("float", 0.0, None),
        "narrow_opening_threshold": ("float", 1e-9, None),
    },
    "AvoidanceMixer": {
        "vehicle_type": ("int", 0, 1),
        "wheelbase": ("float", 1e-9, None),
        "max_steering_angle": ("float", 1e-9, math.pi / 2),
        "direction_tolerance": ("float", 0.0, None),
        "avoid_gain": ("float", 0.0, None),
        "recovery_angular_velocity": ("float", 0.0, None),
    },
}
# MATLAB-style pairs: key -> (low parameter, high parameter).
PAIRS = {
    "distance_limits": ("distance_limit_min", "distance_limit_max"),
    "histogram_thresholds": ("histogram_threshold_low", "histogram_threshold_high"),
    "wheel_speed_range": ("wheel_speed_min", "wheel_speed_max"),
    "speed_range": ("speed_min", "speed_max"),
}
# Parameters the run sets from other sections; setting them in the section too would be ambiguous.
SET_BY_RUN = {"x0": "[start].x", "y0": "[start].y", "theta0": "[start].theta"}


def check_parameters(
    table: TableReader, fmu: str, parameters: dict[str, object]
) -> dict[str, float | int | bool]:
    """Validate one section's parameters; return role parameter name -> value with pairs split."""
    checked: dict[str, float | int | bool] = {}
    known = KNOWN_PARAMETERS.get(fmu, {})
    for key, value in parameters.items():
        if key in SET_BY_RUN:
            raise table.error(key, f"is set from {SET_BY_RUN[key]}; remove it here")
        if key in PAIRS:
            low, high = table.interval(key, minimum=None)
            checked[PAIRS[key][0]], checked[PAIRS[key][1]] = low, high
            continue
        if isinstance(value, bool):
            checked[key] = value
            continue
        if not is_number(value):
            raise table.error(key, f"an FMU parameter must be a number or true/false, got {describe(value)}")
        kind, minimum, maximum = known.get(key, ("float", None, None))
        if kind == "int":
            checked[key] = table.integer(key)
            if minimum is not None and value < minimum or maximum is not None and value > maximum:
                raise table.error(key, f"must be an integer in [{minimum:g}, {maximum:g}], got {value}")
        else:
            checked[key] = table.number(key, minimum=minimum, maximum=maximum)
    for low_name, high_name in PAIRS.values():
        if low_name in checked and high_name in checked and checked[low_name] > checked[high_name]:
            pair = next(key for key, names in PAIRS.items() if names[0] == low_name)
            raise table.error(pair, f"low {checked[low_name]:g} > high {checked[high_name]:g}")
    return checked
