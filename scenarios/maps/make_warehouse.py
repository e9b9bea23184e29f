"""Generate the shipped warehouse map (`warehouse.pgm` + `warehouse.yaml`, ROS map_server format).

A 100 m x 60 m warehouse at 0.5 m/cell, comparable to the one of the thesis's chapter 3: four rows
of racks (shelves) running along x, each cut in three segments by two vertical cross corridors, with
open corridors along all four walls. The layout is sized for both thesis vehicles (see README.md):
rack aisles 8 m wide, cross corridors at least 9.5 m wide.

Deterministic: `python3 scenarios/maps/make_warehouse.py [OUT_DIR]` rewrites the two files, and the
test suite checks that the committed PGM equals this script's output.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

RESOLUTION = 0.5  # m/cell
WIDTH = 100.0  # m (x)
HEIGHT = 60.0  # m (y)

# Racks run along x: four rows of back-to-back double racks, 3 m deep, AISLE_WIDTH of free floor
# between neighbouring rows. Each row is cut into segments by the vertical cross corridors.
RACK_ROWS_Y = ((12.0, 15.0), (23.0, 26.0), (34.0, 37.0), (45.0, 48.0))  # m, (y_bottom, y_top)
RACK_SEGMENTS_X = ((10.0, 37.0), (47.0, 74.0), (84.0, 90.0))  # m, (x_left, x_right)
# Cross corridors (free): x 0.5-10 (left), 37-47, 74-84, 90-99.5 (right); y 0.5-12 (bottom), 48-59.5 (top).
AISLE_WIDTH = 8.0  # m, for the README and tests: 15-23, 26-34, 37-45
CROSS_CORRIDOR_WIDTH = 9.5  # m, the narrowest cross corridor (left, right)

FREE_VALUE = 254  # what ROS map_saver writes for free cells
OCCUPIED_VALUE = 0


def _fill_rectangle(occupied: np.ndarray, x_range: tuple[float, float], y_range: tuple[float, float]) -> None:
    """Mark every cell whose centre lies inside [x0, x1] x [y0, y1] (metres, map frame) occupied."""
    rows, cols = occupied.shape
    x_centres = (np.arange(cols) + 0.5) * RESOLUTION
    y_centres = (rows - np.arange(rows) - 0.5) * RESOLUTION  # row 0 is the top of the image
    in_x = (x_centres >= x_range[0]) & (x_centres <= x_range[1])
    in_y = (y_centres >= y_range[0]) & (y_centres <= y_range[1])
    occupied[np.ix_(in_y, in_x)] = True


def build_warehouse() -> np.ndarray:
    """Return the warehouse occupancy as a bool array [row, col], row 0 at the top (y = 60 m)."""
    rows, cols = round(HEIGHT / RESOLUTION), round(WIDTH / RESOLUTION)
    occupied = np.zeros((rows, cols), dtype=bool)
    # Outer wall, one cell thick.
    occupied[0, :] = occupied[-1, :] = True
    occupied[:, 0] = occupied[:, -1] = True
    # The half-cell inset keeps a rack of D metres exactly D / RESOLUTION cells wide.
    inset = RESOLUTION / 2
    for y_bottom, y_top in RACK_ROWS_Y:
        for x_left, x_right in RACK_SEGMENTS_X:
            _fill_rectangle(occupied, (x_left + inset, x_right - inset), (y_bottom + inset, y_top - inset))
    return occupied


def pgm_bytes(occupied: np.ndarray) -> bytes:
    """Binary PGM (P5) image of the occupancy: 0 = occupied (black), 254 = free, as ROS map_saver."""
    pixels = np.where(occupied, OCCUPIED_VALUE, FREE_VALUE).astype(np.uint8)
    header = f"P5\n# navcosim warehouse, {RESOLUTION} m/cell\n{occupied.shape[1]} {occupied.shape[0]}\n255\n"
    return header.encode("ascii") + pixels.tobytes()


def yaml_text(image_name: str) -> str:
    """ROS map_server YAML describing the PGM (trinary mode, map_saver's thresholds)."""
    return (
        f"image: {image_name}\n"
        "mode: trinary\n"
        f"resolution: {RESOLUTION}\n"
        "origin: [0.0, 0.0, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )


def main(out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "warehouse.pgm").write_bytes(pgm_bytes(build_warehouse()))
    (out_dir / "warehouse.yaml").write_text(yaml_text("warehouse.pgm"))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
