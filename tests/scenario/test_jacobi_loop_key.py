"""`[simulation] algebraic_loops = "iterate"` or `"error"` under `master = "jacobi"` would be a key
that silently does nothing (a Jacobi master delays every connection by one macro step: no loop is
ever iterated or refused), so it is refused in one line naming the file and key; the default
"delay" loads under either master."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.errors import CosimError
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


@pytest.mark.parametrize("handling", ["iterate", "error"])
def test_a_loop_handling_jacobi_ignores_is_refused(handling):
    overrides = ["simulation.master=jacobi", f"simulation.algebraic_loops={handling}"]
    with pytest.raises(CosimError) as raised:
        load_scenario(SCENARIO, overrides)
    message = str(raised.value)
    assert "\n" not in message
    assert "[simulation].algebraic_loops" in message and f"'{handling}' has no effect" in message
    assert "master = 'gauss-seidel'" in message


def test_the_default_loads_under_either_master():
    for master in ("jacobi", "gauss-seidel"):
        scenario = load_scenario(
            SCENARIO, [f"simulation.master={master}", "simulation.algebraic_loops=delay"]
        )
        assert (scenario.master, scenario.algebraic_loops) == (master, "delay")
    assert load_scenario(SCENARIO, ["simulation.algebraic_loops=iterate"]).algebraic_loops == "iterate"
