"""The scenario's world: the known map the planner sees and the true world the robot drives in.

The true world is the known occupancy grid plus the unknown obstacles (seen only by the lidar).
`WorldDistance` gives the exact Euclidean distance from a point to the nearest true obstacle: to
the nearest occupied cell *square* (not its centre) and to the exact shape of each unknown
obstacle. Outside the map counts as an obstacle (a robot leaving the map has crashed).
"""

from __future__ import annotations

import ctypes
import functools
import math
import struct

import numpy as np

from cosim.errors import CosimError
from cosim.world import kernels
from cosim.world.geometry import polygon_distance
from cosim.world.obstacles import ObstacleArrays
from cosim.world.shapes import Circle, Obstacle
from planner.errors import PlannerError
from planner.grid import OccupancyGrid
from planner.inflation import distance_to_nearest


def load_known_map(scenario) -> OccupancyGrid:
    """The planner's map: the scenario's map file with its resolution/origin where the format lacks them."""
    options = {}
    if scenario.map_resolution is not None:
        options["resolution"] = scenario.map_resolution
    if scenario.map_origin is not None:
        options["origin"] = scenario.map_origin
    try:
        return OccupancyGrid.from_file(scenario.map_file, **options)
    except PlannerError as error:
        raise CosimError(f"{scenario.source}: [map].file: {error}") from None


def distance_to_obstacle(x: float, y: float, obstacle: Obstacle) -> float:
    """Exact distance [m] from (x, y) to the shape; 0 inside it."""
    if isinstance(obstacle, Circle):
        return max(0.0, math.hypot(x - obstacle.center[0], y - obstacle.center[1]) - obstacle.radius)
    vertices = np.ascontiguousarray(obstacle.polygon(), dtype=np.float64)
    return polygon_distance(float(x), float(y), vertices, 0, len(vertices))


class WorldDistance(kernels.Bound):
    """Exact distance [m] from a point to the nearest true obstacle (grid cells + unknown shapes,
    moving ones at their pose at the time last given to `at`).

    Speed: a per-cell field of the distance from each cell centre to the nearest occupied cell
    centre bounds the search. `lower_bound` is cheap; `distance` looks only at the occupied cells
    of a small window that must contain the nearest one, as exact point-to-square distances (in C:
    `world_distance` of native/world.c, given the grid and shapes once as a struct).
    """

    def __init__(self, grid: OccupancyGrid, obstacles: tuple[Obstacle, ...] = ()):
        self.grid = grid
        self.resolution = grid.resolution
        self.half = grid.resolution / 2.0
        rows, cols = grid.shape
        self.rows, self.cols = rows, cols
        self.occupied = grid.occupied
        # Distance [m] from each cell centre to the nearest occupied cell centre (0 on occupied cells).
        if grid.occupied.any():
            self.centre_field = distance_to_nearest(grid.occupied) * grid.resolution
        else:
            self.centre_field = np.full(grid.shape, np.inf)
        self.x_min, self.y_min = grid.origin
        self.x_max = self.x_min + cols * grid.resolution
        self.y_max = self.y_min + rows * grid.resolution
        self.obstacles = tuple(obstacles)
        # The shapes as arrays for the compiled `distance` (moved by `at`); polygons' bounding
        # circles give cheap lower bounds.
        self.shapes = ObstacleArrays(self.obstacles)
        self._occupied_u8 = np.ascontiguousarray(grid.occupied, dtype=np.uint8)
        self._bind()

    _BOUND = ("_refs", "_arrays", "_address", "_query", "_kernel")

    def _bind(self) -> None:
        """The kernel's view of the grid and shapes (`at` moves the shapes in place: same arrays)."""
        refs = self._refs = kernels.ArrayRefs()
        shapes = self.shapes
        rows, cols = self.rows, self.cols
        self._arrays = kernels.WorldArrays(
            occupied=refs.pointer(self._occupied_u8, np.uint8), rows=rows, cols=cols,
            x_min=self.x_min, y_min=self.y_min, x_max=self.x_max, y_max=self.y_max,
            resolution=self.resolution,
            circles=refs.pointer(shapes.circles, np.float64), n_circles=len(shapes.circles),
            vertices=refs.pointer(shapes.vertices, np.float64),
            starts=refs.pointer(shapes.starts, np.int64), n_starts=len(shapes.starts),
        )  # fmt: skip
        self._address = ctypes.addressof(self._arrays)
        self._query = functools.partial(
            struct.Struct(kernels.WorldArrays.QUERY).pack_into, self._arrays, kernels.WorldArrays.x.offset
        )
        self._kernel = kernels.library().world_distance

    @property
    def moving(self) -> bool:
        """True when an unknown obstacle moves: distances then depend on the time set by `at`."""
        return self.shapes.moving

    @property
    def max_speed(self) -> float:
        """The fastest any obstacle moves [m/s]: a distance changes at most this fast in time."""
        return self.shapes.max_speed

    def at(self, t: float) -> None:
        """Measure from now on against the obstacles' poses at time t [s]."""
        self.shapes.at(t)

    def _cell(self, x: float, y: float) -> tuple[int, int, float]:
        """(row, col) of the cell holding (x, y) and the distance [m] from (x, y) to its centre."""
        col = int((x - self.x_min) / self.resolution)
        row = self.rows - 1 - int((y - self.y_min) / self.resolution)
        centre_x = self.x_min + (col + 0.5) * self.resolution
        centre_y = self.y_min + (self.rows - 1 - row + 0.5) * self.resolution
        return row, col, math.hypot(x - centre_x, y - centre_y)

    def inside_map(self, x: float, y: float) -> bool:
        return self.x_min <= x < self.x_max and self.y_min <= y < self.y_max

    def lower_bound(self, x: float, y: float) -> float:
        """A cheap lower bound of `distance(x, y)` [m]."""
        if not self.inside_map(x, y):
            return 0.0
        row, col, offset = self._cell(x, y)
        # Nearest occupied centre >= field - offset; its square's boundary is at most a half diagonal closer.
        bound = min(
            self.centre_field[row, col] - offset - math.sqrt(2.0) * self.half, self.distance_to_edge(x, y)
        )
        for circles in (self.shapes.circles, self.shapes.bounds):
            for cx, cy, radius in circles.tolist():
                bound = min(bound, math.hypot(x - cx, y - cy) - radius)
        return max(0.0, bound)

    def distance(self, x: float, y: float) -> float:
        """Exact distance [m] from (x, y) to the nearest true obstacle; 0 inside one or off the map."""
        if not self.inside_map(x, y):
            return 0.0
        row, col, offset = self._cell(x, y)
        # The kernel adds the distance to the map edge (`distance_to_edge`, same arithmetic).
        self._query(x, y, row, col, offset, self.centre_field[row, col])
        return self._kernel(self._address)

    def distance_to_edge(self, x: float, y: float) -> float:
        """Distance [m] to the edge of the map (beyond it counts as obstacle)."""
        return min(x - self.x_min, self.x_max - x, y - self.y_min, self.y_max - y)


def check_start_goal(scenario) -> None:
    """Start and goal must lie in free space: not in a known cell, the inflated map or an unknown
    obstacle (where it stands at t = 0); a moving obstacle's path must lie on the map."""
    grid = load_known_map(scenario)
    x_min, y_min = grid.origin
    x_max, y_max = x_min + grid.shape[1] * grid.resolution, y_min + grid.shape[0] * grid.resolution
    for index, obstacle in enumerate(scenario.obstacles):
        for k, (x, y) in enumerate(obstacle.motion.path if obstacle.motion is not None else ()):
            if not (x_min <= x <= x_max and y_min <= y <= y_max):
                raise CosimError(
                    f"{scenario.source}: [[obstacles]][{index}].path[{k}]: ({x:g}, {y:g}) is outside the "
                    f"map {scenario.map_file.name} (x {x_min:g}..{x_max:g}, y {y_min:g}..{y_max:g} m)"
                )
    inflated = (
        grid.inflate(scenario.planner.expansion_distance) if scenario.planner.expansion_distance else grid
    )
    for label, point in (("[start]", scenario.start[:2]), ("[goal]", scenario.goal)):
        x, y = point
        cell = grid.world_to_cell((x, y))
        where = f"{scenario.source}: {label}: ({x:g}, {y:g})"
        if not grid.contains_cell(cell):
            raise CosimError(f"{where} is outside the map {scenario.map_file.name}")
        if grid.occupied[cell]:
            raise CosimError(f"{where} is inside an obstacle of the known map {scenario.map_file.name}")
        if inflated.occupied[cell]:
            raise CosimError(
                f"{where} is inside the inflated known map (expansion_distance "
                f"{scenario.planner.expansion_distance:g} m of [planner])"
            )
        for index, obstacle in enumerate(scenario.obstacles):
            if distance_to_obstacle(x, y, obstacle.at(0.0)) < scenario.vehicle_radius:
                raise CosimError(
                    f"{where} is inside unknown obstacle [[obstacles]][{index}] ({obstacle.kind}, "
                    f"counting the vehicle radius {scenario.vehicle_radius:g} m)"
                )
