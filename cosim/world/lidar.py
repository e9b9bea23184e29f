"""A 2-D lidar: ray casting on the true world (occupancy grid plus unknown obstacles).

Semantics follow MATLAB's `rangeSensor` (Navigation Toolbox):
* Beams leave the sensor at the robot pose (x, y, theta) at `angles` in the sensor frame
  (counter-clockwise from the heading, radians). Angles are given as a list, or as
  `angle_min`, `angle_max`, `count` (`evenly_spaced_beams`: both ends included, except that a
  full turn leaves out its end, the start's own direction).
* A beam returns the distance to the first occupied cell boundary or obstacle outline it meets.
  A beam whose true distance lies outside [range_min, range_max] is a missed reading: NaN.
  A sensor inside an occupied cell or an obstacle reads 0 (so NaN when range_min > 0).
* Noise, drawn from one seeded generator so a run is reproducible: the range of every hit gets
  Gaussian noise of standard deviation `range_noise` [m]; each beam is cast at its nominal angle
  plus Gaussian noise of standard deviation `angle_noise` [rad], while the reported angle stays
  nominal (the sensor does not know its jitter).
* Other robots of a fleet (`robot_radii`, one footprint circle each) are seen as circles at the
  poses on the inputs `robots_x[j]`, `robots_y[j]` at the scan's time; a NaN position is no robot.
* Cells outside the grid are free. Grid cells are hit on their boundary (exact for axis-aligned
  walls); circles, rectangles and polygons (cosim.world.shapes) are intersected exactly, moving
  ones at their pose at the scan's time (the start of the lidar's step).

Outputs `ranges[k]` and `angles[k]`, k = 1..capacity (capacity >= beam count, the rest NaN), so
the ports match VFH inputs of a fixed size. Inputs `x`, `y`, `theta` (and `robots_x[j]`,
`robots_y[j]`, j = 1..len(robot_radii), for a fleet).

The sweep is C (`lidar_scan` of native/world.c: exact intersections with the shapes, then
Amanatides-Woo traversal of the grid up to the shapes' nearest hit, crossing free space in strides
given by each cell's distance to the nearest occupied one), given the grid, beams, shapes and
buffers once as a struct; the master's compiled kernel calls it itself where a step needs nothing
else (`kernel_sweep`).
"""

from __future__ import annotations

import ctypes
import hashlib
import math
from collections.abc import Mapping, Sequence

import numpy as np

from cosim.core.component import Port, PythonComponent, array_ports
from cosim.errors import CosimError
from cosim.world import kernels
from cosim.world.obstacles import ObstacleArrays
from cosim.world.shapes import Circle, Obstacle

MAX_BEAMS = 100_000  # beams of one sweep (two output ports each); a scenario allows fewer (the VFH's 720)


def evenly_spaced_beams(angle_min: float, angle_max: float, count: int) -> np.ndarray:
    """`count` beam angles [rad] from `angle_min` to `angle_max`, both ends included.

    A full turn (angle_max - angle_min >= 2 pi) leaves out its end: that beam would point where the
    first one does and be counted twice. One beam points at `angle_min`. The scenario's `[lidar]`
    keys and `Lidar(angle_min=, angle_max=, count=)` both come here, so the same three numbers give
    the same beams by either path.
    """
    if count == 1:
        return np.array([float(angle_min)])
    full_turn = angle_max - angle_min >= 2 * math.pi - 1e-9
    return np.linspace(angle_min, angle_max, count, endpoint=not full_turn)


_GRIDS: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # `_grid_arrays` of the grids seen, by content


def _grid_arrays(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid (bool, row 0 at the top) with row 0 at the bottom, and its clearance (native/world.c's
    `lidar_clearance`), read-only: the same arrays for every grid of the same cells (a fleet's
    lidars share their map: one copy for the sweeps to read, not one a robot in the caches). The
    last few grids are kept."""
    occupied_up = np.array(grid[::-1], dtype=bool, order="C")  # (a copy: made read-only below)
    key = (occupied_up.shape, hashlib.blake2b(occupied_up.view(np.uint8).data, digest_size=16).digest())
    found = _GRIDS.get(key)
    if found is not None and np.array_equal(found[0], occupied_up):
        return found
    clearance = np.empty(occupied_up.shape, dtype=np.uint8)
    kernels.library().lidar_clearance(
        occupied_up.view(np.uint8).ctypes.data, *occupied_up.shape, clearance.ctypes.data
    )
    occupied_up.flags.writeable = False
    clearance.flags.writeable = False
    if len(_GRIDS) >= 8:
        _GRIDS.pop(next(iter(_GRIDS)))
    _GRIDS[key] = (occupied_up, clearance)
    return occupied_up, clearance


class Lidar(kernels.Bound, PythonComponent):
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
        robot_radii: Sequence[float] = (),
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
            angles = evenly_spaced_beams(angle_min, angle_max, count)
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
        # Row 0 at the bottom: y grows with the row. With each cell's Chebyshev distance (cells) to
        # the nearest occupied one, at most 255: the sweep crosses free space in strides
        # (native/world.c's cast_grid). Both read-only, shared by the lidars of equal grids.
        self.occupied_up, self._clearance = _grid_arrays(grid)
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        self.obstacles = list(obstacles)
        # The other robots' footprints: the last circles of the world, moved by each scan's inputs.
        self.robot_radii = np.asarray(robot_radii, dtype=float).reshape(-1)
        robots = [Circle((math.nan, math.nan), float(radius)) for radius in self.robot_radii]
        # The shapes as arrays; moving ones are put at their pose of each scan's time.
        self.world = ObstacleArrays([*self.obstacles, *robots])
        self._robot_rows = self.world.circles[len(self.world.circles) - len(robots) :]
        count = len(self.beam_angles)
        self._directions = np.empty((count, 2))  # scratch of the kernel, reused every scan
        # Each scan's noise is copied in here (zeros without noise), so the kernel keeps one address.
        self._angle_jitter = np.zeros(count)
        self._range_jitter = np.zeros(count)
        outputs = array_ports("ranges", capacity, unit="m") + array_ports("angles", capacity, unit="rad")
        inputs = [Port("x", unit="m"), Port("y", unit="m"), Port("theta", unit="rad")]
        if len(robots):
            inputs += array_ports("robots_x", len(robots), unit="m") + array_ports(
                "robots_y", len(robots), unit="m"
            )
        # `angles[k]` are the beams' own angles, set once: they depend on no input (ranges[k],
        # not listed, on every input). Half the lidar's dependency edges: a fleet of 50 robots
        # seeing each other had 3.6 M, most of what the algebraic-loop check walked.
        constant = {port.name: () for port in outputs[capacity:]}
        super().__init__(name, inputs, outputs, period=period, feedthrough=constant)
        self._ranges = self.output_buffer[:capacity]
        self._angles = self.output_buffer[capacity:]
        self._bind()

    _BOUND = ("_refs", "_arrays", "_address", "_scan", "_measure")

    def _bind(self) -> None:
        """The kernel's struct: addresses of the grid, beams, noise buffers, shapes and outputs."""
        refs = self._refs = kernels.ArrayRefs()
        world = self.world
        self._arrays = kernels.LidarArrays(
            occupied_up=refs.pointer(self.occupied_up.view(np.uint8), np.uint8),
            rows=self.occupied_up.shape[0], cols=self.occupied_up.shape[1],
            origin_x=self.origin[0], origin_y=self.origin[1], resolution=self.resolution,
            range_min=self.range_min, range_max=self.range_max,
            beam_angles=refs.pointer(self.beam_angles, np.float64), count=len(self.beam_angles),
            angle_jitter=refs.pointer(self._angle_jitter, np.float64),
            range_jitter=refs.pointer(self._range_jitter, np.float64),
            circles=refs.pointer(world.circles, np.float64), n_circles=len(world.circles),
            segments=refs.pointer(world.segments, np.float64), n_segments=len(world.segments),
            vertices=refs.pointer(world.vertices, np.float64),
            starts=refs.pointer(world.starts, np.int64), n_starts=len(world.starts),
            directions=refs.pointer(self._directions, np.float64, writable=True),
            ranges=refs.pointer(self._ranges, np.float64, writable=True),
            clearance=refs.pointer(self._clearance, np.uint8),
        )  # fmt: skip
        self._address = ctypes.addressof(self._arrays)
        library = kernels.library()
        self._scan, self._measure = library.lidar_scan, library.lidar_measure

    def kernel_sweep(self) -> tuple[int, int] | None:
        """How the master's compiled kernel may step this lidar (`cosim.core.fast_loop`): the
        address of `lidar_scan` and of this lidar's struct, the call `step` makes on the inputs x,
        y, theta; None when a step needs Python: noise (drawn from NumPy's generator), other
        robots (placed from their inputs) or moving obstacles (posed at each scan's time)."""
        if self.angle_noise > 0 or self.range_noise > 0 or len(self._robot_rows) or self.world.moving:
            return None
        return ctypes.cast(self._scan, ctypes.c_void_p).value, self._address

    def on_setup(self, t0: float, parameters: Mapping[str, float]) -> None:
        # The generator only with noise: a noiseless run does not import numpy.random (~5 ms).
        noisy = self.angle_noise > 0 or self.range_noise > 0
        self._rng = np.random.default_rng(self.seed) if noisy else None
        self._angles_written = False

    def on_initialize(self) -> None:
        self._place_robots()
        self.scan(*self.input_buffer[:3], t=self.t0)

    def step(self, t: float, h: float) -> None:
        # The scan at the start of the step, from the pose the vehicle had then and the obstacles'
        # poses at that time (sample and hold).
        self._place_robots()
        self.scan(*self.input_buffer[:3], t=t)

    def _place_robots(self) -> None:
        """The other robots' circles at the positions on the inputs (in place: the kernel keeps
        reading the same array)."""
        count = len(self._robot_rows)
        if count:
            self._robot_rows[:, 0] = self.input_buffer[3 : 3 + count]
            self._robot_rows[:, 1] = self.input_buffer[3 + count : 3 + 2 * count]

    def measure(self, x: float, y: float, theta: float, directions: np.ndarray, t: float = 0.0) -> np.ndarray:
        """True distances [m] along unit `directions` (N x 2, world frame) at time t [s]; inf for no hit."""
        self.world.at(t)
        directions = np.ascontiguousarray(directions, dtype=float)
        if directions.ndim != 2 or directions.shape[1] != 2:
            raise ValueError(f"directions must be an (N, 2) array, got shape {directions.shape}")
        distances = np.empty(len(directions))
        self._measure(
            self._address, float(x), float(y), directions.ctypes.data, len(directions), distances.ctypes.data
        )
        return distances

    def scan(self, x: float, y: float, theta: float, t: float = 0.0) -> None:
        """Fill `ranges[k]`/`angles[k]` for the pose (x, y [m], theta [rad]) at time t [s]."""
        self.world.at(t)
        # The generator is drawn in the same order as always (angles, then ranges), so a seed
        # gives the same noise whatever computes the sweep.
        if self.angle_noise > 0:
            self._angle_jitter[:] = self._rng.normal(0.0, self.angle_noise, len(self._angle_jitter))
        if self.range_noise > 0:
            self._range_jitter[:] = self._rng.normal(0.0, self.range_noise, len(self._range_jitter))
        self._scan(self._address, float(x), float(y), float(theta))
        if not self._angles_written:
            count = len(self.beam_angles)
            self._ranges[count:] = np.nan
            self._angles[:count] = self.beam_angles
            self._angles[count:] = np.nan
            self._angles_written = True
