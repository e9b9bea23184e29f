"""A fleet as a checked system description: every robot the navigation template under its name.

`describe_fleet(fleet)` describes and checks each robot as the single-robot scenario it is
(`cosim.scenario.compose.describe_system`: every problem names the file, the robot and the key),
then makes the robots see each other: each robot's template lidar gets the inputs
`robots_x[j]`, `robots_y[j]` (j = 1..N-1, the other robots in fleet order) and its footprint radii
(`ComponentDescription.robot_radii`), fed by the other robots' `vehicle.x`, `vehicle.y` (not with
`[fleet] coordination` other than "none": the coordinator keeps the robots apart, and a lidar that
sees only the world lets VFH and the costmap react to unknown obstacles alone). A robot's
`speed_factor` scales the connections into its vehicle's `v` (and a differential drive's `omega`). Those
links run from a vehicle's pose (a state: no direct dependency on the vehicle's inputs) to a
lidar, so they close no algebraic loop.

In the fleet's system every name is qualified by the robot's name: component `robot1.vehicle`,
port `robot1.vehicle.x` (`qualified`, `FleetDescription.flat`). Within a robot's own description
(`FleetDescription.robots`) the names stay the template's, so everything that reads one robot's
system (the run, the recorder, the outcome) reads each robot's unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from cosim.scenario.compose import describe_system
from cosim.scenario.description import ConnectionDescription, Observed, ScanSource, SystemDescription
from cosim.scenario.fleet import Fleet

FLEET = "[[robots]] (robots see each other)"  # `where` of the links between robots
SEEN_BY = "lidar"  # the template component that sees the other robots
POSE_OF = "vehicle"  # whose x, y it sees


@dataclass(frozen=True)
class FleetDescription:
    """The robots' descriptions (by name, in fleet order; template names inside) and the links
    between robots (qualified names: `robot2.vehicle.x -> robot1.lidar.robots_x[1]`)."""

    robots: dict[str, SystemDescription]
    links: tuple[ConnectionDescription, ...]
    # robot -> the robots its lidar sees, in the order of its robots_x[j] inputs.
    seen: dict[str, tuple[str, ...]]

    def flat(self) -> SystemDescription:
        """One system of every robot's components and connections, qualified, and the links."""
        parts = [qualified(name, description) for name, description in self.robots.items()]
        first = parts[0]
        return replace(
            first,
            components={k: v for part in parts for k, v in part.components.items()},
            connections=tuple(c for part in parts for c in part.connections) + self.links,
            observed=None,
            replaced=tuple(pair for part in parts for pair in part.replaced),
            removed=tuple(name for part in parts for name in part.removed),
            replacing=tuple(name for part in parts for name in part.replacing),
            dropped=tuple(item for part in parts for item in part.dropped),
            loop=tuple(port for part in parts for port in part.loop),
        )


def describe_fleet(fleet: Fleet) -> FleetDescription:
    """Every robot's system, checked, and the links that let the robots see each other."""
    robots: dict[str, SystemDescription] = {}
    seen: dict[str, tuple[str, ...]] = {}
    links: list[ConnectionDescription] = []
    radius = {robot.name: robot.radius for robot in fleet.robots}
    for robot in fleet.robots:
        description = _slowed(robot, _own_sections(robot, describe_system(robot.scenario)))
        lidar = description.components.get(SEEN_BY)
        # Coordinated robots are kept apart by the coordinator: their lidars see the world only
        # (VFH and the costmap then react to unknown obstacles, not to the other robots).
        alone = fleet.settings.coordination == "none"
        if lidar is None or lidar.kind != "lidar" or len(fleet.robots) == 1 or not alone:
            robots[robot.name] = description  # no template lidar: this robot sees no one
            seen[robot.name] = ()
            continue
        others = tuple(other.name for other in fleet.robots if other.name != robot.name)
        count = len(others)
        inputs = tuple(f"robots_{axis}[{j}]" for axis in ("x", "y") for j in range(1, count + 1))
        # One tuple per distinct dependency list, shared by the outputs that have it (1440 ports
        # of a 720-beam lidar each holding its own copy of 3 + 2(N - 1) names was ~1 MB a robot).
        extended: dict[tuple[str, ...], tuple[str, ...]] = {}
        feedthrough = {}
        for name, deps in lidar.feedthrough.items():
            key = tuple(deps)
            if key not in extended:
                extended[key] = (*key, *inputs)
            feedthrough[name] = extended[key]
        components = dict(description.components)
        components[SEEN_BY] = replace(
            lidar,
            inputs=(*lidar.inputs, *inputs),
            feedthrough=feedthrough,
            robot_radii=tuple(radius[name] for name in others),
        )
        robots[robot.name] = replace(description, components=components)
        seen[robot.name] = others
        for j, other in enumerate(others, start=1):
            for axis in ("x", "y"):
                links.append(
                    ConnectionDescription(
                        f"{other}.{POSE_OF}.{axis}", f"{robot.name}.{SEEN_BY}.robots_{axis}[{j}]", where=FLEET
                    )
                )
    return FleetDescription(robots, tuple(links), seen)


def _own_sections(robot, description: SystemDescription) -> SystemDescription:
    """Components that the robot's own sections set say so in `where`: "[vfh] + [[robots]][1].vfh"
    (a `[components.NAME]` of the robot's: "+ [[robots]][1].components")."""
    label = f"[[robots]][{robot.index}]"
    components = {}
    for name, component in description.components.items():
        section = "components" if component.where.startswith("[components.") else name
        if section in robot.sections:
            component = replace(component, where=f"{component.where} + {label}.{section}")
        components[name] = component
    return replace(description, components=components)


def _slowed(robot, description: SystemDescription) -> SystemDescription:
    """A robot with `speed_factor` f < 1: the connections into its vehicle's speed commands (`v`,
    and `omega` of a differential drive) scaled by f, so it drives the same path f times as fast
    (a bicycle's steering angle stays: same curvature)."""
    factor = robot.speed_factor
    if factor == 1.0:
        return description
    ports = ("v", "omega") if robot.scenario.vehicle_type == "differential" else ("v",)
    targets = {f"{POSE_OF}.{port}" for port in ports}
    connections = tuple(
        replace(c, scale=c.scale * factor, offset=c.offset * factor, where=f"{c.where} x speed_factor")
        if c.target in targets
        else c
        for c in description.connections
    )
    fed = {c.target for c in connections} & targets
    if fed != targets:
        from cosim.errors import CosimError

        missing = ", ".join(sorted(targets - fed))
        raise CosimError(f"{robot.scenario.source}: speed_factor: nothing feeds {missing} to scale")
    return replace(description, connections=connections)


def qualified(robot: str, description: SystemDescription) -> SystemDescription:
    """`description` with every component name (and reference) under the robot's name."""

    def name(component: str) -> str:
        return f"{robot}.{component}"

    def reference(text: str) -> str:
        return f"{robot}.{text}"

    def connection(c: ConnectionDescription) -> ConnectionDescription:
        return replace(c, source=reference(c.source), target=reference(c.target))

    observed = description.observed
    if observed is not None:
        scan = observed.scan
        observed = Observed(
            pose=tuple(reference(r) for r in observed.pose),
            command=tuple(reference(r) for r in observed.command) if observed.command else None,
            mode=reference(observed.mode) if observed.mode else None,
            scan=ScanSource(name(scan.component), scan.angles, scan.range_min, scan.range_max)
            if scan
            else None,
        )
    return replace(
        description,
        components={name(k): replace(v, name=name(k)) for k, v in description.components.items()},
        connections=tuple(connection(c) for c in description.connections),
        observed=observed,
        replaced=tuple((connection(a), connection(b)) for a, b in description.replaced),
        removed=tuple(name(n) for n in description.removed),
        replacing=tuple(name(n) for n in description.replacing),
        dropped=tuple((connection(c), why) for c, why in description.dropped),
        loop=tuple(reference(port) for port in description.loop),
    )
