"""Point-polygon geometry shared by the lidar (is the sensor inside an obstacle?) and the outcome
checks (distance to the true obstacles), in C (native/geometry.h, inlined into the kernels of
native/world.c that use them); `polygon_distance` is the distance for Python callers.

Polygons are rows `first` to `stop - 1` of an (N, 2) vertex array, closed implicitly, so many
polygons can share one array.
"""

from __future__ import annotations

import numpy as np

from cosim.world import kernels


def _checked(vertices: np.ndarray, first: int, stop: int) -> tuple[np.ndarray, int, int]:
    """The vertices as float64 (N, 2) in C order (the caller holds them through the call) and the rows."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 2:
        raise ValueError(f"vertices must be an (N, 2) array, got shape {vertices.shape}")
    first, stop = int(first), int(stop)
    if not 0 <= first <= stop <= len(vertices):
        raise ValueError(f"rows {first}..{stop} are not rows of {len(vertices)} vertices")
    return vertices, first, stop


def polygon_distance(x: float, y: float, vertices: np.ndarray, first: int, stop: int) -> float:
    """Exact distance [m] from (x, y) to the polygon's boundary; 0 inside it."""
    vertices, first, stop = _checked(vertices, first, stop)
    return kernels.library().world_polygon_distance(float(x), float(y), vertices.ctypes.data, first, stop)
