"""A fleet's kernel block as calls side by side on the block program's threads, each on tables of a
part of the robots (`_SplitKernel`), against the one kernel call on all of them: after every block
every component's inputs and outputs bit for bit, the same outcome and the same log, message for
message, through a last block cut at the stop time (stepped by the one call, after the split
calls); and no split where an FMU reads another robot's FMU."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from fixtures.mcap_messages import logged_messages

from cosim.core.system import System
from cosim.navigation import fleet as fleet_module
from cosim.navigation.fleet_log import outcome_record
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _threads(patched) -> None:
    """Block programs on two threads from two robots' chains on (so ten robots use them)."""
    patched.setattr(fleet_module._BlockProgram, "threads", 2)
    patched.setattr(fleet_module._BlockProgram, "MIN_CHAINS", 2)


def _run(monkeypatch, log: Path, split: bool) -> tuple:
    """fleet_missions (ten robots) to 3.05 s: the outcome, every component's buffers after each
    block, and the splits made."""
    blocks, made = [], []
    advance = fleet_module._advance
    make = fleet_module._SplitKernel.make.__func__

    def recorded(master, robots, count, tables, python=None, rows=None, split=None):
        histories = advance(master, robots, count, tables, python, rows, split)
        state = [
            (c.input_buffer.tobytes(), c.output_buffer.tobytes()) for c in master.system.components.values()
        ]
        blocks.append((master.step_index, state, split is not None and split.active))
        return histories

    def making(cls, *args):
        made.append(make(cls, *args) if split else None)
        return made[-1]

    with monkeypatch.context() as patched:
        _threads(patched)
        patched.setattr(fleet_module, "_advance", recorded)
        patched.setattr(fleet_module._SplitKernel, "make", classmethod(making))
        fleet = load_scenario(SCENARIOS / "fleet_missions.toml", ["simulation.stop_time=3.05"], fleet=True)
        outcome = fleet_module.run_fleet(fleet, log_path=log)
    return outcome, blocks, made


@pytest.mark.slow  # a fleet run of several seconds
def test_split_kernel_steps_as_the_one_call(tmp_path, monkeypatch):
    fast, fast_blocks, made = _run(monkeypatch, tmp_path / "split.mcap", split=True)
    slow, slow_blocks, _ = _run(monkeypatch, tmp_path / "one.mcap", split=False)
    assert made and made[0] is not None and len(made[0].parts) == fleet_module._SplitKernel.PARTS
    active = [on for _, _, on in fast_blocks]
    assert all(active[:-1]) and not active[-1]  # the cut last block: the one call
    assert not any(on for _, _, on in slow_blocks)
    assert [(k, state) for k, state, _ in fast_blocks] == [(k, state) for k, state, _ in slow_blocks]
    assert outcome_record(fast) == outcome_record(slow)
    assert logged_messages(tmp_path / "split.mcap") == logged_messages(tmp_path / "one.mcap")


def test_no_split_where_an_fmu_reads_another_robots(monkeypatch):
    made = []
    make = fleet_module._SplitKernel.make.__func__
    links = System.links

    def linked(system):
        # robot1's mixer reading robot10's vehicle (as if connected): the split is refused
        found = dict(links(system))
        fed = list(found.get("robot1:mixer", []))
        found["robot1:mixer"] = [*fed, SimpleNamespace(producer="robot10:vehicle")]
        return found

    def making(cls, master, *args):
        made.append(make(cls, master, *args))
        with monkeypatch.context() as patched:
            patched.setattr(System, "links", linked)
            made.append(make(cls, master, *args))
        return made[0]

    with monkeypatch.context() as patched:
        _threads(patched)
        patched.setattr(fleet_module._SplitKernel, "make", classmethod(making))
        fleet = load_scenario(SCENARIOS / "fleet_missions.toml", ["simulation.stop_time=0.2"], fleet=True)
        fleet_module.run_fleet(fleet)
    assert made[0] is not None and made[1] is None
