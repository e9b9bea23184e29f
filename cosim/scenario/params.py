"""Parameters as a scenario sets them: numbers or true/false, MATLAB-style pairs.

A component section's keys other than `fmu`, `ports`, `rate`, `isolation`, `nan_outputs` are FMU
parameters. Here, on load, each must be a number, true/false or a string (for an FMU's String
variable, or hex digits for a Binary one: "0a0b" is the two bytes 0x0a 0x0b), and the MATLAB-style pairs
(`distance_limits = [min, max]`, `histogram_thresholds = [low, high]`, ...) are split into the
FMU's two scalar parameters, low <= high. Whether a name exists, its type (Real, Integer, Boolean)
and its range are the FMU's: they are read from its modelDescription.xml (`min`, `max`) when the
scenario is described (`cosim.scenario.compose`), the same for the project's FMUs and any other,
so each range is written once, beside the model that checks it.
"""

from __future__ import annotations

from cosim.scenario.schema import TableReader, describe, is_number

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
    table: TableReader, parameters: dict[str, object]
) -> dict[str, float | int | bool | str]:
    """Check one section's parameters; return parameter name -> value with the pairs split."""
    checked: dict[str, float | int | bool | str] = {}
    for key, value in parameters.items():
        if key in SET_BY_RUN:
            raise table.error(key, f"is set from {SET_BY_RUN[key]}; remove it here")
        if key in PAIRS:
            low, high = table.interval(key, minimum=None)
            checked[PAIRS[key][0]], checked[PAIRS[key][1]] = low, high
            continue
        if isinstance(value, str):
            checked[key] = value  # a String or Binary variable's (the FMU's type is checked on describing)
            continue
        if not (isinstance(value, bool) or is_number(value)):
            raise table.error(
                key, f"an FMU parameter must be a number, true/false or a string, got {describe(value)}"
            )
        checked[key] = table.number(key) if not isinstance(value, bool | int) else value
    for key, (low_name, high_name) in PAIRS.items():
        if low_name in checked and high_name in checked and checked[low_name] > checked[high_name]:
            raise table.error(key, f"low {checked[low_name]:g} > high {checked[high_name]:g}")
    return checked


def pair_key(name: str) -> str | None:
    """The pair key (e.g. `distance_limits`) a split parameter can come from, or None."""
    return next((key for key, names in PAIRS.items() if name in names), None)


def has_start(variable) -> bool:
    """Whether an FMU variable (fmpy's) declares a start value. FMI 2.0 and 3.0 require one on every
    input and parameter (FMI 3.0 Clocks excepted) and define no default for one that lacks it, so an
    unconnected input without a start value has no value to keep: an error, not the type's zero."""
    return getattr(variable, "start", None) not in (None, "")


def unstarted_inputs(layout) -> tuple[str, ...]:
    """The input ports (numbers and text) of an FMU's layout (`cosim.fmi.layout.fmu_layout`)
    whose variable has no start value."""
    variables = {variable.name: variable for variable in layout.model_description.modelVariables}
    return tuple(
        port.name
        for port in (*layout.inputs, *layout.text.get("input", ()))
        if not has_start(
            layout.variables[port.name][0] if port.name in layout.variables else variables[port.name]
        )
    )


def unstarted_problem(port: str, remedy: str) -> str:
    """The one line for an input that nothing feeds and that has no start value."""
    return (
        f"input '{port}' is not connected and the FMU gives it no start value (FMI requires one on "
        f"every input): {remedy}"
    )
