"""The planner's costmap: the known map plus what the lidar has seen.

Cells are those of the known map (same shape, resolution and origin). `marked` holds the lidar's
obstacles: every scan marks the cell of each return, and clears the marked cells its rays pass
through before they end (at the return, or at `range_max` for a beam without one), so an obstacle
that moved away is forgotten once a ray crosses where it stood. Known occupied cells are never
cleared. A beam reads NaN both without a return and below `range_min`; with `range_min` > 0 a
NaN beam is not used to clear (the obstacle may be closer than the sensor sees).

`inflated(radius)` is the known map plus the marks, inflated by `radius` [m] with the planner's
rule (a cell is blocked when its centre is within `radius` of an obstacle cell's centre). The grid
of `grid()` carries its obstacle distance, which that rule reads: the known map's exact transform
(made once per map and shared, as the known cells are, by the costmaps of equal maps) lowered
round each mark, the transform of the whole grid bit for bit.
`new_marks_near(points, radius, since)` says whether a cell marked after the snapshot `since`
lies within `radius` of any of the points: a newly seen obstacle on the plan.

Both run in C (native/costmap.c: Amanatides-Woo traversal of each beam), given the marks, the
known cells and the beams once as a struct. Only marked cells can be cleared, so a beam is
traversed only where it may meet a mark: for beams evenly spread round the full turn, over the
distances where a mark lies within its window of directions (found from each mark once a scan);
for others, when it passes near the box of the marks (kept from per-row and per-column counts of
the marks). `marked` is therefore read-only outside `integrate`.
"""

from __future__ import annotations

import ctypes
import hashlib
import math
from pathlib import Path

import numpy as np

from cosim.world import kernels
from native.load import bind, load
from planner.grid import OccupancyGrid
from planner.inflation import distance_to_nearest, set_obstacle_distance

_p, _i64, _f64 = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double


class _Arrays(ctypes.Structure):
    """`Costmap` of native/costmap.c: the marks, the known cells, the beams and the scan buffer."""

    _fields_ = [
        ("marked", _p), ("known", _p), ("rows", _i64), ("cols", _i64),
        ("origin_x", _f64), ("origin_y", _f64), ("resolution", _f64),
        ("angles", _p), ("count", _i64), ("ranges", _p), ("clear_to", _f64),
        ("row_marks", _p), ("col_marks", _p), ("cos_angles", _p), ("sin_angles", _p),
        ("uniform", _i64), ("first_angle", _f64), ("step", _f64),
        ("near_from", _p), ("near_to", _p), ("near_cell", _p),
    ]  # fmt: skip


_library: ctypes.CDLL | None = None


def _kernels() -> ctypes.CDLL:
    """native/costmap.c built (if needed) and loaded, its functions typed; once per process."""
    global _library
    if _library is None:
        _library = bind(
            load(Path(__file__).parent / "native" / "costmap.c"),
            {
                "costmap_integrate_scan": (_i64, [_p, _f64, _f64, _f64]),
                "costmap_new_marks_near": (ctypes.c_int, [_p, _p, _p, _i64, _f64]),
                "costmap_new_marks_maybe_near": (
                    ctypes.c_int,
                    [_p, _p, _p, _p, _i64, _i64, _f64, _f64, _f64],
                ),
                "path_progress": (_f64, [_p, _p, _i64, _i64, _f64, _f64, ctypes.POINTER(_i64)]),
                "planner_look_ahead": (_i64, [_p]),
                "costmap_distance": (None, [_p, _p, _i64, _p]),
            },
        )
    return _library


def path_progress():
    """native/costmap.c's `path_progress(points, arc, first, stop, x, y, &segment)` (addresses of
    C-contiguous float64 arrays; see there), for the planner's progress along its plan."""
    return _kernels().path_progress


class _KnownMap:
    """A known map's cells (bool, C order, read-only), shared by the costmaps of equal maps (`_known_map`:
    a fleet's robots read one copy), and their transform, made on first use (`transform`)."""

    def __init__(self, cells: np.ndarray) -> None:
        self.cells = cells
        self._transform: tuple[np.ndarray, int] | None = None
        self._made = False

    def transform(self) -> tuple[np.ndarray, int] | None:
        """The squared distance (cells, exact integers) from every cell to the nearest known one and
        an integer at least every finite distance; None when no cell is known."""
        if not self._made:
            self._made = True
            if self.cells.any():
                distance = distance_to_nearest(self.cells)
                finite = distance[np.isfinite(distance)]
                squared = np.rint(distance * distance)  # each the square root of an integer: exact
                squared.flags.writeable = False
                self._transform = (squared, math.ceil(float(finite.max())) if len(finite) else 0)
        return self._transform


_KNOWN: dict[tuple, _KnownMap] = {}  # `_known_map`, by content (the last few)


def _known_map(occupied: np.ndarray) -> _KnownMap:
    """The shared `_KnownMap` of these cells."""
    cells = np.ascontiguousarray(occupied, dtype=np.bool_)
    key = (cells.shape, hashlib.blake2b(cells.view(np.uint8).data, digest_size=16).digest())
    found = _KNOWN.get(key)
    if found is not None and np.array_equal(found.cells, cells):
        return found
    copy = cells.copy()
    copy.flags.writeable = False
    if len(_KNOWN) >= 8:
        _KNOWN.pop(next(iter(_KNOWN)))
    _KNOWN[key] = found = _KnownMap(copy)
    return found


class Costmap(kernels.Bound):
    """The known map (`planner.OccupancyGrid`) plus lidar marks; see the module docstring."""

    def __init__(self, known: OccupancyGrid, angles: np.ndarray, range_min: float, range_max: float):
        self.known = known
        self._marked = np.zeros(known.shape, dtype=np.bool_)
        self._shared = _known_map(known.occupied)  # read-only, shared by equal maps' costmaps
        self._known = self._shared.cells
        self.angles = np.array(angles, dtype=float)  # a read-only copy: the kernel keeps cos and sin of them
        self.angles.flags.writeable = False
        self.clear_to = float(range_max) if range_min == 0.0 else 0.0
        self._ranges = np.empty(len(self.angles))  # each scan is copied in: one address for the kernel
        rows, cols = known.shape
        # Marked cells per row and per column, kept by the kernel: the box of the marks, which
        # only the beams passing near it can clear.
        self._row_marks = np.zeros(rows, dtype=np.int64)
        self._col_marks = np.zeros(cols, dtype=np.int64)
        # The beams' directions to a few ulp, for the kernel's cheap first look at each beam.
        self._cos_angles, self._sin_angles = np.cos(self.angles), np.sin(self.angles)
        # Beams evenly spread round the full turn (a 360-degree lidar): the kernel then finds the
        # beams near each mark once a scan, and traverses a beam only where a mark may lie on it.
        count = len(self.angles)
        self._step = 2.0 * math.pi / max(count, 1)
        self._first = float(self.angles[0]) if count else 0.0
        spread = self._first + np.arange(count) * self._step
        self._uniform = count > 0 and bool(np.all(np.abs(self.angles - spread) <= 1e-9))
        self._near_from, self._near_to = np.empty(count), np.empty(count)  # the kernel's scratch
        self._near_cell = np.empty(count, dtype=np.int64)
        self._bind()

    _BOUND = ("_arrays", "_address", "_integrate", "_new_marks_near", "_maybe_near")

    def _bind(self) -> None:
        """The kernel's struct: addresses of the marks, known cells, beams, scan buffer and counts."""
        origin_x, origin_y = self.known.origin
        rows, cols = self._marked.shape
        self._arrays = _Arrays(
            marked=self._marked.ctypes.data, known=self._known.ctypes.data, rows=rows, cols=cols,
            origin_x=float(origin_x), origin_y=float(origin_y), resolution=float(self.known.resolution),
            angles=self.angles.ctypes.data, count=len(self.angles), ranges=self._ranges.ctypes.data,
            clear_to=self.clear_to,
            row_marks=self._row_marks.ctypes.data, col_marks=self._col_marks.ctypes.data,
            cos_angles=self._cos_angles.ctypes.data, sin_angles=self._sin_angles.ctypes.data,
            uniform=int(self._uniform), first_angle=self._first, step=self._step,
            near_from=self._near_from.ctypes.data, near_to=self._near_to.ctypes.data,
            near_cell=self._near_cell.ctypes.data,
        )  # fmt: skip
        self._address = ctypes.addressof(self._arrays)
        library = _kernels()
        self._integrate, self._new_marks_near = library.costmap_integrate_scan, library.costmap_new_marks_near
        self._maybe_near = library.costmap_new_marks_maybe_near

    @property
    def marked(self) -> np.ndarray:
        """The lidar's marks (bool, the grid's shape), read-only: only `integrate` changes them (it
        keeps the per-row and per-column counts of the marks with them)."""
        view = self._marked.view()
        view.flags.writeable = False
        return view

    def integrate(self, x: float, y: float, theta: float, ranges: np.ndarray) -> int:
        """Add one scan taken at pose (x, y [m], theta [rad]); returns the number of changed cells."""
        ranges = ranges[: len(self._ranges)]
        if len(ranges) != len(self._ranges):
            raise ValueError(f"a scan needs {len(self._ranges)} ranges, got {len(ranges)}")
        self._ranges[:] = ranges
        return self._integrate(self._address, float(x), float(y), float(theta))

    def grid(self) -> OccupancyGrid:
        """Known obstacles plus the marks, as a grid (with its `planner.inflation.obstacle_distance`
        when the marks give it cheaper than a transform of the whole grid: `_distance`)."""
        grid = OccupancyGrid(self._known | self._marked, self.known.resolution, self.known.origin)
        distance = self._distance()
        if distance is not None:
            set_obstacle_distance(grid, distance)
        return grid

    def _distance(self) -> np.ndarray | None:
        """The distance (cells) from every cell to the nearest known or marked cell, as
        `planner.inflation.distance_to_nearest` gives it, from the known cells' transform (made
        once per known map) lowered round each mark (native/costmap.c's `costmap_distance`);
        None without known cells, or when the marks' squares would cover the grid four times over
        (a square's cell costs a compare, the transform's several operations a cell)."""
        known = self._shared.transform()
        if known is None:
            return None
        squared, reach = known
        rows, cols = self._marked.shape
        marks = int(self._row_marks.sum())
        if marks * (2 * reach + 1) ** 2 > 4 * rows * cols:
            return None
        out = np.empty((rows, cols))
        _kernels().costmap_distance(self._address, squared.ctypes.data, reach, out.ctypes.data)
        return out

    def inflated(self, radius: float) -> OccupancyGrid:
        """`grid()` inflated by `radius` [m] (the planner's rule)."""
        grid = self.grid()
        return grid.inflate(radius) if radius > 0 else grid

    def snapshot(self) -> np.ndarray:
        """A copy of the marks, for `new_marks_near` later."""
        return self._marked.copy()

    def new_marks_near(self, points: np.ndarray, radius: float, since: np.ndarray) -> bool:
        """True when a cell marked after `since` has its centre within `radius` [m] of a point (N x 2)."""
        if len(points) == 0:
            return False
        since = np.ascontiguousarray(since, dtype=np.bool_)
        if since.shape != self._marked.shape:
            raise ValueError(f"since must have the costmap's shape {self._marked.shape}, got {since.shape}")
        points = np.ascontiguousarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2:
            raise ValueError(f"points must be an (N, 2) array, got shape {points.shape}")
        return bool(
            self._new_marks_near(
                self._address, since.ctypes.data, points.ctypes.data, len(points), float(radius)
            )
        )

    def new_marks_maybe_near(
        self, since: np.ndarray, plan: tuple[int, int, int], first: int, low: float, high: float,
        radius: float,
    ) -> bool:  # fmt: skip
        """False when `new_marks_near` is certainly False for every point interpolated on the plan
        at arc lengths `low` to `high` [m] (np.interp of the plan's points against their arc
        lengths), so those points need not be made: no mark newer than `since` in the window it
        would search round the box of the plan's points that bracket them. `plan`: addresses of
        the points (N x 2) and arc lengths (N), C-contiguous float64, and N; `first`: a point whose
        arc length is at most `low`. `since` is the costmap's shape (C-contiguous bool), unchecked."""
        points, arc, count = plan
        address = since.ctypes.data
        return bool(self._maybe_near(self._address, address, points, arc, count, first, low, high, radius))
