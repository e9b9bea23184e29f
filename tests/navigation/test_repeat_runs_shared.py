"""Later runs in one process (a sweep's worker) take what earlier ones kept: the template's
connections (`cosim.scenario.template._TEMPLATES`), the connection graph and its facts
(`cosim.core.system._GRAPHS`), the project FMUs found up to date (`cosim.fmi.builtin._SEEN_FRESH`),
the kernel's record buffer (`cosim.core.fast_loop._SPARE`).
They write the same bytes as a run with nothing kept, and a scenario of another structure is not
served what the first one kept.

Truth: the log bytes of the same scenario run after those are emptied (as in a fresh process)."""

from __future__ import annotations

from pathlib import Path

import cosim.core.fast_loop as fast_loop
import cosim.core.system as system_module
import cosim.fmi.builtin as builtin
import cosim.scenario.template as template
from cosim.navigation.build import build_run
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
SHORT = "simulation.stop_time=3"


def _forget() -> None:
    system_module._GRAPHS.clear()
    system_module._PENDING.clear()
    template._TEMPLATES.clear()
    builtin._SEEN_FRESH.clear()
    fast_loop._SPARE.clear()


def _log(folder: Path, name: str, overrides: list[str]) -> bytes:
    path = folder / f"{name}.mcap"
    run_scenario(load_scenario(SCENARIO, [SHORT, *overrides]), path)
    return path.read_bytes()


SEEDS = (["lidar.seed=0", "lidar.noise=0.02"], ["lidar.seed=1", "lidar.noise=0.05"])
OTHER = ["lidar.count=180", "planner.replan=false"]  # fewer beams, no replanning: another graph


def test_later_runs_write_the_bytes_of_runs_with_nothing_kept(tmp_path):
    cold = []
    for number, overrides in enumerate([*SEEDS, OTHER]):
        _forget()
        cold.append(_log(tmp_path, f"cold{number}", overrides))
    _forget()
    warm = [
        _log(tmp_path, f"warm{number}", o) for number, o in enumerate([*SEEDS, SEEDS[0], OTHER, SEEDS[1]])
    ]
    assert warm[:3] == [cold[0], cold[1], cold[0]]
    assert warm[3] == cold[2]  # another structure after the first: not served the first one's graph
    assert warm[4] == cold[1]  # and back
    assert cold[0] != cold[1] != cold[2]


def test_runs_of_one_structure_share_one_graph_and_another_gets_its_own():
    first = build_run(load_scenario(SCENARIO, [SHORT, *SEEDS[0]])).system
    second = build_run(load_scenario(SCENARIO, [SHORT, *SEEDS[1]])).system
    other = build_run(load_scenario(SCENARIO, [SHORT, *OTHER])).system
    assert first._graph is not None and second._graph is first._graph
    assert other._graph is not first._graph
    assert len(other.connections) < len(first.connections)
    assert all(c is second.components[c.name] for c in second.order())
