"""A rate that does not fit the macro step is refused with rates that do fit, and the command
scenarios/README.md gives for its outcome table runs as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.scenario.load import fitting_rates, rate_problem

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ("rate", "step"), [(50.0, 0.05), (20.0, 0.03), (7.0, 0.01), (1000.0, 0.01), (0.3, 0.1)]
)
def test_every_suggested_rate_fits(rate, step):
    problem = rate_problem(rate, step)
    assert problem is not None and "rates that fit:" in problem
    suggested = fitting_rates(rate, step)
    assert len(suggested) == 3 and suggested == sorted(suggested, reverse=True)
    for fitting in suggested:
        assert rate_problem(fitting, step) is None
        steps = 1 / (fitting * step)
        assert abs(steps - round(steps)) < 1e-9  # a whole number of steps, by arithmetic
    nearest = min(suggested, key=lambda r: abs(r - rate))
    n = round(1 / (rate * step))
    assert nearest in (pytest.approx(1 / (max(n, 1) * step)), pytest.approx(1 / ((n + 1) * step)))


def test_the_readme_outcome_command_runs_as_written(tmp_path, capsys):
    text = (REPO / "scenarios" / "README.md").read_text()
    command = re.search(r"`(python3 -m cosim run S [^`]*)`", text).group(1)
    words = shlex.split(command.replace("false|true", "true"))
    scenario = REPO / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    arguments = [str(scenario) if word == "S" else word for word in words[4:]]
    short = ["--set", "simulation.stop_time=1", "--no-plot", "--out", str(tmp_path / "r.mcap")]
    assert main(["run", *arguments, *short]) == 1  # stop time reached: it ran
    assert "error" not in capsys.readouterr().err
