"""A fleet scenario: `[[robots]]` and `[fleet]` in a scenario file.

Each `[[robots]]` table makes one robot, the navigation template under its name:

    [[robots]]
    name = "robot1"                                  # an identifier: the robot's namespace
    start = { x = 6.0, y = 6.0, theta = 0.0 }        # the keys of [start]
    goal = { x = 84.0, y = 53.0, tolerance = 1.0 }   # the keys of [goal]; or a mission:
    # mission = [{ x = 20.0, y = 6.0, dwell = 5.0 }, { x = 6.0, y = 6.0 }]
    # repeat = 3                                     # runs of the mission (with `mission` only)
    vfh = { safety_distance = 0.5 }                  # any template section, over the scenario's
    # speed_factor = 0.5                             # 0 < f <= 1: the vehicle's commands times f
    # stop = { at = 10.0, duration = 5.0 }           # [s]: the robot halts for that long

A robot is checked as a single-robot scenario: the scenario-wide TOML with the robot's `start`,
its (first) goal and its own sections put over the scenario's. A robot's section is merged key by
key over the scenario-wide one (its `ports` and `[components.NAME]` tables too), except that a
section naming another `fmu` replaces the scenario's section (another FMU has other parameters);
the robot's `connections` are added after the scenario's. So every robot is a complete `Scenario`
(`Robot.scenario`) and everything that checks or builds one robot serves each robot of a fleet.

A fleet gives no top-level `[start]` or `[goal]` (each robot has its own). `[fleet]` holds
`coordination` ("none": each robot plans alone; "mapf": all robots planned together by multi-agent
path finding, "prioritized": one after the other; both executed through an action dependency graph,
`cosim.navigation.coordination`), `on_collision` ("stop" ends the run at the first
robot-robot contact, "continue" records it and runs on) and `deadlock_after` [s] (a robot that
made no progress for that long is deadlocked). `--set robots.robot2.vfh.safety_distance=0.5`
addresses a robot by its name (`robots.1.…` by its position also works).
"""

from __future__ import annotations

import copy
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.scenario.limits import MAX_NAME_LENGTH
from cosim.scenario.schema import TableReader, describe

MAX_ROBOTS = 1000
# Sections a robot may give for itself, over the scenario-wide ones.
# Sections a fleet refuses: their topics exist only in a single-robot log.
NOT_FOR_FLEETS = ("imu", "bumper")
ROBOT_SECTIONS = ("vehicle", "pure_pursuit", "vfh", "mixer", "lidar", "planner", "components", "connections")
COORDINATIONS = ("none", "prioritized", "mapf")
ON_COLLISION = ("stop", "continue")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True)
class Goal:
    """One goal of a mission: position [m], tolerance [m], time to stay there once reached [s]."""

    x: float
    y: float
    tolerance: float = 1.0
    dwell: float = 0.0


@dataclass(frozen=True)
class Robot:
    """One robot: its name (namespace), its single-robot scenario (start, first goal, its own
    sections), its mission (goals in order; one goal for `goal = {…}`) and how often it runs."""

    name: str
    index: int  # position in [[robots]]
    scenario: object  # cosim.scenario.load.Scenario
    mission: tuple[Goal, ...]
    repeat: int = 1
    sections: tuple[str, ...] = ()  # the template sections the robot gives for itself
    speed_factor: float = 1.0  # the vehicle's commands scaled by this (a slow robot)
    stop: tuple[float, float] | None = None  # (at [s], duration [s]): the robot halts

    @property
    def radius(self) -> float:
        """[m] the footprint circle (the robot's [vehicle] radius)."""
        return self.scenario.vehicle_radius


@dataclass(frozen=True)
class FleetSettings:
    coordination: str = "none"
    on_collision: str = "stop"
    deadlock_after: float = 30.0  # [s] without progress


@dataclass(frozen=True)
class Fleet:
    """A scenario with `[[robots]]`: the robots and the fleet settings. The map, obstacles and
    simulation settings are common to the robots (`first`)."""

    source: str
    path: Path | None
    text: str
    name: str
    description: str
    robots: tuple[Robot, ...]
    settings: FleetSettings = FleetSettings()
    overrides: tuple[str, ...] = field(default=())

    def robot(self, name: str) -> Robot:
        return next(robot for robot in self.robots if robot.name == name)

    @property
    def first(self):
        """Robot 1's scenario: the map, obstacles and time base every robot shares."""
        return self.robots[0].scenario


def find_robot(robots: list, part: str):
    """The robot table named `part` in a `[[robots]]` list (for `--set robots.NAME.…`), or None."""
    for item in robots:
        if isinstance(item, dict) and item.get("name") == part:
            return item
    return None


def build_fleet(raw: dict, source: str, build: Callable[..., Any], *args) -> Fleet:
    """The fleet of parsed TOML `raw` (overrides applied): each robot made by
    `build(robot_raw, robot_source, *args)` (the loader's single-robot build: base_dir, text, path,
    overrides), so checked as a single-robot scenario (see the module docstring)."""
    top = TableReader(source, "", raw)
    if "robots" not in raw:
        raise top.error("fleet", "needs at least one [[robots]] table")
    tables = top.raw("robots")
    if not isinstance(tables, list) or not tables:
        raise top.error("robots", f"must be a non-empty array of tables [[robots]], got {describe(tables)}")
    if len(tables) > MAX_ROBOTS:
        raise top.error("robots", f"at most {MAX_ROBOTS} robots, got {len(tables)}")
    for key in ("start", "goal"):
        if key in raw:
            raise top.error(key, f"a fleet gives each robot its own {key} in [[robots]]; delete [{key}]")
    for key in NOT_FOR_FLEETS:  # written by the single-robot recorder only, not by the fleet's log
        if key in raw:
            raise top.error(key, f"[{key}] is not recorded for a fleet yet ([[robots]]); delete [{key}]")
    settings = _settings(TableReader(source, "[fleet]", top.raw("fleet", {})))
    common = {key: value for key, value in raw.items() if key not in ("robots", "fleet")}
    scenario_table = raw.get("scenario") if isinstance(raw.get("scenario"), dict) else {}
    robots: list[Robot] = []
    names: set[str] = set()
    for index, table in enumerate(tables):
        where = f"[[robots]][{index}]"
        reader = TableReader(source, where, table)
        name = reader.string("name")
        if not _NAME.match(name) or len(name) > MAX_NAME_LENGTH:
            raise reader.error(
                "name",
                f"must be an identifier (letters, digits, _) of at most {MAX_NAME_LENGTH} characters: "
                f"it names the robot's components and topics, got {describe(name)}",
            )
        if name in names:
            raise reader.error("name", f"'{name}' is already the name of another robot")
        names.add(name)
        robot_raw = copy.deepcopy(common)
        robot_raw["start"] = reader.raw("start")
        if not isinstance(robot_raw["start"], dict):
            raise reader.error(
                "start",
                f"must be an inline table {{ x = …, y = …, theta = … }}, got {describe(robot_raw['start'])}",
            )
        mission, repeat = _mission(reader)
        speed_factor, stop = _delays(reader)
        first = mission[0]
        robot_raw["goal"] = {"x": first.x, "y": first.y, "tolerance": first.tolerance}
        for section in ROBOT_SECTIONS:
            if reader.has(section):
                robot_raw[section] = _merge(robot_raw.get(section), reader.raw(section), section)
        reader.finish(extra_allowed=None)
        label = f"{source}: {where} ({name})"
        robot_raw["scenario"] = dict(scenario_table)
        scenario = build(robot_raw, label, *args)
        own = tuple(section for section in ROBOT_SECTIONS if section in table)
        robots.append(Robot(name, index, scenario, mission, repeat, own, speed_factor, stop))
    _check_common(source, robots)
    _check_coordination(source, robots, settings)
    first = robots[0].scenario
    return Fleet(
        source,
        first.path,
        first.text,
        first.name,
        first.description,
        tuple(robots),
        settings,
        first.overrides,
    )


def _settings(table: TableReader) -> FleetSettings:
    default = FleetSettings
    settings = FleetSettings(
        coordination=table.string("coordination", default.coordination, choices=COORDINATIONS),
        on_collision=table.string("on_collision", default.on_collision, choices=ON_COLLISION),
        deadlock_after=table.number(
            "deadlock_after", default.deadlock_after, minimum=0.0, exclusive_minimum=True
        ),
    )
    table.finish()
    return settings


def _mission(reader: TableReader) -> tuple[tuple[Goal, ...], int]:
    """A robot's `goal` (one goal) or `mission` (goals with `dwell`) and `repeat`."""
    if reader.has("goal") == reader.has("mission"):
        raise reader.error("goal", "give either goal = { x, y } or mission = [{ x, y, dwell }, …]")
    if reader.has("goal"):
        goal = TableReader(reader.source, f"{reader.where}.goal", reader.raw("goal"))
        result = (Goal(goal.number("x"), goal.number("y"), _tolerance(goal)),)
        goal.finish()
        if reader.has("repeat"):
            raise reader.error("repeat", "belongs to a mission; a single goal is reached once")
        return result, 1
    items = reader.raw("mission")
    if not isinstance(items, list) or not items:
        raise reader.error(
            "mission", f"must be a non-empty list of goals {{ x, y, dwell }}, got {describe(items)}"
        )
    goals = []
    for k, item in enumerate(items):
        goal = TableReader(reader.source, f"{reader.where}.mission[{k}]", item)
        goals.append(
            Goal(goal.number("x"), goal.number("y"), _tolerance(goal), goal.number("dwell", 0.0, minimum=0.0))
        )
        # Pure Pursuit's goal_tolerance is set once, from the first goal: it stops the robot within
        # that distance of every goal, so a smaller tolerance later could never be met.
        if goals[-1].tolerance < goals[0].tolerance:
            raise goal.error(
                "tolerance",
                f"must be >= the first goal's ({goals[0].tolerance:g} m): the robot stops within that "
                f"distance of every goal, got {goals[-1].tolerance:g}",
            )
        goal.finish()
    return tuple(goals), reader.integer("repeat", 1, minimum=1, maximum=1_000_000)


def _delays(reader: TableReader) -> tuple[float, tuple[float, float] | None]:
    """A robot's `speed_factor` (0 < f <= 1) and `stop = { at = t, duration = d }`."""
    factor = reader.number("speed_factor", 1.0, minimum=0.0, maximum=1.0, exclusive_minimum=True)
    if not reader.has("stop"):
        return factor, None
    table = TableReader(reader.source, f"{reader.where}.stop", reader.raw("stop"))
    stop = (table.number("at", minimum=0.0), table.number("duration", minimum=0.0, exclusive_minimum=True))
    table.finish()
    return factor, stop


def _check_coordination(source: str, robots: list[Robot], settings: FleetSettings) -> None:
    """Coordination and stops hand the planner component waypoints at run time: its outputs must
    not be constant ([planner] replan = true, the default)."""
    for robot in robots:
        if robot.scenario.planner.replan:
            continue
        why = (
            f"[fleet] coordination = '{settings.coordination}'"
            if settings.coordination != "none"
            else "stop"
            if robot.stop is not None
            else None
        )
        if why is not None:
            raise TableReader(source, f"[[robots]][{robot.index}]", {}).error(
                "planner.replan",
                f"{why} hands the planner new waypoints during the run: needs [planner] replan = true",
            )


def _tolerance(goal: TableReader) -> float:
    return goal.number("tolerance", Goal.tolerance, minimum=0.0, exclusive_minimum=True)


def _merge(common, own, section: str):
    """A robot's section over the scenario-wide one (see the module docstring)."""
    if section == "connections":
        base = common if isinstance(common, list) else []
        return [*base, *own] if isinstance(own, list) else own  # not a list: the build says so
    if not isinstance(common, dict) or not isinstance(own, dict):
        return copy.deepcopy(own)
    if section != "components" and "fmu" in own and own.get("fmu") != common.get("fmu"):
        return copy.deepcopy(own)  # another FMU: the scenario's parameters are not its own
    merged = copy.deepcopy(common)
    for key, value in own.items():
        if section == "components" and isinstance(value, dict):
            merged[key] = _merge(merged.get(key), value, "component")
        elif key == "ports" and isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _check_common(source: str, robots: list[Robot]) -> None:
    """What the robots share in one world and one run must agree: the map and the time base (a
    robot's own sections cannot change them, but say so if that ever slips)."""
    first = robots[0].scenario
    for robot in robots[1:]:
        for key in ("map_file", "macro_step", "stop_time", "master"):
            if getattr(robot.scenario, key) != getattr(first, key):
                raise TableReader(source, f"[[robots]][{robot.index}]", {}).error(
                    None,
                    f"{key} differs from robot '{robots[0].name}''s: the robots share one world and clock",
                )


def check_fleet_world(fleet: Fleet) -> None:
    """Every robot's start and every goal of its mission in free space (as for one robot), and no
    two robots' footprints overlapping at the start."""
    import math
    from dataclasses import replace

    from cosim.world.distance import check_start_goal

    for robot in fleet.robots:
        for goal in robot.mission:
            check_start_goal(replace(robot.scenario, goal=(goal.x, goal.y)))
    for k, robot in enumerate(fleet.robots):
        for other in fleet.robots[k + 1 :]:
            (x1, y1, _), (x2, y2, _) = robot.scenario.start, other.scenario.start
            if math.hypot(x2 - x1, y2 - y1) < robot.radius + other.radius:
                raise TableReader(fleet.source, f"[[robots]][{other.index}]", {}).error(
                    "start",
                    f"'{other.name}' starts within {robot.radius + other.radius:g} m of '{robot.name}' "
                    "(their footprints overlap)",
                )
