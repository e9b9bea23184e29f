"""The scenario's world: the known map the planner sees and the true world the robot drives in.

The true world is the known occupancy grid plus the unknown obstacles (seen only by the lidar).
`WorldDistance` gives the exact Euclidean distance from a point to the nearest true obstacle: to
the nearest occupied cell *square* (not its centre) and to the exact shape of each unknown
obstacle. Outside the map counts as an obstacle (a robot leaving the map has crashed).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from cosim.errors import CosimError
from cosim.world import Circle, Obstacle
from planner.errors import PlannerError
from planner.grid import OccupancyGrid


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


def point_in_polygon(x: float, y: float, vertices: np.ndarray) -> bool:
    """Even-odd rule; a point on an edge may fall either way (it has distance 0 anyway)."""
    inside = False
    count = len(vertices)
    for index in range(count):
        x1, y1 = vertices[index]
        x2, y2 = vertices[(index + 1) % count]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def distance_to_obstacle(x: float, y: float, obstacle: Obstacle) -> float:
    """Exact distance [m] from (x, y) to the shape; 0 inside it."""
    if isinstance(obstacle, Circle):
        return max(0.0, math.hypot(x - obstacle.center[0], y - obstacle.center[1]) - obstacle.radius)
    vertices = obstacle.polygon()
    if point_in_polygon(x, y, vertices):
        return 0.0
    best = math.inf
    count = len(vertices)
    for index in range(count):
        ax, ay = vertices[index]
        bx, by = vertices[(index + 1) % count]
        dx, dy = bx - ax, by - ay
        length_sq = dx * dx + dy * dy
        t = 0.0 if length_sq == 0 else min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / length_sq))
        best = min(best, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return best


class WorldDistance:
    """Exact distance [m] from a point to the nearest true obstacle (grid cells + unknown shapes).

    Speed: a per-cell distance field gives a cheap lower bound; the exact computation (KD-tree of
    occupied cell centres, then point-to-square distances of the candidates) runs only when that
    bound is below `exact_below`, so a run pays for exactness only near obstacles.
    """

    def __init__(self, grid: OccupancyGrid, obstacles: tuple[Obstacle, ...] = ()):
        self.grid = grid
        self.half = grid.resolution / 2.0
        rows, cols = grid.shape
        occupied_cells = np.argwhere(grid.occupied)
        self.centres = grid.cells_to_world(occupied_cells) if len(occupied_cells) else np.empty((0, 2))
        self.tree = cKDTree(self.centres) if len(self.centres) else None
        # Distance [m] from each cell centre to the nearest occupied cell centre (0 on occupied cells).
        if grid.occupied.any():
            self.centre_field = distance_transform_edt(~grid.occupied) * grid.resolution
        else:
            self.centre_field = np.full(grid.shape, np.inf)
        self.x_min, self.y_min = grid.origin
        self.x_max = self.x_min + cols * grid.resolution
        self.y_max = self.y_min + rows * grid.resolution
        self.obstacles = obstacles
        # Bounding circles (centre, radius) give lower bounds for the unknown shapes.
        self.bounds = []
        for obstacle in obstacles:
            vertices = obstacle.polygon()
            centre = vertices.mean(axis=0)
            radius = float(np.max(np.hypot(*(vertices - centre).T)))
            if isinstance(obstacle, Circle):
                centre, radius = np.asarray(obstacle.center), obstacle.radius
            self.bounds.append((float(centre[0]), float(centre[1]), radius))

    def lower_bound(self, x: float, y: float) -> float:
        """A cheap lower bound of `distance(x, y)` [m]."""
        if not (self.x_min <= x < self.x_max and self.y_min <= y < self.y_max):
            return 0.0
        row, col = self.grid.world_to_cell((x, y))
        # The nearest occupied square is at least (centre distance - |p - cell centre| - half diagonal) away.
        bound = min(self.centre_field[row, col] - 2.0 * math.sqrt(2.0) * self.half, self.distance_to_edge(x, y))
        for cx, cy, radius in self.bounds:
            bound = min(bound, math.hypot(x - cx, y - cy) - radius)
        return max(0.0, bound)

    def distance(self, x: float, y: float) -> float:
        """Exact distance [m] from (x, y) to the nearest true obstacle; 0 inside one or off the map."""
        if not (self.x_min <= x < self.x_max and self.y_min <= y < self.y_max):
            return 0.0
        best = self.distance_to_edge(x, y)
        if self.tree is not None:
            centre_distance, _ = self.tree.query((x, y))
            # Every square within reach has its centre within best + half diagonal.
            best = min(best, centre_distance)
            candidates = self.centres[self.tree.query_ball_point((x, y), best + math.sqrt(2.0) * self.half)]
            if len(candidates):
                dx = np.maximum(np.abs(candidates[:, 0] - x) - self.half, 0.0)
                dy = np.maximum(np.abs(candidates[:, 1] - y) - self.half, 0.0)
                best = min(best, float(np.min(np.hypot(dx, dy))))
        for obstacle in self.obstacles:
            best = min(best, distance_to_obstacle(x, y, obstacle))
        return best

    def distance_to_edge(self, x: float, y: float) -> float:
        """Distance [m] to the edge of the map (beyond it counts as obstacle)."""
        return min(x - self.x_min, self.x_max - x, y - self.y_min, self.y_max - y)


def check_start_goal(scenario) -> None:
    """Start and goal must lie in free space: not in a known cell, the inflated map or an unknown obstacle."""
    grid = load_known_map(scenario)
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
            if distance_to_obstacle(x, y, obstacle) < scenario.vehicle_radius:
                raise CosimError(
                    f"{where} is inside unknown obstacle [[obstacles]][{index}] ({obstacle.kind}, "
                    f"counting the vehicle radius {scenario.vehicle_radius:g} m)"
                )
