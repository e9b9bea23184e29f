"""A fleet is built with the cyclic garbage collector paused (`cosim.navigation.fleet._collector_paused`):
afterwards the caller's collector is as it was (on or off), objects a caller froze stay frozen, and
what the build made is still collected when it becomes garbage."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

import pytest

from cosim.navigation.fleet import _collector_paused, run_fleet
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


class _Node:
    pass


def _cycle() -> weakref.ref:
    node = _Node()
    node.me = node  # only the collector frees it
    return weakref.ref(node)


@pytest.mark.parametrize("enabled", [True, False])
def test_the_collector_is_as_the_caller_left_it(enabled):
    was = gc.isenabled()
    (gc.enable if enabled else gc.disable)()
    try:
        with _collector_paused():
            assert not gc.isenabled()
            made = _cycle()
        assert gc.isenabled() == enabled
        gc.collect()
        assert made() is None  # the build's garbage is garbage still
    finally:
        (gc.enable if was else gc.disable)()


def test_objects_frozen_by_the_caller_stay_frozen():
    # A frozen cycle is never collected: it is garbage already, and survives a collection only while
    # it stays frozen. (Not the freeze count: another thread, pytest-xdist's, may free frozen objects.)
    frozen = _cycle()
    gc.freeze()
    try:
        with _collector_paused():
            _cycle()
        gc.collect()
        assert frozen() is not None
    finally:
        gc.unfreeze()
    gc.collect()
    assert frozen() is None


@pytest.mark.slow
def test_a_fleet_run_leaves_the_collector_on():
    fleet = load_scenario(SCENARIOS / "fleet_head_on.toml", ["simulation.stop_time=0.5"], fleet=True)
    assert gc.isenabled()
    frozen = gc.get_freeze_count()
    run_fleet(fleet)
    assert gc.isenabled() and gc.get_freeze_count() == frozen
