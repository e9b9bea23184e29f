"""`cosim system FLEET.toml`: the system of a fleet, every robot's components under its name.

The components and connections of every robot (`robot1.vehicle`, `robot1.lidar.ranges[1..360] ->
robot1.vfh.ranges[1..360]`, ...), the links by which the robots see each other
(`robot2.vehicle.x -> robot1.lidar.robots_x[1]`), the step order of the fleet's one system
(`cosim.navigation.fleet.fleet_system`: every lidar before any vehicle), and a table of the
robots: start, goal or mission, footprint, whom its lidar sees.
"""

from __future__ import annotations

from cosim.cli.wiring import table_lines
from cosim.errors import CosimError


def show_fleet(args, fleet, format_system) -> int:
    """Print the fleet's system with `format_system` (`cosim.cli.system`'s, handed in: that module
    imports this one)."""
    from cosim.navigation.build import build_run
    from cosim.navigation.fleet import fleet_system
    from cosim.scenario.fleet_compose import describe_fleet

    if args.png is not None:
        raise CosimError(f"{fleet.source}: --png draws one robot's system; a fleet's is not drawn yet")
    described = describe_fleet(fleet)
    builts = [build_run(robot.scenario, described.robots[robot.name]) for robot in fleet.robots]
    system, _ = fleet_system(fleet, described, builts)  # the system `cosim run` steps
    order = [component.name.replace(":", ".", 1) for component in system.order()]
    constant = {name.replace(":", ".", 1) for name, c in system.components.items() if c.constant_outputs}
    text = format_system(described.flat(), order, constant, f"{fleet.name} ({fleet.source})")
    rows = [("robot", "start (x, y, theta)", "goal / mission", "footprint", "sees")]
    for robot in fleet.robots:
        x, y, theta = robot.scenario.start
        goals = ", ".join(
            f"({goal.x:g}, {goal.y:g})" + (f" dwell {goal.dwell:g} s" if goal.dwell else "")
            for goal in robot.mission
        )
        if robot.repeat > 1:
            goals += f" x{robot.repeat}"
        sees = ", ".join(described.seen[robot.name]) or "no one (no template lidar)"
        rows.append((robot.name, f"({x:g}, {y:g}, {theta:g})", goals, f"r {robot.radius:g} m", sees))
    settings = fleet.settings
    lines = [
        text,
        "",
        f"robots ({len(fleet.robots)}; coordination {settings.coordination}, on_collision "
        f"{settings.on_collision}, deadlock_after {settings.deadlock_after:g} s)",
        *table_lines(rows),
    ]
    print("\n".join(lines))
    return 0
