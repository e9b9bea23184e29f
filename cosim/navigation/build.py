"""From a validated `Scenario` to a ready `System`: the checked description, made into components.

`cosim.scenario.compose.describe_system` says what the system is (the navigation template plus
the scenario's components and connections) and checks it as a whole; this module makes each
component by its kind (`COMPONENT_KINDS`: an FMU, the planner, the lidar), sets held inputs,
wires the connections, and plans the path. Everything that can fail because of the input happens
here, before a log exists: the known map loads, every FMU loads, the plan is found, and the
connection graph has no algebraic loop (unless `[simulation] algebraic_loops = "delay"`, the
default, runs it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cosim.core.component import Component
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.navigation.planner import PlannerComponent, Replanning
from cosim.scenario.compose import describe_system
from cosim.scenario.description import ComponentDescription, SystemDescription
from cosim.scenario.load import Scenario
from cosim.world.distance import WorldDistance, load_known_map

if TYPE_CHECKING:
    from planner import OccupancyGrid

# Role outputs whose NaN is a value, whatever FMU fills the role: VFH's steering direction is NaN when
# no direction is free, which the mixer answers with recovery. Every other FMU output must be finite
# (unless the component's `nan_outputs` or the project FMU's documentation says otherwise).
ROLE_NAN_OUTPUTS = {"vfh": ("steering_dir",)}


@dataclass
class BuiltRun:
    """A system ready to initialise, and what the run loop and the log need besides."""

    scenario: Scenario
    description: SystemDescription
    system: System
    parameters: dict[str, dict[str, float]]
    grid: object  # planner.OccupancyGrid (known map)
    inflated: object  # the known map inflated by the expansion distance
    world: WorldDistance
    plan: object  # planner.PlanResult of the planner component (its first plan)
    planner: PlannerComponent | None = None  # the template's planner (replans, no_path)


def make_fmu(
    component: ComponentDescription,
    isolation: str = "none",
    timeout: float = Scenario.fmu_timeout,
    max_unpacked_size: int | None = None,
    nan_outputs: tuple[str, ...] = (),
    max_memory: int | None = round(Scenario.fmu_max_memory * (1 << 20)),
) -> Component:
    """The FMU component of a description (its interface as described: port map, dependencies), in
    this process (`isolation` "none") or in a child process ("process", calls limited to `timeout`
    seconds, its memory to `max_memory` bytes); `nan_outputs` may be NaN. A Model Exchange FMU
    (`component.integration`) is a `cosim.fmi.model_exchange.ModelExchangeComponent`."""
    from cosim.fmi.model_exchange import fmu_component

    port_map = {port: {"name": m.variable, "scale": m.scale} for port, m in component.port_map.items()}
    override = dict(component.feedthrough)  # (outputs sharing a tuple keep sharing it: checked once)
    options = {"port_map": port_map, "period": component.period, "feedthrough_override": override}
    options.update(max_unpacked_size=max_unpacked_size, nan_outputs=nan_outputs)
    given = component.integration
    if given.interface == "me":
        options["integration"] = {
            "solver": given.solver,
            "tolerance": given.tolerance,
            "max_step": given.max_step,
        }
    if isolation == "process":
        from cosim.fmi.isolated import IsolatedFmuComponent

        fmu = IsolatedFmuComponent(
            component.fmu, component.name, timeout=timeout, max_memory=max_memory, **options
        )
    else:
        fmu = fmu_component(path=component.fmu, name=component.name, **options)
    for name, value in component.held_inputs.items():
        if isinstance(value, str):  # a String's, or a Binary's in hex (`cosim.fmi.text`)
            fmu.set_text(name, value)
        else:
            fmu.input_buffer[fmu.input_index[name]] = value
    return fmu


def replanning(scenario: Scenario) -> Replanning:
    """The replanning settings of `scenario`; a bicycle replans with Hybrid A* at `[planner]`'s
    min_turning_radius, else its wheelbase / tan(max_steering_angle)."""
    settings = scenario.planner
    turning_radius = None
    if scenario.vehicle_type == "bicycle" or settings.algorithm == "hybrid":
        turning_radius = settings.min_turning_radius
        vehicle = scenario.components["vehicle"].parameters
        if turning_radius is None and "wheelbase" in vehicle and "max_steering_angle" in vehicle:
            turning_radius = float(vehicle["wheelbase"]) / math.tan(float(vehicle["max_steering_angle"]))
        if turning_radius is None or not turning_radius > 0:
            raise CosimError(
                f"{scenario.source}: [planner].min_turning_radius: a bicycle replans with Hybrid A*, "
                "which needs it (or [vehicle] wheelbase and max_steering_angle)"
            )
    return Replanning(
        angles=np.asarray(scenario.lidar.angles, dtype=float),
        range_min=scenario.lidar.range_min,
        range_max=scenario.lidar.range_max,
        vehicle_radius=scenario.vehicle_radius,
        hybrid_turning_radius=turning_radius,
        replan_after=settings.replan_after,
        replan_stall_time=settings.replan_stall_time,
        replan_horizon=settings.replan_horizon,
        replan_interval=settings.replan_interval,
    )


def _fmu(scenario: Scenario, grid: OccupancyGrid, component: ComponentDescription) -> Component:
    """An FMU of the scenario, where `Scenario.isolation` says, with its NaN allowance."""
    from cosim.fmi.archive import MIB

    spec = scenario.components[component.name]
    outputs = set(component.outputs)
    for port in spec.nan_outputs:
        if port not in outputs:
            raise CosimError(
                f"{scenario.source}: {component.where}.nan_outputs: '{port}' is not an output of the FMU; "
                f"outputs: {', '.join(component.outputs)[:400]}"
            )
    allowed = spec.nan_outputs + tuple(p for p in ROLE_NAN_OUTPUTS.get(component.name, ()) if p in outputs)
    try:
        return make_fmu(
            component,
            scenario.isolation(spec),
            scenario.fmu_timeout,
            round(scenario.fmu_max_size * MIB),
            allowed,
            round(scenario.fmu_max_memory * MIB),
        )
    except CosimError as error:
        raise CosimError(f"{scenario.source}: {component.where}.fmu: {error}") from None


def _planner(scenario: Scenario, grid: OccupancyGrid, component: ComponentDescription) -> Component:
    """The planner on the known map, with its first plan made (a replanning one when it has inputs)."""
    planner = PlannerComponent(
        component.name,
        grid,
        scenario.start,
        scenario.goal,
        scenario.planner,
        period=component.period,
        replanning=replanning(scenario) if component.inputs else None,
    )
    try:
        planner.plan_path()
    except CosimError as error:
        raise CosimError(f"{scenario.source}: {error}") from None
    return planner


def _lidar(scenario: Scenario, grid: OccupancyGrid, component: ComponentDescription) -> Component:
    """The lidar casting on the true world: the map and the scenario's obstacles (and, for a fleet
    robot, the other robots' footprints)."""
    from cosim.world.lidar import Lidar

    lidar = scenario.lidar
    return Lidar(
        component.name,
        occupied=grid.occupied,
        resolution=grid.resolution,
        origin=grid.origin,
        obstacles=scenario.obstacles,
        angles=lidar.angles,
        range_min=lidar.range_min,
        range_max=lidar.range_max,
        range_noise=lidar.noise,
        seed=lidar.seed,
        period=component.period,
        robot_radii=component.robot_radii,
    )


# What makes a component of each `ComponentDescription.kind`: (scenario, known map, description) ->
# component. A new kind is a new entry here; its name is also in `cosim.scenario.load.PYTHON_COMPONENTS`
# when the navigation template declares it (tests/navigation/test_build_kinds.py keeps the two in step).
COMPONENT_KINDS: dict[str, Callable[[Scenario, OccupancyGrid, ComponentDescription], Component]] = {
    "fmu": _fmu,
    "planner": _planner,
    "lidar": _lidar,
}


# Known maps of this process, by content (cells, resolution, origin): a fleet's robots share one
# map object (a grid is read-only, and what the planner derives from it, its distance field and search
# maps, is kept with it: made once for every robot instead of once per robot). A few are kept.
_KNOWN_MAPS: dict[tuple, OccupancyGrid] = {}
_KNOWN_MAPS_KEPT = 4


def _known_map(scenario: Scenario) -> OccupancyGrid:
    """`load_known_map(scenario)`, or the grid of the same content read before in this process."""
    grid = load_known_map(scenario)
    key = (grid.occupied.shape, grid.occupied.tobytes(), grid.resolution, tuple(grid.origin))
    known = _KNOWN_MAPS.get(key)
    if known is not None:
        return known
    if len(_KNOWN_MAPS) >= _KNOWN_MAPS_KEPT:
        _KNOWN_MAPS.pop(next(iter(_KNOWN_MAPS)))
    _KNOWN_MAPS[key] = grid
    return grid


def build_run(scenario: Scenario, description: SystemDescription | None = None) -> BuiltRun:
    """Describe, check and build the system of `scenario` (or the `description` made of it: a
    fleet robot's, `cosim.scenario.fleet_compose`); plan the path."""
    description = describe_system(scenario) if description is None else description
    grid = _known_map(scenario)
    expansion = scenario.planner.expansion_distance
    inflated = grid.inflate(expansion) if expansion > 0 else grid
    world = WorldDistance(grid, scenario.obstacles)
    system = System(
        description.macro_step,
        description.master,
        description.algebraic_loops,
        scenario.loop_tolerance,
        scenario.loop_max_iterations,
    )
    for component in description.components.values():
        system.add(COMPONENT_KINDS[component.kind](scenario, grid, component))
    system.connect_many((c.source, c.target, c.scale, c.offset) for c in description.connections)
    for made in system.components.values():
        system.period_steps(made)
    parameters = {
        name: dict(component.parameters)
        for name, component in description.components.items()
        if component.kind == "fmu"
    }
    planner = next((c for c in system.components.values() if isinstance(c, PlannerComponent)), None)
    plan = planner.result if planner is not None else None
    return BuiltRun(scenario, description, system, parameters, grid, inflated, world, plan, planner)
