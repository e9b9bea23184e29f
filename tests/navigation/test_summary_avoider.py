"""The run summary names the avoider that ran: "APF interventions" where the potential field
took VFH's place (it said "VFH interventions" whatever ran)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main
from cosim.navigation.outcome import avoider_name
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize(
    ("scenario", "name"),
    [("warehouse_apf.toml", "APF"), ("warehouse_diff_drive_one_obstacle.toml", "VFH")],
)
def test_the_summary_names_the_fmu_in_the_avoidance_role(scenario, name, tmp_path, capsys):
    loaded = load_scenario(SCENARIOS / scenario)
    assert avoider_name(loaded) == name
    short = ["--set", "simulation.stop_time=0.2", "--no-plot", "--out", str(tmp_path / "r.mcap")]
    assert main(["run", str(SCENARIOS / scenario), *short]) == 1
    out = capsys.readouterr().out
    assert f"{name} interventions" in out
    other = {"APF": "VFH", "VFH": "APF"}[name]
    assert f"{other} interventions" not in out


def test_a_removed_avoidance_role_is_named_generically():
    """The summary only reads the components and what `[system] remove` took out."""
    from types import SimpleNamespace

    assert avoider_name(SimpleNamespace(components={}, removed=("vfh",))) == "avoidance"
