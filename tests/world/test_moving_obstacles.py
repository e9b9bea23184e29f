"""Moving unknown obstacles: motion laws, the lidar and the exact clearance at each obstacle's pose,
and the scenario keys (path/speed/motion, velocity/start_time) with their errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import CosimError
from cosim.navigation.outcome import OutcomeMonitor
from cosim.scenario.load import load_scenario
from cosim.world.distance import WorldDistance
from cosim.world.lidar import Lidar
from cosim.world.motion import Motion
from cosim.world.shapes import Circle, Polygon, Rectangle
from planner.grid import OccupancyGrid

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

SQUARE = ((0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (0.0, 3.0))  # perimeter 14 m


@pytest.mark.parametrize(
    ("mode", "t", "expected"),
    [
        # Arc lengths s = 2 m/s * t walked corner to corner by hand (edges 4, 3, 4 and closing 3 m).
        ("loop", 0.0, (0.0, 0.0)),
        ("loop", 2.0, (4.0, 0.0)),  # s = 4: the first corner
        ("loop", 3.0, (4.0, 2.0)),  # s = 6: 2 m up the second edge
        ("loop", 6.0, (0.0, 2.0)),  # s = 12: 1 m down the closing edge
        ("loop", 7.5, (1.0, 0.0)),  # s = 15 = one 14 m lap + 1 m
        ("bounce", 6.0, (1.0, 3.0)),  # open path 11 m: s = 12 is 10 m along on the way back
        ("bounce", 12.0, (2.0, 0.0)),  # s = 24 = 22 m there and back + 2 m
        ("once", 100.0, (0.0, 3.0)),  # stays at the last point
    ],
)
def test_path_motion_against_arc_length(mode, t, expected):
    assert Motion(SQUARE, speed=2.0, mode=mode).offset(t) == pytest.approx(expected, abs=1e-12)


def test_velocity_motion_starts_at_start_time():
    motion = Motion(velocity=(1.0, -0.5), start_time=2.0)
    assert motion.offset(1.0) == (0.0, 0.0)
    assert motion.offset(6.0) == pytest.approx((4.0, -2.0))
    assert motion.max_speed == pytest.approx(math.hypot(1.0, 0.5))


def test_shapes_translate_with_their_motion():
    motion = Motion(velocity=(1.0, 2.0))
    assert Circle((1.0, 1.0), 0.5, motion).at(2.0) == Circle((3.0, 5.0), 0.5)
    assert Rectangle((0.0, 0.0), (2.0, 1.0), 0.3, motion).at(1.0) == Rectangle((1.0, 2.0), (2.0, 1.0), 0.3)
    triangle = Polygon(((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)), motion)
    assert triangle.at(1.0).vertices == ((1.0, 2.0), (2.0, 2.0), (1.0, 3.0))


def test_lidar_sees_a_moving_circle_where_it_is():
    """A circle crossing in front of the sensor: the forward beam's range is the analytic chord."""
    person = Circle((10.0, -5.0), 0.4, Motion(velocity=(0.0, 1.0)))
    lidar = Lidar(obstacles=[person], angles=[0.0], range_max=30.0, count=1)
    lidar.instantiate()
    lidar.setup(0.0, {})
    for t in (0.0, 4.0, 4.8, 5.0, 5.3, 6.0):
        centre_y = -5.0 + t
        lidar.scan(0.0, 0.0, 0.0, t=t)
        if abs(centre_y) < 0.4:
            expected = 10.0 - math.sqrt(0.4**2 - centre_y**2)
            assert lidar._ranges[0] == pytest.approx(expected, abs=1e-9), t
        else:
            assert math.isnan(lidar._ranges[0]), t
    # A moving polygon: its near edge at the range the translation puts it.
    box = Rectangle((5.0, 0.0), (1.0, 1.0), 0.0, Motion(((5.0, 0.0), (9.0, 0.0)), speed=1.0, mode="once"))
    lidar = Lidar(obstacles=[box], angles=[0.0], range_max=30.0, count=1)
    lidar.instantiate()
    lidar.setup(0.0, {})
    for t, near in ((0.0, 4.5), (2.5, 7.0), (10.0, 8.5)):
        lidar.scan(0.0, 0.0, 0.0, t=t)
        assert lidar._ranges[0] == pytest.approx(near, abs=1e-12)


def test_exact_clearance_follows_a_moving_obstacle():
    grid = OccupancyGrid(np.zeros((40, 40), dtype=bool), 0.5, (0.0, 0.0))
    drum = Circle((2.0, 10.0), 1.0, Motion(((2.0, 10.0), (18.0, 10.0)), speed=2.0, mode="bounce"))
    world = WorldDistance(grid, (drum,))
    assert world.moving and world.max_speed == 2.0
    for t in (0.0, 3.0, 8.0, 11.0):
        world.at(t)
        s = (2.0 * t) % 32.0
        cx = 2.0 + (32.0 - s if s > 16.0 else s)
        expected = min(math.hypot(10.0 - cx, 15.0 - 10.0) - 1.0, 20.0 - 15.0)
        assert world.distance(10.0, 15.0) == pytest.approx(expected, abs=1e-9)
        assert world.lower_bound(10.0, 15.0) <= world.distance(10.0, 15.0) + 1e-12


def test_monitor_catches_an_obstacle_that_runs_into_a_standing_robot():
    """The robot stands still; the distance bound of the last check must shrink as the obstacle moves."""
    grid = OccupancyGrid(np.zeros((40, 40), dtype=bool), 0.5, (0.0, 0.0))
    cart = Circle((2.0, 10.0), 1.0, Motion(velocity=(1.0, 0.0)))
    monitor = OutcomeMonitor(WorldDistance(grid, (cart,)), (19.0, 19.0), 0.5, 0.5, (10.0, 10.0))
    reason, t = None, 0.0
    while reason is None and t < 20.0:
        t = round(t + 0.01, 2)
        reason = monitor.check_position(t, 10.0, 10.0)
    assert reason == "collision"
    # The circle's edge meets the footprint (radius 0.5) when its centre is 1.5 m away: t = 6.5 s.
    assert t == pytest.approx(6.5, abs=0.011)


def _scenario(tmp_path: Path, obstacle: str) -> Path:
    text = (SCENARIOS / "warehouse_diff_drive_one_obstacle.toml").read_text()
    text = text.replace('type = "rectangle"\ncenter = [60.0, 19.25]\nsize = [2.0, 2.0]\n', obstacle)
    (tmp_path / "maps").symlink_to(SCENARIOS / "maps")
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def test_scenario_keys_give_the_motion(tmp_path: Path):
    path = _scenario(
        tmp_path,
        'type = "circle"\nradius = 0.4\npath = [[60.0, 16.0], [60.0, 22.0]]\nspeed = 1.2\n'
        'motion = "bounce"\nstart_time = 3.0\n',
    )
    obstacle = load_scenario(path).obstacles[0]
    assert obstacle.center == (60.0, 16.0)  # the centre defaults to the path's first point
    assert obstacle.motion == Motion(((60.0, 16.0), (60.0, 22.0)), 1.2, "bounce", start_time=3.0)
    assert obstacle.at(5.5).center == pytest.approx((60.0, 19.0))


@pytest.mark.parametrize(
    ("obstacle", "message"),
    [
        (
            'type = "circle"\nradius = 0.4\npath = [[60.0, 16.0], [60.0, 22.0]]\nspeed = -1.0\n',
            r"\[\[obstacles\]\]\[0\]\.speed: must be > 0",
        ),
        (
            'type = "circle"\nradius = 0.4\npath = [[60.0, 16.0], [160.0, 22.0]]\nspeed = 1.0\n',
            r"\[\[obstacles\]\]\[0\]\.path\[1\]: \(160, 22\) is outside the map",
        ),
        (
            'type = "circle"\nradius = 0.4\ncenter = [60.0, 19.0]\nvelocity = [1.0, 0.0]\nspeed = 1.0\n',
            r"\[\[obstacles\]\]\[0\]\.speed: belongs to a path",
        ),
        (
            'type = "circle"\nradius = 0.4\ncenter = [60.0, 19.0]\nstart_time = 2.0\n',
            r"\[\[obstacles\]\]\[0\]\.start_time: needs a path",
        ),
        (
            'type = "circle"\nradius = 0.4\npath = [[60.0, 16.0], [60.0, 22.0]]\nspeed = 1.0\n'
            'motion = "zigzag"\n',
            r"\[\[obstacles\]\]\[0\]\.motion: ",
        ),
    ],
)
def test_motion_errors_name_the_key(tmp_path: Path, obstacle: str, message: str):
    with pytest.raises(CosimError, match=message):
        load_scenario(_scenario(tmp_path, obstacle))


def test_republished_obstacles_read_back_at_their_poses(tmp_path: Path):
    """/obstacles written again and again (circles and rectangles reuse one message's bytes, a
    polygon is serialised in full) reads back through mcap-ros2 with each marker at the shape's
    analytic pose at the stamp, and the bytes equal a fresh serialisation of every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from cosim.record.markers import obstacles_cdr
    from cosim.record.recorder import Recorder

    walker = Circle((2.0, 1.0), 0.3, Motion(velocity=(1.0, 0.5)))
    cart = Rectangle((5.0, 5.0), (1.0, 2.0), 0.4, Motion(((5.0, 5.0), (5.0, 9.0)), 2.0, "bounce"))
    box = Rectangle((1.0, 8.0), (0.5, 0.5))
    shapes = [walker, cart, box]
    triangle = Polygon(((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)), Motion(velocity=(0.0, -1.0)))

    def centres(t: float) -> list[tuple[float, float]]:
        """By hand: the walker at 1 m/s x 0.5 m/s; the cart 2 m/s up 4 m and back; the box stands."""
        s = math.fmod(2.0 * t, 8.0)
        return [(2.0 + t, 1.0 + 0.5 * t), (5.0, 5.0 + (s if s <= 4.0 else 8.0 - s)), (1.0, 8.0)]

    times = [0.1 * k for k in range(1, 40)]
    stamps = [round(t * 1e9) for t in times]
    log = tmp_path / "obstacles.mcap"
    with Recorder(log) as recorder:
        for t, t_ns in zip(times, stamps, strict=True):
            recorder.write_obstacles(t_ns, [shape.at(t) for shape in shapes])
        recorder.write_obstacles(stamps[-1] + 1, [triangle.at(5.0)])
        recorder.write_obstacles(stamps[-1] + 2, [shape.at(0.0) for shape in shapes])

    with open(log, "rb") as stream:
        raw = [(message.log_time, message.data) for _, _, message in make_reader(stream).iter_messages()]
    written = [*zip(times, stamps, strict=True), (5.0, stamps[-1] + 1), (0.0, stamps[-1] + 2)]
    assert [log_time for log_time, _ in raw] == [t_ns for _, t_ns in written]
    for (t, t_ns), (_, data) in zip(written, raw, strict=True):
        drawn = [triangle.at(t)] if t_ns == stamps[-1] + 1 else [shape.at(t) for shape in shapes]
        assert data == obstacles_cdr(t_ns, drawn)

    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [message for *_, message in reader.iter_decoded_messages()]
    for (t, t_ns), message in zip(written[:-2], decoded, strict=False):
        assert len(message.markers) == 3
        for index, (marker, centre) in enumerate(zip(message.markers, centres(t), strict=True)):
            stamp = marker.header.stamp
            assert marker.id == index and stamp.sec * 10**9 + stamp.nanosec == t_ns
            assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(centre, abs=1e-12)
        assert [marker.type for marker in message.markers] == [3, 1, 1]  # cylinder, cube, cube
        assert message.markers[1].scale.y == 2.0
    (polygon,) = decoded[-2].markers
    # Flat: pytest 9.2's approx refuses nested sequences.
    corners = [c for p in polygon.points[:3] for c in (p.x, p.y)]
    assert corners == pytest.approx([0.0, -5.0, 1.0, -5.0, 0.0, -4.0])
