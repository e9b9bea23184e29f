"""A system as data: components (with their interfaces), connections, macro step, what is observed.

`cosim.scenario.compose.describe_system(scenario)` makes a `SystemDescription` from a scenario
(the navigation template plus the scenario's own components and connections), checked as a whole;
`cosim.navigation.build` turns it into a running `cosim.core.system.System`; `cosim system` prints
and draws it. Nothing here is specific to a robot: the template's roles are just names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from cosim.scenario.load import Integration, PortMapping

TEMPLATE = "navigation template"  # `where` of what the template declares


@dataclass(frozen=True)
class ComponentDescription:
    """One component. `kind` says what makes it: "fmu", or a Python component of the navigation
    template (`cosim.scenario.load.PYTHON_COMPONENTS`); `cosim.navigation.build.COMPONENT_KINDS`
    holds the maker of each kind.

    where: the scenario section that declares it ("[vehicle]", "[components.lag]").
    rate: stepping rate [Hz]; None = every macro step.
    fmu: the .fmu file (project FMUs resolved to their built file); fmi_version, model_name from it.
    port_map: port name -> FMU variable (and scale), for role FMUs.
    parameters: parameter name -> value, set before initialisation (FMU parameters by port name).
    held_inputs: input name -> value, for inputs held at a constant instead of connected.
    defaults: parameters the template derives from other sections; set only when the FMU has them.
    required_parameters: parameter name -> the key it comes from (e.g. "x0" -> "[start].x"); the FMU
        must have it.
    inputs, outputs, parameter_names: the interface (port names), filled in by `describe_system`.
    feedthrough: output -> inputs it depends on directly (an FMU output without declared
        dependencies depends on every input; `state_outputs` override that).
    integration: the FMU's interface ("cs" or "me") and, for Model Exchange, its solver settings.
    robot_radii: a lidar of a fleet robot: the footprint radii [m] of the other robots it sees at
        its inputs robots_x[j], robots_y[j] (`cosim.scenario.fleet_compose`).
    state_outputs: outputs taken as states (no direct dependency) when the FMU declares no
        dependencies for them: a kinematic vehicle's pose integrates its inputs.
    """

    name: str
    kind: str
    where: str
    rate: float | None = None
    fmu: Path | None = None
    fmi_version: int | None = None
    model_name: str = ""
    port_map: Mapping[str, PortMapping] = field(default_factory=dict)
    parameters: Mapping[str, float] = field(default_factory=dict)
    held_inputs: Mapping[str, float] = field(default_factory=dict)
    defaults: Mapping[str, float] = field(default_factory=dict)
    required_parameters: Mapping[str, str] = field(default_factory=dict)
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    parameter_names: tuple[str, ...] = ()
    feedthrough: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    state_outputs: tuple[str, ...] = ()
    integration: Integration = Integration(interface="cs")  # an FMU's interface (and solver), resolved
    robot_radii: tuple[float, ...] = ()

    @property
    def period(self) -> float:
        """[s] between steps; 0 = every macro step."""
        return 0.0 if self.rate is None else 1.0 / self.rate


@dataclass(frozen=True, init=False)
class ConnectionDescription:
    """`target` input = `source` output * scale + offset; `where` says who declared it."""

    source: str  # "component.port"
    target: str
    scale: float = 1.0
    offset: float = 0.0
    where: str = TEMPLATE

    def __init__(
        self, source: str, target: str, scale: float = 1.0, offset: float = 0.0, where: str = TEMPLATE
    ) -> None:
        # Written out (not generated): the template makes ~3,100 a robot, and a frozen dataclass's
        # generated __init__ sets each field through object.__setattr__.
        self.__dict__.update(source=source, target=target, scale=scale, offset=offset, where=where)

    @property
    def source_component(self) -> str:
        return self.source.split(".", 1)[0]

    @property
    def target_component(self) -> str:
        return self.target.split(".", 1)[0]


@dataclass(frozen=True)
class ScanSource:
    """A component whose outputs `ranges[k]` are a lidar sweep at `angles` [rad, robot frame]."""

    component: str
    angles: tuple[float, ...]
    range_min: float  # [m]
    range_max: float  # [m]


@dataclass(frozen=True)
class Observed:
    """What a run reads from the system besides recording it, named as "component.port".

    pose: x [m], y [m], theta [rad] of the robot (outcome, /odom, /tf, /pose); required.
    command: commanded v [m/s], omega [rad/s] (/cmd_vel and the twist of /odom), or None (no
        /cmd_vel; the twist of /odom is NaN: unknown).
    mode: the avoidance mode (0 follow, 1 avoid, 2 recover) counted in the outcome, or None (the
        VFH counts stay 0).
    scan: the component whose ranges go to /scan, or None.
    """

    pose: tuple[str, str, str]
    command: tuple[str, str] | None = None
    mode: str | None = None
    scan: ScanSource | None = None

    def references(self) -> list[tuple[str, str]]:
        """(what, "component.port") of every observed output, for checking that they exist."""
        named = [("pose", reference) for reference in self.pose]
        named += [("command", reference) for reference in self.command or ()]
        named += [("mode", self.mode)] if self.mode else []
        return named


@dataclass(frozen=True)
class SystemDescription:
    """Components in the order they are added (it breaks ties of the step order), connections,
    the macro step [s] and master algorithm, what is observed, which template connections the
    scenario replaced (template connection, the scenario's connection into the same input), the
    template components it removed (`[system] remove`) and replaced (`[components.NAME]` of a
    template name), and the template connections dropped with them (connection, why)."""

    components: dict[str, ComponentDescription]
    connections: tuple[ConnectionDescription, ...]
    macro_step: float
    master: str
    observed: Observed | None = None
    replaced: tuple[tuple[ConnectionDescription, ConnectionDescription], ...] = ()
    removed: tuple[str, ...] = ()
    replacing: tuple[str, ...] = ()
    dropped: tuple[tuple[ConnectionDescription, str], ...] = ()
    algebraic_loops: str = "delay"  # `[simulation] algebraic_loops`
    loop: tuple[str, ...] = ()  # an algebraic loop run by `algebraic_loops = "delay"` (ports)
