"""Each project FMU parameter's valid range lives in one place, its modelDescription.xml (FMI
`min`/`max`, inclusive; "> 0" is written min = 1e-9), and the scenario check reads it from there.

Truth: the C models' own checks at initialisation (through fmpy): every bound is accepted, and the
nearest value outside it (one integer further, 0 below a 1e-9 minimum, the next double past a
real bound) makes exitInitializationMode fail. Then a scenario value outside a range is one line
naming the key and the range, before any log exists (VFH's 1000 sectors used to pass the loader's
2..3600 and fail inside the FMU, whose capacity is 720).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from fmu_harness import FmuInstance, unpacked

from cosim.cli import main

PROJECT_FMUS = (
    "DifferentialDrive", "Bicycle", "PurePursuit", "VectorFieldHistogram", "ArtificialPotentialField",
    "AvoidanceMixer",
)  # fmt: skip
# Other parameters a bound needs to be checked alone: the pairs (low <= high) and the mixer's
# bicycle-only checks.
CONTEXT = {
    ("VectorFieldHistogram", "distance_limit_max"): {"distance_limit_min": 0.0},
    ("VectorFieldHistogram", "histogram_threshold_high"): {"histogram_threshold_low": 0.0},
    ("ArtificialPotentialField", "distance_limit_max"): {"distance_limit_min": 0.0},
    ("AvoidanceMixer", "wheelbase"): {"vehicle_type": 1},
    ("AvoidanceMixer", "max_steering_angle"): {"vehicle_type": 1},
}
SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _bounds():
    for name in PROJECT_FMUS:
        _, description = unpacked(name)
        for variable in description.modelVariables:
            if variable.causality == "parameter" and (variable.min is not None or variable.max is not None):
                yield name, variable


BOUNDS = list(_bounds())


def test_every_range_checked_parameter_has_its_range_in_the_description():
    named = {(fmu, variable.name) for fmu, variable in BOUNDS}
    for expected in [
        ("VectorFieldHistogram", "num_angular_sectors"),
        ("PurePursuit", "lookahead_distance"),
        ("DifferentialDrive", "wheel_radius"),
        ("Bicycle", "max_steering_angle"),
        ("AvoidanceMixer", "direction_tolerance"),
        ("ArtificialPotentialField", "influence_distance"),
    ]:
        assert expected in named


def _outside(variable, bound: str, side: str):
    value = int(bound) if variable.type == "Integer" else float(bound)
    if variable.type == "Integer":
        return value - 1 if side == "min" else value + 1
    if side == "min" and value == 1e-9:
        return 0.0  # "> 0"
    return math.nextafter(value, -math.inf if side == "min" else math.inf)


def _initialises(fmu: str, values: dict) -> bool:
    instance = FmuInstance(fmu)
    try:
        instance.initialize(**values)
        return True
    except Exception:  # fmpy raises on fmi2Error
        return False
    finally:
        instance.free()


@pytest.mark.parametrize("fmu, variable", BOUNDS, ids=[f"{f}.{v.name}" for f, v in BOUNDS])
def test_the_model_accepts_exactly_the_described_range(fmu, variable):
    context = CONTEXT.get((fmu, variable.name), {})
    for side in ("min", "max"):
        bound = getattr(variable, side)
        if bound is None:
            continue
        inside = int(bound) if variable.type == "Integer" else float(bound)
        assert _initialises(fmu, {**context, variable.name: inside}), (side, bound)
        outside = _outside(variable, bound, side)
        assert not _initialises(fmu, {**context, variable.name: outside}), (side, outside)


@pytest.mark.parametrize(
    "override, message",
    [
        (
            "vfh.num_angular_sectors=1000",
            "[vfh].num_angular_sectors: must be an integer in [1, 720], got 1000",
        ),
        ("pure_pursuit.goal_tolerance=-0.5", "[pure_pursuit].goal_tolerance: must be >= 0, got -0.5"),
        ("mixer.direction_tolerance=-1", "[mixer].direction_tolerance: must be >= 0, got -1"),
    ],
)
def test_a_scenario_value_outside_the_range_is_one_line_before_the_log(override, message, tmp_path, capsys):
    log = tmp_path / "run.mcap"
    overrides = [item for setting in override.split() for item in ("--set", setting)]
    code = main(["run", str(SCENARIO), "--out", str(log), "--quiet", "--no-plot", *overrides])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and message in lines[0], lines
    assert not log.exists()


def test_the_largest_sector_count_runs(tmp_path):
    log = tmp_path / "run.mcap"
    overrides = ["--set", "vfh.num_angular_sectors=720", "--set", "simulation.stop_time=1.0"]
    assert main(["run", str(SCENARIO), "--out", str(log), "--quiet", "--no-plot", *overrides]) == 1
