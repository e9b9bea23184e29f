"""The messages a run writes at its start are packed without rosbags (`rosmsg._PACKERS`): the bytes
equal rosbags' serialisation of the same message (rosbags' Humble store, every field set, sequences
of 0-2 elements), a field rosbags would not take goes to rosbags, and a run imports neither rosbags
nor difflib (they cost a warm `cosim run` ~20 ms)."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore
from test_ros_conventions import _sample

from cosim.record import rosmsg

REPO = Path(__file__).resolve().parents[2]
HUMBLE = get_typestore(Stores.ROS2_HUMBLE)


def _ours(message):
    """rosbags' `message` as `rosmsg.make` builds it (a `rosmsg.Message` of the same fields)."""
    if isinstance(message, list):
        return [_ours(item) for item in message]
    if not hasattr(message, "__msgtype__"):
        return message
    cls = rosmsg._types[message.__msgtype__]
    return cls(**{name: _ours(getattr(message, name)) for name in cls.__slots__})


@pytest.mark.parametrize("typename", sorted(rosmsg._PACKERS))
def test_packed_messages_are_rosbags_bytes(typename):
    for seed in range(60):
        theirs = _sample(HUMBLE, typename, seed)
        ours = _ours(theirs)
        assert isinstance(ours, rosmsg.Message)
        expected = bytes(HUMBLE.serialize_cdr(theirs, typename, little_endian=True))
        assert rosmsg._PACKERS[typename](ours) == expected, seed
        assert rosmsg.serialize(ours, typename) == expected
        # and rosbags reads them back: the message it reads serialises to the same bytes
        again = HUMBLE.deserialize_cdr(expected, typename)
        assert rosmsg.serialize(_ours(again), typename) == expected


def test_the_run_messages_are_rosbags_bytes():
    """What the recorder builds: maps with their int8 cells, a path, a scan with NaN and inf, markers
    of every shape, the goal, the bumper."""
    from cosim.record.markers import marker_array
    from cosim.world.shapes import Circle, Polygon, Rectangle

    cells = np.array([0, 100, -1, 100, 0], dtype=np.int8)
    info = rosmsg.make(
        "nav_msgs/msg/MapMetaData",
        map_load_time=rosmsg.time_msg(7),
        resolution=0.05,
        width=5,
        height=1,
        origin=rosmsg.pose(-1.5, 2.25, 0.3),
    )
    grid = rosmsg.make("nav_msgs/msg/OccupancyGrid", header=rosmsg.header(7, "map"), info=info, data=cells)
    path = rosmsg.make(
        "nav_msgs/msg/Path",
        header=rosmsg.header(10**9 + 5, "map"),
        poses=[rosmsg.pose_stamped(10**9 + 5, 0.1 * k, -0.2 * k, 0.01 * k) for k in range(5)],
    )
    ranges = np.array([1.0, np.inf, np.nan, 0.25], dtype=np.float32)
    scan = rosmsg.laser_scan(3 * 10**9, "base_link", -np.pi, np.pi / 2, ranges, 0.1, 0.0, 20.0)
    shapes = [
        Circle(center=(1.0, 2.0), radius=0.5),
        Rectangle(center=(3.0, -1.0), size=(2.0, 1.0), yaw=0.4),
        Polygon(vertices=((0.0, 0.0), (1.0, 0.0), (0.5, 0.75))),
    ]
    messages = [
        (grid, "nav_msgs/msg/OccupancyGrid"),
        (path, "nav_msgs/msg/Path"),
        (scan, "sensor_msgs/msg/LaserScan"),
        (marker_array(12_345, shapes), "visualization_msgs/msg/MarkerArray"),
        (marker_array(0, []), "visualization_msgs/msg/MarkerArray"),
        (rosmsg.pose_stamped(5, 84.0, 53.0, 0.0), "geometry_msgs/msg/PoseStamped"),
        (rosmsg.make("std_msgs/msg/Bool", data=True), "std_msgs/msg/Bool"),
    ]
    for message, typename in messages:
        data = rosmsg.serialize(message, typename)
        assert data == bytes(HUMBLE.serialize_cdr(_theirs(message), typename, little_endian=True))
        assert data == bytes(rosmsg.TYPESTORE.serialize_cdr(message, typename))  # rosbags, our classes


def _theirs(message):
    """`message` as an instance of rosbags' Humble class of its type."""
    if isinstance(message, list):
        return [_theirs(item) for item in message]
    if not isinstance(message, rosmsg.Message):
        return message
    return HUMBLE.types[message.__msgtype__](**{n: _theirs(getattr(message, n)) for n in message.__slots__})


def test_a_field_rosbags_would_refuse_is_left_to_rosbags():
    """A float64 array in a float32[] field, a list for int8[] cells: not packed; rosbags serialises
    it as before (raising for what it cannot write)."""
    scan = rosmsg.laser_scan(0, "base_link", 0.0, 0.1, np.ones(3), 0.1, 0.0, 5.0)  # float64 ranges
    assert rosmsg._PACKERS["sensor_msgs/msg/LaserScan"](scan) is None
    with pytest.raises(Exception) as ours:  # noqa: PT011 - whatever rosbags raises
        rosmsg.serialize(scan, "sensor_msgs/msg/LaserScan")
    with pytest.raises(type(ours.value)):
        HUMBLE.serialize_cdr(_theirs(scan), "sensor_msgs/msg/LaserScan")
    info = rosmsg.make(
        "nav_msgs/msg/MapMetaData",
        map_load_time=rosmsg.time_msg(0),
        resolution=1.0,
        width=2,
        height=1,
        origin=rosmsg.pose(0.0, 0.0, 0.0),
    )
    grid = rosmsg.make("nav_msgs/msg/OccupancyGrid", header=rosmsg.header(0), info=info, data=[0, 100])
    assert rosmsg._PACKERS["nav_msgs/msg/OccupancyGrid"](grid) is None


def test_messages_have_their_fields_constants_and_equality():
    marker_type = rosmsg._types["visualization_msgs/msg/Marker"]
    assert (marker_type.CUBE, marker_type.DELETEALL, marker_type.__msgtype__) == (
        1,
        3,
        "visualization_msgs/msg/Marker",
    )
    assert rosmsg.point(1, 2) == rosmsg.point(1.0, 2.0, 0.0) != rosmsg.point(1.0, 2.5)
    assert rosmsg.point(1, 2) != rosmsg.vector3(1, 2)
    assert rosmsg.time_msg(1_500_000_000) == rosmsg.make(
        "builtin_interfaces/msg/Time", sec=1, nanosec=500_000_000
    )
    path = rosmsg.make(
        "nav_msgs/msg/Path", header=rosmsg.header(3), poses=[rosmsg.pose_stamped(3, 1, 2, 0.5)]
    )
    assert pickle.loads(pickle.dumps(path)) == path
    with pytest.raises(TypeError, match="missing the fields nanosec"):
        rosmsg.make("builtin_interfaces/msg/Time", sec=1)
    with pytest.raises(TypeError, match="unexpected or repeated field 'nsec'"):
        rosmsg.make("builtin_interfaces/msg/Time", sec=1, nsec=2)


@pytest.mark.slow
def test_a_run_imports_neither_rosbags_nor_difflib(tmp_path):
    """A scenario run (the CLI's `cosim run`, in a fresh process) writes its whole log without
    importing rosbags (its messages are packed), difflib (only for "did you mean" messages) or
    concurrent.futures (only for a chunk large enough to compress on a thread)."""
    scenario = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
    code = (
        "import sys\n"
        "from cosim.cli import main\n"
        f"code = main(['run', {str(scenario)!r}, '--out', {str(tmp_path / 'run.mcap')!r}, '--no-plot',"
        " '--quiet', '--set', 'simulation.stop_time=2.0'])\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rosbags', 'difflib', 'concurrent')))\n"
        "sys.exit(code)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, env=_environment()
    )
    assert done.returncode == 1, done.stderr  # the goal is not reached in 2 s
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "run.mcap").stat().st_size > 0


def _environment() -> dict[str, str]:
    import os

    return {**os.environ, "PYTHONPATH": str(REPO)}
