"""The global planner as a component: plans once, before the run, on the KNOWN map.

It mirrors the thesis's setup (section 4.4): the modified A* computes the waypoints in advance on
the known warehouse map (inflated by the expansion distance, then smoothed) and hands them to the
Pure Pursuit block as an N x 2 input padded with NaN. Unknown obstacles are not in this map; the
lidar and VFH deal with them at run time.
"""

from __future__ import annotations

import numpy as np

from cosim.core.component import PythonComponent, array_ports
from cosim.errors import CosimError
from cosim.scenario.template import WAYPOINT_CAPACITY
from planner.errors import PlannerError


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


class PlannerComponent(PythonComponent):
    """Outputs `waypoints[k,1]` (x [m]) and `waypoints[k,2]` (y [m]), k = 1..1000, NaN padded.

    `plan_path()` runs the search (call it before the log is opened: a failed plan is bad input);
    the outputs are constant afterwards, so the master may step it once.
    """

    # The plan is fixed for the whole run: the master copies the waypoints once at initialisation.
    constant_outputs = True

    def __init__(self, name: str, grid, start, goal, settings, period: float = 0.0):
        super().__init__(
            name,
            outputs=array_ports("waypoints", WAYPOINT_CAPACITY, columns=2, unit="m"),
            period=period,
            feedthrough={},
        )
        self.grid = grid
        self.start = start
        self.goal = goal
        self.settings = settings
        self.result = None
        self.waypoints = np.empty((0, 2))

    def plan_path(self):
        """Plan from start to goal; returns the `PlanResult`. Raises `CosimError` when there is no path."""
        from planner import plan

        start = tuple(self.start) if self.settings.algorithm == "hybrid" else tuple(self.start[:2])
        goal = tuple(self.goal)
        if self.settings.algorithm == "hybrid" and len(goal) == 2:
            goal = (*goal, float(np.arctan2(goal[1] - start[1], goal[0] - start[0])))
        try:
            self.result = plan(self.grid, start, goal, **plan_options(self.settings))
        except PlannerError as error:
            raise CosimError(f"[planner]: {error}") from None
        path = np.asarray(self.result.path, dtype=float)[:, :2]
        if len(path) == 0:
            raise CosimError("[planner]: no path from start to goal")
        path = end_at_goal(path, self.goal[:2])
        self.waypoints = downsample_path(path)
        self.output_buffer[:] = np.nan
        self.output_buffer[: 2 * len(self.waypoints)] = self.waypoints.reshape(-1)
        return self.result

    def on_initialize(self) -> None:
        if self.result is None:
            self.plan_path()

    def step(self, t: float, h: float) -> None:
        """Nothing to do: the plan is fixed for the whole run."""
