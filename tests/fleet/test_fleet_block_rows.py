"""Every robot's poses, commands and modes of a block gathered at once from the kernel's record
buffer (`_BlockRows`) against each robot taking its own from its components' rows
(`_Robot.take`): after every block the same arrays bit for bit, for robots stepped and switched
off (`_halt`), and the same outcome and log, message for message."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fixtures.mcap_messages import logged_messages

from cosim.navigation import fleet as fleet_module
from cosim.navigation.fleet_log import outcome_record
from cosim.scenario.load import load_scenario, parse_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _run(monkeypatch, fleet, log: Path, batched: bool) -> tuple:
    """The run of `fleet` logged to `log`: its outcome, per block every robot's arrays (as bytes)
    and whether they were gathered at once."""
    blocks: list = []
    advance = fleet_module._advance

    def recorded(master, robots, count, tables, *args):
        histories = advance(master, robots, count, tables, *args)
        rows = args[1] if len(args) > 1 else None
        arrays = [
            (np.asarray(each.poses, float).tobytes(), np.asarray(each.commands_now, float).tobytes(),
             np.asarray(each.modes, float).tobytes(), each.halted)
            for each in robots
        ]  # fmt: skip
        blocks.append((master.step_index, arrays, rows is not None and rows.pose_rows is not None))
        return histories

    with monkeypatch.context() as patched:
        patched.setattr(fleet_module, "_advance", recorded)
        if not batched:
            patched.setattr(fleet_module._BlockRows, "make", classmethod(lambda *_: None))
        outcome = fleet_module.run_fleet(fleet, log_path=log)
    return outcome, blocks


def test_rows_gathered_at_once_are_each_robots_own(tmp_path, monkeypatch):
    # fleet_head_on with on_collision = "continue", robot1 starting 0.2 m into a rack: it hits it in
    # its first step and is switched off at the end of the first block, while robot2 drives on.
    text = (SCENARIOS / "fleet_head_on.toml").read_text()
    text = text.replace('on_collision = "stop"', 'on_collision = "continue"')
    text = text.replace(
        "start = { x = 12.0, y = 19.0, theta = 0.0 }",
        "start = { x = 20.0, y = 15.3, theta = 0.0 }\nplanner = { expansion_distance = 0.1 }",
    )
    text = text.replace("stop_time = 60.0", "stop_time = 6.0")

    def fleet():
        return parse_scenario(text, "wall.toml", SCENARIOS)

    fast, fast_blocks = _run(monkeypatch, fleet(), tmp_path / "fast.mcap", batched=True)
    slow, slow_blocks = _run(monkeypatch, fleet(), tmp_path / "slow.mcap", batched=False)
    assert fast.robots[0].status == "collision"
    gathered = [taken for _, _, taken in fast_blocks]
    halted = [any(h for *_, h in arrays) for _, arrays, _ in fast_blocks]
    assert all(gathered) and halted[0] is False and any(halted)  # before and after the halt
    assert not any(taken for _, _, taken in slow_blocks)
    assert [(k, arrays) for k, arrays, _ in fast_blocks] == [(k, arrays) for k, arrays, _ in slow_blocks]
    assert outcome_record(fast) == outcome_record(slow)
    assert logged_messages(tmp_path / "fast.mcap") == logged_messages(tmp_path / "slow.mcap")


@pytest.mark.slow
def test_rows_gathered_at_once_through_goals_dwells_and_a_cut_last_block(tmp_path, monkeypatch):
    # fleet_missions (ten robots, a mode component stepped every 5 steps) to 7.55 s: the last
    # block is cut at the stop time (its steps one at a time: each robot takes its own).
    overrides = ["simulation.stop_time=7.55"]
    fast, fast_blocks = _run(
        monkeypatch, load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True),
        tmp_path / "fast.mcap", batched=True,
    )  # fmt: skip
    slow, slow_blocks = _run(
        monkeypatch, load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True),
        tmp_path / "slow.mcap", batched=False,
    )  # fmt: skip
    assert math.isclose(fast.time, 7.55)
    gathered = [taken for _, _, taken in fast_blocks]
    assert sum(gathered) >= len(gathered) - 1
    assert [(k, arrays) for k, arrays, _ in fast_blocks] == [(k, arrays) for k, arrays, _ in slow_blocks]
    assert outcome_record(fast) == outcome_record(slow)
    assert logged_messages(tmp_path / "fast.mcap") == logged_messages(tmp_path / "slow.mcap")
