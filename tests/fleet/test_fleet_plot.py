"""A fleet's log read back: `cosim log info` and `cosim log plot` show every robot, the fleet's
outcome and its collisions. The truth: the run's own `FleetOutcome` (in memory, not the log) and
the log's /robotN/odom read here with the mcap reader and rosbags' own message definitions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.logs.fleet_plot import build_fleet_figure
from cosim.logs.reader import open_log
from cosim.navigation.fleet import run_fleet
from cosim.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.fixture(scope="module")
def intersection(tmp_path_factory):
    """Four robots at a crossing, run 12 s ("continue": every contact reported): (log, outcome)."""
    fleet = load_scenario(SCENARIOS / "fleet_intersection.toml", ["simulation.stop_time=12"], fleet=True)
    log = tmp_path_factory.mktemp("fleet") / "intersection.mcap"
    return log, run_fleet(fleet, log_path=log)


def _odometry(path: Path) -> dict[str, np.ndarray]:
    """Every robot's logged positions, read with the mcap reader: name -> N x 2 [m]."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    points: dict[str, list] = {}
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if channel.topic.endswith("/odom"):
                data = store.deserialize_cdr(message.data, schema.name)
                position = data.pose.pose.position
                points.setdefault(channel.topic.split("/")[1], []).append((position.x, position.y))
    return {name: np.array(rows) for name, rows in points.items()}


def _contact_point(contact) -> tuple[float, float]:
    """Where two footprints touch: on the line between the centres, one radius from the first."""
    (x1, y1), (x2, y2) = contact.first_center, contact.second_center
    gap = math.hypot(x2 - x1, y2 - y1)
    return x1 + (x2 - x1) * contact.first_radius / gap, y1 + (y2 - y1) * contact.first_radius / gap


def test_the_plot_draws_each_robots_logged_trajectory_in_its_own_colour(intersection):
    path, outcome = intersection
    logged = _odometry(path)
    assert (
        sorted(logged) == [robot.name for robot in outcome.robots] == ["robot1", "robot2", "robot3", "robot4"]
    )
    with open_log(path) as log:
        figure = build_fleet_figure(log)
    lines = {line.get_gid(): line for line in figure.axes[0].lines if line.get_gid()}
    colours = set()
    for name, points in logged.items():
        line = lines[f"trajectory {name}"]
        assert len(points) == math.floor(outcome.time * 50 + 1e-9) + 1  # 50 Hz, from t = 0 to the end
        np.testing.assert_array_equal(line.get_xydata(), points)
        colours.add(line.get_color())
    assert len(colours) == 4
    # the speed and distance panels: a line per robot each, in its colour
    for axes in figure.axes[1:3]:
        assert colours <= {line.get_color() for line in axes.lines}


def test_each_collision_is_marked_where_the_footprints_touched(intersection):
    path, outcome = intersection
    assert len(outcome.collisions) >= 2
    with open_log(path) as log:
        figure = build_fleet_figure(log)
    axes = figure.axes[0]
    markers = {line.get_gid(): line for line in axes.lines if (line.get_gid() or "").startswith("collision")}
    assert len(markers) == len(outcome.collisions) + sum(
        robot.collision is not None for robot in outcome.robots
    )
    pixels = np.asarray(figure.canvas.buffer_rgba())
    for index, contact in enumerate(outcome.collisions):
        expected = _contact_point(contact)
        (x,), (y,) = markers[f"collision {index}"].get_data()
        assert (x, y) == pytest.approx(expected, abs=1e-9)
        # the marker's yellow fill is in the picture at that place
        column, row = axes.transData.transform(expected)
        row, column = int(round(pixels.shape[0] - row)), int(round(column))
        near = pixels[row - 3 : row + 4, column - 3 : column + 4, :3].reshape(-1, 3).astype(int)
        assert np.min(np.abs(near - (0xFF, 0xD6, 0x0A)).sum(axis=1)) < 30
        texts = [text.get_text() for text in axes.texts]
        assert f"{contact.first}-{contact.second} t = {contact.time:.2f} s" in texts


def test_no_collision_text_covers_another_or_a_marker(intersection):
    path, _ = intersection
    with open_log(path) as log:
        figure = build_fleet_figure(log)
    axes = figure.axes[0]
    renderer = figure.canvas.get_renderer()
    markers = [axes.transData.transform(line.get_xydata()[0]) for line in axes.lines
               if (line.get_gid() or "").startswith("collision")]  # fmt: skip
    boxes = [text.get_bbox_patch().get_window_extent(renderer) for text in axes.texts]
    assert len(boxes) == len(markers) >= 3  # contacts within a metre of each other at the crossing
    for i, box in enumerate(boxes):
        assert not any(box.overlaps(other) for other in boxes[i + 1 :])
        assert not any(box.contains(x, y) for x, y in markers)


@pytest.mark.slow
def test_a_head_on_fleet_runs_to_a_png_titled_by_the_fleet_line(tmp_path, capsys):
    log = tmp_path / "head_on.mcap"
    assert main(["run", str(SCENARIOS / "fleet_head_on.toml"), "--out", str(log)]) == 1
    out = capsys.readouterr().out
    assert f"plot: {log.with_suffix('.png')}" in out and log.with_suffix(".png").stat().st_size > 10_000
    with open_log(log) as opened:
        assert opened.warnings == []
        figure = build_fleet_figure(opened)
    title = figure.get_suptitle()
    assert title.startswith("fleet_head_on: fleet: collision at t = 7.36 s, 1 collision, makespan -")
    assert (
        main(["run", str(SCENARIOS / "fleet_head_on.toml"), "--out", str(tmp_path / "b.mcap"), "--no-plot"])
        == 1
    )
    assert not (tmp_path / "b.png").exists()


def test_log_info_prints_each_robot_and_every_collision(intersection, capsys):
    path, outcome = intersection
    assert main(["log", "info", str(path)]) == 0
    captured = capsys.readouterr()
    assert "no outcome" not in captured.out + captured.err and "none recorded" not in captured.out
    rows = {line.split()[0]: line.split() for line in captured.out.splitlines() if line.startswith("  robot")}
    for robot in outcome.robots:
        row = rows[robot.name]
        assert row[1] == robot.status and row[2] == f"{robot.goals_reached}/{robot.goals}"
        assert float(row[4]) == pytest.approx(robot.distance, abs=0.006)
    for contact in outcome.collisions:
        assert (
            f"collision: {contact.first} and {contact.second} collide at t = {contact.time:.3f} s"
            in captured.out
        )
    assert f"collisions {len(outcome.collisions)};" in captured.out


def test_log_animate_of_a_fleet_shows_every_robot_where_its_odometry_puts_it(intersection, tmp_path):
    from cosim.logs.animate import _FleetScene, animate_log, frame_times
    from cosim.logs.plot_map import run_colour

    path, outcome = intersection
    logged = _odometry(path)
    with open_log(path) as log:
        video = animate_log(log, tmp_path / "fleet.gif", fps=10, speed=10, progress=False)
        assert video.frames == len(frame_times(log.start_time, log.end_time, 10, 10))
        scene = _FleetScene(log)
        t = 4.0  # before any contact: each robot's footprint alone, centred where its odometry is
        frame = scene.render(t)
    for index, name in enumerate(sorted(logged)):
        x, y = logged[name][round(t * 50)]  # 50 Hz from t = 0
        column, row = scene.axes.transData.transform((x, y))
        row, column = int(round(frame.shape[0] - row)), int(round(column))
        near = {tuple(p) for p in frame[row - 2 : row + 3, column - 2 : column + 3, :3].reshape(-1, 3)}
        colour = run_colour(index)  # beside the centre (the heading line starts there) its fill
        assert tuple(int(colour[i : i + 2], 16) for i in (1, 3, 5)) in near
    assert all(contact.time > t for contact in outcome.collisions)
