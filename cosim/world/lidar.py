"""A 2-D lidar: ray casting on the true world (occupancy grid plus unknown obstacles).

Semantics follow MATLAB's `rangeSensor` (reference/matlab-blocks.md §1.7):
* Beams leave the sensor at the robot pose (x, y, theta) at `angles` in the sensor frame
  (counter-clockwise from the heading, radians). Angles are given as a list, or as
  `angle_min`, `angle_max`, `count` (evenly spaced, both ends included).
* A beam returns the distance to the first occupied cell boundary or obstacle outline it meets.
  A beam whose true distance lies outside [range_min, range_max] is a missed reading: NaN.
  A sensor inside an occupied cell or an obstacle reads 0 (so NaN when range_min > 0).
* Noise, drawn from one seeded generator so a run is reproducible: the range of every hit gets
  Gaussian noise of standard deviation `range_noise` [m]; each beam is cast at its nominal angle
  plus Gaussian noise of standard deviation `angle_noise` [rad], while the reported angle stays
  nominal (the sensor does not know its jitter).
* Cells outside the grid are free. Grid cells are hit on their boundary (exact for axis-aligned
  walls); circles, rectangles and polygons (cosim.world.shapes) are intersected exactly, moving
  ones at their pose at the scan's time (the start of the lidar's step).

Outputs `ranges[k]` and `angles[k]`, k = 1..capacity (capacity >= beam count, the rest NaN), so
the ports match VFH inputs of a fixed size. Inputs `x`, `y`, `theta`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numba
import numpy as np

from cosim.core.component import Port, PythonComponent, array_ports
from cosim.errors import CosimError
from cosim.world.geometry import inside_polygon
from cosim.world.obstacles import ObstacleArrays
from cosim.world.shapes import Obstacle


@numba.njit(cache=True)
def _cast_grid(occupied_up, origin_x, origin_y, resolution, x, y, directions, max_range, out):
    """Distance [m] to the first occupied cell along each direction (inf when none within max_range).

    `occupied_up[iy, ix]` has row 0 at the bottom (y grows with iy). Amanatides-Woo traversal:
    the ray visits cells in order, always crossing the nearer of the next vertical or
    horizontal cell boundary.
    """
    rows, cols = occupied_up.shape
    gx = (x - origin_x) / resolution
    gy = (y - origin_y) / resolution
    limit = max_range / resolution
    start_x = int(math.floor(gx))
    start_y = int(math.floor(gy))
    for beam in range(directions.shape[0]):
        dx = directions[beam, 0]
        dy = directions[beam, 1]
        ix, iy = start_x, start_y
        step_x = 1 if dx > 0 else -1
        step_y = 1 if dy > 0 else -1
        next_x = ((ix + 1) - gx) / dx if dx > 0 else ((gx - ix) / -dx if dx < 0 else np.inf)
        next_y = ((iy + 1) - gy) / dy if dy > 0 else ((gy - iy) / -dy if dy < 0 else np.inf)
        delta_x = 1.0 / abs(dx) if dx != 0 else np.inf
        delta_y = 1.0 / abs(dy) if dy != 0 else np.inf
        travelled = 0.0
        out[beam] = np.inf
        while travelled <= limit:
            if 0 <= ix < cols and 0 <= iy < rows:
                if occupied_up[iy, ix]:
                    out[beam] = travelled * resolution
                    break
            elif (ix < 0 and step_x < 0) or (ix >= cols and step_x > 0):
                break  # left the grid for good in x
            elif (iy < 0 and step_y < 0) or (iy >= rows and step_y > 0):
                break
            if next_x < next_y:
                travelled = next_x
                next_x += delta_x
                ix += step_x
            else:
                travelled = next_y
                next_y += delta_y
                iy += step_y


@numba.njit(cache=True)
def _cast_shapes(x, y, directions, circles, segments, out):
    """Lower `out` to the nearest hit [m] with circles (C x 3: cx, cy, r) and polygon edges
    (S x 4: ax, ay, bx, by) along each unit direction; 0 when the sensor is inside a circle or a
    tangent ray starts on its outline."""
    for beam in range(directions.shape[0]):
        dx = directions[beam, 0]
        dy = directions[beam, 1]
        best = out[beam]
        for index in range(circles.shape[0]):
            offset_x = x - circles[index, 0]
            offset_y = y - circles[index, 1]
            b = dx * offset_x + dy * offset_y
            c = offset_x**2 + offset_y**2 - circles[index, 2] ** 2
            if c <= 0:
                best = 0.0
                continue
            discriminant = b**2 - c
            if discriminant < 0:
                continue
            root = math.sqrt(discriminant)
            near, far = -b - root, -b + root
            if near >= 0:
                best = min(best, near)
            elif far >= 0:
                best = 0.0
        for index in range(segments.shape[0]):
            ax = segments[index, 0] - x
            ay = segments[index, 1] - y
            ex = segments[index, 2] - segments[index, 0]
            ey = segments[index, 3] - segments[index, 1]
            # Solve t d = a + u e  ->  cross products (2-D determinant of [d, -e]).
            denominator = dx * ey - dy * ex
            if denominator == 0:
                continue
            t = (ax * ey - ay * ex) / denominator
            u = (ax * dy - ay * dx) / denominator
            if t >= 0 and u >= 0 and u <= 1:
                best = min(best, t)
        out[beam] = best


@numba.njit(cache=True)
def _inside_polygons(x, y, vertices, starts):
    """True when (x, y) is inside one of the polygons; polygon p is vertices[starts[p]:starts[p + 1]]."""
    for polygon in range(starts.shape[0] - 1):
        if inside_polygon(x, y, vertices, starts[polygon], starts[polygon + 1]):
            return True
    return False


@numba.njit(cache=True)
def _scan(
    occupied_up, origin_x, origin_y, resolution, x, y, theta, beam_angles, angle_jitter, range_jitter,
    range_min, range_max, circles, segments, vertices, starts, directions, ranges,
):  # fmt: skip
    """One sweep into `ranges` (NaN for missed beams): cast directions from the nominal angles plus
    theta plus `angle_jitter` (same length, zeros without noise), true distances, then the range
    limits, then `range_jitter` added to the hits."""
    count = beam_angles.shape[0]
    for beam in range(count):
        cast = beam_angles[beam] + theta + angle_jitter[beam]
        directions[beam, 0] = math.cos(cast)
        directions[beam, 1] = math.sin(cast)
    _cast_grid(occupied_up, origin_x, origin_y, resolution, x, y, directions, range_max, ranges)
    _cast_shapes(x, y, directions, circles, segments, ranges)
    inside = _inside_polygons(x, y, vertices, starts)
    for beam in range(count):
        distance = 0.0 if inside else ranges[beam]
        if distance < range_min or distance > range_max or not math.isfinite(distance):
            ranges[beam] = np.nan
        else:
            ranges[beam] = distance + range_jitter[beam]


MAX_BEAMS = 100_000  # beams of one sweep (two output ports each); a scenario allows fewer (the VFH's 720)


class Lidar(PythonComponent):
    """Lidar component (see the module docstring). Lengths [m], angles [rad], period [s]."""

    def __init__(
        self,
        name: str = "lidar",
        occupied: np.ndarray | None = None,
        resolution: float = 1.0,
        origin: Sequence[float] = (0.0, 0.0),
        obstacles: Sequence[Obstacle] = (),
        angles: Sequence[float] | None = None,
        angle_min: float = -math.pi,
        angle_max: float = math.pi,
        count: int = 258,
        range_min: float = 0.0,
        range_max: float = 20.0,
        range_noise: float = 0.0,
        angle_noise: float = 0.0,
        seed: int = 0,
        capacity: int | None = None,
        period: float = 0.1,
    ) -> None:
        if angles is None:
            if (
                isinstance(count, bool)
                or not isinstance(count, int | np.integer)
                or not 1 <= count <= MAX_BEAMS
            ):
                raise CosimError(
                    f"lidar '{name}': count must be an integer in 1..{MAX_BEAMS}, got {count!r:.80}"
                )
            angles = np.linspace(angle_min, angle_max, count) if count > 1 else np.array([angle_min])
        try:
            self.beam_angles = np.ascontiguousarray(angles, dtype=float)
        except (TypeError, ValueError):
            raise CosimError(f"lidar '{name}': beam angles must be a list of numbers [rad]") from None
        beams = self.beam_angles.size
        if self.beam_angles.ndim != 1 or not 1 <= beams <= MAX_BEAMS:
            raise CosimError(
                f"lidar '{name}': needs a flat list of 1..{MAX_BEAMS} beam angles, "
                f"got shape {self.beam_angles.shape}"
            )
        if not np.isfinite(self.beam_angles).all():
            raise CosimError(f"lidar '{name}': beam angles must be finite")
        capacity = beams if capacity is None else capacity
        if not beams <= capacity <= MAX_BEAMS:
            raise CosimError(
                f"lidar '{name}': capacity (ports ranges[k], angles[k]) must be in {beams}..{MAX_BEAMS} "
                f"for {beams} beams, got {capacity}"
            )
        if not 0 <= range_min < range_max:
            raise CosimError(f"lidar '{name}': range limits [{range_min}, {range_max}] m need 0 <= min < max")
        if range_noise < 0 or angle_noise < 0:
            raise CosimError(f"lidar '{name}': noise standard deviations must be >= 0")
        if resolution <= 0:
            raise CosimError(f"lidar '{name}': grid resolution must be > 0 m")
        self.capacity = capacity
        self.range_min, self.range_max = float(range_min), float(range_max)
        self.range_noise, self.angle_noise, self.seed = float(range_noise), float(angle_noise), seed
        grid = np.zeros((1, 1), dtype=bool) if occupied is None else np.asarray(occupied, dtype=bool)
        self.occupied_up = np.ascontiguousarray(grid[::-1])  # row 0 at the bottom: y grows with the row
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        self.obstacles = list(obstacles)
        # The shapes as arrays; moving ones are put at their pose of each scan's time.
        self.world = ObstacleArrays(self.obstacles)
        count = len(self.beam_angles)
        self._directions = np.empty((count, 2))  # scratch of the kernel, reused every scan
        self._no_jitter = np.zeros(count)
        outputs = array_ports("ranges", capacity, unit="m") + array_ports("angles", capacity, unit="rad")
        inputs = [Port("x", unit="m"), Port("y", unit="m"), Port("theta", unit="rad")]
        super().__init__(name, inputs, outputs, period=period)
        self._ranges = self.output_buffer[:capacity]
        self._angles = self.output_buffer[capacity:]

    def on_setup(self, t0: float, parameters: Mapping[str, float]) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._angles_written = False

    def on_initialize(self) -> None:
        self.scan(*self.input_buffer[:3], t=self.t0)

    def step(self, t: float, h: float) -> None:
        # The scan at the start of the step, from the pose the vehicle had then and the obstacles'
        # poses at that time (sample and hold).
        self.scan(*self.input_buffer[:3], t=t)

    def measure(self, x: float, y: float, theta: float, directions: np.ndarray, t: float = 0.0) -> np.ndarray:
        """True distances [m] along unit `directions` (N x 2, world frame) at time t [s]; inf for no hit."""
        self.world.at(t)
        world = self.world
        directions = np.ascontiguousarray(directions, dtype=float)
        distances = np.empty(len(directions))
        x, y = float(x), float(y)
        _cast_grid(
            self.occupied_up, self.origin[0], self.origin[1], self.resolution, x, y, directions,
            self.range_max, distances,
        )  # fmt: skip
        _cast_shapes(x, y, directions, world.circles, world.segments, distances)
        if _inside_polygons(x, y, world.vertices, world.starts):
            distances[:] = 0.0
        return distances

    def scan(self, x: float, y: float, theta: float, t: float = 0.0) -> None:
        """Fill `ranges[k]`/`angles[k]` for the pose (x, y [m], theta [rad]) at time t [s]."""
        world = self.world
        world.at(t)
        count = len(self.beam_angles)
        # The generator is drawn in the same order as always (angles, then ranges), so a seed
        # gives the same noise whatever computes the sweep.
        angle_jitter = (
            self._rng.normal(0.0, self.angle_noise, count) if self.angle_noise > 0 else self._no_jitter
        )
        range_jitter = (
            self._rng.normal(0.0, self.range_noise, count) if self.range_noise > 0 else self._no_jitter
        )
        _scan(
            self.occupied_up, self.origin[0], self.origin[1], self.resolution, float(x), float(y),
            float(theta), self.beam_angles, angle_jitter, range_jitter, self.range_min, self.range_max,
            world.circles, world.segments, world.vertices, world.starts, self._directions, self._ranges,
        )  # fmt: skip
        if not self._angles_written:
            self._ranges[count:] = np.nan
            self._angles[:count] = self.beam_angles
            self._angles[count:] = np.nan
            self._angles_written = True
