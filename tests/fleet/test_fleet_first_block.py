"""What a fleet's first block made or brought in first, done before the loop: the robots' /scan and
/cmd_vel channels registered (`FleetSteps.register_step_channels`) against the first block
registering them, and the kernel warmed up (`_warm_up`) against a cold kernel: the same log, its
channels (ids, topics, order of their records among the messages) and messages, byte for byte."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from cosim.core.fast_loop import KernelTables
from cosim.navigation import fleet as fleet_module
from cosim.navigation.fleet_log import outcome_record
from cosim.record.fleet_steps import FleetSteps
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _chunk_records(path: Path) -> list:
    """The log's channel and message records in file order (the chunks' records read out)."""
    found = []
    with open(path, "rb") as stream:
        for record in StreamReader(stream, skip_magic=False, emit_chunks=False).records:
            if isinstance(record, Channel):
                found.append(("channel", record.id, record.topic))
            elif isinstance(record, Message):
                found.append(
                    ("message", record.channel_id, record.sequence, record.log_time, bytes(record.data))
                )
    return found


@pytest.mark.slow  # a fleet run of several seconds
def test_channels_and_kernel_made_before_the_loop_leave_the_same_log(tmp_path, monkeypatch):
    overrides = ["simulation.stop_time=1.5"]
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True)
    registered, filled = [], []
    register = FleetSteps.register_step_channels
    monkeypatch.setattr(
        FleetSteps, "register_step_channels", lambda self, *a: registered.append(a) or register(self, *a)
    )
    warm = KernelTables.warm_up
    monkeypatch.setattr(
        KernelTables, "warm_up", lambda self: filled.append(bool(np.all(self.history == 0))) or warm(self)
    )
    early = fleet_module.run_fleet(fleet, log_path=tmp_path / "early.mcap")
    assert registered == [(0, 10)] and filled == [True]

    monkeypatch.setattr(FleetSteps, "register_step_channels", lambda self, *a: None)
    monkeypatch.setattr(fleet_module, "_warm_up", lambda *a: None)
    fleet = load_scenario(SCENARIOS / "fleet_missions.toml", overrides, fleet=True)
    late = fleet_module.run_fleet(fleet, log_path=tmp_path / "late.mcap")
    assert outcome_record(early) == outcome_record(late)
    records = _chunk_records(tmp_path / "early.mcap")
    assert any(kind == "channel" and topic.endswith("/scan") for kind, _, topic, *_ in records)
    assert records == _chunk_records(tmp_path / "late.mcap")
