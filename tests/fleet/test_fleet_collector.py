"""`cosim run` holds Python's cyclic collector off while it imports and builds
(`cosim.hold_collector`); a fleet run turns it on again when its loop starts, as a robot's run does
(a fleet's loop makes cyclic garbage like any other: left off, it would grow with simulated time).
An uncoordinated fleet has no coordination line nor counts."""

from __future__ import annotations

import gc
from pathlib import Path

import cosim
from cosim.navigation import fleet as fleet_module
from cosim.navigation.fleet import format_fleet, run_fleet
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_a_fleet_run_turns_the_held_collector_on_when_its_loop_starts(monkeypatch):
    seen = []
    loop = fleet_module._run

    def watched(*args, **kwargs):
        seen.append(gc.isenabled())
        return loop(*args, **kwargs)

    monkeypatch.setattr(fleet_module, "_run", watched)
    fleet = load_scenario(SCENARIOS / "fleet_head_on.toml", ["simulation.stop_time=0.5"], fleet=True)
    frozen = gc.get_freeze_count()
    cosim.hold_collector()
    try:
        assert not gc.isenabled()
        outcome = run_fleet(fleet)
    finally:
        cosim.release_collector()  # a no-op when the run released it
        gc.enable()
        if gc.get_freeze_count() > frozen:
            gc.unfreeze()
    assert seen == [True]
    assert outcome.coordination is None
    assert "coordination:" not in format_fleet(fleet, outcome)
