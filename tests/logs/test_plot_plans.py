"""The plot shows the run as it went: every plan (the first and each replan, older ones fainter),
each goal given (a live goal change: the old goal and the new one, the distance to the goal in
force at each time), a Hybrid A* plan's reverse segments, and the last frame of the animation at
the run's end with its outcome. Truth: the /plan and /goal messages and the metadata read with the
mcap package directly (its own ROS 2 decoder, not `cosim.logs.reader`), the goals the test gives,
the planner's own driving directions, and colours computed from the documented opacities."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from cosim.logs import plot, plot_data, plot_map
from cosim.logs.animate import _Scene, frame_times
from cosim.logs.reader import open_log
from cosim.navigation.run import run_scenario
from cosim.record.recorder import Recorder
from cosim.scenario.load import load_scenario
from planner.grid import OccupancyGrid
from planner.hybrid import plan_hybrid

REPO = Path(__file__).resolve().parents[2]
NEW_GOAL = (20.0, 53.0)  # the far end of the top aisle: reached through the aisle the replan takes
GOAL_POLL = 350  # the goal changes at the 350th poll (the planner's 10 Hz: t = 34.9 s)


class GoalAt:
    """A live goal source (the live view's /goal_pose) that gives `goal` at its `polls`-th poll."""

    def __init__(self, polls: int, goal: tuple[float, float]) -> None:
        self.polls, self.goal, self.calls = polls, goal, 0

    def take(self):
        self.calls += 1
        return self.goal if self.calls == self.polls else None

    def report(self, text: str, warning: bool = True) -> None:
        pass


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The blocked aisle: the wall makes a replan, the goal change another."""
    scenario = load_scenario(REPO / "scenarios" / "warehouse_blocked_aisle.toml", [])
    log_path = tmp_path_factory.mktemp("plans") / "blocked_goal_change.mcap"
    return run_scenario(scenario, log_path, goals=GoalAt(GOAL_POLL, NEW_GOAL))


def _decoded(path: Path, topic: str) -> list:
    """(log time [s], message) of every message on `topic`, decoded by mcap_ros2."""
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        return [
            (item.message.log_time / 1e9, item.decoded_message)
            for item in reader.iter_decoded_messages(topic)
        ]


def _metadata(path: Path, name: str) -> dict[str, str]:
    with open(path, "rb") as handle:
        return next(dict(m.metadata) for m in make_reader(handle).iter_metadata() if m.name == name)


def test_every_plan_and_goal_of_the_log_is_collected(run):
    plans, goals = _decoded(run.log_path, "/plan"), _decoded(run.log_path, "/goal")
    assert len(plans) == 3, "the first plan, the replan at the wall and the one for the new goal"
    with open_log(run.log_path) as log:
        data = plot.collect(log)
    assert len(data.plans) == len(plans) == len(data.reverse)
    for (t, points), (t_message, message) in zip(data.plans, plans, strict=True):
        assert t == t_message
        expected = np.array([(p.pose.position.x, p.pose.position.y) for p in message.poses])
        np.testing.assert_array_equal(points, expected)
    assert [t for t, _ in data.plans] == sorted(t for t, _ in data.plans)
    # the goals are the scenario's and the one given, the latter when it was given
    assert [(x, y) for _, x, y in data.goals] == [(84.0, 53.0), NEW_GOAL]
    assert [t for t, _, _ in data.goals] == [t for t, _ in goals]
    assert math.isclose(data.goals[1][0], GOAL_POLL * 0.1 - 0.1, abs_tol=0.02)
    # the goal in force at the end is the outcome's, and the run reached it
    outcome = _metadata(run.log_path, "outcome")
    assert outcome["reached"] == "true" and tuple(map(float, outcome["goal"].split(","))) == NEW_GOAL
    assert data.goal == NEW_GOAL
    assert run.outcome.replans == 2


def test_distance_is_to_the_goal_in_force_at_each_time(run):
    with open_log(run.log_path) as log:
        data = plot.collect(log)
        vehicle = log.signals("vehicle")
    (series,) = [item for item in data.series if item.panel == "goal"]
    changed = data.goals[1][0]
    before = vehicle.t < changed
    assert before.any() and (~before).any()
    np.testing.assert_array_equal(series.t, vehicle.t)
    expected = np.where(
        before,
        np.hypot(vehicle["x"] - 84.0, vehicle["y"] - 53.0),
        np.hypot(vehicle["x"] - NEW_GOAL[0], vehicle["y"] - NEW_GOAL[1]),
    )
    np.testing.assert_allclose(series.values, expected, rtol=0, atol=1e-12)
    assert series.values[-1] <= 1.0  # within the tolerance of the new goal at the end


def test_trace_and_log_draw_the_same_plans_and_goals(run, tmp_path):
    from test_plot_trace import _same

    from_trace = plot.collect(plot.TraceSource(run.trace))
    with open_log(run.log_path) as log:
        from_log = plot.collect(log)
    _same(from_trace, from_log, "plot")
    a = plot.plot_trace(run.trace, tmp_path / "trace.png").read_bytes()
    assert a == plot.plot_run(run.log_path, tmp_path / "log.png").read_bytes()


def _pixel_window(figure, axes, point, half: int = 3) -> np.ndarray:
    """The RGB pixels (2 half + 1 square) around the data point `point` of `axes`."""
    pixels = np.asarray(figure.canvas.buffer_rgba())[:, :, :3].astype(int)
    x, y = axes.transData.transform(point)
    column, row = int(round(x)), int(round(pixels.shape[0] - y))
    return pixels[row - half : row + half + 1, column - half : column + half + 1]


def _strongest(window: np.ndarray, background: np.ndarray) -> np.ndarray:
    """The pixel of `window` farthest from `background`: where a line covers the pixel fully."""
    distance = np.abs(window - background).sum(axis=2)
    return window.reshape(-1, 3)[int(np.argmax(distance))]


def _rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])


def _lonely_point(points: np.ndarray, others: list[np.ndarray]) -> np.ndarray:
    """The midpoint of a segment of `points` farthest from every point of `others`."""
    middles = (points[1:] + points[:-1]) / 2.0
    crowd = np.vstack(others)
    distance = np.min(np.hypot(*(middles[:, None, :] - crowd[None, :, :]).transpose(2, 0, 1)), axis=1)
    return middles[int(np.argmax(distance))]


def test_older_plans_are_drawn_fainter(run):
    with open_log(run.log_path) as log:
        data = plot.collect(log)
    figure = plot.build_figure(data)
    bare = plot.build_figure(
        plot_data.PlotData(data.title, image=data.image, extent=data.extent, has_zone=data.has_zone,
                      limits=data.limits, series=data.series)
    )  # fmt: skip
    (oldest, _), (middle, _), (newest, _) = [(points, t) for t, points in data.plans]
    dense = [
        np.linspace(a, b, 20) for a, b in zip(data.trajectory[:-1:50], data.trajectory[50::50], strict=False)
    ]
    # the first of three plans at the oldest opacity, the second (the previous one) at the previous one's
    for points, others, alpha in (
        (oldest, [middle, newest, data.trajectory, *data.obstacles, *dense], plot_map.OLDEST_PLAN_ALPHA),
        (middle, [oldest, newest, data.trajectory, *data.obstacles, *dense], plot_map.PREVIOUS_PLAN_ALPHA),
    ):
        at = _lonely_point(points, others)
        background = _pixel_window(bare, bare.axes[0], at)[3, 3]
        drawn = _strongest(_pixel_window(figure, figure.axes[0], at), background)
        expected = alpha * _rgb(plot_map.PLAN_COLOR) + (1.0 - alpha) * background
        assert np.abs(drawn - expected).max() <= 6, (at, drawn, expected)
    assert plot_map.OLDEST_PLAN_ALPHA < plot_map.PREVIOUS_PLAN_ALPHA < 1.0


def test_the_old_goal_is_hollow_and_the_new_one_filled(run):
    with open_log(run.log_path) as log:
        figure = plot.build_figure(plot.collect(log))
    old = _pixel_window(figure, figure.axes[0], (84.0, 53.0), half=1)
    assert np.all(old == 255), "the old goal's star is hollow (white inside)"
    ring = _pixel_window(figure, figure.axes[0], (84.0, 53.0), half=8)
    assert np.any(np.all(ring == _rgb(plot_map.GOAL_COLOR), axis=2)), "its outline in the goal's colour"
    new = _pixel_window(figure, figure.axes[0], NEW_GOAL, half=1)
    assert np.all(new == _rgb(plot_map.GOAL_COLOR)), "the new goal's star is filled"
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert "earlier goal" in labels and "goal at the end (tolerance circle)" in labels
    notes = [child.get_text() for child in figure.axes[0].texts]
    assert any(note.startswith("goal until t = 34.9 s") for note in notes)


def test_animation_shows_the_goal_in_force_and_ends_on_the_outcome(run):
    outcome = _metadata(run.log_path, "outcome")
    end = float(outcome["time"])
    with open_log(run.log_path) as log:
        scene = _Scene(log)
        changed = log.goals()[1][0]
        scene.render(changed - 1.0)
        assert [float(v[0]) for v in scene.goal_marker.get_data()] == [84.0, 53.0]
        assert not scene.banner.get_visible()
        times = frame_times(log.start_time, log.end_time, 20.0, 8.0)
        plain = scene.render(times[-1])
        last = scene.render(times[-1], final=True)
    assert [float(v[0]) for v in scene.goal_marker.get_data()] == list(NEW_GOAL)
    # 62.3 s is not a multiple of 8/20 s: after the frames every 0.4 s, one at the end
    assert times[-1] == end and len(times) == math.floor(end / 0.4) + 2
    assert scene.banner.get_text() == f"goal reached at t = {end:.1f} s" and scene.banner.get_visible()
    assert scene.clock.get_text().startswith(f"t = {end:.1f} s")
    assert np.any(plain != last)


@pytest.mark.parametrize(
    "goal, cusps", [((12.0, 12.0, math.pi / 2), 1), ((17.0, 10.0, math.pi), 2)]
)  # fmt: skip
def test_reverse_segments_of_a_hybrid_plan_are_the_planners(goal, cusps, tmp_path):
    """A Hybrid A* plan with cusps, logged as a run logs it and read back: the segments the plot
    marks as reverse are those the planner drives backwards (its `directions`: that of the
    segment reaching each pose)."""
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    grid = OccupancyGrid(occupied, 0.5, (0.0, 0.0))
    result = plan_hybrid(grid, (20.0, 10.0, 0.0), goal, min_turning_radius=3.0)
    assert result.info["cusps"] == cusps
    path = tmp_path / "hybrid.mcap"
    with Recorder(path) as recorder:
        recorder.write_grid(0, grid, "/map")
        recorder.write_path(0, result.path)
        recorder.write_goal(0, goal[0], goal[1], goal[2])
    with open_log(path) as log:
        data = plot.collect(log)
    (reverse,) = data.reverse
    np.testing.assert_array_equal(reverse, result.directions[1:] < 0)
    assert reverse.any() and not reverse.all()
    # drawn in the reverse colour (the plan in force: opaque), on the longest reverse stretch
    figure = plot.build_figure(data)
    runs = plot_map._direction_runs(data.plans[0][1], reverse)
    points = max((points for points, backwards in runs if backwards), key=len)
    at = (points[len(points) // 2 - 1] + points[len(points) // 2]) / 2.0
    drawn = _strongest(_pixel_window(figure, figure.axes[0], at), np.array([255, 255, 255]))
    assert np.abs(drawn - _rgb(plot_map.REVERSE_COLOR)).max() <= 6
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert "plan: reverse segments" in labels


def test_the_reverse_rule_on_poses_made_here():
    """Straight on, backing along a line, and a cusp on an arc, from their geometry alone."""
    s = np.linspace(0.0, 3.0, 7)
    forward = np.column_stack((s, 0.5 * s, np.full(7, math.atan2(0.5, 1.0))))
    backing = np.column_stack((-s, np.zeros(7), np.zeros(7)))  # facing +x, moving -x
    assert not plot.reverse_segments(forward).any()
    assert plot.reverse_segments(backing).all()
    radius, angles = 2.0, np.linspace(0.0, 1.0, 6)
    ahead = np.column_stack((radius * np.sin(angles), radius * (1 - np.cos(angles)), angles))
    back = ahead[::-1][1:]  # the same arc driven back, the car facing the same way
    cusp = np.vstack((ahead, back))
    np.testing.assert_array_equal(plot.reverse_segments(cusp), [False] * 5 + [True] * 5)
    grid_path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])  # a U-turn on a grid
    headings = np.append(np.arctan2(*np.diff(grid_path, axis=0).T[::-1]), 0.0)
    assert not plot.reverse_segments(np.column_stack((grid_path, headings))).any()


def test_the_plot_names_the_avoider_that_ran(tmp_path):
    """The potential field in the avoider's role: the legend, the shading and the direction panel
    say APF (the FMU's model name in the log's metadata, read with the mcap package), never VFH."""
    scenario = load_scenario(REPO / "scenarios" / "warehouse_apf.toml", ["simulation.stop_time=25"])
    log_path = tmp_path / "apf.mcap"
    run_scenario(scenario, log_path)
    assert _metadata(log_path, "fmu/vfh")["model_name"] == "ArtificialPotentialField"
    with open_log(log_path) as log:
        data = plot.collect(log)
        scene = _Scene(log)
    assert plot_data.MODE_AVOID in data.mode_points, "the field took over in these 25 s"
    figure = plot.build_figure(data)
    legend = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    panels = [text.get_text() for axes in figure.axes[1:] for text in axes.texts]
    assert "APF avoiding (mode 1)" in legend and "APF avoiding (mode 1)" in panels
    assert "APF steering direction" in panels
    assert not any("VFH" in text for text in legend + panels)
    assert scene.mode_labels[plot_data.MODE_AVOID] == "avoid (APF)"
