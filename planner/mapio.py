"""Map files in and out: ROS map_server YAML + PGM/PNG, Moving AI `.map`, images, NumPy `.npy`.

Every malformed file raises `PlannerError` with a one-line message that names the file. This module
reads and writes plain arrays (`MapData`); `planner.grid.OccupancyGrid.from_file` and `.to_yaml`
wrap them, so the grid depends on its file formats and not the other way round. Values
quoted from a file are cut to 80 characters. A map has at most `MAX_MAP_CELLS` cells, checked from
the header before any pixel is decoded (a 40000 x 40000 PGM is refused, not allocated).

Image semantics follow ROS map_server (trinary mode): with `negate` false a pixel's occupancy
probability is p = (255 - v) / 255 (dark = occupied); p > occupied_thresh is occupied,
p < free_thresh is free, anything between is *unknown*, which a boolean grid treats as occupied
(a planner must not drive through space nobody has seen). Colour pixels use the mean of R, G, B.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from planner.errors import PlannerError

#: ROS map_server defaults.
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196

_MOVINGAI_PASSABLE = (ord("."), ord("G"))

#: The largest map: 2^26 cells (8192 x 8192, 410 m x 410 m at 5 cm). Planning, inflation and the
#: exact world distance each hold a few arrays of this many float64 or int64 values.
MAX_MAP_CELLS = 1 << 26
_QUOTE = 80  # characters of a value quoted in a message


def _shown(value: object) -> str:
    """repr(value) on one line, cut to 80 characters (a file may hold a 50 MB line)."""
    text = repr(value) if not isinstance(value, str) or len(value) <= _QUOTE else repr(value[:_QUOTE])
    return text if len(text) <= _QUOTE else text[: _QUOTE - 1] + "…"


def _path_text(path: Path) -> str:
    """A path for a message, cut to 200 characters."""
    text = str(path)
    return text if len(text) <= 200 else text[:199] + "…"


def _check_cells(path: Path, rows: int, cols: int) -> None:
    if rows * cols > MAX_MAP_CELLS:
        raise PlannerError(
            f"{path}: map of {rows} x {cols} cells is larger than the limit of {MAX_MAP_CELLS} cells"
        )


def _is_file(path: Path) -> bool:
    """Path.is_file() that reports a name too long or a symbolic link loop as PlannerError."""
    try:
        return path.is_file()
    except (OSError, ValueError) as error:
        reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
        raise PlannerError(f"{_path_text(path)}: cannot open ({reason})") from None


class MapData(NamedTuple):
    """What a map file holds: the arguments of `planner.grid.OccupancyGrid` (checked there).

    occupied: 2-D array [row, col], True / 1 = obstacle, row 0 at the top of the file.
    resolution: cell size [m/cell] as the file (or the caller) gives it.
    origin: (x, y) [m] of the lower-left corner.
    """

    occupied: np.ndarray
    resolution: object
    origin: object


def load_map(path: str | Path, **options) -> MapData:
    """Read a map by its suffix (`.yaml`, `.map`, `.png`/`.pgm`, `.npy`); see OccupancyGrid.from_file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if not _is_file(path):
        raise PlannerError(f"map file not found: {_path_text(path)}")
    if suffix in (".yaml", ".yml"):
        _reject_options(path, options, ())
        return read_ros_yaml(path)
    if suffix == ".map":
        _reject_options(path, options, ())
        return MapData(read_movingai(path), 1.0, (0.0, 0.0))
    if suffix in (".png", ".pgm", ".bmp", ".jpg", ".jpeg", ".tif", ".tiff"):
        _reject_options(path, options, ("resolution", "origin", "negate", "occupied_thresh", "free_thresh"))
        resolution = options.pop("resolution", 1.0)
        origin = options.pop("origin", (0.0, 0.0))
        return MapData(read_image_occupancy(path, **options), resolution, origin)
    if suffix == ".npy":
        _reject_options(path, options, ("resolution", "origin"))
        return MapData(read_npy(path), options.get("resolution", 1.0), options.get("origin", (0.0, 0.0)))
    raise PlannerError(f"{path}: unknown map format {_shown(suffix)} (use .yaml, .map, .png, .pgm or .npy)")


def _reject_options(path: Path, options: dict, allowed: tuple[str, ...]) -> None:
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        what = ", ".join(allowed) if allowed else "none"
        raise PlannerError(
            f"{path}: option(s) {', '.join(unknown)} not valid for this format (valid: {what})"
        )


# -- Moving AI ------------------------------------------------------------------------------------
def read_movingai(path: Path) -> np.ndarray:
    """Occupancy (True = blocked) of a Moving AI `.map`: `.` and `G` are passable, anything else blocked."""
    try:
        lines = Path(path).read_text(encoding="ascii").splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise PlannerError(f"{path}: cannot read Moving AI map ({error})") from None
    header: dict[str, str] = {}
    index = 0
    while index < len(lines) and lines[index].strip().lower() != "map":
        parts = lines[index].split()
        if len(parts) != 2 or parts[0] not in ("type", "height", "width"):
            raise PlannerError(f"{path}:{index + 1}: bad Moving AI header line {_shown(lines[index])}")
        header[parts[0]] = parts[1]
        index += 1
    missing = [key for key in ("type", "height", "width") if key not in header]
    if index == len(lines) or missing:
        raise PlannerError(f"{path}: bad Moving AI header (missing {', '.join(missing) or 'the line `map`'})")
    try:
        if max(len(header["height"]), len(header["width"])) > 18:  # int() of 5000 digits is refused
            raise ValueError
        height, width = int(header["height"]), int(header["width"])
    except ValueError:
        raise PlannerError(f"{path}: height and width must be integers in the header") from None
    if height <= 0 or width <= 0:
        raise PlannerError(f"{path}: height and width must be > 0, got {height} x {width}")
    _check_cells(path, height, width)
    rows = [line.rstrip("\r\n ") for line in lines[index + 1 :]]
    while rows and rows[-1] == "":
        rows.pop()
    if len(rows) != height:
        raise PlannerError(f"{path}: header says height {height} but the map has {len(rows)} rows")
    for number, row in enumerate(rows):
        if len(row) != width:
            raise PlannerError(
                f"{path}:{index + 2 + number}: header says width {width} "
                f"but the row has {len(row)} characters"
            )
    chars = np.frombuffer("".join(rows).encode("ascii"), dtype=np.uint8).reshape(height, width)
    return ~np.isin(chars, _MOVINGAI_PASSABLE)


# -- images -----------------------------------------------------------------------------------------
def _binary_pgm(path: Path) -> np.ndarray | None:
    """Grey levels of an 8-bit binary PGM (P5, maxval 255: what map_server and `write_yaml` write),
    read without PIL (whose import costs more than the read); None for any other file, and for one
    over the cell limit (PIL's reading says what is wrong with those)."""
    try:
        with open(path, "rb") as stream:
            data = stream.read(_PGM_HEADER_BYTES)
            fields: list[bytes] = []
            position = 0
            while len(fields) < 4:  # magic, width, height, maxval; '#' comments run to the line's end
                while position < len(data) and data[position] in b" \t\r\n":
                    position += 1
                if position < len(data) and data[position] == ord("#"):
                    end = data.find(b"\n", position)
                    position = len(data) if end < 0 else end + 1
                    continue
                start = position
                while position < len(data) and data[position] not in b" \t\r\n#":
                    position += 1
                if start == position:
                    return None
                fields.append(data[start:position])
            if fields[0] != b"P5" or not all(field.isdigit() for field in fields[1:]) or fields[3] != b"255":
                return None
            if position >= len(data) or data[position] not in b" \t\r\n":
                return None
            width, height = int(fields[1]), int(fields[2])
            if width == 0 or height == 0 or width * height > MAX_MAP_CELLS:
                return None
            pixels = data[position + 1 :] + stream.read(width * height + 1)
    except OSError:
        return None
    if len(pixels) != width * height:
        return None
    return np.frombuffer(pixels, dtype=np.uint8).reshape(height, width).astype(np.float64)


# Bytes read for a PGM's header (comments included) before the fast reader leaves it to PIL.
_PGM_HEADER_BYTES = 1 << 16


def _image_gray(path: Path) -> np.ndarray:
    """Grey levels 0..255 (float) of an image file; colour = mean of R, G, B; alpha ignored."""
    if path.suffix.lower() == ".pgm":
        gray = _binary_pgm(path)
        if gray is not None:
            return gray
    import warnings

    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            # Our own limit is checked from the header below; PIL's warning would be a second voice.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(path)
    except Image.DecompressionBombError:
        raise PlannerError(f"{path}: image larger than the map limit of {MAX_MAP_CELLS} pixels") from None
    except (OSError, UnidentifiedImageError, ValueError) as error:
        raise PlannerError(f"{path}: unreadable image ({error})") from None
    try:
        with image:
            _check_cells(path, image.height, image.width)
            image.load()
            if image.mode in ("I;16", "I;16B", "I;16L", "I"):
                values = np.asarray(image, dtype=np.float64)
                maximum = 65535.0 if values.max(initial=0) > 255 else 255.0
                return values * (255.0 / maximum)
            array = np.asarray(image.convert("RGB"), dtype=np.float64)
    except (OSError, UnidentifiedImageError, ValueError) as error:
        raise PlannerError(f"{path}: unreadable image ({error})") from None
    return array.mean(axis=2)


def read_image_occupancy(
    path: Path,
    negate: bool = False,
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
    free_thresh: float = DEFAULT_FREE_THRESH,
) -> np.ndarray:
    """Occupancy of an image by map_server's trinary rule (unknown counts as occupied)."""
    occupied_thresh = _probability(path, "occupied_thresh", occupied_thresh)
    free_thresh = _probability(path, "free_thresh", free_thresh)
    if free_thresh > occupied_thresh:
        raise PlannerError(
            f"{path}: free_thresh {free_thresh} must not exceed occupied_thresh {occupied_thresh}"
        )
    gray = _image_gray(path)
    probability = gray / 255.0 if negate else (255.0 - gray) / 255.0
    return ~(probability < free_thresh)


def _probability(path: Path, key: str, value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise PlannerError(f"{path}: {key} must be a number in [0, 1], got {_shown(value)}") from None
    if not 0.0 <= value <= 1.0:
        raise PlannerError(f"{path}: {key} must be in [0, 1], got {value}")
    return value


def read_npy(path: Path) -> np.ndarray:
    """A 2-D bool or 0/1 array from `.npy` (True / 1 = occupied)."""
    try:
        with open(path, "rb") as stream:  # the shape from the header, before any data is read
            version = np.lib.format.read_magic(stream)
            if version == (1, 0):
                shape, _, _ = np.lib.format.read_array_header_1_0(stream)
            else:
                shape, _, _ = np.lib.format.read_array_header_2_0(stream)
        if len(shape) == 2:
            _check_cells(path, *shape)
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as error:
        raise PlannerError(f"{path}: unreadable .npy ({_shown(str(error))})") from None
    if array.ndim != 2:
        raise PlannerError(f"{path}: .npy map must be 2-D, got shape {_shown(array.shape)}")
    if array.dtype != np.bool_ and not (
        np.issubdtype(array.dtype, np.number) and np.isin(array, (0, 1)).all()
    ):
        raise PlannerError(f"{path}: .npy map must hold bool or 0/1 values (1 = occupied)")
    return array.astype(bool)


# -- ROS map_server YAML ------------------------------------------------------------------------------
def _parse_flat_yaml(path: Path) -> dict[str, object]:
    """The flat `key: value` YAML that map_server writes (scalars, quoted strings, [a, b, c] lists)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise PlannerError(f"{path}: cannot read map YAML ({error})") from None
    values: dict[str, object] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(" #", 1)[0].strip() if not raw.lstrip().startswith("#") else ""
        if not line or line == "---":
            continue
        key, colon, value = line.partition(":")
        if not colon or not key.strip():
            raise PlannerError(f"{path}:{number}: expected `key: value`, got {_shown(raw.strip())}")
        value = value.strip()
        if value.startswith("[") and value.endswith("]"):
            values[key.strip()] = [_scalar(item.strip()) for item in value[1:-1].split(",") if item.strip()]
        else:
            values[key.strip()] = _scalar(value)
    return values


def _scalar(text: str) -> object:
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_ros_yaml(path: Path) -> MapData:
    """Load a ROS map_server map (keys image, resolution, origin, negate, occupied/free_thresh)."""
    values = _parse_flat_yaml(path)
    missing = [key for key in ("image", "resolution", "origin") if key not in values]
    if missing:
        raise PlannerError(f"{path}: missing key(s) {', '.join(missing)}")
    mode = values.get("mode", "trinary")
    if mode not in ("trinary", "scale"):
        raise PlannerError(f"{path}: mode {_shown(mode)} not supported (trinary or scale)")
    origin = values["origin"]
    if not isinstance(origin, list) or len(origin) not in (2, 3) or not all(_is_number(v) for v in origin):
        raise PlannerError(f"{path}: origin must be [x, y, yaw], got {_shown(origin)}")
    if len(origin) == 3 and abs(float(origin[2])) > 1e-9:
        raise PlannerError(f"{path}: origin yaw {origin[2]} not supported (maps must be axis-aligned)")
    resolution = values["resolution"]
    if not _is_number(resolution) or not float(resolution) > 0.0:
        raise PlannerError(f"{path}: resolution must be > 0 [m/cell], got {_shown(resolution)}")
    negate = values.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise PlannerError(f"{path}: negate must be 0 or 1, got {_shown(negate)}")
    image_path = Path(str(values["image"]))
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    if not _is_file(image_path):
        raise PlannerError(f"{path}: image file not found: {_path_text(image_path)}")
    occupied = read_image_occupancy(
        image_path,
        negate=bool(negate),
        occupied_thresh=values.get("occupied_thresh", DEFAULT_OCCUPIED_THRESH),
        free_thresh=values.get("free_thresh", DEFAULT_FREE_THRESH),
    )
    return MapData(occupied, float(resolution), (float(origin[0]), float(origin[1])))


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def write_yaml(
    path: str | Path, occupied: np.ndarray, resolution: float, origin: tuple[float, float]
) -> Path:
    """Write a map as map_server YAML + binary PGM (occupied 0 = black, free 254); returns the YAML path.

    occupied: bool [row, col], row 0 at the top; resolution [m/cell]; origin (x, y) [m] of the
    lower-left corner."""
    path = Path(path)
    if path.suffix.lower() not in (".yaml", ".yml"):
        path = path.with_suffix(".yaml")
    image_path = path.with_suffix(".pgm")
    rows, cols = occupied.shape
    pixels = np.where(occupied, 0, 254).astype(np.uint8)
    try:
        with open(image_path, "wb") as stream:
            stream.write(f"P5\n{cols} {rows}\n255\n".encode("ascii"))
            stream.write(pixels.tobytes())
        path.write_text(
            f"image: {image_path.name}\n"
            f"resolution: {resolution!r}\n"
            f"origin: [{origin[0]!r}, {origin[1]!r}, 0.0]\n"
            "negate: 0\n"
            f"occupied_thresh: {DEFAULT_OCCUPIED_THRESH}\n"
            f"free_thresh: {DEFAULT_FREE_THRESH}\n",
            encoding="utf-8",
        )
    except OSError as error:
        raise PlannerError(f"{path}: cannot write map ({error})") from None
    return path
