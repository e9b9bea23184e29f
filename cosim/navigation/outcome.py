"""Outcomes of a run: goal, collision, clearance, distance driven, VFH interventions, recovery time.

`OutcomeMonitor` is fed the vehicle's position after every vehicle step and the mixer's mode after
every mixer step; it decides when the run ends (goal reached or collision) and keeps the numbers
of the summary. `format_summary` prints them as a table; `outcome_metadata` stores them in the log.
`SafeCircle` tells the compiled loop where a position may end the run, so that it hands the steps
back before the monitor's exact checks could end it.

Definitions:
- goal reached: the vehicle's reference point is within the goal tolerance of the goal.
- clearance: distance from the vehicle's footprint circle (centre = its (x, y), radius = the
  scenario's vehicle radius) to the nearest TRUE obstacle (known map cells as exact squares and the
  unknown shapes, moving ones at their pose at that time; off the map counts as an obstacle);
  exact (`cosim.world.distance.WorldDistance`), checked at every vehicle step. A collision is
  clearance < 0.
- VFH interventions: the number of times the mixer enters avoid mode (mode 1) from another mode.
- time in recovery: the time the mixer spends in recover mode (mode 2), counted per mixer period.
"""

from __future__ import annotations

import ctypes
import math
import struct
from dataclasses import dataclass

import numpy as np

from cosim.record.steps import Reading

MODE_FOLLOW, MODE_AVOID, MODE_RECOVER = 0, 1, 2  # AvoidanceMixer's `mode` output


@dataclass
class Outcome:
    """The summary of one run. `reason`: goal_reached, collision, stop_time, no_path (the goal
    cannot be reached any more: a replan found no path), interrupted, fmu_failed, fmu_terminated (an
    FMU asked to end the simulation)."""

    reached: bool = False
    reason: str = "running"
    time: float = 0.0  # [s] simulated
    distance: float = 0.0  # [m] driven
    min_clearance: float = math.inf  # [m]
    vfh_interventions: int = 0
    recovery_time: float = 0.0  # [s]
    collision_point: tuple[float, float] | None = None
    replans: int = 0  # plans made at run time (the first plan not counted)
    no_path: str | None = None  # why the last replan found no path


class OutcomeMonitor:
    """Tracks one run's outcome; `world` gives the exact distance to the true obstacles."""

    def __init__(self, world, goal: tuple[float, float], tolerance: float, radius: float, start_xy):
        self.world = world
        self.goal = goal
        self.tolerance = tolerance
        self.radius = radius
        self.outcome = Outcome()
        self.last_xy = (float(start_xy[0]), float(start_xy[1]))
        self.last_mode = MODE_FOLLOW
        # A known lower bound of the true distance at an anchor point and time: the distance is
        # 1-Lipschitz in space, and moving obstacles come closer at most at their top speed, so at
        # a point r away and dt later it is at least bound - r - speed * dt (no need to ask the
        # world every step).
        self._speed = getattr(world, "max_speed", 0.0)
        self._moving = bool(getattr(world, "moving", False))
        self._anchor = (self.last_xy[0], self.last_xy[1], 0.0, -math.inf)
        self._compiled = _CompiledChecks.for_world(world)
        self.check_position(0.0, *self.last_xy)

    def check_position(self, t: float, x: float, y: float) -> str | None:
        """Update at time t [s] with the vehicle at (x, y) [m]; return why the run ends, or None."""
        return self.check_positions((t,), (x,), (y,))[1]

    def check_positions(self, times, xs, ys) -> tuple[int, str | None]:
        """`check_position` for consecutive steps (sequences of floats, or float64 arrays): (index
        of the step that ends the run, why) or (len(times), None); no step after the one that ends
        it is looked at. A static `WorldDistance` is checked in C (`world_check_positions` of
        cosim/world/native/world.c: the same operations, Python's hypot reproduced), the rest here."""
        compiled = self._compiled
        if compiled is not None:
            return compiled(self, times, xs, ys)
        # Python floats, whatever came in: the arithmetic below is Python's.
        times, xs, ys = (
            values.tolist() if isinstance(values, np.ndarray) else values for values in (times, xs, ys)
        )
        return self._check_in_python(times, xs, ys)

    def _check_in_python(self, times, xs, ys) -> tuple[int, str | None]:
        outcome = self.outcome
        radius = self.radius
        speed = self._speed
        moving = self._moving
        world = self.world
        goal_x, goal_y = self.goal
        tolerance = self.tolerance
        hypot, isfinite = math.hypot, math.isfinite
        last_x, last_y = self.last_xy
        distance = outcome.distance
        anchor_x, anchor_y, anchor_t, anchor_bound = self._anchor
        index, reason = len(times), None
        for i, (t, x, y) in enumerate(zip(times, xs, ys, strict=True)):
            distance += hypot(x - last_x, y - last_y)
            last_x, last_y = x, y
            if not (isfinite(x) and isfinite(y)):
                outcome.reason = "collision"
                outcome.collision_point = (x, y)
                index, reason = i, "collision"
                break
            # The exact distance only matters when it could set a new minimum (or a collision).
            margin = outcome.min_clearance + radius
            drift = speed * (t - anchor_t) if speed else 0.0
            if anchor_bound - hypot(x - anchor_x, y - anchor_y) - drift < margin:
                if moving:
                    world.at(t)
                bound = world.lower_bound(x, y)
                anchor_x, anchor_y, anchor_t, anchor_bound = x, y, t, bound
                if bound < margin:
                    exact = world.distance(x, y)
                    anchor_bound = exact
                    clearance = exact - radius
                    if clearance < outcome.min_clearance:
                        outcome.min_clearance = clearance
                    if clearance < 0.0:
                        outcome.reason = "collision"
                        outcome.collision_point = (x, y)
                        index, reason = i, "collision"
                        break
            if hypot(x - goal_x, y - goal_y) <= tolerance:
                outcome.reached = True
                outcome.reason = "goal_reached"
                index, reason = i, "goal_reached"
                break
        if len(times):
            outcome.time = times[min(index, len(times) - 1)]
        outcome.distance = distance
        self.last_xy = (last_x, last_y)
        self._anchor = (anchor_x, anchor_y, anchor_t, anchor_bound)
        return index, reason

    def check_mode(self, mode: float, period: float) -> None:
        """Update with the mixer's mode after a mixer step of `period` [s]."""
        if not math.isfinite(mode):
            return
        mode = int(round(mode))
        if mode == MODE_AVOID and self.last_mode != MODE_AVOID:
            self.outcome.vfh_interventions += 1
        if mode == MODE_RECOVER:
            self.outcome.recovery_time += period
        self.last_mode = mode

    def finish(self, t: float, reason: str) -> Outcome:
        """End the run at t [s] for `reason` unless a position check already ended it."""
        if self.outcome.reason == "running":
            self.outcome.reason = reason
            self.outcome.time = t
        return self.outcome


class _CompiledChecks:
    """`OutcomeMonitor.check_positions` in C for a static `WorldDistance`: the positions and times
    are copied into one array the C struct (world.c's `Monitor`) points at, the monitor's state
    into the struct, checked there step by step, and copied back."""

    def __init__(self, world) -> None:
        from cosim.world import kernels

        self.kernels = kernels
        self.world = world  # its struct, arrays and field stay alive with it
        self.field = np.ascontiguousarray(world.centre_field, dtype=np.float64)
        self.bounds = np.ascontiguousarray(world.shapes.bounds, dtype=np.float64).reshape(-1, 3)
        self.state = kernels.MonitorArrays(
            world=world._address,
            centre_field=self.field.ctypes.data,
            bounds=self.bounds.ctypes.data,
            n_bounds=len(self.bounds),
        )
        self.address = ctypes.addressof(self.state)
        self._points(1024)
        # The numbers from `radius` on, written and read as one block (one call each).
        self.offset = kernels.MonitorArrays.radius.offset
        self.at = kernels.MonitorArrays.last_x.offset
        self.pack = struct.Struct("=13d").pack_into
        self.unpack = struct.Struct("=8dq").unpack_from
        self.function = kernels.library().world_check_positions

    def _points(self, capacity: int) -> None:
        """Room for `capacity` steps: rows x, y, t."""
        self.points = np.empty((3, capacity))
        self.capacity = capacity
        self.state.points = self.points.ctypes.data
        self.state.capacity = capacity

    @classmethod
    def for_world(cls, world) -> _CompiledChecks | None:
        """The C checks of `world`, or None: not a `WorldDistance`, or its obstacles move (their
        poses are Python's, `WorldDistance.at`)."""
        from cosim.world.distance import WorldDistance

        if type(world) is not WorldDistance or world.moving or world.max_speed != 0.0:
            return None
        return cls(world)

    def __call__(self, monitor: OutcomeMonitor, times, xs, ys) -> tuple[int, str | None]:
        n = len(times)
        if n == 0 or len(xs) != n or len(ys) != n:
            return monitor._check_in_python(times, xs, ys)  # (which raises for differing lengths)
        if n > self.capacity:
            self._points(2 * n)
        points = self.points
        points[0, :n] = xs
        points[1, :n] = ys
        points[2, :n] = times
        self.put(monitor)
        index = self.function(self.address, n)
        code = self.get(monitor)
        if code == self.kernels.CHECK_PYTHON:
            # The rest from step `index` on, in Python (which indexes off the grid there).
            rest, reason = monitor._check_in_python(
                points[2, index:n].tolist(), points[0, index:n].tolist(), points[1, index:n].tolist()
            )
            return index + rest, reason
        return index, self.ended(monitor, index, code, n)

    def put(self, monitor: OutcomeMonitor) -> None:
        """The monitor's goal and state into the struct."""
        outcome = monitor.outcome
        goal_x, goal_y = monitor.goal
        last_x, last_y = monitor.last_xy
        self.pack(
            self.state, self.offset, monitor.radius, goal_x, goal_y, monitor.tolerance, monitor._speed,
            last_x, last_y, outcome.distance, outcome.min_clearance, *monitor._anchor,
        )  # fmt: skip

    def get(self, monitor: OutcomeMonitor) -> int:
        """The monitor's state from the struct (after a call); returns why the call stopped."""
        outcome = monitor.outcome
        last_x, last_y, outcome.distance, outcome.min_clearance, *anchor, code = self.unpack(
            self.state, self.at
        )
        monitor.last_xy = (last_x, last_y)
        monitor._anchor = tuple(anchor)
        return code

    def ended(self, monitor: OutcomeMonitor, index: int, code: int, n: int) -> str | None:
        """The monitor's outcome after a call over n steps that returned `index` for `code`
        (CHECK_GOING, CHECK_COLLISION or CHECK_GOAL, the points still in place): why the run
        ends, or None."""
        outcome = monitor.outcome
        points = self.points
        if code == 0:  # CHECK_GOING
            outcome.time = points.item(2, n - 1)
            return None
        if code == self.kernels.CHECK_COLLISION:
            outcome.reason = reason = "collision"
            outcome.collision_point = (points.item(0, index), points.item(1, index))
        else:
            outcome.reached = True
            outcome.reason = reason = "goal_reached"
        outcome.time = points.item(2, index)
        return reason


class SafeCircle:
    """The run loop's watch on `Master.run_blocks`: where the kernel must return to the run loop.

    The kernel returns after any step whose position may end the run: not finite, within the
    goal tolerance (plus a margin), or outside a circle around the last checked position that
    the true obstacles cannot reach within the block (the world's distance there, minus the
    vehicle's radius, minus what moving obstacles can cover in a block, minus a margin). So the
    exact checks of `OutcomeMonitor.check_position`, made for every step from the rows the kernel
    kept (`cosim.record.replay`), can only end the run at the last step of a block, where the
    kernel stopped (`cosim.navigation.run`).
    """

    def __init__(self, system, master, tables, monitor: OutcomeMonitor, pose: tuple[str, str], radius: float):
        """`pose`: the observed x and y ("component.port"); `radius` [m] the vehicle's."""
        self.master = master
        self.monitor = monitor
        self.tables = tables
        (vehicle_x, x), (vehicle_y, y) = (system.resolve(reference, "output") for reference in pose)
        self.x, self.y = Reading(vehicle_x.output_buffer, x), Reading(vehicle_y.output_buffer, y)
        tables.watch_addresses[:] = (
            1,
            ctypes.addressof(vehicle_x.output_cbuffer) + 8 * x,
            ctypes.addressof(vehicle_y.output_cbuffer) + 8 * y,
        )
        self.radius = radius
        self.world = monitor.world
        self.speed = getattr(self.world, "max_speed", 0.0)
        self.moving = bool(getattr(self.world, "moving", False))
        # Moving obstacles: short blocks, so the reach of the obstacles in one block stays small.
        self.block = 50 if self.speed > 0.0 else 1000
        self.h = system.macro_step
        self.anchor: tuple[float, float] | None = None

    def watch(self) -> None:
        """Before a kernel call: the circle around the current position known free of collisions."""
        x, y = self.x.value(), self.y.value()
        numbers = self.tables.watch_numbers
        # The goal as the monitor has it now (a hook may move it between blocks).
        goal, tolerance = self.monitor.goal, self.monitor.tolerance
        reach = tolerance + 1e-6 * (1.0 + tolerance)
        numbers[:3] = (goal[0], goal[1], reach * reach)
        if not self.moving and self.anchor is not None:
            # A static world: the circle stays valid; a new one only when half of it is used up.
            anchor_x, anchor_y = self.anchor
            dx, dy = x - anchor_x, y - anchor_y
            if 4.0 * (dx * dx + dy * dy) < numbers[5]:
                return
        self.anchor = (x, y)
        if not (math.isfinite(x) and math.isfinite(y)):
            numbers[3:] = (0.0, 0.0, -1.0)  # every step is checked
            return
        if self.moving:
            self.world.at(self.master.time)
        distance = self.world.lower_bound(x, y)
        if distance - self.radius < 1.0:
            distance = self.world.distance(x, y)
        drift = self.speed * (self.block + 1) * self.h
        free = distance - self.radius - drift - 1e-6 * (1.0 + distance)
        numbers[3:] = (x, y, free * free if free > 0.0 else -1.0)


def outcome_metadata(outcome: Outcome) -> dict[str, str]:
    """The `outcome` metadata record of the log (strings, SI units)."""
    return {
        "reached": "true" if outcome.reached else "false",
        "reason": outcome.reason,
        "time": f"{outcome.time:.6f}",
        "distance": f"{outcome.distance:.6f}",
        "min_clearance": f"{outcome.min_clearance:.6f}",
        "vfh_interventions": str(outcome.vfh_interventions),
        "recovery_time": f"{outcome.recovery_time:.6f}",
        "replans": str(outcome.replans),
    } | ({"no_path": outcome.no_path} if outcome.no_path else {})


# The project's avoidance FMUs by the short name a summary gives them.
_AVOIDERS = {"VectorFieldHistogram": "VFH", "ArtificialPotentialField": "APF"}


def avoider_name(scenario) -> str:
    """What avoided obstacles in `scenario`'s run, as the summary names it: "VFH", "APF", the stem
    of a user's FMU in the vfh role, or "avoidance" when the role was removed."""
    from pathlib import PurePath

    spec = scenario.components.get("vfh")
    if spec is None or "vfh" in scenario.removed:
        return "avoidance"
    fmu = str(spec.fmu)
    return _AVOIDERS.get(fmu, PurePath(fmu).stem or fmu)


def format_summary(
    name: str, outcome: Outcome, log_path=None, wall_time: float | None = None, avoider: str = "VFH"
) -> str:
    """A two-column table of the outcome, for the terminal; `avoider` names what the mode counts
    count (`avoider_name`): "APF interventions" where the potential field replaced VFH."""
    rows = [
        ("scenario", name),
        ("goal reached", "yes" if outcome.reached else f"no ({outcome.reason.replace('_', ' ')})"),
        ("simulated time", f"{outcome.time:.2f} s"),
        ("distance driven", f"{outcome.distance:.2f} m"),
        ("minimum clearance", f"{outcome.min_clearance:.3f} m"),
        (f"{avoider} interventions", str(outcome.vfh_interventions)),
        ("time in recovery", f"{outcome.recovery_time:.2f} s"),
        ("replans", str(outcome.replans)),
    ]
    if outcome.collision_point is not None:
        rows.append(
            ("collision at", f"({outcome.collision_point[0]:.2f}, {outcome.collision_point[1]:.2f}) m")
        )
    if wall_time is not None and wall_time > 0:
        rows.append(("real-time factor", f"{outcome.time / wall_time:.0f}x ({wall_time:.2f} s wall)"))
    if log_path is not None:
        rows.append(("log", str(log_path)))
    width = max(len(label) for label, _ in rows)
    rule = "-" * (width + 2 + max(len(value) for _, value in rows))
    return "\n".join([rule, *(f"{label:<{width}}  {value}" for label, value in rows), rule])
