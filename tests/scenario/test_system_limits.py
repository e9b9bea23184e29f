"""Limits of a system's size: at most `[simulation].max_components` FMU components (one line, raised
with the key), and an error with many problems shows the first `SHOWN_PROBLEMS` and the count of
the rest."""

from __future__ import annotations

import pytest
from test_compose import write_scenario

from cosim.errors import CosimError
from cosim.scenario.compose import SHOWN_PROBLEMS, describe_system
from cosim.scenario.limits import MAX_COMPONENTS
from cosim.scenario.load import load_scenario

BASE = "warehouse_diff_drive_one_obstacle.toml"


def _many_components(count: int) -> str:
    return "".join(f'[components.c{i}]\nfmu = "AvoidanceMixer"\n' for i in range(count))


def test_more_components_than_the_limit_is_one_line_naming_the_key(tmp_path):
    template = 4  # vehicle, pure_pursuit, vfh, mixer
    path = write_scenario(tmp_path, "many", BASE, _many_components(MAX_COMPONENTS - template + 1))
    with pytest.raises(CosimError) as raised:
        load_scenario(path)
    (line,) = str(raised.value).splitlines()
    assert f"{MAX_COMPONENTS + 1} components, above max_components = {MAX_COMPONENTS}" in line
    assert "[simulation].max_components" in line
    assert len(load_scenario(path, [f"simulation.max_components={MAX_COMPONENTS + 1}"]).components) == (
        MAX_COMPONENTS + 1
    )
    at_limit = write_scenario(tmp_path, "at_limit", BASE, _many_components(MAX_COMPONENTS - template))
    assert len(load_scenario(at_limit).components) == MAX_COMPONENTS


def test_many_problems_show_the_first_ones_and_how_many_more(tmp_path):
    bad = "".join(f'[[connections]]\nfrom = "nowhere{i}.y"\nto = "nobody{i}.u"\n' for i in range(15))
    path = write_scenario(tmp_path, "bad", BASE, bad)
    with pytest.raises(CosimError) as raised:
        describe_system(load_scenario(path))
    lines = str(raised.value).splitlines()
    assert len(lines) == SHOWN_PROBLEMS + 1
    assert all("no component 'nobody" in line or "no component 'nowhere" in line for line in lines[:-1])
    assert lines[-1] == f"{path}: ... and {30 - SHOWN_PROBLEMS} more problems"
