"""The global planner as a component: plans before the run on the KNOWN map, and replans at run time.

It mirrors the thesis's setup (section 4.4): the modified A* computes the waypoints in advance on
the known warehouse map (inflated by the expansion distance, then smoothed) and hands them to the
Pure Pursuit block as an N x 2 input padded with NaN. Unknown obstacles are not in this map; the
lidar and VFH deal with them at run time.

With replanning (`[planner] replan = true`, `Replanning`), the component also reads the vehicle's
pose, VFH's steering direction and the lidar's ranges, and keeps a costmap (`Costmap`: the known
map plus the lidar's returns, cleared by the rays that pass through). It replans from the current
pose when
- VFH has had no free direction (NaN steering) for `replan_after` s, or
- progress along the plan (arc length of the closest point) has grown by less than
  `STALL_DISTANCE` in `replan_stall_time` s, or
- a cell marked since the current plan was made lies within the vehicle radius of the plan's next
  `replan_horizon` m, if the lidar resolves obstacles (`Replanning.resolves_obstacles`: adjacent
  beams at most the vehicle's diameter apart at the lidar's range),
and at most once every `replan_interval` s.

Why the last condition: a sparse scan marks a point of an obstacle and nothing of its extent. With
the thesis's three beams 45 degrees apart (Table 4.5) the beams are 7.9 m apart at 10 m, more than
twice the 3 m car; a replan round the one cell a beam marked goes through the part of the obstacle
no beam has seen, and the car, turned onto it, no longer looks at it (observed in
warehouse_bicycle_three_obstacles: the plan round the first return from the pallet row brushed its
unseen corner, clearance -0.13 m at t = 2.6 s). Such a lidar leaves an obstacle on the plan to VFH,
as the thesis does, and replans only when VFH has no free direction or progress stalls.

A replan searches the costmap with the footprint (vehicle radius) as the hard limit and the
expansion distance as a cost (grid planners); Hybrid A*, which has no cost, first with half the
expansion distance's extra margin, then with the footprint. When there is no path, the goal cannot
be reached any more: `no_path` is set and the run ends. Cells of the inflation around the robot's
own position are opened (not the obstacles themselves), so a robot that stands closer to an
obstacle than the inflation can still leave. Bicycles replan with Hybrid A* from their pose. The
new waypoints are the component's outputs from that step on (`constant_outputs` is False then).
`replan(t, pose, reason)` is the entry point: from a pose to `self.goal`.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from cosim.core.component import Port, PythonComponent, array_ports
from cosim.errors import CosimError
from cosim.navigation.costmap import Costmap, path_progress
from cosim.scenario.load import PlannerSettings
from cosim.scenario.template import WAYPOINT_CAPACITY
from planner.errors import PlannerError
from planner.grid import OccupancyGrid

STALL_DISTANCE = 1.0  # [m] of progress along the plan that counts as progress
COST_WEIGHT = 3.0  # of the cost gradient in a replan (planner.options cost_weight)
SEARCH_WINDOW = 60  # plan segments searched ahead of the last progress for the closest point
# Points ahead on the plan that the C step looks at itself (more: Python's `_look_ahead`).
AHEAD_CAPACITY = 4096


def downsample_path(path: np.ndarray, capacity: int = WAYPOINT_CAPACITY) -> np.ndarray:
    """At most `capacity` rows of `path` (N x 2), evenly spread by arc length, first and last kept."""
    if len(path) <= capacity:
        return path
    arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))))
    targets = np.linspace(0.0, arc[-1], capacity)
    indices = np.unique(np.searchsorted(arc, targets).clip(0, len(path) - 1))
    indices[0], indices[-1] = 0, len(path) - 1
    return path[indices]


def end_at_goal(path: np.ndarray, goal) -> np.ndarray:
    """`path` (N x 2) whose last waypoint is exactly `goal` (x, y) [m].

    A grid planner ends at the centre of the goal's cell, up to half a cell diagonal (0.35 m at
    0.5 m/cell) from the goal itself. Pure Pursuit stops within its tolerance of the LAST waypoint
    while the run judges the distance to the scenario's goal: with the cell centre as last waypoint
    a robot could stop "at the goal" for the controller yet outside the run's tolerance (seen:
    stopped 1.1 m from the goal with a 1.0 m tolerance, until the stop time).
    """
    goal = np.asarray(goal, dtype=float)
    if len(path) >= 2 and np.allclose(path[-1], goal):
        return path
    ended = path.copy()
    ended[-1] = goal
    return ended


def plan_options(settings) -> dict:
    """`planner.plan` keyword options from the scenario's `[planner]` table (`PlannerSettings`)."""
    options = {
        "configuration": settings.configuration,
        "planner": settings.algorithm,
        "connectivity": settings.connectivity,
        "expansion_distance": settings.expansion_distance,
        "smoothing": None if settings.smoothing == "none" else settings.smoothing,
    }
    if settings.heuristic is not None:
        options["heuristic"] = settings.heuristic
    if settings.algorithm == "hybrid":
        options["min_turning_radius"] = settings.min_turning_radius
        options["reverse"] = settings.reverse
    return options


@dataclass(frozen=True)
class Replanning:
    """What replanning needs besides `[planner]`: the lidar's beams [rad] and limits [m], the
    vehicle radius [m], and the Hybrid A* turning radius [m] (None: replan with `[planner]`'s
    algorithm; a number: Hybrid A*, as for a bicycle)."""

    angles: np.ndarray
    range_min: float
    range_max: float
    vehicle_radius: float
    hybrid_turning_radius: float | None = None
    # The scenario's [planner] settings and their defaults (declared in PlannerSettings).
    replan_after: float = PlannerSettings.replan_after  # [s]
    replan_stall_time: float = PlannerSettings.replan_stall_time  # [s]
    replan_horizon: float = PlannerSettings.replan_horizon  # [m]
    replan_interval: float = PlannerSettings.replan_interval  # [s]

    @cached_property
    def beam_spacing(self) -> float:
        """[m] The widest gap between adjacent beams at the lidar's range, within its view.

        Of the gaps round the circle the widest one is outside the view of a sector scan; it is
        left out unless the beams are evenly spread all round (then every gap is inside the view).
        """
        angles = np.sort(np.mod(np.asarray(self.angles, dtype=float), 2.0 * math.pi))
        if len(angles) < 2:
            return math.inf
        gaps = np.append(np.diff(angles), angles[0] + 2.0 * math.pi - angles[-1])
        if gaps.max() - gaps.min() > 1e-9:
            gaps = np.delete(gaps, int(np.argmax(gaps)))
        return float(gaps.max() * self.range_max)

    @cached_property
    def resolves_obstacles(self) -> bool:
        """Whether the scan shows an obstacle's extent well enough to plan round it: adjacent beams at
        most the vehicle's diameter apart at the lidar's range (see the module docstring)."""
        return self.beam_spacing <= 2.0 * self.vehicle_radius


@dataclass
class Replan:
    """One replan: time [s], why (`no_free_direction`, `stalled`, `obstacle_on_plan`, `new_goal`), and the new
    path's length [m] (NaN when there was none)."""

    time: float
    reason: str
    length: float
    inflation: float = field(default=math.nan)  # [m] the costmap was inflated by


# The planner's C step (native/costmap.c's `planner_step`): where it hands over to Python, and why.
PENDING_MARKS, PENDING_REPLAN = 1, 2
REASON_NO_FREE_DIRECTION, REASON_STALLED, REASON_OBSTACLE_ON_PLAN = 1, 2, 3
REASONS = (None, "no_free_direction", "stalled", "obstacle_on_plan")  # by REASON_* code

_p, _i64, _f64 = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double


class _StepState(ctypes.Structure):
    """native/costmap.c's `PlannerStep`: what the planner's C step reads, and the replanning state
    it shares with `PlannerComponent.step` (the component's attributes are these fields)."""

    _fields_ = [
        ("costmap", _p), ("scan", _p), ("inputs", _p), ("points", _p), ("arc", _p),
        ("waypoint_count", _i64), ("marks_at_plan", _p),
        ("replan_after", _f64), ("replan_stall_time", _f64), ("replan_horizon", _f64),
        ("replan_interval", _f64), ("vehicle_radius", _f64), ("spacing", _f64), ("stall_distance", _f64),
        ("resolves_obstacles", _i64), ("search_window", _i64), ("active", _i64), ("following", _i64),
        ("segment", _i64), ("progress", _f64), ("blocked_since", _f64), ("mark_time", _f64),
        ("mark_progress", _f64), ("obstacle_on_plan", _i64), ("last_replan", _f64),
        ("pending", _i64), ("reason", _i64), ("ahead", _p), ("ahead_capacity", _i64),
    ]  # fmt: skip


def _state_field(name: str, kind=float, doc: str = ""):
    """A component attribute kept in its `_StepState` field `name` (read as `kind`)."""

    def get(self):
        return kind(getattr(self._state, name))

    def set(self, value) -> None:
        setattr(self._state, name, value)

    return property(get, set, doc=doc)


class PlannerComponent(PythonComponent):
    """Outputs `waypoints[k,1]` (x [m]) and `waypoints[k,2]` (y [m]), k = 1..1000, NaN padded.

    `plan_path()` runs the first search (call it before the log is opened: a failed plan is bad
    input). Without `replanning` the outputs are constant afterwards, so the master copies them
    once; with it the inputs are `x`, `y`, `theta` (vehicle pose), `steering_dir` (VFH, NaN = no
    free direction) and `ranges[k]` (lidar), and `replans`, `no_path` and `plan_version` tell the
    run what happened.
    """

    def __init__(
        self,
        name: str,
        grid,
        start,
        goal,
        settings,
        period: float = 0.0,
        replanning: Replanning | None = None,
    ):
        inputs = []
        if replanning is not None:
            inputs = [Port("x", unit="m"), Port("y", unit="m"), Port("theta", unit="rad")]
            inputs += [Port("steering_dir", unit="rad")] + array_ports(
                "ranges", len(replanning.angles), unit="m"
            )
        outputs = array_ports("waypoints", WAYPOINT_CAPACITY, columns=2, unit="m")
        # A replan uses the scan of the same step, so the planner steps after the lidar; one range
        # declared is enough to order it (cosim.scenario.template). Never VFH's direction: VFH
        # depends on the waypoints.
        direct = ["ranges[1]"] if replanning is not None else []
        super().__init__(
            name,
            inputs=inputs,
            outputs=outputs,
            period=period,
            feedthrough={port.name: direct for port in outputs},
        )
        # A plan fixed for the run: the master copies the waypoints once at initialisation.
        self.constant_outputs = replanning is None
        self.grid = grid
        self.start = start
        self.goal = goal
        self.settings = settings
        self.replanning = replanning
        self._state = _StepState(blocked_since=math.nan, last_replan=-math.inf)
        self.result = None
        self.waypoints = np.empty((0, 2))
        self.replans: list[Replan] = []
        self.no_path: str | None = None  # why the goal cannot be reached any more
        self.plan_version = 0  # counts the plans made (1 after plan_path)
        self.following = False
        self.kernel_steps = True  # the compiled kernel may step it (`kernel_step`)
        if replanning is not None:
            self.costmap = Costmap(grid, replanning.angles, replanning.range_min, replanning.range_max)
            self._path_progress = path_progress()
            self._nearest = ctypes.c_int64()  # the segment `path_progress` found
            self._nearest_ref = ctypes.byref(self._nearest)
            state = self._state
            state.costmap, state.scan = self.costmap._address, self.costmap._ranges.ctypes.data
            state.inputs = ctypes.addressof(self.input_cbuffer)
            state.replan_after = replanning.replan_after
            state.replan_stall_time = replanning.replan_stall_time
            state.replan_horizon = replanning.replan_horizon
            state.replan_interval = replanning.replan_interval
            state.vehicle_radius, state.spacing = replanning.vehicle_radius, self.grid.resolution / 2.0
            state.stall_distance, state.search_window = STALL_DISTANCE, SEARCH_WINDOW
            state.resolves_obstacles = int(replanning.resolves_obstacles)
            # The C step's scratch for the points ahead (`_plan_ahead`): the arc lengths, then x, y.
            spacing = self.grid.resolution / 2.0
            capacity = min(AHEAD_CAPACITY, math.ceil(replanning.replan_horizon / spacing) + 4)
            self._ahead = np.empty(3 * capacity)
            state.ahead, state.ahead_capacity = self._ahead.ctypes.data, capacity

    # The replanning state, shared with the C step (`kernel_step`).
    following = _state_field("following", bool, "waypoints given from outside (`follow`): no replanning")
    _segment = _state_field("segment", int, "index of the plan segment the progress lies on")
    _progress = _state_field("progress", float, "[m] along the plan")
    _obstacle_on_plan = _state_field("obstacle_on_plan", bool)
    _last_replan = _state_field("last_replan", float, "[s]")

    @property
    def no_path(self) -> str | None:
        """Why the goal cannot be reached any more (the planner stops replanning), or None."""
        return self._no_path

    @no_path.setter
    def no_path(self, why: str | None) -> None:
        self._no_path = why
        self._state.active = int(self.replanning is not None and why is None)

    @property
    def _blocked_since(self) -> float | None:
        """[s] since when VFH has had no free direction; None: it has one."""
        since = self._state.blocked_since
        return None if math.isnan(since) else since

    @_blocked_since.setter
    def _blocked_since(self, since: float | None) -> None:
        self._state.blocked_since = math.nan if since is None else since

    @property
    def _progress_mark(self) -> tuple[float, float]:
        """(time [s], progress [m]) of the last real progress."""
        return self._state.mark_time, self._state.mark_progress

    @_progress_mark.setter
    def _progress_mark(self, mark: tuple[float, float]) -> None:
        self._state.mark_time, self._state.mark_progress = mark

    def kernel_step(self) -> tuple[int, int] | None:
        """The C step of the master's compiled kernel (`cosim.core.fast_loop.KernelTables`): (address
        of native/costmap.c's `planner_step`, of its state). It does what `step` does while that
        needs no Python (the scan into the costmap, the progress, the triggers, the look for new
        marks near the plan ahead: `_look_ahead`, with the points of NumPy's arange and interp)
        and hands the step to Python where a replan may follow (or the look needs more than
        `AHEAD_CAPACITY` points); then `step` goes on from where it stopped. None
        without replanning, or when `kernel_steps` is False (every step in Python)."""
        if self.replanning is None or not self.kernel_steps:
            return None
        from cosim.navigation.costmap import _kernels

        function = ctypes.cast(_kernels().planner_step, ctypes.c_void_p).value
        return function, ctypes.addressof(self._state)

    def plan_path(self):
        """Plan from start to goal; returns the `PlanResult`. Raises `CosimError` when there is no path."""
        from planner import plan

        start = tuple(self.start) if self.settings.algorithm == "hybrid" else tuple(self.start[:2])
        goal = tuple(self.goal)
        if self.settings.algorithm == "hybrid" and len(goal) == 2:
            goal = (*goal, float(np.arctan2(goal[1] - start[1], goal[0] - start[0])))
        try:
            result = plan(self.grid, start, goal, **plan_options(self.settings))
        except PlannerError as error:
            raise CosimError(f"[planner]: {error}") from None
        if len(result.path) == 0:
            raise CosimError("[planner]: no path from start to goal")
        self._use(result)
        return self.result

    def _use(self, result) -> None:
        """Make `result` the plan: waypoints, outputs, the progress along it."""
        self.result = result
        path = end_at_goal(np.asarray(result.path, dtype=float)[:, :2], self.goal[:2])
        self.waypoints = np.ascontiguousarray(downsample_path(path), dtype=float)
        self.output_buffer[:] = np.nan
        self.output_buffer[: 2 * len(self.waypoints)] = self.waypoints.reshape(-1)
        self.plan_version += 1
        self._arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(self.waypoints, axis=0).T))))
        self._plan_addresses = (self.waypoints.ctypes.data, self._arc.ctypes.data)  # for path_progress
        state = self._state
        state.points, state.arc = self._plan_addresses
        state.waypoint_count = len(self.waypoints)
        self._plan_arrays = (self.waypoints, self._arc)  # what the state points into, alive
        self._segment = 0
        self._progress = 0.0
        if self.replanning is not None:
            self._marks_at_plan = self.costmap.snapshot()
            state.marks_at_plan = self._marks_at_plan.ctypes.data
            self._obstacle_on_plan = False

    def on_setup(self, t0: float, parameters) -> None:
        self._last_replan = -math.inf
        self._blocked_since: float | None = None
        self._progress_mark = (t0, 0.0)  # (time [s], progress [m]) of the last real progress

    def on_initialize(self) -> None:
        if self.result is None:
            self.plan_path()

    def step(self, t: float, h: float) -> None:
        """Update the costmap and the progress from the inputs; replan when a trigger fires."""
        if self._state.pending:
            self._go_on(t)
            return
        if self.replanning is None or self.no_path is not None:
            return
        inputs = self.input_buffer
        x, y, theta, steering = inputs.item(0), inputs.item(1), inputs.item(2), inputs.item(3)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(theta)):
            return
        changed = self.costmap.integrate(x, y, theta, inputs[4:])
        if self.following:  # the costmap only (a coordinator reads it)
            return
        self._advance_progress(x, y)
        reason = self._trigger(t, steering, changed > 0)
        if reason is not None and t - self._last_replan >= self.replanning.replan_interval:
            self.replan(t, (x, y, theta), reason)

    def _go_on(self, t: float) -> None:
        """The rest of a step the C step (`kernel_step`) handed over: the look for new marks near
        the plan ahead (more points than its scratch holds) and what follows it in `_trigger`, or
        the replan it found due."""
        state = self._state
        pending, state.pending = state.pending, 0
        inputs = self.input_buffer
        x, y, theta = inputs.item(0), inputs.item(1), inputs.item(2)
        reason = self._look_ahead() if pending == PENDING_MARKS else REASONS[state.reason]
        if reason is not None and t - self._last_replan >= self.replanning.replan_interval:
            self.replan(t, (x, y, theta), reason)

    def _advance_progress(self, x: float, y: float) -> None:
        """Move the progress to the closest point of the plan ahead (never backwards): of the next
        `SEARCH_WINDOW` segments, the one nearest to (x, y) (`path_progress` of native/costmap.c)."""
        first = self._segment
        stop = min(first + SEARCH_WINDOW, len(self.waypoints) - 1)
        if stop <= first:
            return
        points, arc = self._plan_addresses
        progress = self._path_progress(points, arc, first, stop, x, y, self._nearest_ref)
        if progress > self._progress:
            self._segment, self._progress = self._nearest.value, progress

    def _trigger(self, t: float, steering: float, new_marks: bool) -> str | None:
        """Why to replan now, or None (see the module docstring)."""
        settings = self.replanning
        if math.isnan(steering):
            if self._blocked_since is None:
                self._blocked_since = t
            elif t - self._blocked_since >= settings.replan_after:
                return "no_free_direction"
        else:
            self._blocked_since = None
        mark_time, mark_progress = self._progress_mark
        if self._progress >= mark_progress + STALL_DISTANCE:
            self._progress_mark = (t, self._progress)
        elif t - mark_time >= settings.replan_stall_time:
            return "stalled"
        # The marks only change with a scan; a finding held back by the interval is kept.
        if (
            new_marks
            and not self._obstacle_on_plan
            and settings.resolves_obstacles
            and self._marks_maybe_ahead()
        ):
            return self._look_ahead()
        return "obstacle_on_plan" if self._obstacle_on_plan else None

    def _look_ahead(self) -> str | None:
        """Whether a new mark lies near the plan ahead (kept: `_obstacle_on_plan`); the trigger."""
        settings = self.replanning
        ahead = self._plan_ahead(settings.replan_horizon)
        near = self.costmap.new_marks_near(ahead, settings.vehicle_radius, self._marks_at_plan)
        self._obstacle_on_plan = near
        return "obstacle_on_plan" if self._obstacle_on_plan else None

    def _marks_maybe_ahead(self) -> bool:
        """False when no point of `_plan_ahead` can have a new mark near it (`Costmap.new_marks_maybe_near`:
        a look at the marks round the plan's points that bracket them, without making them)."""
        settings = self.replanning
        spacing = self.grid.resolution / 2.0
        # `_plan_ahead`'s points lie at arc lengths from the progress to at most a spacing past
        # min(progress + horizon, plan's end) (np.arange stops short of its stop, up to rounding).
        high = min(self._progress + settings.replan_horizon, self._arc[-1]) + 2.0 * spacing
        points, arc = self._plan_addresses
        return self.costmap.new_marks_maybe_near(
            self._marks_at_plan, (points, arc, len(self.waypoints)), self._segment, self._progress, high,
            settings.vehicle_radius,
        )  # fmt: skip

    def _plan_ahead(self, horizon: float) -> np.ndarray:
        """Points every half cell along the plan from the progress to `horizon` [m] further."""
        end = self._progress + horizon
        spacing = self.grid.resolution / 2.0
        along = np.arange(self._progress, min(end, self._arc[-1]) + spacing, spacing)
        along = along[along <= self._arc[-1]]
        x = np.interp(along, self._arc, self.waypoints[:, 0])
        y = np.interp(along, self._arc, self.waypoints[:, 1])
        return np.column_stack((x, y))

    def replan(self, t: float, pose: tuple[float, float, float], reason: str) -> bool:
        """Plan from `pose` (x, y [m], theta [rad]) to the goal on the costmap; False (and `no_path`
        set) when there is no path any more."""
        self._last_replan = t
        self._blocked_since = None
        self._progress_mark = (t, 0.0)
        radius = self.replanning.vehicle_radius
        inflations = [radius]
        if self.replanning.hybrid_turning_radius is not None and self.settings.expansion_distance > radius:
            # Hybrid A* has no cost gradient: first keep half the expansion distance's extra margin.
            inflations.insert(0, (radius + self.settings.expansion_distance) / 2.0)
        error = None
        for inflation in inflations:
            try:
                result = self._search(pose, inflation)
            except PlannerError as failure:
                error = failure
                continue
            self._use(result)
            self.replans.append(Replan(t, reason, float(result.length), inflation))
            return True
        self.replans.append(Replan(t, reason, math.nan))
        self.no_path = f"no path from ({pose[0]:.2f}, {pose[1]:.2f}) m at t = {t:.2f} s: {error}"
        return False

    def _search(self, pose: tuple[float, float, float], inflation: float):
        """One search on the costmap inflated by `inflation` [m], opened around the pose and goal."""
        from planner import plan

        grid = self.costmap.grid()
        blocked = (grid.inflate(inflation) if inflation > 0 else grid).occupied.copy()
        for point in (pose[:2], self.goal[:2]):
            blocked &= ~_disc(grid, point, inflation) | grid.occupied
        costmap = OccupancyGrid(blocked, grid.resolution, grid.origin)
        if self.replanning.hybrid_turning_radius is not None:
            # Arrive as the current plan does (the heading of its last segment).
            end = self.waypoints[-2:] if len(self.waypoints) >= 2 else np.array([pose[:2], self.goal[:2]])
            heading = float(np.arctan2(end[-1, 1] - end[0, 1], end[-1, 0] - end[0, 0]))
            options = {
                "planner": "hybrid",
                "min_turning_radius": self.replanning.hybrid_turning_radius,
                "reverse": self.settings.reverse,
            }
            result = plan(costmap, tuple(pose), (*self.goal[:2], heading), **options)
        else:
            # The footprint is the hard limit; the expansion distance becomes a cost that keeps the
            # path away from obstacles where there is room (a hard expansion would close an aisle
            # that a box narrows, and send the robot round another one).
            options = {
                **plan_options(self.settings),
                "expansion_distance": 0.0,
                "cost_weight": COST_WEIGHT,
                "cost_scaling_factor": 1.0 / max(self.settings.expansion_distance, self.grid.resolution),
            }
            result = plan(costmap, tuple(pose[:2]), tuple(self.goal[:2]), **options)
        if len(result.path) == 0:
            raise PlannerError("empty path")
        return result

    def follow(self, waypoints: np.ndarray | None, t: float) -> None:
        """Drive along `waypoints` (N x 2 [m]) given from outside from t [s] on (a fleet's
        coordinator: the cells released to the robot; a halted robot: its own position), not
        replanning meanwhile (the costmap still takes the scans); `follow(None, t)` goes back to
        the component's own plan, from where the robot stands. Needs replanning (the outputs are
        not constant)."""
        if waypoints is None:
            self.following = False
            self._use(self.result)
            self._blocked_since = None
            self._progress_mark = (t, 0.0)
            return
        self.following = True
        self.waypoints = np.ascontiguousarray(downsample_path(np.asarray(waypoints, dtype=float)))
        self.output_buffer[:] = np.nan
        self.output_buffer[: 2 * len(self.waypoints)] = self.waypoints.reshape(-1)
        self.plan_version += 1

    def set_goal(self, x: float, y: float, t: float, pose: tuple[float, float, float]) -> str | None:
        """A new goal (x, y) [m] at time t [s] (the live view's /goal_pose): replan from `pose` to
        it at once. Returns None when the new plan is in use, else why not; then the old goal and
        plan stay (no `no_path`: the run goes on). Needs replanning (the pose and costmap inputs)."""
        if self.replanning is None:
            return "the scenario does not replan ([planner].replan = false)"
        grid = self.costmap.grid()
        cell = grid.world_to_cell((x, y))
        if not grid.contains_cell(cell):
            return "outside the map"
        if grid.occupied[cell]:
            return "on an occupied cell of the costmap"
        old_goal, old_waypoints = self.goal, self.waypoints
        self.goal = (float(x), float(y))
        # Hybrid A* arrives with the heading of the plan's last segment: here, from the pose to the goal.
        self.waypoints = np.array([pose[:2], self.goal], dtype=float)
        if self.replan(t, pose, "new_goal"):
            return None
        self.replans.pop()
        self.goal, self.waypoints, self.no_path = old_goal, old_waypoints, None
        return f"no path to it from ({pose[0]:.2f}, {pose[1]:.2f}) m"


def _disc(grid: OccupancyGrid, point, radius: float) -> np.ndarray:
    """Cells whose centre is within `radius` [m] of `point`, plus the point's own cell."""
    rows, cols = grid.shape
    x = grid.origin[0] + (np.arange(cols) + 0.5) * grid.resolution
    y = grid.origin[1] + (rows - 1 - np.arange(rows) + 0.5) * grid.resolution
    disc = np.hypot(x[None, :] - point[0], y[:, None] - point[1]) <= radius
    row, col = grid.world_to_cell((point[0], point[1]))
    if grid.contains_cell((row, col)):
        disc[row, col] = True
    return disc
