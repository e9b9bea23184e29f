"""The navigation template: the default components and connections of a robot scenario.

The robot pipeline of the thesis (chapter 4) as data. `cosim.scenario.compose.describe_system`
merges it with the scenario's `[components.NAME]` and `[[connections]]` (a connection into an input
that the template feeds replaces the template's) and checks the whole; `cosim.navigation.build`
makes the components. What a run reads besides the recording (robot pose, commanded velocity,
avoidance mode, scan) is declared here (`Observed`). The component names are also known by name to
what reads a robot log (cosim.logs.plot, .animate, .reader), to the recorder's plot trace
(cosim.record.recorder) and to cosim.navigation.build: renaming one here renames it there too.

Components, in the order they are added to the system (it breaks ties of the step order):
    planner       Python: the plan on the known map; outputs waypoints[k,c], k = 1..1000, c = 1 (x), 2 (y);
                  with [planner].replan also inputs x, y, theta, steering_dir, ranges[k] (at the lidar rate)
    pure_pursuit  [pure_pursuit] FMU
    lidar         Python: ray casting on the true world; inputs x, y, theta; outputs ranges[k], angles[k]
    vfh           [vfh] FMU
    mixer         [mixer] FMU
    vehicle       [vehicle] FMU; its x, y, theta are states unless its FMU declares dependencies

Connections:
    vehicle.x/y/theta         -> pure_pursuit.x/y/theta, lidar.x/y/theta
    planner.waypoints[k,c]    -> pure_pursuit.waypoints[k,c]
    vehicle.x/y/theta, lidar.ranges[k], vfh.steering_dir -> planner (with [planner].replan)
    lidar.ranges[k]/angles[k] -> vfh.ranges[k]/angles[k]               (k = 1..lidar beams)
    pure_pursuit.target_dir   -> vfh.target_dir, mixer.target_dir
    pure_pursuit.v/omega/goal_reached -> mixer.v_in/omega_in/goal_reached
    vfh.steering_dir          -> mixer.steering_dir
    mixer.v, mixer.omega      -> vehicle.v, vehicle.omega               (differential drive)
    mixer.v, mixer.steering_angle -> vehicle.v, vehicle.steering_angle  (bicycle)

Parameters derived from other sections: vehicle x0, y0, theta0 from [start] (the vehicle FMU must
have them); pure_pursuit goal_tolerance from [goal].tolerance; mixer vehicle_type from
[vehicle].type and wheelbase, max_steering_angle from [vehicle] (set when the FMU has them).

A scenario changes the template (`cosim.scenario.compose` applies it):
- `[system] remove = ["vfh", "mixer"]` leaves template components out (any but the vehicle: the run
  needs the robot pose); their connections go with them.
- `[components.pure_pursuit]` (or `vfh`, `mixer`) replaces that component by any FMU: the template
  connections to and from ports the new FMU has are kept, the others dropped.
An input that a dropped connection fed must then be connected or held at a value.

What a run observes (`template_observed`): the pose is always the vehicle's x, y, theta. The
command (/cmd_vel, /odom twist) is the mixer's v, omega; without a mixer (or with a replacement
lacking them), the outputs that feed the vehicle's v and omega directly (scale 1, offset 0); else
there is none (no /cmd_vel, a NaN twist on /odom; so for a bicycle without a mixer, which takes
no omega). The avoidance
mode counted in the outcome is the mixer's `mode` (none without it: VFH counts stay 0); the scan
is the template lidar's (none when it is removed).
"""

from __future__ import annotations

from dataclasses import replace

from cosim.core.component import array_ports
from cosim.scenario.description import (
    TEMPLATE,
    ComponentDescription,
    ConnectionDescription,
    Observed,
    ScanSource,
)
from cosim.scenario.load import TEMPLATE_ORDER, ComponentSpec, Scenario

WAYPOINT_CAPACITY = 1000  # rows of the planner's waypoints output (PurePursuit's waypoints input)
ORDER = TEMPLATE_ORDER
POSE_COMPONENT = "vehicle"  # the run reads the robot pose from its x, y, theta; it cannot be removed
VEHICLE_INPUTS = {"differential": ("v", "omega"), "bicycle": ("v", "steering_angle")}
POSE = ("x", "y", "theta")
# The ports each role FMU has for the template (the keys its `ports` table may map, besides its
# parameters): what the template connects, for either vehicle type, and what a run observes.
ROLE_PORTS = {
    "vehicle": ("v", "omega", "steering_angle", *POSE, "x0", "y0", "theta0"),
    "pure_pursuit": (*POSE, "waypoints", "v", "omega", "target_dir", "goal_reached", "goal_tolerance"),
    "vfh": ("ranges", "angles", "target_dir", "steering_dir"),
    "mixer": (
        "v_in", "omega_in", "target_dir", "steering_dir", "goal_reached", "v", "omega", "steering_angle",
        "mode", "vehicle_type", "wheelbase", "max_steering_angle",
    ),
}  # fmt: skip


def planner_outputs() -> list[str]:
    return [port.name for port in array_ports("waypoints", WAYPOINT_CAPACITY, columns=2)]


def lidar_outputs(beams: int) -> list[str]:
    return [port.name for port in array_ports("ranges", beams) + array_ports("angles", beams)]


def _fmu_component(
    spec: ComponentSpec,
    defaults: dict[str, float] | None = None,
    required: dict[str, tuple[float, str]] | None = None,
) -> ComponentDescription:
    """A role FMU; `defaults` are set when the FMU has them, `required` (value, key it comes from)
    must exist in the FMU. The section's own values win over both."""
    parameters = {  # a string is a String or Binary variable's (checked with the FMU's interface)
        name: value if isinstance(value, str) else float(value) for name, value in spec.parameters.items()
    }
    required = {name: item for name, item in (required or {}).items() if name not in parameters}
    parameters.update({name: float(value) for name, (value, _) in required.items()})
    return ComponentDescription(
        name=spec.name,
        kind="fmu",
        where=spec.where,
        rate=spec.rate,
        port_map=dict(spec.ports),
        parameters=parameters,
        defaults={k: float(v) for k, v in (defaults or {}).items() if k not in spec.parameters},
        required_parameters={name: key for name, (_, key) in required.items()},
    )


def planner_inputs(scenario: Scenario) -> tuple[str, ...]:
    """A replanning planner reads the pose, VFH's steering direction and the lidar's ranges."""
    if not scenario.planner.replan:
        return ()
    ranges = [port.name for port in array_ports("ranges", len(scenario.lidar.angles))]
    return (*POSE, "steering_dir", *ranges)


def _planner_component(scenario: Scenario) -> ComponentDescription:
    """The planner: a plan fixed for the run at the controller rate, or (replanning) a costmap fed
    by every scan, so it steps with the lidar; its waypoints depend on the scan and pose of the
    same step (not on VFH's direction, which depends on the waypoints)."""
    inputs = planner_inputs(scenario)
    rate = scenario.lidar.rate if inputs else scenario.controller_rate
    # Every range counts, but one declared range already orders the planner after the lidar (all
    # ranges come from it) without a 1000 x beams dependency graph.
    direct = ("ranges[1]",) if inputs else ()
    return ComponentDescription(
        "planner",
        "planner",
        "[planner]",
        rate=rate,
        inputs=inputs,
        outputs=tuple(planner_outputs()),
        feedthrough={name: direct for name in planner_outputs()},
    )


def template_components(scenario: Scenario) -> list[ComponentDescription]:
    """The template's components (interfaces of the FMUs not yet read), in `ORDER`, without those
    `[system] remove` leaves out; a `[components.NAME]` replacement is described from its own table
    (the derived parameters are still set when its FMU has them)."""
    components = scenario.components
    start_x, start_y, start_theta = scenario.start
    vehicle = components["vehicle"]
    start = {"x0": start_x, "y0": start_y, "theta0": start_theta}
    mixer_defaults = {"vehicle_type": 0 if scenario.vehicle_type == "differential" else 1}
    for name in ("wheelbase", "max_steering_angle"):
        # A string here is no number for the mixer: the vehicle FMU's own parameter check names it.
        if name in vehicle.parameters and not isinstance(vehicle.parameters[name], str):
            mixer_defaults[name] = vehicle.parameters[name]
    beams = len(scenario.lidar.angles)
    removed = set(scenario.removed) - {POSE_COMPONENT}
    made = {
        "planner": _planner_component(scenario),
        "lidar": ComponentDescription(
            "lidar",
            "lidar",
            "[lidar]",
            rate=scenario.lidar.rate,
            inputs=POSE,
            outputs=tuple(lidar_outputs(beams)),
            feedthrough={name: POSE for name in lidar_outputs(beams)},
        ),
        "vehicle": _fmu_component(
            vehicle, required={name: (value, f"[start].{name[:-1]}") for name, value in start.items()}
        ),
    }
    made["vehicle"] = replace(made["vehicle"], state_outputs=POSE)
    defaults = {"pure_pursuit": {"goal_tolerance": scenario.goal_tolerance}, "mixer": mixer_defaults}
    for name in ("pure_pursuit", "vfh", "mixer"):
        if name in components:
            made[name] = _fmu_component(components[name], defaults=defaults.get(name))
            if components[name].added and components[name].rate is None:  # a replacement: the role's rate
                made[name] = replace(made[name], rate=scenario.controller_rate)
    return [made[name] for name in ORDER if name not in removed]


def template_connections(scenario: Scenario) -> list[ConnectionDescription]:
    """The template's connections, in the order listed in the module docstring (a new list; the
    connections themselves are frozen and shared)."""
    return list(
        _template_connections(
            bool(scenario.planner.replan), len(scenario.lidar.angles), scenario.vehicle_type
        )
    )


def template_ends(scenario: Scenario) -> tuple[tuple[str, str, str, str], ...]:
    """(source component, output, target component, input) of each of `template_connections`, in
    its order (read-only)."""
    key = (bool(scenario.planner.replan), len(scenario.lidar.angles), scenario.vehicle_type)
    _template_connections(*key)
    return _TEMPLATES[key][1]


# The template's connections by what they depend on (replanning, beams, vehicle type), with their
# ends split into component and port: a sweep's worker describes the same system for every run
# (~3,100 connections, ~5 ms each time). A few kept.
_TEMPLATES: dict[tuple[bool, int, str], tuple[tuple[ConnectionDescription, ...], tuple]] = {}
_TEMPLATES_KEPT = 8


def _template_connections(replan: bool, beams: int, vehicle_type: str) -> tuple[ConnectionDescription, ...]:
    key = (replan, beams, vehicle_type)
    made = _TEMPLATES.get(key)
    if made is None:
        connections = tuple(_make_template_connections(replan, beams, vehicle_type))
        ends = tuple((*c.source.partition(".")[::2], *c.target.partition(".")[::2]) for c in connections)
        if len(_TEMPLATES) >= _TEMPLATES_KEPT:
            _TEMPLATES.pop(next(iter(_TEMPLATES)))
        made = _TEMPLATES[key] = (connections, ends)
    return made[0]


def _make_template_connections(replan: bool, beams: int, vehicle_type: str) -> list[ConnectionDescription]:
    pairs: list[tuple[str, str]] = []
    for axis in POSE:
        pairs += [(f"vehicle.{axis}", f"pure_pursuit.{axis}"), (f"vehicle.{axis}", f"lidar.{axis}")]
    pairs += [(f"planner.{name}", f"pure_pursuit.{name}") for name in planner_outputs()]
    if replan:
        pairs += [(f"vehicle.{axis}", f"planner.{axis}") for axis in POSE]
        pairs += [(f"lidar.ranges[{k}]", f"planner.ranges[{k}]") for k in range(1, beams + 1)]
        pairs += [("vfh.steering_dir", "planner.steering_dir")]
    for k in range(1, beams + 1):
        pairs += [(f"lidar.{signal}[{k}]", f"vfh.{signal}[{k}]") for signal in ("ranges", "angles")]
    pairs += [
        ("pure_pursuit.target_dir", "vfh.target_dir"),
        ("pure_pursuit.target_dir", "mixer.target_dir"),
        ("pure_pursuit.v", "mixer.v_in"),
        ("pure_pursuit.omega", "mixer.omega_in"),
        ("pure_pursuit.goal_reached", "mixer.goal_reached"),
        ("vfh.steering_dir", "mixer.steering_dir"),
    ]
    pairs += [(f"mixer.{port}", f"vehicle.{port}") for port in VEHICLE_INPUTS[vehicle_type]]
    return [ConnectionDescription(source, target, where=TEMPLATE) for source, target in pairs]


def template_observed(
    scenario: Scenario,
    components: dict[str, ComponentDescription],
    connections: list[ConnectionDescription],
) -> Observed:
    """What a run reads of the described system (see the module docstring): the robot pose is the
    vehicle's; command and mode the mixer's (a template mixer must have them, a replacement may
    not), else the command is what feeds the vehicle; the scan is the template lidar's."""
    pose = tuple(f"{POSE_COMPONENT}.{axis}" for axis in POSE)
    mixer = components.get("mixer")
    template_mixer = mixer is not None and not scenario.components["mixer"].added
    has = set(mixer.outputs) if mixer is not None else set()
    command = None
    if template_mixer or {"v", "omega"} <= has:
        command = ("mixer.v", "mixer.omega")
    else:
        feeds = {c.target: c for c in connections}
        inputs = [feeds.get(f"{POSE_COMPONENT}.{port}") for port in ("v", "omega")]
        if all(c is not None and c.scale == 1.0 and c.offset == 0.0 for c in inputs):
            command = (inputs[0].source, inputs[1].source)
    mode = "mixer.mode" if template_mixer or "mode" in has else None
    lidar = scenario.lidar
    scan = None
    if components.get("lidar") is not None and components["lidar"].kind == "lidar":
        scan = ScanSource("lidar", tuple(float(a) for a in lidar.angles), lidar.range_min, lidar.range_max)
    return Observed(pose=pose, command=command, mode=mode, scan=scan)
