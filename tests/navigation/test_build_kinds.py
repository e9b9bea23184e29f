"""Component kinds are a registry: `cosim.navigation.build.COMPONENT_KINDS` makes every kind the
scenario layer declares (the FMU and the template's Python components), the component a kind makes
is of that kind's class, and a kind added to the registry is built without any other change."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from cosim.core.component import Port, PythonComponent
from cosim.fmi.component import FmuComponent
from cosim.navigation import build
from cosim.navigation.planner import PlannerComponent
from cosim.scenario.compose import describe_system
from cosim.scenario.load import PYTHON_COMPONENTS, load_scenario
from cosim.world.lidar import Lidar

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


def test_registry_makes_every_declared_kind():
    assert set(build.COMPONENT_KINDS) == {"fmu", *PYTHON_COMPONENTS}


def test_each_kind_makes_its_class():
    built = build.build_run(load_scenario(SCENARIO))
    classes = {"fmu": FmuComponent, "planner": PlannerComponent, "lidar": Lidar}
    kinds = {name: c.kind for name, c in built.description.components.items()}
    assert set(kinds.values()) == set(classes)
    for name, kind in kinds.items():
        assert isinstance(built.system.components[name], classes[kind]), name
    assert built.plan is built.planner.result and len(built.plan.path) > 1


class _Echo(PythonComponent):
    """A Python component of a kind the builder did not know: its output is its input."""

    def __init__(self, name: str):
        super().__init__(name, [Port("x", start=0.0)], [Port("y", start=0.0)])

    def step(self, t: float, h: float) -> None:
        self.output_buffer[0] = self.input_buffer[0]


def test_a_new_kind_is_one_entry(monkeypatch: pytest.MonkeyPatch):
    scenario = load_scenario(SCENARIO)
    description = describe_system(scenario)
    echo = replace(
        description.components["planner"],
        name="echo",
        kind="echo",
        inputs=("x",),
        outputs=("y",),
        feedthrough={},
    )
    description = replace(description, components={**description.components, "echo": echo})
    monkeypatch.setitem(
        build.COMPONENT_KINDS, "echo", lambda scenario, grid, component: _Echo(component.name)
    )
    built = build.build_run(scenario, description)
    assert isinstance(built.system.components["echo"], _Echo)
    monkeypatch.delitem(build.COMPONENT_KINDS, "echo")
    with pytest.raises(KeyError, match="echo"):
        build.build_run(scenario, description)
