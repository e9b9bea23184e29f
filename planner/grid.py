"""The occupancy grid: a boolean map with a resolution [m/cell] and an origin [m].

Conventions: `occupied[row, col]`, row 0 is the TOP row of the map image or file
(as Moving AI and image files store it); the world frame has x to the right and y up, and
`origin` is the (x, y) of the grid's lower-left corner (ROS map_server convention). So the centre
of cell (row, col) is at (origin_x + (col + 0.5) * res, origin_y + (rows - 1 - row + 0.5) * res).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from planner.errors import PlannerError
from planner.mapio import load_map, write_yaml


class OccupancyGrid:
    """A boolean occupancy grid.

    occupied: 2-D bool array [row, col], True = obstacle; stored read-only (a planner caches
        derived arrays per grid, so the map must not change under it: make a new grid instead).
    resolution: cell size [m/cell], > 0.
    origin: (x, y) [m] of the lower-left corner of the grid.
    """

    # Weakly referable: what its `_cache` holds refers back to it weakly (no reference cycle).
    __slots__ = ("occupied", "resolution", "origin", "_cache", "__weakref__")

    def __init__(
        self,
        occupied: np.ndarray,
        resolution: float = 1.0,
        origin: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        array = np.asarray(occupied)
        if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
            raise PlannerError(f"occupancy grid must be a non-empty 2-D array, got shape {array.shape}")
        if array.dtype != np.bool_:
            if not np.issubdtype(array.dtype, np.number):
                raise PlannerError(f"occupancy grid must be bool or 0/1 numbers, got dtype {array.dtype}")
            if not np.isin(array, (0, 1)).all():
                raise PlannerError("occupancy grid of numbers must hold only 0 (free) and 1 (occupied)")
        try:
            resolution = float(resolution)
        except (TypeError, ValueError):
            raise PlannerError(f"resolution must be a number [m/cell], got {resolution!r}") from None
        if not math.isfinite(resolution) or resolution <= 0.0:
            raise PlannerError(f"resolution must be > 0 [m/cell], got {resolution}")
        try:
            origin_x, origin_y = (float(value) for value in origin)
        except (TypeError, ValueError):
            raise PlannerError(f"origin must be (x, y) in metres, got {origin!r}") from None
        if not (math.isfinite(origin_x) and math.isfinite(origin_y)):
            raise PlannerError(f"origin must be finite, got {origin!r}")
        grid = np.array(array, dtype=np.bool_, order="C", copy=True)
        grid.flags.writeable = False
        self.occupied: np.ndarray = grid
        self.resolution: float = resolution
        self.origin: tuple[float, float] = (origin_x, origin_y)
        self._cache: dict = {}

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        return self.occupied.shape

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the map [m]."""
        rows, cols = self.occupied.shape
        return cols * self.resolution, rows * self.resolution

    def __repr__(self) -> str:
        rows, cols = self.shape
        return (
            f"OccupancyGrid({rows}x{cols} cells, resolution={self.resolution} m, origin={self.origin}, "
            f"{int(self.occupied.sum())} occupied)"
        )

    # -- world <-> cell ---------------------------------------------------------------------------
    def cell_to_world(self, cell: tuple[int, int]) -> tuple[float, float]:
        """Centre (x, y) [m] of cell (row, col)."""
        row, col = cell
        rows = self.occupied.shape[0]
        return (
            self.origin[0] + (col + 0.5) * self.resolution,
            self.origin[1] + (rows - 1 - row + 0.5) * self.resolution,
        )

    def cells_to_world(self, cells: np.ndarray) -> np.ndarray:
        """Centres (N x 2, x y [m]) of cells (N x 2, row col)."""
        cells = np.asarray(cells)
        rows = self.occupied.shape[0]
        world = np.empty((len(cells), 2), dtype=np.float64)
        world[:, 0] = self.origin[0] + (cells[:, 1] + 0.5) * self.resolution
        world[:, 1] = self.origin[1] + (rows - 1 - cells[:, 0] + 0.5) * self.resolution
        return world

    def world_to_cell(self, point: tuple[float, float]) -> tuple[int, int]:
        """(row, col) of the cell that contains point (x, y) [m]; may lie outside the grid."""
        x, y = point[0], point[1]
        rows = self.occupied.shape[0]
        col = math.floor((x - self.origin[0]) / self.resolution)
        row = rows - 1 - math.floor((y - self.origin[1]) / self.resolution)
        return row, col

    def world_to_cells(self, points: np.ndarray) -> np.ndarray:
        """(row, col) of the cells that contain points (N x 2, x y [m]); may lie outside the grid."""
        points = np.asarray(points, dtype=np.float64)
        rows = self.occupied.shape[0]
        cells = np.empty((len(points), 2), dtype=np.int64)
        cells[:, 1] = np.floor((points[:, 0] - self.origin[0]) / self.resolution)
        cells[:, 0] = rows - 1 - np.floor((points[:, 1] - self.origin[1]) / self.resolution)
        return cells

    def contains_cell(self, cell: tuple[int, int]) -> bool:
        """True when (row, col) lies inside the grid."""
        rows, cols = self.occupied.shape
        return 0 <= cell[0] < rows and 0 <= cell[1] < cols

    # -- derived grids and files ------------------------------------------------------------------
    def inflate(self, radius_m: float) -> OccupancyGrid:
        """A new grid: obstacles plus every cell within `radius_m` [m] of one (planner.inflation)."""
        # Imported here: only a grid that is inflated needs planner.inflation (and its C kernel).
        from planner.inflation import inflation_mask

        return OccupancyGrid(self.occupied | inflation_mask(self, radius_m), self.resolution, self.origin)

    @classmethod
    def from_file(cls, path: str | Path, **options) -> OccupancyGrid:
        """Load a map: `.yaml` (ROS map_server), `.map` (Moving AI), `.png`/`.pgm` image, `.npy`.

        Keyword options for images and `.npy` (ignored elsewhere is an error): `resolution` [m/cell],
        `origin` (x, y) [m]; for images also `negate`, `occupied_thresh`, `free_thresh`.
        """
        return cls(*load_map(path, **options))

    def to_yaml(self, path: str | Path) -> Path:
        """Write a ROS map_server YAML and a PGM beside it (same stem); returns the YAML path."""
        return write_yaml(path, self.occupied, self.resolution, self.origin)
