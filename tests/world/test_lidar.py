"""The lidar against analytic distances, a brute-force ray march, range limits and noise."""

import math

import numpy as np
import pytest

from cosim.core.master import Master
from cosim.core.system import System
from cosim.errors import CosimError
from cosim.world.lidar import Lidar
from cosim.world.shapes import Circle, Polygon, Rectangle


def scan(lidar, x, y, theta):
    lidar.instantiate()
    lidar.setup(0.0, {})
    lidar.set_inputs([0, 1, 2], [x, y, theta])
    lidar.initialize()
    outputs = lidar.get_outputs()
    return outputs[: lidar.capacity].copy(), outputs[lidar.capacity :].copy()


def test_wall_of_the_grid_at_a_known_distance():
    occupied = np.zeros((100, 100), dtype=bool)
    occupied[:, 80] = True  # column 80 spans x = 8.0 .. 8.1 m at 0.1 m cells, origin (0, 0)
    angles = np.array([0.0, 0.3, -0.5, math.pi])
    lidar = Lidar(occupied=occupied, resolution=0.1, angles=angles, range_max=20.0, period=0.0)
    ranges, reported = scan(lidar, 2.05, 5.0, 0.0)
    expected = (8.0 - 2.05) / np.cos(angles[:3])
    assert ranges[:3] == pytest.approx(expected, abs=1e-9)
    assert np.isnan(ranges[3])  # leaves the grid at x = 0 without a hit: missed
    assert np.array_equal(reported, angles)


def test_heading_rotates_the_beams_and_row_zero_is_the_top_of_the_map():
    occupied = np.zeros((50, 50), dtype=bool)
    occupied[0, :] = True  # the top row: y = 4.9 .. 5.0 m at 0.1 m cells
    lidar = Lidar(occupied=occupied, resolution=0.1, origin=(-1.0, 0.0), angles=[0.0], range_max=10.0)
    ranges, _ = scan(lidar, 1.0, 1.0, math.pi / 2)
    assert ranges[0] == pytest.approx(3.9, abs=1e-9)


def test_circle_rectangle_and_polygon_obstacles():
    obstacles = [
        Circle((5.0, 0.0), 1.0),
        Rectangle((0.0, 4.0), (2.0, 1.0)),  # lower edge at y = 3.5
        Polygon(((-3.0, -1.0), (-4.0, 0.0), (-3.0, 1.0))),  # edge x = -3 facing the sensor
        Rectangle((0.0, -6.0), (2.0, 2.0), yaw=math.pi / 4),  # a diamond, top corner at y = -6 + sqrt(2)
    ]
    lidar = Lidar(obstacles=obstacles, angles=[0.0, math.pi / 2, math.pi, -math.pi / 2, 0.1], range_max=10.0)
    ranges, _ = scan(lidar, 0.0, 0.0, 0.0)
    # Beam at 0.1 rad meets the circle: smallest root of |t d - c|^2 = r^2.
    b = 5.0 * math.cos(0.1)
    circle_hit = b - math.sqrt(b * b - 25.0 + 1.0)
    expected = [4.0, 3.5, 3.0, 6.0 - math.sqrt(2.0), circle_hit]
    assert ranges == pytest.approx(expected, abs=1e-9)


def test_misses_and_range_limits_give_nan():
    lidar = Lidar(
        obstacles=[Circle((3.0, 0.0), 0.5), Circle((0.0, 0.8), 0.2)],
        angles=[0.0, math.pi / 2, math.pi],
        range_min=1.0,
        range_max=2.0,
        capacity=5,
    )
    ranges, angles = scan(lidar, 0.0, 0.0, 0.0)
    assert np.isnan(ranges).all()  # 2.5 m beyond max, 0.6 m below min, nothing behind
    assert np.isnan(angles[3:]).all() and len(ranges) == 5
    inside = Lidar(obstacles=[Circle((0.0, 0.0), 1.0)], angles=[0.0, 1.0], range_max=5.0)
    ranges, _ = scan(inside, 0.2, 0.0, 0.0)
    assert ranges[:2].tolist() == [0.0, 0.0]  # a sensor inside an obstacle reads 0


def brute_force_ranges(occupied, resolution, x, y, angles, range_max, step=1e-4):
    """Second implementation: march along each beam in tiny steps, look up the cell."""
    rows = occupied.shape[0]
    out = []
    for angle in angles:
        distances = np.arange(0.0, range_max, step)
        px, py = x + distances * math.cos(angle), y + distances * math.sin(angle)
        cols = np.floor(px / resolution).astype(int)
        rws = rows - 1 - np.floor(py / resolution).astype(int)
        valid = (cols >= 0) & (cols < occupied.shape[1]) & (rws >= 0) & (rws < rows)
        hit = np.zeros(len(distances), dtype=bool)
        hit[valid] = occupied[rws[valid], cols[valid]]
        out.append(distances[np.argmax(hit)] if hit.any() else np.nan)
    return np.array(out)


def test_grid_ray_casting_agrees_with_a_brute_force_march():
    rng = np.random.default_rng(7)
    occupied = rng.random((60, 60)) < 0.03
    occupied[28:32, 28:32] = False  # keep the sensor's cell free
    angles = rng.uniform(-math.pi, math.pi, 40)
    lidar = Lidar(occupied=occupied, resolution=0.1, angles=angles, range_max=4.0)
    ranges, _ = scan(lidar, 3.01, 2.97, 0.0)
    expected = brute_force_ranges(occupied, 0.1, 3.01, 2.97, angles, 4.0)
    assert np.array_equal(np.isnan(ranges), np.isnan(expected))
    hit = ~np.isnan(expected)
    assert hit.sum() > 10
    assert ranges[hit] == pytest.approx(expected[hit], abs=2e-4)


def test_the_grid_and_the_shapes_together_give_the_nearer_of_each_bit_for_bit():
    """The sweep casts the shapes first and stops a beam's grid traversal past their nearest hit:
    each distance is exactly the smaller of the grid's alone and the shapes' alone, shapes before,
    at (a circle touching a wall's face) and behind the walls, the sensor in free space."""
    rng = np.random.default_rng(3)
    occupied = rng.random((80, 90)) < 0.02
    occupied[:, 80] = True  # a wall whose face is x = 8.0 m
    occupied[35:45, 15:25] = False  # the sensor's surroundings
    circles = [Circle((9.0, 4.0), 1.0)]  # touches the wall's face at (8.0, 4.0)
    circles += [Circle((rng.uniform(0, 9), rng.uniform(0, 8)), rng.uniform(0.1, 0.6)) for _ in range(25)]
    shapes = [
        *circles,
        Rectangle((3.0, 6.5), (1.0, 0.4), yaw=0.3),
        Polygon(((6.0, 1.0), (7.0, 1.5), (6.5, 2.5))),
    ]
    directions = np.column_stack([np.cos(a := np.linspace(-math.pi, math.pi, 720)), np.sin(a)])

    def lidar(occupied, obstacles):
        return Lidar(occupied=occupied, resolution=0.1, obstacles=obstacles, angles=[0.0], range_max=9.0)

    both, grid, alone = lidar(occupied, shapes), lidar(occupied, []), lidar(None, shapes)
    for x, y in [(2.0, 4.0), (2.03, 3.91), (2.2, 3.7)]:
        expected = np.minimum(grid.measure(x, y, 0.0, directions), alone.measure(x, y, 0.0, directions))
        measured = both.measure(x, y, 0.0, directions)
        assert np.array_equal(measured, expected)
        assert (measured < grid.measure(x, y, 0.0, directions)).sum() > 50  # shapes in front of walls
    # The beam to the circle's touching point meets the wall and the circle at 6 m, to rounding.
    wall = np.zeros_like(occupied)
    wall[:, 80] = True
    beam = np.array([[1.0, 0.0]])
    at_wall = lidar(wall, []).measure(2.0, 4.0, 0.0, beam)[0]
    at_circle = lidar(None, circles[:1]).measure(2.0, 4.0, 0.0, beam)[0]
    assert at_wall == pytest.approx(6.0, abs=1e-12) and at_circle == pytest.approx(6.0, abs=1e-12)
    assert lidar(wall, circles[:1]).measure(2.0, 4.0, 0.0, beam)[0] == min(at_wall, at_circle)
    # A circle 1e-12 m behind the wall's face: the wall, just nearer, is still found.
    behind = [Circle((9.0 + 1e-12, 4.0), 1.0)]
    assert lidar(None, behind).measure(2.0, 4.0, 0.0, beam)[0] > at_wall
    assert lidar(wall, behind).measure(2.0, 4.0, 0.0, beam)[0] == at_wall


def cell_by_cell(occupied, resolution, origin, x, y, directions, range_max):
    """Second implementation: the Amanatides-Woo traversal one cell at a time, the distance where
    the ray enters the first occupied cell (inf for none within range_max), the same IEEE
    operations in the same order (occupied: row 0 at the top)."""
    rows, cols = occupied.shape
    gx, gy = (x - origin[0]) / resolution, (y - origin[1]) / resolution
    limit = range_max / resolution
    out = []
    for dx, dy in directions:
        ix, iy = math.floor(gx), math.floor(gy)
        step_x, step_y = (1 if dx > 0 else -1), (1 if dy > 0 else -1)
        next_x = ((ix + 1) - gx) / dx if dx > 0 else ((gx - ix) / -dx if dx < 0 else math.inf)
        next_y = ((iy + 1) - gy) / dy if dy > 0 else ((gy - iy) / -dy if dy < 0 else math.inf)
        delta_x, delta_y = (1.0 / abs(dx) if dx else math.inf), (1.0 / abs(dy) if dy else math.inf)
        travelled, found = 0.0, math.inf
        while travelled <= limit:
            if 0 <= ix < cols and 0 <= iy < rows:
                if occupied[rows - 1 - iy, ix]:
                    found = travelled * resolution
                    break
            elif (ix < 0 and step_x < 0) or (ix >= cols and step_x > 0):
                break
            elif (iy < 0 and step_y < 0) or (iy >= rows and step_y > 0):
                break
            if next_x < next_y:
                travelled, next_x, ix = next_x, next_x + delta_x, ix + step_x
            else:
                travelled, next_y, iy = next_y, next_y + delta_y, iy + step_y
        out.append(found)
    return np.array(out)


def test_strides_through_free_space_give_the_cell_by_cell_distances_bit_for_bit():
    """The sweep crosses free space in strides (each cell's distance to the nearest occupied one);
    every distance is the one-cell-at-a-time traversal's, to the last bit: open halls, narrow gaps,
    beams along the axes and diagonals, sensors on cell corners and outside the grid."""
    rng = np.random.default_rng(9)
    occupied = np.zeros((120, 150), dtype=bool)
    occupied[0, :] = occupied[:, 0] = occupied[:, -1] = True  # the bottom edge is open
    occupied[60, 20:130] = True  # a long wall with gaps
    occupied[60, 50:52] = occupied[60, 90] = False
    occupied[rng.random(occupied.shape) < 0.002] = True  # scattered posts
    occupied[30:34, 70:110] = True
    angles = np.concatenate(
        (np.linspace(-math.pi, math.pi, 361), [0.0, math.pi / 2, math.pi / 4, -3 * math.pi / 4])
    )
    directions = np.column_stack((np.cos(angles), np.sin(angles)))
    directions = np.vstack((directions, [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]))  # exact axes
    lidar = Lidar(occupied=occupied, resolution=0.25, origin=(-3.0, 1.5), angles=[0.0], range_max=40.0)
    assert lidar._clearance.max() > 10  # strides of several cells
    poses = [(15.0, 12.0), (15.25, 12.25), (2.1, 28.7), (33.0, 31.0), (20.0, -2.0), (-10.0, 10.0)]
    poses += [(rng.uniform(-5, 40), rng.uniform(0, 33)) for _ in range(20)]
    hits = 0
    for x, y in poses:
        expected = cell_by_cell(occupied, 0.25, (-3.0, 1.5), x, y, directions, 40.0)
        assert np.array_equal(lidar.measure(x, y, 0.0, directions), expected), (x, y)
        hits += int(np.isfinite(expected).sum())
    assert hits > 5000


def noisy_scan(seed, range_noise, angle_noise):
    """2000 beams, all at nominal angle 0, against a wall at x = 5 m."""
    wall = Rectangle((5.5, 0.0), (1.0, 100.0))
    lidar = Lidar(
        obstacles=[wall], angles=np.zeros(2000), range_noise=range_noise, angle_noise=angle_noise, seed=seed
    )
    return scan(lidar, 0.0, 0.0, 0.0)


def test_range_noise_is_seeded_and_has_the_requested_spread():
    ranges, _ = noisy_scan(3, 0.05, 0.0)
    assert np.array_equal(ranges, noisy_scan(3, 0.05, 0.0)[0])
    assert not np.array_equal(ranges, noisy_scan(4, 0.05, 0.0)[0])
    assert np.mean(ranges) == pytest.approx(5.0, abs=0.005)
    assert np.std(ranges) == pytest.approx(0.05, rel=0.1)


def test_angle_noise_tilts_the_cast_beam_but_not_the_reported_angle():
    ranges, angles = noisy_scan(5, 0.0, 0.02)
    assert np.all(angles == 0.0)
    tilt = np.arccos(5.0 / ranges)  # |angle noise| of each beam, from the wall geometry
    assert np.mean(tilt) == pytest.approx(0.02 * math.sqrt(2.0 / math.pi), rel=0.1)  # half-normal mean


def test_a_sensor_inside_a_rectangle_reads_zero():
    square = Rectangle((0.0, 0.0), (4.0, 4.0))
    ranges, _ = scan(Lidar(obstacles=[square], angles=[0.0], range_max=5.0), 0.5, 0.0, 0.0)
    assert ranges[0] == 0.0  # inside a rectangle obstacle


def test_measure_gives_true_distances_along_world_directions():
    occupied = np.zeros((100, 100), dtype=bool)
    occupied[:, 80] = True  # a wall at x = 8.0 m (0.1 m cells, origin (0, 0))
    lidar = Lidar(occupied=occupied, resolution=0.1, obstacles=[Circle((2.0, 8.0), 1.0)], range_max=20.0)
    directions = np.array([[1.0, 0.0], [0.8, 0.6], [0.0, 1.0], [-1.0, 0.0]])
    distances = lidar.measure(2.05, 5.0, 0.0, directions)
    # The wall along +x and (0.8, 0.6); the circle straight up (its lowest point y = 7 is 2 m away,
    # 0.05 m off its centre line); nothing along -x (inf, not NaN: no range limits here).
    circle = 3.0 - math.sqrt(1.0 - 0.05**2)
    assert distances[:3] == pytest.approx([5.95, 5.95 / 0.8, circle], abs=1e-9)
    assert distances[3] == math.inf
    inside = lidar.measure(2.0, 8.2, 0.0, directions)  # inside the circle: every beam 0
    assert np.array_equal(inside, np.zeros(4))
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        lidar.measure(2.05, 5.0, 0.0, np.ones(3))


def test_bad_settings_are_errors():
    with pytest.raises(CosimError, match="range limits"):
        Lidar(range_min=3.0, range_max=2.0)
    with pytest.raises(CosimError, match="capacity"):
        Lidar(count=10, capacity=5)
    with pytest.raises(CosimError, match="noise"):
        Lidar(range_noise=-1.0)


def test_lidar_in_a_master_scans_at_its_period():
    system = System(0.01)
    lidar = system.add(Lidar(obstacles=[Circle((2.0, 0.0), 0.5)], angles=[0.0], range_max=10.0, period=0.1))
    with Master(system) as master:
        master.initialize()
        assert lidar.output_buffer[0] == pytest.approx(1.5)
        lidar.input_buffer[0] = 0.5  # unconnected input: the pose set by hand
        master.run(5)
        assert lidar.output_buffer[0] == pytest.approx(1.0)  # scanned at k = 0
        lidar.input_buffer[0] = 1.0
        master.run(5)
        assert lidar.output_buffer[0] == pytest.approx(1.0)  # held until k = 10
        master.step()
        assert lidar.output_buffer[0] == pytest.approx(0.5)


def test_range_noise_is_numpys_generator_with_the_seed_drawn_scan_by_scan():
    """The noise is NumPy's default generator seeded with `seed` (made at setup, only with noise):
    each scan draws the next `count` normals of that one stream."""
    wall = Rectangle((5.5, 0.0), (1.0, 100.0))
    lidar = Lidar(obstacles=[wall], angles=np.zeros(500), range_noise=0.05, seed=11)
    first, _ = scan(lidar, 0.0, 0.0, 0.0)
    lidar.scan(0.0, 0.0, 0.0)  # the next scan of the same run
    second = lidar.get_outputs()[: lidar.capacity].copy()
    expected = np.random.default_rng(11).normal(0.0, 0.05, 1000)
    assert np.allclose(first - 5.0, expected[:500], rtol=0.0, atol=1e-6)
    assert np.allclose(second - 5.0, expected[500:], rtol=0.0, atol=1e-6)


@pytest.mark.slow
def test_a_noiseless_lidar_does_not_load_numpys_random_module():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import numpy as np\n"
        "from cosim.world.lidar import Lidar\n"
        "from cosim.world.shapes import Rectangle\n"
        "lidar = Lidar(obstacles=[Rectangle((5.5, 0.0), (1.0, 100.0))], angles=np.zeros(8))\n"
        "lidar.instantiate()\n"
        "lidar.setup(0.0, {})\n"
        "lidar.set_inputs([0, 1, 2], [0.0, 0.0, 0.0])\n"
        "lidar.initialize()\n"
        "assert np.allclose(lidar.get_outputs()[:8], 5.0)\n"
        "print('numpy.random' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "False"
