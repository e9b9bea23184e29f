"""From a validated `Scenario` to a ready `System`: components, parameters and connections.

Everything that can fail because of the input happens here, before a log exists: the known map
loads, the plan is found, every FMU loads (zip, platform binary, co-simulation support), every
mapped port and parameter exists, and the connection graph has no algebraic loop.

Connections (role ports; see scenarios/README.md):
    vehicle.x/y/theta        -> pure_pursuit.x/y/theta, lidar.x/y/theta
    planner.waypoints[k,c]   -> pure_pursuit.waypoints[k,c]
    lidar.ranges[k]/angles[k]-> vfh.ranges[k]/angles[k]
    pure_pursuit.target_dir  -> vfh.target_dir, mixer.target_dir
    pure_pursuit.v/omega/goal_reached -> mixer.v_in/omega_in/goal_reached
    vfh.steering_dir         -> mixer.steering_dir
    mixer.v, mixer.omega     -> vehicle.v, vehicle.omega            (differential drive)
    mixer.v, mixer.steering_angle -> vehicle.v, vehicle.steering_angle (bicycle)
"""

from __future__ import annotations

from dataclasses import dataclass

from cosim.core.master import System
from cosim.errors import CosimError
from cosim.navigation.planner import PlannerComponent
from cosim.scenario.load import ComponentSpec, Scenario
from cosim.world.distance import WorldDistance, load_known_map

ROLE_INPUTS = {
    "pure_pursuit": ("x", "y", "theta"),
    "vfh": ("target_dir",),
    "mixer": ("v_in", "omega_in", "target_dir", "steering_dir", "goal_reached"),
}
ROLE_OUTPUTS = {
    "vehicle": ("x", "y", "theta"),
    "pure_pursuit": ("v", "omega", "target_dir", "goal_reached"),
    "vfh": ("steering_dir",),
    "mixer": ("v", "omega", "steering_angle", "mode"),
}
VEHICLE_INPUTS = {"differential": ("v", "omega"), "bicycle": ("v", "steering_angle")}


@dataclass
class BuiltRun:
    """A system ready to initialise, and what the run loop and the log need besides."""

    scenario: Scenario
    system: System
    parameters: dict[str, dict[str, float]]
    grid: object  # planner.OccupancyGrid (known map)
    inflated: object  # the known map inflated by the expansion distance
    world: WorldDistance
    planner: PlannerComponent


def _where(scenario: Scenario, role: str) -> str:
    return f"{scenario.source}: [{role}]"


def role_parameters(scenario: Scenario, spec: ComponentSpec) -> dict[str, float]:
    """The section's parameters plus those the run derives from other sections (unless set)."""
    values = dict(spec.parameters)
    derived: dict[str, float] = {}
    if spec.role == "vehicle":
        derived = {"x0": scenario.start[0], "y0": scenario.start[1], "theta0": scenario.start[2]}
    elif spec.role == "pure_pursuit":
        derived = {"goal_tolerance": scenario.goal_tolerance}
    elif spec.role == "mixer":
        vehicle = scenario.components["vehicle"].parameters
        derived = {"vehicle_type": 0 if scenario.vehicle_type == "differential" else 1}
        for name in ("wheelbase", "max_steering_angle"):
            if name in vehicle:
                derived[name] = vehicle[name]
    for name, value in derived.items():
        values.setdefault(name, value)
    return {name: float(value) for name, value in values.items()}, set(derived) - set(spec.parameters)


def _fmu_component(scenario: Scenario, spec: ComponentSpec):
    """Load the FMU of one role with its port mapping; errors name the scenario file and section."""
    from cosim.fmi.builtin import builtin_fmu
    from cosim.fmi.component import FmuComponent

    where = _where(scenario, spec.role)
    try:
        path = builtin_fmu(spec.fmu) if spec.is_builtin else spec.fmu
        port_map = {role: {"name": m.variable, "scale": m.scale} for role, m in spec.ports.items()}
        period = 0.0 if spec.rate is None else 1.0 / spec.rate
        return FmuComponent(path, spec.role, port_map=port_map, period=period)
    except CosimError as error:
        raise CosimError(f"{where}.fmu: {error}") from None


def _pose_is_state(vehicle) -> None:
    """Treat the vehicle's x, y, theta as states when its FMU does not declare their dependencies.

    FMI reads a missing `dependencies` attribute as "depends on every input", which would make the
    closed loop vehicle -> controllers -> vehicle an algebraic loop. A kinematic vehicle integrates
    its inputs, so its pose at the end of a step never depends on the inputs of the next one; an FMU
    that declares its dependencies explicitly is taken at its word.
    """
    declared = {
        unknown.variable.name
        for unknown in vehicle.model_description.outputs
        if unknown.dependencies is not None
    }
    for port in ("x", "y", "theta"):
        variable = vehicle._variables[port][0]
        if variable.name not in declared:
            vehicle.feedthrough[port] = []


def _check_ports(scenario: Scenario, component, role: str, names, kind: str) -> None:
    known = component.input_index if kind == "input" else component.output_index
    for name in names:
        if name not in known:
            listed = ", ".join(p.name for p in (component.inputs if kind == "input" else component.outputs))
            raise CosimError(
                f"{_where(scenario, role)}.ports: the FMU has no {kind} for port '{name}'; map it with "
                f'ports = {{ {name} = "<variable>" }}; its {kind}s: {listed[:400]}'
            )


def build_run(scenario: Scenario) -> BuiltRun:
    """Build every component and connection of `scenario` (see the module docstring)."""
    from cosim.world.lidar import Lidar

    grid = load_known_map(scenario)
    expansion = scenario.planner.expansion_distance
    inflated = grid.inflate(expansion) if expansion > 0 else grid
    world = WorldDistance(grid, scenario.obstacles)
    controller_period = 1.0 / scenario.controller_rate
    planner = PlannerComponent(
        "planner", grid, scenario.start, scenario.goal, scenario.planner, period=controller_period
    )
    try:
        planner.plan_path()
    except CosimError as error:
        raise CosimError(f"{scenario.source}: {error}") from None

    system = System(scenario.macro_step, scenario.master)
    parameters: dict[str, dict[str, float]] = {}
    fmus = {}
    for role in ("vehicle", "pure_pursuit", "vfh", "mixer"):
        spec = scenario.components[role]
        component = _fmu_component(scenario, spec)
        values, derived = role_parameters(scenario, spec)
        known = {p.name for p in component.parameters}
        for name in list(values):
            if name in known:
                continue
            if name in derived and not (role == "vehicle"):
                del values[name]  # a derived default the FMU does not have: nothing to set
                continue
            from cosim.scenario.schema import did_you_mean

            raise CosimError(
                f"{_where(scenario, role)}.{name}: the FMU has no parameter '{name}'"
                f"{did_you_mean(name, known)}"
            )
        parameters[role] = values
        fmus[role] = component
    lidar = Lidar(
        "lidar",
        occupied=grid.occupied,
        resolution=grid.resolution,
        origin=grid.origin,
        obstacles=scenario.obstacles,
        angles=scenario.lidar.angles,
        range_min=scenario.lidar.range_min,
        range_max=scenario.lidar.range_max,
        range_noise=scenario.lidar.noise,
        seed=scenario.lidar.seed,
        period=1.0 / scenario.lidar.rate,
    )
    _check_ports(scenario, fmus["vehicle"], "vehicle", VEHICLE_INPUTS[scenario.vehicle_type], "input")
    for role, names in ROLE_INPUTS.items():
        _check_ports(scenario, fmus[role], role, names, "input")
    for role, names in ROLE_OUTPUTS.items():
        _check_ports(scenario, fmus[role], role, names, "output")
    _pose_is_state(fmus["vehicle"])
    for component in (planner, fmus["pure_pursuit"], lidar, fmus["vfh"], fmus["mixer"], fmus["vehicle"]):
        system.add(component)
    _connect(scenario, system, planner, lidar, fmus)
    system.order()  # raises on an algebraic loop
    for component in system.components.values():
        system.period_steps(component)
    return BuiltRun(scenario, system, parameters, grid, inflated, world, planner)


def _connect(scenario: Scenario, system: System, planner, lidar, fmus) -> None:
    for axis in ("x", "y", "theta"):
        system.connect(f"vehicle.{axis}", f"pure_pursuit.{axis}")
        system.connect(f"vehicle.{axis}", f"lidar.{axis}")
    pure_pursuit = fmus["pure_pursuit"]
    for port in planner.outputs:
        if port.name not in pure_pursuit.input_index:
            raise CosimError(
                f"{_where(scenario, 'pure_pursuit')}.ports: the FMU has no input '{port.name}' "
                "(waypoints[k,1], waypoints[k,2] for k = 1..1000)"
            )
        system.connect(f"planner.{port.name}", f"pure_pursuit.{port.name}")
    vfh = fmus["vfh"]
    beams = sum(1 for p in lidar.outputs if p.array_name == "ranges")
    for k in range(1, beams + 1):
        for signal in ("ranges", "angles"):
            if f"{signal}[{k}]" not in vfh.input_index:
                raise CosimError(
                    f"{_where(scenario, 'vfh')}.ports: the FMU has no input '{signal}[{k}]' for the "
                    f"{beams} lidar beams of [lidar]"
                )
            system.connect(f"lidar.{signal}[{k}]", f"vfh.{signal}[{k}]")
    system.connect("pure_pursuit.target_dir", "vfh.target_dir")
    system.connect("pure_pursuit.target_dir", "mixer.target_dir")
    system.connect("pure_pursuit.v", "mixer.v_in")
    system.connect("pure_pursuit.omega", "mixer.omega_in")
    system.connect("pure_pursuit.goal_reached", "mixer.goal_reached")
    system.connect("vfh.steering_dir", "mixer.steering_dir")
    for port in VEHICLE_INPUTS[scenario.vehicle_type]:
        system.connect(f"mixer.{port}", f"vehicle.{port}")
