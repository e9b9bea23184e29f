"""A bicycle's `wheelbase` or `max_steering_angle` given as a string (a mutant the scenario mutator
found) is one line naming the key, exit 2: the mixer takes both from the vehicle as defaults, and
converting the string there raised a ValueError traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_bicycle_one_obstacle.toml"


@pytest.mark.parametrize("command", ["run", "system"])
@pytest.mark.parametrize("key", ["wheelbase", "max_steering_angle"])
def test_a_string_vehicle_geometry_is_one_line(tmp_path, capsys, command, key):
    argv = [command, str(SCENARIO), f'--set=vehicle.{key}="xxx"']
    if command == "run":
        argv += ["--no-plot", "--quiet", "--out", str(tmp_path / "run.mcap")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert (
        err == f"cosim: error: {SCENARIO}: [vehicle].{key}: must be a number (the FMU's Real), got a string\n"
    )
    assert not (tmp_path / "run.mcap").exists()
