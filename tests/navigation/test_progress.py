"""The progress bar of a run ends full whatever ends the run (issue 15: it used to vanish at about
37 % when the goal was reached before the stop time)."""

from __future__ import annotations

import re
from pathlib import Path

from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _last_bar(text: str) -> tuple[int, float, float]:
    states = re.findall(r"simulated:\s+(\d+)%\|[^|]*\|\s*([\d.]+)/([\d.]+) s", text)
    percent, done, total = states[-1]
    return int(percent), float(done), float(total)


def test_bar_is_full_when_the_goal_is_reached_early(tmp_path, capsys):
    result = run_scenario(load_scenario(SCENARIO), tmp_path / "run.mcap", progress=True)
    assert result.outcome.reached and result.outcome.time < 200.0 / 2  # well before the stop time
    percent, done, total = _last_bar(capsys.readouterr().err)
    assert percent == 100 and done == total == round(result.outcome.time, 1)


def test_bar_is_full_at_the_stop_time(tmp_path, capsys):
    scenario = load_scenario(SCENARIO, ["simulation.stop_time=5.0"])
    result = run_scenario(scenario, tmp_path / "run.mcap", progress=True)
    assert not result.outcome.reached and result.outcome.reason == "stop_time"
    assert _last_bar(capsys.readouterr().err) == (100, 5.0, 5.0)
