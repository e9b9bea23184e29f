"""Generate a warehouse occupancy map (`NAME.pgm` + `NAME.yaml`, ROS map_server format).

Without layout options it writes the shipped map, `warehouse.pgm` + `warehouse.yaml`: a 100 m x
60 m warehouse at 0.5 m/cell, comparable to the one of the thesis's chapter 3: four rows of racks
(shelves) running along x, each cut in three segments by two vertical cross corridors, with open
corridors along all four walls. That layout is sized for both thesis vehicles (see README.md): rack
aisles 8 m wide, cross corridors at least 9.5 m wide. The test suite checks that the committed PGM
equals this script's output.

With layout options it lays out a regular warehouse of any size (`layout_from_options`):

    python3 scenarios/maps/make_warehouse.py OUT_DIR --name warehouse_large --size 160 100 \\
        --rack-rows 6 --rack-columns 4 --aisle-width 8 --cross-aisle-width 10 --station 16 2

`--rack-rows` rows of racks (`--rack-depth` m deep) run along x, `--aisle-width` m of free floor
between neighbouring rows; each row is cut into `--rack-columns` equal segments by vertical cross
corridors `--cross-aisle-width` m wide (one also along each side wall). The rack rows stand
centred in y between a bottom corridor (`--bottom-corridor` m, default the space left split equally)
and the top one. `--station WIDTH DEPTH` puts a packing station (a counter, occupied) of that size
in the middle of the bottom corridor, against the wall; robots dwell in front of it. The script
prints the layout (racks, aisle centre lines, the station's front) so scenarios can place robots.

Deterministic: the same arguments write the same bytes (no clock, no randomness).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import NamedTuple

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
STATION_FRONT = 3.5  # [m] from the station's counter to where a robot stops in front of it


class Layout(NamedTuple):  # not a dataclass: tests load this file without registering a module
    """A warehouse in metres (map frame, origin at the lower-left corner): its size, cell size,
    racks as rectangles (x_left, x_right, y_bottom, y_top) and the packing station's rectangle
    (or None). The outer wall is one cell thick."""

    width: float
    height: float
    resolution: float
    racks: tuple[tuple[float, float, float, float], ...]
    station: tuple[float, float, float, float] | None = None
    aisles_y: tuple[float, ...] = ()  # centre lines of the aisles between rack rows [m]
    cross_aisles_x: tuple[float, ...] = ()  # centre lines of the vertical cross corridors [m]

    @property
    def station_front(self) -> tuple[float, float] | None:
        """[m] the point 3.5 m in front of the station's middle (where a robot dwells), or None."""
        if self.station is None:
            return None
        x_left, x_right, _, y_top = self.station
        return ((x_left + x_right) / 2, y_top + STATION_FRONT)


def shipped_layout() -> Layout:
    """The layout of the shipped `warehouse.pgm` (module docstring)."""
    racks = tuple((x0, x1, y0, y1) for y0, y1 in RACK_ROWS_Y for x0, x1 in RACK_SEGMENTS_X)
    aisles = tuple((a[1] + b[0]) / 2 for a, b in zip(RACK_ROWS_Y, RACK_ROWS_Y[1:], strict=False))
    return Layout(WIDTH, HEIGHT, RESOLUTION, racks, None, aisles, (5.25, 42.0, 79.0, 94.75))


def regular_layout(
    width: float,
    height: float,
    rack_rows: int,
    rack_columns: int,
    aisle_width: float = 8.0,
    cross_aisle_width: float = 10.0,
    rack_depth: float = 3.0,
    bottom_corridor: float | None = None,
    station: tuple[float, float] | None = None,
    resolution: float = RESOLUTION,
) -> Layout:
    """A regular warehouse (module docstring); ValueError when the racks do not fit."""
    if resolution <= 0 or width <= 0 or height <= 0:
        raise ValueError("size and resolution must be > 0")
    if rack_rows < 1 or rack_columns < 1:
        raise ValueError("at least one rack row and one rack column")
    if min(aisle_width, cross_aisle_width, rack_depth) <= 0:
        raise ValueError("aisle widths and rack depth must be > 0")
    inner_width, inner_height = width - 2 * resolution, height - 2 * resolution  # inside the wall
    segment = (inner_width - (rack_columns + 1) * cross_aisle_width) / rack_columns
    if segment < resolution:
        raise ValueError(
            f"{rack_columns} rack columns with {cross_aisle_width:g} m cross aisles do not fit "
            f"in {width:g} m (segments would be {segment:g} m long)"
        )
    block = rack_rows * rack_depth + (rack_rows - 1) * aisle_width
    spare = inner_height - block
    bottom = spare / 2 if bottom_corridor is None else bottom_corridor
    if bottom <= 0 or spare - bottom <= 0:
        raise ValueError(
            f"{rack_rows} rack rows ({block:g} m with the aisles) leave no corridor in {height:g} m "
            f"(bottom corridor {bottom:g} m)"
        )

    def snap(value: float) -> float:  # rack edges on cell boundaries: a rack of D m is D / res cells
        return round(value / resolution) * resolution

    racks, rows_y = [], []
    for row in range(rack_rows):
        y0 = snap(resolution + bottom + row * (rack_depth + aisle_width))
        y1 = snap(y0 + rack_depth)
        rows_y.append((y0, y1))
        for column in range(rack_columns):
            x0 = snap(resolution + cross_aisle_width + column * (segment + cross_aisle_width))
            racks.append((x0, snap(x0 + segment), y0, y1))
    aisles = tuple((a[1] + b[0]) / 2 for a, b in zip(rows_y, rows_y[1:], strict=False))
    crosses = [resolution + cross_aisle_width / 2]
    crosses += [(racks[c][1] + racks[c + 1][0]) / 2 for c in range(rack_columns - 1)]
    crosses.append(width - resolution - cross_aisle_width / 2)
    counter = None
    if station is not None:
        station_width, station_depth = station
        room = bottom - 2 * STATION_FRONT  # the station's depth and a robot's stop in front of it
        if not 0 < station_width < inner_width or not 0 < station_depth <= room:
            raise ValueError(
                f"the station {station_width:g} m x {station_depth:g} m must fit in the bottom corridor "
                f"({bottom:g} m high) with {2 * STATION_FRONT:g} m in front of it"
            )
        x0 = snap(width / 2 - station_width / 2)
        counter = (x0, snap(x0 + station_width), resolution, snap(resolution + station_depth))
    return Layout(width, height, resolution, tuple(racks), counter, aisles, tuple(crosses))


def _fill_rectangle(
    occupied: np.ndarray, x_range: tuple[float, float], y_range: tuple[float, float], resolution: float
) -> None:
    """Mark every cell whose centre lies inside [x0, x1] x [y0, y1] (metres, map frame) occupied."""
    rows, cols = occupied.shape
    x_centres = (np.arange(cols) + 0.5) * resolution
    y_centres = (rows - np.arange(rows) - 0.5) * resolution  # row 0 is the top of the image
    in_x = (x_centres >= x_range[0]) & (x_centres <= x_range[1])
    in_y = (y_centres >= y_range[0]) & (y_centres <= y_range[1])
    occupied[np.ix_(in_y, in_x)] = True


def build_warehouse(layout: Layout | None = None) -> np.ndarray:
    """Return the occupancy of `layout` (default: the shipped one) as a bool array [row, col],
    row 0 at the top."""
    layout = shipped_layout() if layout is None else layout
    resolution = layout.resolution
    rows, cols = round(layout.height / resolution), round(layout.width / resolution)
    occupied = np.zeros((rows, cols), dtype=bool)
    # Outer wall, one cell thick.
    occupied[0, :] = occupied[-1, :] = True
    occupied[:, 0] = occupied[:, -1] = True
    # The half-cell inset keeps a rack of D metres exactly D / resolution cells wide.
    inset = resolution / 2
    boxes = list(layout.racks) + ([layout.station] if layout.station is not None else [])
    for x_left, x_right, y_bottom, y_top in boxes:
        _fill_rectangle(
            occupied, (x_left + inset, x_right - inset), (y_bottom + inset, y_top - inset), resolution
        )
    return occupied


def pgm_bytes(occupied: np.ndarray, resolution: float = RESOLUTION) -> bytes:
    """Binary PGM (P5) image of the occupancy: 0 = occupied (black), 254 = free, as ROS map_saver."""
    pixels = np.where(occupied, OCCUPIED_VALUE, FREE_VALUE).astype(np.uint8)
    header = f"P5\n# navcosim warehouse, {resolution} m/cell\n{occupied.shape[1]} {occupied.shape[0]}\n255\n"
    return header.encode("ascii") + pixels.tobytes()


def yaml_text(image_name: str, resolution: float = RESOLUTION) -> str:
    """ROS map_server YAML describing the PGM (trinary mode, map_saver's thresholds)."""
    return (
        f"image: {image_name}\n"
        "mode: trinary\n"
        f"resolution: {resolution}\n"
        "origin: [0.0, 0.0, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )


def main(out_dir: Path, layout: Layout | None = None, name: str = "warehouse") -> None:
    layout = shipped_layout() if layout is None else layout
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / f"{name}.pgm").write_bytes(pgm_bytes(build_warehouse(layout), layout.resolution))
    (out_dir / f"{name}.yaml").write_text(yaml_text(f"{name}.pgm", layout.resolution))


def describe(layout: Layout) -> str:
    """The layout in lines a scenario author reads (metres)."""
    rows = sorted({(y0, y1) for _, _, y0, y1 in layout.racks})
    columns = sorted({(x0, x1) for x0, x1, _, _ in layout.racks})
    lines = [
        f"size {layout.width:g} m x {layout.height:g} m at {layout.resolution:g} m/cell "
        f"({round(layout.width / layout.resolution)} x {round(layout.height / layout.resolution)} cells)",
        "rack rows y: " + ", ".join(f"{a:g}-{b:g}" for a, b in rows),
        "rack segments x: " + ", ".join(f"{a:g}-{b:g}" for a, b in columns),
        "aisle centre lines y: " + ", ".join(f"{y:g}" for y in layout.aisles_y),
        "cross corridor centre lines x: " + ", ".join(f"{x:g}" for x in layout.cross_aisles_x),
    ]
    if layout.station is not None:
        x0, x1, y0, y1 = layout.station
        front = layout.station_front
        lines.append(
            f"packing station x {x0:g}-{x1:g}, y {y0:g}-{y1:g}; its front ({front[0]:g}, {front[1]:g})"
        )
    return "\n".join(lines)


LAYOUT_OPTIONS = ("size", "rack_rows", "rack_columns", "aisle_width", "cross_aisle_width", "rack_depth",
                  "bottom_corridor", "station", "resolution")  # fmt: skip


def layout_from_options(options: argparse.Namespace) -> Layout:
    """The layout the command line asks for: the shipped one without layout options."""
    if all(getattr(options, key) is None for key in LAYOUT_OPTIONS):
        return shipped_layout()
    width, height = options.size if options.size is not None else (WIDTH, HEIGHT)
    return regular_layout(
        width,
        height,
        options.rack_rows if options.rack_rows is not None else 4,
        options.rack_columns if options.rack_columns is not None else 3,
        aisle_width=options.aisle_width if options.aisle_width is not None else 8.0,
        cross_aisle_width=options.cross_aisle_width if options.cross_aisle_width is not None else 10.0,
        rack_depth=options.rack_depth if options.rack_depth is not None else 3.0,
        bottom_corridor=options.bottom_corridor,
        station=tuple(options.station) if options.station is not None else None,
        resolution=options.resolution if options.resolution is not None else RESOLUTION,
    )


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", type=Path, default=Path(__file__).resolve().parent)
    parser.add_argument("--name", default="warehouse", help="file names NAME.pgm, NAME.yaml")
    parser.add_argument("--size", nargs=2, type=float, metavar=("WIDTH", "HEIGHT"), help="[m]")
    parser.add_argument("--resolution", type=float, help="[m/cell] (0.5)")
    parser.add_argument("--rack-rows", type=int, help="rows of racks along x (4)")
    parser.add_argument("--rack-columns", type=int, help="rack segments per row (3)")
    parser.add_argument("--aisle-width", type=float, help="[m] between rack rows (8)")
    parser.add_argument("--cross-aisle-width", type=float, help="[m] vertical cross corridors (10)")
    parser.add_argument("--rack-depth", type=float, help="[m] (3)")
    parser.add_argument("--bottom-corridor", type=float, help="[m] below the first rack row (the rest split)")
    parser.add_argument(
        "--station", nargs=2, type=float, metavar=("WIDTH", "DEPTH"), help="packing station [m]"
    )
    return parser.parse_args(argv)


if __name__ == "__main__":
    arguments = parse()
    try:
        chosen = layout_from_options(arguments)
    except ValueError as error:
        sys.exit(f"make_warehouse: {error}")
    main(arguments.out_dir, chosen, arguments.name)
    print(describe(chosen))
