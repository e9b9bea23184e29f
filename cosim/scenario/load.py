"""Scenario files: TOML in, a validated `Scenario` out.

`load_scenario(path, overrides)` reads the file, applies `--set key=value` overrides to the parsed
TOML (so they pass the same validation), checks types, ranges and unknown keys, and checks that
start and goal lie in free space of the true world. `scenarios/example_commented.toml` documents
every key. What needs the FMU files themselves (does the FMU load, do the variables of the ports,
parameters and connections exist, is there an algebraic loop) is checked when the scenario is
turned into a system description (`cosim.scenario.compose.describe_system`), still before any log
is created.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.loops import DEFAULT_MAX_ITERATIONS, DEFAULT_TOLERANCE
from cosim.core.system import LOOP_HANDLING
from cosim.errors import PATH_LIMIT, CosimError, wrong_file_message
from cosim.fmi.builtin import known_names
from cosim.fmi.solvers import SOLVERS
from cosim.scenario.limits import (
    MAX_COMPONENTS,
    MAX_LIDAR_BEAMS,
    MAX_LIDAR_RANGE,
    MAX_LINEAR_SPEED,
    MAX_NAME_LENGTH,
    MAX_OBSTACLES,
    MAX_TIME,
    check_component_count,
    check_run_length,
    check_speeds,
    check_time_base,
)
from cosim.scenario.schema import REQUIRED, TableReader, describe, did_you_mean, is_number, shorten
from cosim.scenario.topics import REMAPPABLE_TOPICS
from cosim.world.imu import ImuSettings
from cosim.world.lidar import evenly_spaced_beams
from cosim.world.motion import MOTIONS, Motion
from cosim.world.shapes import Circle, Obstacle, Polygon, Rectangle
from planner.options import CONFIGURATIONS, PLANNERS, USER_HEURISTICS


@cache
def builtin_fmus() -> tuple[str, ...]:
    """The project FMUs' names (`fmu = "PurePursuit"`): the models in the FMU source folder, or the
    FMUs a wheel ships."""
    return tuple(known_names())


VEHICLE_TYPES = {"DifferentialDrive": "differential", "Bicycle": "bicycle"}
DEFAULT_FMUS = {"pure_pursuit": "PurePursuit", "vfh": "VectorFieldHistogram", "mixer": "AvoidanceMixer"}
INTERFACES = ("cs", "me")  # co-simulation, Model Exchange
INTEGRATION_KEYS = ("interface", "solver", "tolerance", "max_step")
# Section keys that are not FMU parameters; every other key of a component section is one.
COMPONENT_KEYS = ("fmu", "ports", "rate", "isolation", "nan_outputs", *INTEGRATION_KEYS)
ISOLATIONS = ("process", "none")  # an FMU in a child process, or in the run's own process
ROLE_SECTIONS = ("vehicle", "pure_pursuit", "vfh", "mixer")
SECTIONS = (
    "scenario", "map", "obstacles", "start", "goal", "planner", "vehicle", "pure_pursuit", "vfh",
    "mixer", "lidar", "simulation", "output", "components", "connections", "system", "imu", "bumper",
    "robots", "fleet",
)  # fmt: skip
# Components of the navigation template that are not FMUs (`cosim.scenario.template`); each name is
# also its kind, made by `cosim.navigation.build.COMPONENT_KINDS`.
PYTHON_COMPONENTS = ("planner", "lidar")
# The template's components in the order a system lists them (`cosim.scenario.template.ORDER`).
TEMPLATE_ORDER = ("planner", "pure_pursuit", "lidar", "vfh", "mixer", "vehicle")
# Template components a `[components.NAME]` of the same name replaces by any FMU (the vehicle is
# swapped in [vehicle]: the run reads the robot pose from it).
REPLACEABLE = ("pure_pursuit", "vfh", "mixer")
DEFAULT_LOG_PATTERN = "logs/{scenario}-{timestamp}.mcap"  # [output].log when the scenario gives none


@dataclass(frozen=True)
class Integration:
    """How a component section runs its FMU: `interface` "cs" or "me" (None: co-simulation when the
    FMU has it, else Model Exchange); for Model Exchange the `solver` ("cvode", "rk4", "euler";
    None: cvode), CVode's relative `tolerance` and the solver's `max_step` [s]
    (`cosim.fmi.model_exchange` gives their defaults). Checked against the FMU by `describe_system`."""

    interface: str | None = None
    solver: str | None = None
    tolerance: float | None = None
    max_step: float | None = None


@dataclass(frozen=True)
class PortMapping:
    """Where a role port lives in the FMU: its variable name and a scale.

    The scale multiplies along the data flow: FMU input = scale * port value, port output = scale *
    FMU output, FMU parameter = scale * given value (`cosim.fmi.layout`).
    """

    variable: str
    scale: float = 1.0


@dataclass(frozen=True)
class ComponentSpec:
    """One FMU component as the scenario declares it: a role section (`[vehicle]`, `[pure_pursuit]`,
    `[vfh]`, `[mixer]`) or an added one (`[components.NAME]`).

    fmu: a project FMU name (`cosim.fmi.builtin.builtin_fmu`) or an absolute path to a `.fmu`.
    parameters: parameter name -> value (role sections: translated through `ports` when mapped;
        added components: the FMU's variable names, a parameter or an input held at that value).
    rate: stepping rate [Hz]; None = every macro step.
    added: True for `[components.NAME]` (also one that replaces a template component of its name).
    isolation: "process" or "none"; None = [simulation] fmu_isolation decides (`Scenario.isolation`).
    nan_outputs: output ports that may be NaN (every other FMU output must stay finite).
    """

    name: str
    fmu: str
    parameters: dict[str, float | int | bool]
    ports: dict[str, PortMapping]
    rate: float | None
    added: bool = False
    isolation: str | None = None
    nan_outputs: tuple[str, ...] = ()
    integration: Integration = Integration()

    @property
    def is_builtin(self) -> bool:
        return self.fmu in builtin_fmus()

    @property
    def where(self) -> str:
        """The section that declares it, for error messages."""
        return f"[components.{self.name}]" if self.added else f"[{self.name}]"


@dataclass(frozen=True)
class ConnectionSpec:
    """One `[[connections]]` table: `target` input = `source` output * scale + offset."""

    source: str  # "component.variable" as written
    target: str
    scale: float
    offset: float
    index: int  # position in the file's [[connections]] array

    @property
    def where(self) -> str:
        return f"[[connections]][{self.index}]"


@dataclass(frozen=True)
class PlannerSettings:
    configuration: str = "modified"
    algorithm: str = "astar"
    heuristic: str | None = None
    connectivity: int = 8
    # [m] The loader's default is the vehicle's radius ([vehicle] radius), not this 0.0, which
    # only a PlannerSettings built in code without the scenario gets.
    expansion_distance: float = 0.0
    smoothing: str = "line_of_sight"
    min_turning_radius: float | None = None
    reverse: bool = False
    # Replanning at run time on the known map plus the lidar's returns (cosim.navigation.planner).
    replan: bool = True
    replan_after: float = 2.0  # [s] without a free VFH direction
    replan_stall_time: float = 10.0  # [s] without 1 m of progress along the plan
    replan_horizon: float = 20.0  # [m] of the plan ahead checked for newly seen obstacles
    replan_interval: float = 1.0  # [s] at least between two replans


@dataclass(frozen=True)
class LidarSettings:
    """Beams [rad, robot frame], range limits [m], Gaussian range noise std [m], seed, rate [Hz]."""

    angles: np.ndarray
    range_min: float
    range_max: float
    noise: float
    seed: int
    rate: float


@dataclass(frozen=True)
class Scenario:
    source: str  # how errors name the file
    path: Path | None
    text: str
    name: str
    description: str
    map_file: Path
    map_resolution: float | None
    map_origin: tuple[float, float] | None
    obstacles: tuple[Obstacle, ...]
    start: tuple[float, float, float]  # x [m], y [m], theta [rad]
    goal: tuple[float, float]  # x [m], y [m]
    goal_tolerance: float  # [m]
    planner: PlannerSettings
    vehicle_type: str  # "differential" | "bicycle"
    vehicle_radius: float  # footprint circle for collisions [m]
    components: dict[str, ComponentSpec]
    lidar: LidarSettings
    macro_step: float  # [s]
    stop_time: float  # [s]
    master: str  # "gauss-seidel" | "jacobi"
    controller_rate: float  # [Hz]
    log_pattern: str
    plot: bool
    pose_rate: float  # [Hz] of /odom, /tf, /pose
    signal_arrays: bool  # /signals/<component> also holds array outputs (lidar ranges, waypoints)
    overrides: tuple[str, ...] = field(default=())
    topics: dict[str, str] = field(default_factory=dict)  # [output.topics]: "/odom" -> name in the log
    connections: tuple[ConnectionSpec, ...] = field(default=())
    algebraic_loops: str = "delay"  # "delay" | "iterate" | "error": see `cosim.core.system.System.loops`
    loop_tolerance: float = DEFAULT_TOLERANCE  # relative, of "iterate": see `cosim.core.loops`
    loop_max_iterations: int = DEFAULT_MAX_ITERATIONS  # of "iterate" per macro step
    fmi_version: int = 2  # which build of the project FMUs the roles use (2 or 3)
    fmu_isolation: str = "auto"  # "auto" | "process" | "none": see `isolation`
    fmu_timeout: float = 10.0  # [s] longest FMI call of an FMU in a child process
    fmu_max_size: float = 1024.0  # [MiB] largest total uncompressed size of an FMU archive
    fmu_max_memory: float = 2048.0  # [MiB] memory limit of an FMU's child process (RLIMIT_DATA)
    # [system] remove: template components left out (as written; `describe_system` checks the names).
    # A removed role has no entry in `components`.
    removed: tuple[str, ...] = ()
    # Component -> how the log names its FMU instead of the file's path: the archive member of an
    # FMU unpacked from an SSP (a path new in every run would make equal runs differ in bytes).
    fmu_labels: dict[str, str] = field(default_factory=dict)
    imu: ImuSettings | None = None  # [imu]: /imu (cosim.world.imu); None without the section
    bumper: bool = False  # [bumper]: /bumper, the footprint touching an obstacle

    def isolation(self, spec: ComponentSpec) -> str:
        """Where one FMU runs: "process" (a child process) or "none" (in the run's process). The
        component's own `isolation` key wins; otherwise [simulation] fmu_isolation, whose "auto"
        puts FMUs given by path in a child process and the project's own FMUs in-process."""
        if spec.isolation is not None:
            return spec.isolation
        if self.fmu_isolation != "auto":
            return self.fmu_isolation
        return "none" if spec.is_builtin else "process"

    @property
    def project_fmus(self) -> list[str]:
        """The names of the project's own FMUs its components use (what a first run builds), in the
        order the run reads them: the template's (`TEMPLATE_ORDER`), then the added components'."""
        position = {name: number for number, name in enumerate(TEMPLATE_ORDER)}
        names = sorted(self.components, key=lambda name: position.get(name, len(position)))
        return [self.components[name].fmu for name in names if self.components[name].is_builtin]


def load_scenario(
    path: str | Path,
    overrides: list[str] | tuple[str, ...] = (),
    check_world: bool = True,
    fleet: bool = False,
):
    """Read, override and validate a scenario file; raise `CosimError` (one line) on any problem.
    A fleet (`[[robots]]`) is a `cosim.scenario.fleet.Fleet`, accepted only with `fleet=True`
    (what takes one robot says so instead of failing on it)."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CosimError(f"{source}: no such scenario file") from None
    except UnicodeDecodeError as error:
        raise CosimError(
            wrong_file_message(path, "a scenario") or f"{source}: cannot read: {error}"
        ) from None
    except OSError as error:
        raise CosimError(f"{source}: cannot read: {error}") from None
    scenario = parse_scenario(text, source, path.resolve().parent, overrides, path=path)
    if not isinstance(scenario, Scenario) and not fleet:
        raise CosimError(
            f"{source}: a fleet ([[robots]]) runs with cosim run and shows with cosim system; "
            "this takes one robot"
        )
    if check_world:
        check_scenario_world(scenario)
    return scenario


def check_scenario_world(scenario) -> None:
    """What `load_scenario` checks after the file (unless `check_world=False`): the start and goal of
    a scenario or of each robot of a fleet against the map and the obstacles; `CosimError` otherwise.
    Apart, so that `cosim run` starts building the FMUs the file names before waiting for the
    kernels this check loads."""
    if isinstance(scenario, Scenario):
        from cosim.world.distance import check_start_goal

        check_start_goal(scenario)
    else:
        from cosim.scenario.fleet import check_fleet_world

        check_fleet_world(scenario)


def is_fleet(raw: dict) -> bool:
    """Whether parsed scenario TOML describes a fleet (`cosim.scenario.fleet`, imported only then)."""
    return "robots" in raw or "fleet" in raw


def parse_scenario(
    text: str,
    source: str,
    base_dir: Path,
    overrides: list[str] | tuple[str, ...] = (),
    path: Path | None = None,
) -> Scenario:
    """Validate scenario TOML `text`; relative file names resolve against `base_dir`."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise CosimError(f"{source}: TOML syntax error: {error}") from None
    except RecursionError:
        raise CosimError(f"{source}: TOML nested too deeply (arrays or inline tables)") from None
    except ValueError as error:  # an integer of more than 4300 digits
        raise CosimError(f"{source}: TOML value not readable: {shorten(str(error))}") from None
    for override in overrides:
        apply_override(raw, override, source)
    if is_fleet(raw):  # [[robots]]: a Fleet of single-robot scenarios (cosim.scenario.fleet)
        from cosim.scenario.fleet import build_fleet

        return build_fleet(raw, source, _build, base_dir, text, path, tuple(overrides))
    return _build(raw, source, base_dir, text, path, tuple(overrides))


def apply_override(raw: dict, override: str, source: str) -> None:
    """Apply `key.path=value` (value in TOML syntax; a bare word is a string) to the parsed TOML."""
    key, separator, value_text = override.partition("=")
    key = key.strip()
    shown = shorten(override)
    if not separator or not key:
        raise CosimError(f"--set {shown}: expected key=value, e.g. vfh.robot_radius=0.6")
    try:
        value = tomllib.loads(f"value = {value_text.strip()}")["value"]
    except (tomllib.TOMLDecodeError, RecursionError, ValueError):
        value = value_text.strip()
    parts = key.split(".")
    if parts[0] not in SECTIONS:
        raise CosimError(
            f"--set {shown}: unknown section {describe(parts[0])}{did_you_mean(parts[0], SECTIONS)}"
        )
    node: Any = raw
    for depth, part in enumerate(parts[:-1]):
        if isinstance(node, list) and depth == 1 and parts[0] == "robots" and not part.isdigit():
            from cosim.scenario.fleet import find_robot

            node = find_robot(node, part)  # robots.robot2.vfh.safety_distance: a robot by its name
            if node is None:
                raise CosimError(f"--set {shown}: no robot named {describe(part)} in [[robots]]")
            continue
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise CosimError(
                    f"--set {shown}: no item {shorten(part)} in {shorten('.'.join(parts[:depth]))}"
                )
            node = node[int(part)]
        else:
            node = node.setdefault(part, {})
        if not isinstance(node, dict | list):
            raise CosimError(f"--set {shown}: {shorten('.'.join(parts[: depth + 1]))} is not a table")
    if isinstance(node, list):  # an item of a list, e.g. vfh.distance_limits.1=25
        if not parts[-1].isdigit() or int(parts[-1]) >= len(node):
            raise CosimError(
                f"--set {shown}: no item {shorten(parts[-1])} in {shorten('.'.join(parts[:-1]))} "
                f"(items 0 to {len(node) - 1})"
            )
        node[int(parts[-1])] = value
        return
    node[parts[-1]] = value


def _build(
    raw: dict, source: str, base_dir: Path, text: str, path: Path | None, overrides: tuple
) -> Scenario:
    top = TableReader(source, "", raw)
    scenario_table = TableReader(source, "[scenario]", top.raw("scenario"))
    name = scenario_table.string("name")
    if not name or len(name) > MAX_NAME_LENGTH or any(char in name for char in "/\\\0"):
        raise scenario_table.error(
            "name",
            f"must be a file-name-safe string of 1 to {MAX_NAME_LENGTH} characters, got {describe(name)}",
        )
    description = scenario_table.string("description", "")
    scenario_table.finish()

    map_table = TableReader(source, "[map]", top.raw("map"))
    map_file = _existing_file(map_table, "file", base_dir, "map file")
    map_resolution = map_table.number("resolution", None, minimum=0.0, exclusive_minimum=True)
    origin = map_table.numbers("origin", None, length=2)
    map_table.finish()

    obstacle_tables = _list(top, "obstacles")
    if len(obstacle_tables) > MAX_OBSTACLES:
        raise top.error("obstacles", f"at most {MAX_OBSTACLES} obstacles, got {len(obstacle_tables)}")
    obstacles = tuple(_obstacle(source, index, item) for index, item in enumerate(obstacle_tables))

    start_table = TableReader(source, "[start]", top.raw("start"))
    start = (start_table.number("x"), start_table.number("y"), start_table.number("theta", 0.0))
    start_table.finish()
    goal_table = TableReader(source, "[goal]", top.raw("goal"))
    goal = (goal_table.number("x"), goal_table.number("y"))
    goal_tolerance = goal_table.number("tolerance", 1.0, minimum=0.0, exclusive_minimum=True)
    goal_table.finish()

    simulation = TableReader(source, "[simulation]", top.raw("simulation", {}))
    macro_step = simulation.number("macro_step", 0.01, minimum=0.0, exclusive_minimum=True, maximum=MAX_TIME)
    check_time_base(simulation, "macro_step", macro_step)
    stop_time = simulation.number("stop_time", 300.0, minimum=0.0, exclusive_minimum=True, maximum=MAX_TIME)
    master = simulation.string("master", "gauss-seidel", choices=("gauss-seidel", "jacobi"))
    controller_rate = simulation.number("controller_rate", 20.0, minimum=0.0, exclusive_minimum=True)
    algebraic_loops = simulation.string("algebraic_loops", Scenario.algebraic_loops, choices=LOOP_HANDLING)
    if master == "jacobi" and algebraic_loops != "delay":
        raise simulation.error(
            "algebraic_loops",
            f"'{algebraic_loops}' has no effect with master = 'jacobi' (a Jacobi master steps every "
            "component on the outputs of the step before, so no loop is iterated or refused): remove "
            "it, or use master = 'gauss-seidel'",
        )
    loop_tolerance = simulation.number(
        "loop_tolerance", Scenario.loop_tolerance, minimum=0.0, exclusive_minimum=True, maximum=1.0
    )
    loop_max_iterations = simulation.integer("loop_max_iterations", Scenario.loop_max_iterations, minimum=1)
    fmi_version = simulation.integer("fmi_version", Scenario.fmi_version)
    if fmi_version not in (2, 3):
        raise simulation.error(
            "fmi_version", f"must be 2 or 3 (the project FMUs' builds), got {describe(fmi_version)}"
        )
    if stop_time < macro_step:
        raise simulation.error(
            "stop_time", f"{stop_time:g} s is shorter than one macro step ({macro_step:g} s)"
        )
    _check_rate(simulation, "controller_rate", controller_rate, macro_step)
    fmu_isolation = simulation.string("fmu_isolation", Scenario.fmu_isolation, choices=("auto", *ISOLATIONS))
    fmu_timeout = simulation.number("fmu_timeout", Scenario.fmu_timeout, minimum=0.0, exclusive_minimum=True)
    fmu_max_size = simulation.number(
        "fmu_max_size", Scenario.fmu_max_size, minimum=0.0, exclusive_minimum=True
    )
    fmu_max_memory = simulation.number(
        "fmu_max_memory", Scenario.fmu_max_memory, minimum=0.0, exclusive_minimum=True
    )
    check_run_length(simulation, macro_step, stop_time)
    max_components = simulation.integer("max_components", MAX_COMPONENTS, minimum=1)
    simulation.finish()

    vehicle_table = TableReader(source, "[vehicle]", top.raw("vehicle"))
    vehicle_fmu = _fmu_name(vehicle_table, None, base_dir)
    # A project FMU implies the type; an FMU given by path must say which ports it fills.
    vehicle_type = vehicle_table.string(
        "type", VEHICLE_TYPES.get(vehicle_fmu, REQUIRED), choices=("differential", "bicycle")
    )
    if vehicle_fmu in VEHICLE_TYPES and VEHICLE_TYPES[vehicle_fmu] != vehicle_type:
        raise vehicle_table.error("type", f"'{vehicle_type}' does not match the project FMU {vehicle_fmu}")
    components: dict[str, ComponentSpec] = {}
    removed = _removed(top)
    tables = top.raw("components", {})
    replaced = set(tables) & set(REPLACEABLE) if isinstance(tables, dict) else set()
    idle = [
        role
        for role in (*ROLE_SECTIONS, *PYTHON_COMPONENTS)
        if role != "vehicle" and (role in removed or role in replaced) and top.has(role)
    ]
    if idle:  # every such section at once: deleting one to be told of the next is a loop of runs
        how = {
            role: "removed by [system].remove" if role in removed else f"replaced by [components.{role}]"
            for role in idle
        }
        if len(idle) == 1:
            role = idle[0]
            raise top.error(role, f"'{role}' is {how[role]}: this section would set nothing; delete it")
        sections = ", ".join(f"[{role}] ({how[role]})" for role in idle)
        raise CosimError(f"{source}: {sections}: these sections would set nothing; delete them")
    vfh_table = TableReader(source, "[vfh]", top.raw("vfh", {}))
    vfh_radius = vfh_table.table.get("robot_radius")
    default_radius = float(vfh_radius) if is_number(vfh_radius) and vfh_radius > 0 else 0.5
    vehicle_radius = vehicle_table.number("radius", default_radius, minimum=0.0, exclusive_minimum=True)
    components["vehicle"] = _component(vehicle_table, "vehicle", vehicle_fmu, None, macro_step)
    for role in ("pure_pursuit", "vfh", "mixer"):
        if role in removed or role in replaced:
            continue
        table = vfh_table if role == "vfh" else TableReader(source, f"[{role}]", top.raw(role, {}))
        fmu = _fmu_name(table, DEFAULT_FMUS[role], base_dir)
        components[role] = _component(table, role, fmu, controller_rate, macro_step)
    if isinstance(tables, dict):  # counted before each table is read: a limit, not a slow refusal
        check_component_count(
            top, "components", len(components) + len(set(tables) - set(components)), max_components
        )
    components.update(_added_components(top, base_dir, removed))
    connections = tuple(
        _connection(source, index, item) for index, item in enumerate(_list(top, "connections"))
    )

    planner = _planner(TableReader(source, "[planner]", top.raw("planner", {})), vehicle_radius)
    lidar = _lidar(TableReader(source, "[lidar]", top.raw("lidar", {})), macro_step)

    imu = _imu(top.table_of("imu"), macro_step) if top.has("imu") else None
    bumper = top.has("bumper")
    top.table_of("bumper").finish()  # no keys: present or not

    output = TableReader(source, "[output]", top.raw("output", {}))
    log_pattern = output.string("log", DEFAULT_LOG_PATTERN)
    try:
        log_pattern.format(scenario="s", timestamp="t")
    except (KeyError, IndexError, ValueError) as error:
        raise output.error(
            "log", f"bad pattern (placeholders: {{scenario}}, {{timestamp}}): {error}"
        ) from None
    plot = output.boolean("plot", True)
    pose_rate = output.number("pose_rate", 50.0, minimum=0.0, exclusive_minimum=True)
    _check_rate(output, "pose_rate", pose_rate, macro_step)
    signal_arrays = output.boolean("signal_arrays", False)
    topics = _topics(output.table_of("topics"))
    output.finish()
    top.finish()

    return Scenario(
        source=source,
        path=path,
        text=text,
        name=name,
        description=description,
        map_file=map_file,
        map_resolution=map_resolution,
        map_origin=origin,
        obstacles=obstacles,
        start=start,
        goal=goal,
        goal_tolerance=goal_tolerance,
        planner=planner,
        vehicle_type=vehicle_type,
        vehicle_radius=vehicle_radius,
        components=components,
        lidar=lidar,
        macro_step=macro_step,
        stop_time=stop_time,
        master=master,
        controller_rate=controller_rate,
        log_pattern=log_pattern,
        plot=plot,
        pose_rate=pose_rate,
        signal_arrays=signal_arrays,
        topics=topics,
        overrides=overrides,
        connections=connections,
        fmi_version=fmi_version,
        algebraic_loops=algebraic_loops,
        loop_tolerance=loop_tolerance,
        loop_max_iterations=loop_max_iterations,
        fmu_isolation=fmu_isolation,
        fmu_timeout=fmu_timeout,
        fmu_max_memory=fmu_max_memory,
        fmu_max_size=fmu_max_size,
        removed=removed,
        imu=imu,
        bumper=bumper,
    )


def _removed(top: TableReader) -> tuple[str, ...]:
    """`[system] remove = ["vfh", "mixer"]`: template components left out of the system."""
    table = TableReader(top.source, "[system]", top.raw("system", {}))
    removed = table.raw("remove", [])
    if not isinstance(removed, list) or not all(isinstance(name, str) for name in removed):
        raise table.error("remove", f"must be a list of component names, got {describe(removed)}")
    table.finish()
    return tuple(removed)


def _topics(table: TableReader) -> dict[str, str]:
    """`[output.topics]`: `odom = "/ground-truth-pose"` names a topic in the log (ROS remapping)."""
    topics: dict[str, str] = {}
    for key in list(table.table):
        if key not in REMAPPABLE_TOPICS:
            raise table.error(key, f"not a topic of the log{did_you_mean(key, REMAPPABLE_TOPICS)}")
        name = table.string(key)
        if not name.startswith("/") or len(name) < 2 or any(c.isspace() for c in name):
            raise table.error(key, f"a topic name starts with '/' and has no spaces, got '{name}'")
        if name in topics.values() or (name != f"/{key}" and name[1:] in REMAPPABLE_TOPICS):
            raise table.error(key, f"'{name}' is already the name of another topic")
        topics[f"/{key}"] = name
    table.finish()
    return topics


def _list(top: TableReader, key: str) -> list:
    value = top.raw(key, [])
    if not isinstance(value, list):
        raise top.error(key, f"must be an array of tables [[{key}]], got {describe(value)}")
    return value


def rate_problem(rate: float, macro_step: float) -> str | None:
    """Why `rate` [Hz] is no period of a whole number (>= 1) of macro steps [s], or None."""
    if 1.0 / rate > MAX_TIME:
        return f"must be >= {1 / MAX_TIME:g} Hz (a period of at most {MAX_TIME:g} s), got {rate:g}"
    steps = 1.0 / (rate * macro_step)
    if steps < 1.0 - 1e-9 or abs(steps - round(steps)) > 1e-6 * steps:
        return (
            f"{rate:g} Hz is not a whole number of macro steps of {macro_step:g} s (period {1 / rate:g} s); "
            f"rates that fit: {', '.join(f'{r:g}' for r in fitting_rates(rate, macro_step))} Hz"
        )
    return None


def fitting_rates(rate: float, macro_step: float, count: int = 3) -> list[float]:
    """The `count` rates [Hz] nearest to `rate` whose period is a whole number of macro steps
    (1 / (n * macro_step), n >= 1), highest first."""
    steps = max(1, round(1.0 / (rate * macro_step)))
    near = sorted(
        range(max(1, steps - count), steps + count + 1), key=lambda n: (abs(1 / (n * macro_step) - rate), n)
    )
    return sorted((1.0 / (n * macro_step) for n in near[:count]), reverse=True)


def _check_rate(table: TableReader, key: str, rate: float, macro_step: float) -> None:
    problem = rate_problem(rate, macro_step)
    if problem:
        raise table.error(key, problem)


def _existing_file(table: TableReader, key: str, base_dir: Path, what: str, name: str | None = None) -> Path:
    """`table[key]` (or `name`) resolved against `base_dir`; it must be an existing file."""
    name = table.string(key) if name is None else name
    try:
        path = (base_dir / name).resolve()
        if path.is_file():
            return path
        if path.is_dir():
            problem = f"the {what} is a directory: {shorten(path, PATH_LIMIT)}"
        elif path.exists():  # a device, a pipe, a socket
            problem = f"the {what} is not a regular file: {shorten(path, PATH_LIMIT)}"
        else:
            problem = f"no such {what}: {shorten(path, PATH_LIMIT)}"
    except RuntimeError:  # Python 3.11's resolve() on a symbolic link loop
        problem = f"cannot open the {what} {describe(name)}: symbolic link loop"
    except (OSError, ValueError) as error:  # name too long, link loop, embedded NUL byte, ...
        reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
        problem = f"cannot open the {what} {describe(name)}: {reason}"
    raise table.error(key, problem)


def _fmu_name(table: TableReader, default: str | None, base_dir: Path) -> str:
    """A project FMU name stays a name; anything else is a path (relative to the scenario file)."""
    fmu = table.string("fmu", REQUIRED if default is None else default)
    if fmu in builtin_fmus():
        return fmu
    if "/" not in fmu and not fmu.endswith(".fmu"):
        raise table.error(
            "fmu", f"unknown project FMU '{shorten(fmu)}'{did_you_mean(fmu, builtin_fmus())}; or give a path"
        )
    return str(_existing_file(table, "fmu", base_dir, "FMU file", fmu))


def _component(
    table: TableReader, role: str, fmu: str, default_rate: float | None, macro_step: float
) -> ComponentSpec:
    from cosim.scenario.params import check_parameters

    ports: dict[str, PortMapping] = {}
    port_table = table.table_of("ports")
    for port, value in port_table.table.items():
        port_table.used.add(port)
        if isinstance(value, str):
            ports[port] = PortMapping(value)
            continue
        entry = TableReader(table.source, f"{port_table.where}.{port}", value)
        ports[port] = PortMapping(entry.string("name"), entry.number("scale", 1.0))
        if ports[port].scale == 0.0:
            raise entry.error("scale", "must not be 0")
        entry.finish()
    rate = table.number("rate", default_rate, minimum=0.0, exclusive_minimum=True)
    if rate is not None:
        _check_rate(table, "rate", rate, macro_step)
    isolation, nan_outputs = _isolation_keys(table)
    integration = _integration_keys(table)
    parameters: dict[str, float | int | bool] = {}
    for key, value in table.table.items():
        if key in COMPONENT_KEYS or key in ("type", "radius") and role == "vehicle":
            continue
        table.used.add(key)
        parameters[key] = value
    parameters = check_parameters(table, parameters)
    check_speeds(table, role, parameters)
    table.finish()
    return ComponentSpec(
        name=role,
        fmu=fmu,
        parameters=parameters,
        ports=ports,
        rate=rate,
        isolation=isolation,
        nan_outputs=nan_outputs,
        integration=integration,
    )


def _integration_keys(table: TableReader) -> Integration:
    """A component section's `interface`, `solver`, `tolerance` and `max_step` (`Integration`)."""
    return Integration(
        interface=table.string("interface", None, choices=INTERFACES),
        solver=table.string("solver", None, choices=SOLVERS),
        tolerance=table.number("tolerance", None, minimum=0.0, exclusive_minimum=True),
        max_step=table.number("max_step", None, minimum=0.0, exclusive_minimum=True),
    )


def _isolation_keys(table: TableReader) -> tuple[str | None, tuple[str, ...]]:
    """A component section's `isolation` and `nan_outputs`."""
    isolation = table.string("isolation", None, choices=ISOLATIONS)
    nan_outputs = table.raw("nan_outputs", [])
    if not isinstance(nan_outputs, list) or not all(isinstance(port, str) for port in nan_outputs):
        raise table.error("nan_outputs", f"must be a list of output port names, got {describe(nan_outputs)}")
    return isolation, tuple(nan_outputs)


def _added_components(top: TableReader, base_dir: Path, removed: tuple[str, ...]) -> dict[str, ComponentSpec]:
    """`[components.NAME]` tables: `fmu` (required), `rate`, every other key an FMU variable's value.
    A name in `REPLACEABLE` replaces the template's component of that name.

    Whether the rate is a whole number of macro steps, and whether the variables exist, is checked
    with everything else about the system (`cosim.scenario.compose.describe_system`), so all
    problems come at once.
    """
    tables = top.table_of("components")
    components: dict[str, ComponentSpec] = {}
    for name, value in tables.table.items():
        tables.used.add(name)
        if not name.isidentifier() or not name.isascii() or len(name) > MAX_NAME_LENGTH:
            raise tables.error(
                name,
                f"a component name must be an identifier (letters, digits, _) of at most {MAX_NAME_LENGTH} "
                "characters",
            )
        where = f"[components.{name}]"
        if not isinstance(value, dict):
            raise tables.error(name, f"must be a table {where}, got {describe(value)}")
        table = TableReader(tables.source, where, value)
        if name in removed and name in REPLACEABLE:
            raise table.error(None, f"'{name}' is also in [system].remove: replace it or remove it, not both")
        if name == "vehicle":
            raise table.error(
                None,
                "swap the vehicle in [vehicle] (fmu, ports): the run reads the robot pose from its x, y, "
                "theta",
            )
        if name in PYTHON_COMPONENTS:
            raise table.error(
                None,
                f"'{name}' is a Python component of the navigation template: set it in [{name}], or leave it "
                f'out with [system] remove = ["{name}"] and add your FMU under another name',
            )
        fmu = _fmu_name(table, None, base_dir)
        rate = table.number("rate", None, minimum=0.0, exclusive_minimum=True)
        isolation, nan_outputs = _isolation_keys(table)
        integration = _integration_keys(table)
        parameters: dict[str, float | int | bool | str] = {}
        for key, item in table.table.items():
            if key in ("fmu", "rate", "isolation", "nan_outputs", *INTEGRATION_KEYS):
                continue
            table.used.add(key)
            if isinstance(item, bool | str) or is_number(item):
                parameters[key] = item  # a string sets a String (or, as hex, a Binary) variable
            else:
                raise table.error(
                    key,
                    f"an FMU variable's value must be a number, true/false or a string, got {describe(item)}",
                )
        table.finish()
        components[name] = ComponentSpec(
            name, fmu, parameters, {}, rate, True, isolation, nan_outputs, integration
        )
    return components


def _connection(source: str, index: int, item: Any) -> ConnectionSpec:
    table = TableReader(source, f"[[connections]][{index}]", item)
    connection = ConnectionSpec(
        source=table.string("from"),
        target=table.string("to"),
        scale=table.number("scale", 1.0),
        offset=table.number("offset", 0.0),
        index=index,
    )
    table.finish()
    return connection


def _obstacle(source: str, index: int, item: Any) -> Obstacle:
    table = TableReader(source, f"[[obstacles]][{index}]", item)
    kind = table.string("type", choices=("rectangle", "circle", "polygon"))
    motion = _motion(table)
    # A shape moving along a path may leave out its centre: it starts at the path's first point.
    at_path = list(motion.path[0]) if motion is not None and motion.path else REQUIRED
    if kind == "circle":
        obstacle: Obstacle = Circle(
            table.numbers("center", at_path, length=2),
            table.number("radius", minimum=0.0, exclusive_minimum=True),
            motion,
        )
    elif kind == "rectangle":
        size = table.numbers("size", length=2)
        if min(size) <= 0:
            raise table.error("size", f"length and width must be > 0, got {list(size)}")
        obstacle = Rectangle(
            table.numbers("center", at_path, length=2), size, table.number("yaw", 0.0), motion
        )
    else:
        vertices = table.raw("vertices")
        if not isinstance(vertices, list) or len(vertices) < 3:
            raise table.error(
                "vertices", f"must be a list of at least 3 [x, y] points, got {describe(vertices)}"
            )
        points = tuple(table.check_numbers(f"vertices[{i}]", v, 2) for i, v in enumerate(vertices))
        area = 0.5 * sum(
            a[0] * b[1] - b[0] * a[1] for a, b in zip(points, points[1:] + points[:1], strict=True)
        )
        if abs(area) < 1e-12:
            raise table.error("vertices", "the polygon has zero area")
        obstacle = Polygon(points, motion)
    table.finish()
    return obstacle


def _motion(table: TableReader) -> Motion | None:
    """An obstacle's `path` + `speed` + `motion`, or `velocity`, each with `start_time` (or None)."""
    if table.has("path") and table.has("velocity"):
        raise table.error("velocity", "give either path (with speed) or velocity, not both")
    if table.has("path"):
        path = table.raw("path")
        if not isinstance(path, list) or len(path) < 2:
            raise table.error("path", f"must be a list of at least 2 [x, y] points, got {describe(path)}")
        points = tuple(table.check_numbers(f"path[{i}]", p, 2) for i, p in enumerate(path))
        speed = table.number("speed", minimum=0.0, exclusive_minimum=True, maximum=MAX_LINEAR_SPEED)
        mode = table.string("motion", "loop", choices=MOTIONS)
        return Motion(points, speed, mode, start_time=table.number("start_time", 0.0, minimum=0.0))
    if table.has("velocity"):
        for key in ("speed", "motion"):
            if table.has(key):
                raise table.error(key, "belongs to a path; a velocity = [vx, vy] motion has no " + key)
        velocity = table.numbers("velocity", length=2)
        if math.hypot(*velocity) > MAX_LINEAR_SPEED:
            raise table.error(
                "velocity", f"a speed of at most {MAX_LINEAR_SPEED:g} m/s, got {math.hypot(*velocity):g} m/s"
            )
        return Motion(velocity=velocity, start_time=table.number("start_time", 0.0, minimum=0.0))
    for key in ("speed", "motion", "start_time"):
        if table.has(key):
            raise table.error(key, "needs a path = [[x, y], ...] or a velocity = [vx, vy]")
    return None


def _planner(table: TableReader, vehicle_radius: float) -> PlannerSettings:
    default = PlannerSettings  # each key's default is the dataclass field's (one declaration)
    settings = PlannerSettings(
        configuration=table.string("configuration", default.configuration, choices=CONFIGURATIONS),
        algorithm=table.string("algorithm", default.algorithm, choices=PLANNERS),
        heuristic=table.string(
            "heuristic",
            default.heuristic,
            choices=USER_HEURISTICS,
        ),
        connectivity=table.integer("connectivity", default.connectivity),
        expansion_distance=table.number("expansion_distance", vehicle_radius, minimum=0.0),
        smoothing=table.string(
            "smoothing", default.smoothing, choices=("none", "line_of_sight", "curvature")
        ),
        min_turning_radius=table.number(
            "min_turning_radius", default.min_turning_radius, minimum=0.0, exclusive_minimum=True
        ),
        reverse=table.boolean("reverse", default.reverse),
        replan=table.boolean("replan", default.replan),
        replan_after=table.number("replan_after", default.replan_after, minimum=0.0, exclusive_minimum=True),
        replan_stall_time=table.number(
            "replan_stall_time", default.replan_stall_time, minimum=0.0, exclusive_minimum=True
        ),
        replan_horizon=table.number("replan_horizon", default.replan_horizon, minimum=0.0),
        replan_interval=table.number("replan_interval", default.replan_interval, minimum=0.0),
    )
    if settings.connectivity not in (4, 8):
        raise table.error("connectivity", f"must be 4 or 8, got {settings.connectivity}")
    if settings.algorithm == "hybrid" and settings.min_turning_radius is None:
        raise table.error("min_turning_radius", "missing required key for algorithm 'hybrid'")
    table.finish()
    return settings


def _lidar(table: TableReader, macro_step: float) -> LidarSettings:
    if table.has("angles") and any(table.has(key) for key in ("angle_min", "angle_max", "count")):
        raise table.error("angles", "give either angles or angle_min/angle_max/count, not both")
    if table.has("angles"):
        angles = np.asarray(table.numbers("angles"))
        if angles.size == 0:
            raise table.error("angles", "must hold at least one angle")
    else:
        angle_min = table.number("angle_min", -math.pi, minimum=-math.pi, maximum=math.pi)
        angle_max = table.number("angle_max", math.pi, minimum=-math.pi, maximum=math.pi)
        if angle_min >= angle_max:
            raise table.error("angle_max", f"must be > angle_min ({angle_min:g}), got {angle_max:g}")
        count = table.integer("count", 360, minimum=1)
        if count > MAX_LIDAR_BEAMS:  # before the angles are made: count may be 2^63 - 1
            raise table.error(
                "count", f"at most {MAX_LIDAR_BEAMS} beams (the VFH input size), got {describe(count)}"
            )
        angles = evenly_spaced_beams(angle_min, angle_max, count)
    if angles.size > MAX_LIDAR_BEAMS:
        raise table.error(
            "angles", f"at most {MAX_LIDAR_BEAMS} beams (the VFH input size), got {angles.size}"
        )
    if np.any(np.abs(angles) > math.pi + 1e-9):
        raise table.error("angles", "every angle must lie in [-pi, pi]")
    range_min, range_max = table.interval("range", [0.0, 20.0], minimum=0.0)
    if range_max <= 0:
        raise table.error("range", f"max must be > 0, got {range_max:g}")
    if range_max > MAX_LIDAR_RANGE:
        raise table.error("range", f"max must be at most {MAX_LIDAR_RANGE:g} m, got {range_max:g}")
    noise = table.number("noise", 0.0, minimum=0.0)
    seed = table.integer("seed", 0, minimum=0)
    rate = table.number("rate", 10.0, minimum=0.0, exclusive_minimum=True)
    _check_rate(table, "rate", rate, macro_step)
    table.finish()
    return LidarSettings(angles, range_min, range_max, noise, seed, rate)


def _imu(table: TableReader, macro_step: float) -> ImuSettings:
    """`[imu]`: rate [Hz], noise = {acceleration, angular_velocity, orientation} standard
    deviations [m/s^2, rad/s, rad], bias = {acceleration, angular_velocity} (x, y, z each), seed."""
    default = ImuSettings()
    rate = table.number("rate", default.rate, minimum=0.0, exclusive_minimum=True)
    _check_rate(table, "rate", rate, macro_step)
    noise = table.table_of("noise")
    standard_deviations = [
        noise.number(key, 0.0, minimum=0.0) for key in ("acceleration", "angular_velocity", "orientation")
    ]
    noise.finish()
    bias = table.table_of("bias")
    biases = [bias.numbers(key, [0.0, 0.0, 0.0], length=3) for key in ("acceleration", "angular_velocity")]
    bias.finish()
    seed = table.integer("seed", default.seed, minimum=0)
    table.finish()
    return ImuSettings(rate, *standard_deviations, *biases, seed)
