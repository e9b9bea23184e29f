"""The template's connections are made once per (replanning, beams, vehicle type) in a process
(`template._TEMPLATES`): each call hands out a new list of the same connections, with their ends
split (`template_ends`), and a scenario of other beams or replanning gets its own.

Truth: the connections made with nothing kept, and `str.partition` of each end."""

from pathlib import Path

import cosim.scenario.template as template
from cosim.scenario.load import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def _made_afresh(scenario):
    template._TEMPLATES.clear()
    return [(c.source, c.target, c.scale, c.offset, c.where) for c in template.template_connections(scenario)]


def test_kept_connections_and_their_ends_are_those_made_afresh():
    other = ["lidar.count=90", "planner.replan=false"]
    for overrides in ([], other[:1], other[1:], other):
        scenario = load_scenario(SCENARIO, overrides)
        truth = _made_afresh(scenario)
        first = template.template_connections(scenario)
        second = template.template_connections(scenario)
        assert first is not second and first == second
        assert [(c.source, c.target, c.scale, c.offset, c.where) for c in second] == truth
        ends = template.template_ends(scenario)
        assert list(ends) == [(*c.source.partition(".")[::2], *c.target.partition(".")[::2]) for c in second]
        second.clear()  # a caller's list is its own
        assert len(template.template_connections(scenario)) == len(truth)


def test_another_structure_gets_its_own_connections():
    template._TEMPLATES.clear()
    full = template.template_connections(load_scenario(SCENARIO))
    fewer = template.template_connections(load_scenario(SCENARIO, ["lidar.count=90"]))
    assert len(fewer) < len(full) and not any("ranges[91]" in c.target for c in fewer)
