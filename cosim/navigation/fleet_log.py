"""A fleet run's log, recorded through the base run: every robot under its ROS namespace.

The fleet's run is the base run of its one system (`cosim.record.system_run.SystemRun`: the
recorder, the header's metadata, the text signals, the clock and progress bar, the last records at
the end), each robot recorded as the single-robot run records one (`cosim.record.fleet_steps`), so
a fleet's log holds what a robot's does, per robot under its namespace:
- metadata `navcosim` (the scenario's name, this version, the robots and their starts and goals,
  the time base, the fleet settings), `fmu/<robot>:<component>` per FMU, `unconnected_inputs`;
  attachments `scenario.toml` (the file as given) and the map file(s);
- `/map` (the known map) and the world's `/obstacles` (the fleet shares them: one topic) at t = 0,
  `/obstacles` again when a moving obstacle moved; per robot `/<robot>/map_inflated` (by its own
  expansion distance) and its first `/<robot>/plan` and `/<robot>/goal` at t = 0;
- per robot `/<robot>/signals/<component>` (component `<robot>:<component>` in the reader: `cosim
  log plot --signals robot1:vehicle.x`), `/<robot>/scan`, `/<robot>/cmd_vel`; `/<robot>/odom`,
  `/<robot>/pose` and one `/tf` tree under `map` at t = 0, every 1/pose_rate s and at the end
  (`cosim.record.fleet_steps`);
- `/<robot>/plan` after each block in which the robot replanned (stamped at the block's start,
  where its planner stepped), `/<robot>/goal` when it takes its next goal;
- metadata `fleet_outcome` at the end (per robot and fleet figures, collisions; each value JSON)
  and, as every log, `outcome` (reached: every robot completed; reason; time [s]).
"""

from __future__ import annotations

import json
import math

from cosim.record.fleet_steps import FleetSteps
from cosim.record.system_run import SystemRun, scenario_attachments
from cosim.record.text_signals import TextRecording


class FleetLog(SystemRun):
    """The fleet's run of the initialised `master` recording to `recorder` (module docstring).
    `robots`: the fleet's `_Robot`s (name, built run, scenario); `progress`: the simulated time [s]
    a progress bar counts up to (None: no bar); `goals` (`cosim.record.live.GoalSource`, the live
    view): a goal a client gives is refused (a fleet's robots follow their missions)."""

    def __init__(self, master, recorder, fleet, robots, progress: float | None = None, goals=None) -> None:
        super().__init__(master, recorder)
        self.goals = goals
        self.robots = robots
        self.steps = FleetSteps(
            recorder,
            master,
            [(r.robot.name, r.built.system, r.built.description.observed, r.robot.scenario) for r in robots],
        )
        self.views = self.steps.views
        first = fleet.first
        details = {
            "robots": ",".join(r.robot.name for r in robots),
            "macro_step": str(first.macro_step),
            "stop_time": str(first.stop_time),
            "overrides": " ".join(fleet.overrides),
            "master": first.master,
            "coordination": fleet.settings.coordination,
            "on_collision": fleet.settings.on_collision,
            "deadlock_after": str(fleet.settings.deadlock_after),
        }
        labels = {}
        for r in robots:
            scenario = r.robot.scenario
            x, y, theta = scenario.start
            details[f"{r.robot.name}.start"] = f"{x},{y},{theta}"
            details[f"{r.robot.name}.goal"] = f"{scenario.goal[0]},{scenario.goal[1]}"
            labels.update({f"{r.robot.name}:{name}": label for name, label in scenario.fmu_labels.items()})
        attachments = scenario_attachments(fleet.text, first.map_file)
        self.write_header(fleet.name, details, master.system.components.values(), labels, attachments)
        recorder.write_grid(0, robots[0].built.grid, "/map")
        recorder.write_obstacles(0, [obstacle.at(0.0) for obstacle in first.obstacles])
        for r in robots:
            view = self.views[r.robot.name]
            view.write_grid(0, r.built.inflated, "/map_inflated")
            if r.built.plan is not None:
                view.write_path(0, r.built.plan.path)
            view.write_goal(0, *r.monitor.goal, None)
        self.begin()
        self.steps.write_constant(master.start_time_ns)
        self.start_clock(progress)

    def begin(self) -> None:
        """The text signals' channels, per robot under its namespace."""
        self.texts = [TextRecording(self.views[r.robot.name], r.built.system) for r in self.robots]

    def write_goal(self, t_ns: int, name: str, x: float, y: float) -> None:
        self.views[name].write_goal(t_ns, x, y, None)

    def write_plan(self, t_ns: int, name: str, path) -> None:
        self.views[name].write_path(t_ns, path)

    def write_poses(self, t_ns: int, rows) -> None:
        self.steps.write_poses(t_ns, rows)

    def block(self, first: int, end: int, histories, poses) -> None:
        """Steps [first, end) of a block (`FleetSteps.block`); then the live view's goals and
        commands, if any."""
        self.steps.block(first, end, histories, poses)
        self.show_progress(end * self.system.macro_step_ns / 1e9)
        if self.goals is not None:
            goal = self.goals.take()
            if goal is not None:
                self.goals.report(
                    f"/goal_pose ({goal[0]:.2f}, {goal[1]:.2f}) m refused: a fleet's robots follow "
                    "their goals and missions"
                )
            for name, record in getattr(self.goals, "acknowledged", tuple)():
                self.recorder.add_metadata(name, record)

    def close(self, outcome, end_ns: int) -> None:
        """The last records at `end_ns` (the end of the last step judged), the outcome, the log
        finalised."""
        for text in self.texts:
            text.finish(end_ns)
        self.recorder.end_steps(end_ns)
        if self.bar is not None:
            self.bar.close()
        self.recorder.add_metadata(
            "fleet_outcome", {key: json.dumps(value) for key, value in outcome_record(outcome).items()}
        )
        self.recorder.close(
            {"reached": str(outcome.completed).lower(), "reason": outcome.reason, "time": repr(outcome.time)}
        )


def outcome_record(outcome) -> dict:
    """The fleet outcome as JSON-able values (metadata `fleet_outcome`)."""
    robots = {
        robot.name: {
            "status": robot.status,
            "goals_reached": robot.goals_reached,
            "goals": robot.goals,
            "completion_time": robot.completion_time,
            "distance": robot.distance,
            "min_clearance_walls": _finite(robot.min_clearance_walls),
            "min_clearance_robots": _finite(robot.min_clearance_robots),
            "stopped_time": robot.stopped_time,
            "recovery_time": robot.recovery_time,
            "deadlocked_at": robot.deadlocked_at,
            "collision": list(robot.collision) if robot.collision else None,
        }
        for robot in outcome.robots
    }
    collisions = [
        {
            "robots": [c.first, c.second],
            "time": c.time,
            "centers": [list(c.first_center), list(c.second_center)],
            "radii": [c.first_radius, c.second_radius],
        }
        for c in outcome.collisions
    ]
    record = {
        "reason": outcome.reason,
        "time": outcome.time,
        "makespan": outcome.makespan,
        "throughput_per_hour": outcome.throughput,
        "deadlocks": [robot.name for robot in outcome.deadlocks],
        "robots": robots,
        "collisions": collisions,
        # the planning's counts (its wall time is in the printed summary only: the log is the same
        # whenever the run is)
        "coordination": None
        if outcome.coordination is None
        else {key: outcome.coordination[key] for key in ("method", "solves", "failures")},
    }
    if outcome.failure:
        record["failure"] = outcome.failure
    return record


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None
