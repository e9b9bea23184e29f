"""Map loaders and writer: ROS YAML + PGM, negate and thresholds, PNG, .npy, Moving AI, bad files."""

import numpy as np
import pytest
from PIL import Image

from planner import OccupancyGrid, PlannerError


def _random_grid(seed=1, shape=(13, 17)):
    return np.random.default_rng(seed).random(shape) < 0.3


def test_yaml_pgm_round_trip(tmp_path):
    grid = OccupancyGrid(_random_grid(), resolution=0.05, origin=(-1.5, 2.25))
    yaml_path = grid.to_yaml(tmp_path / "map.yaml")
    assert (tmp_path / "map.pgm").read_bytes().startswith(b"P5\n17 13\n255\n")
    loaded = OccupancyGrid.from_file(yaml_path)
    assert np.array_equal(loaded.occupied, grid.occupied)
    assert loaded.resolution == 0.05 and loaded.origin == (-1.5, 2.25)


def _write_yaml(tmp_path, image_name, extra=""):
    path = tmp_path / "m.yaml"
    path.write_text(f"image: {image_name}\nresolution: 0.1\norigin: [1.0, 2.0, 0.0]\n{extra}")
    return path


def test_thresholds_and_negate(tmp_path):
    # Grey levels chosen around map_server's defaults: p = (255 - v) / 255.
    levels = np.array([[0, 100, 160, 210, 254]], dtype=np.uint8)  # p = 1, .61, .37, .18, .004
    Image.fromarray(levels).save(tmp_path / "m.png")
    default = OccupancyGrid.from_file(_write_yaml(tmp_path, "m.png"))
    # occupied when p > 0.65, free when p < 0.196, unknown (counted occupied) between.
    assert default.occupied.tolist() == [[True, True, True, False, False]]
    loose = OccupancyGrid.from_file(
        _write_yaml(tmp_path, "m.png", "occupied_thresh: 0.5\nfree_thresh: 0.4\n")
    )
    assert loose.occupied.tolist() == [[True, True, False, False, False]]
    negated = OccupancyGrid.from_file(_write_yaml(tmp_path, "m.png", "negate: 1\n"))
    # With negate p = v / 255: 0 -> free, 254 -> occupied.
    assert negated.occupied.tolist() == [[False, True, True, True, True]]
    assert default.origin == (1.0, 2.0) and default.resolution == 0.1


def test_png_with_keywords(tmp_path):
    occupied = _random_grid(2)
    Image.fromarray(np.where(occupied, 0, 255).astype(np.uint8)).convert("RGB").save(tmp_path / "m.png")
    grid = OccupancyGrid.from_file(tmp_path / "m.png", resolution=0.2, origin=(3, 4))
    assert np.array_equal(grid.occupied, occupied)
    assert grid.resolution == 0.2 and grid.origin == (3.0, 4.0)


def test_npy(tmp_path):
    occupied = _random_grid(3)
    np.save(tmp_path / "b.npy", occupied)
    np.save(tmp_path / "i.npy", occupied.astype(np.int8))
    for name in ("b.npy", "i.npy"):
        assert np.array_equal(OccupancyGrid.from_file(tmp_path / name).occupied, occupied)
    np.save(tmp_path / "bad.npy", np.full((3, 3), 7))
    with pytest.raises(PlannerError, match="0/1"):
        OccupancyGrid.from_file(tmp_path / "bad.npy")
    np.save(tmp_path / "flat.npy", np.zeros(5))
    with pytest.raises(PlannerError, match="2-D"):
        OccupancyGrid.from_file(tmp_path / "flat.npy")


def test_movingai_map(tmp_path):
    path = tmp_path / "t.map"
    path.write_text("type octile\nheight 2\nwidth 3\nmap\n.@G\nTS.\n")
    grid = OccupancyGrid.from_file(path)
    assert grid.occupied.tolist() == [[False, True, False], [True, True, False]]
    assert grid.resolution == 1.0 and grid.origin == (0.0, 0.0)


@pytest.mark.parametrize(
    "text, match",
    [
        ("type octile\nheigth 2\nwidth 3\nmap\n...\n...\n", "header"),
        ("type octile\nheight 2\nwidth 3\n...\n", "header"),
        ("type octile\nheight 3\nwidth 3\nmap\n...\n...\n", "height 3 but the map has 2 rows"),
        ("type octile\nheight 2\nwidth 3\nmap\n...\n....\n", "width 3 but the row has 4"),
        ("type octile\nheight x\nwidth 3\nmap\n...\n", "integers"),
    ],
)
def test_bad_movingai(tmp_path, text, match):
    path = tmp_path / "bad.map"
    path.write_text(text)
    with pytest.raises(PlannerError, match=match) as error:
        OccupancyGrid.from_file(path)
    assert "\n" not in str(error.value) and "bad.map" in str(error.value)


def test_bad_yaml_and_images(tmp_path):
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    with pytest.raises(PlannerError, match="unreadable image"):
        OccupancyGrid.from_file(tmp_path / "junk.png")
    with pytest.raises(PlannerError, match="unreadable image"):
        OccupancyGrid.from_file(_write_yaml(tmp_path, "junk.png"))
    (tmp_path / "short.pgm").write_bytes(b"P5\n10 10\n255\n" + bytes(20))  # 20 of 100 pixels
    with pytest.raises(PlannerError, match="unreadable image"):
        OccupancyGrid.from_file(tmp_path / "short.pgm")
    path = tmp_path / "missing.yaml"
    path.write_text("image: m.png\norigin: [0, 0, 0]\n")
    with pytest.raises(PlannerError, match="missing key.*resolution"):
        OccupancyGrid.from_file(path)
    Image.fromarray(np.zeros((2, 2), np.uint8)).save(tmp_path / "ok.png")
    for extra, match in (("resolution: 0\n", "resolution must be > 0"), ("resolution: -2\n", "resolution")):
        path = tmp_path / "r.yaml"
        path.write_text(f"image: ok.png\norigin: [0, 0, 0]\n{extra}")
        with pytest.raises(PlannerError, match=match):
            OccupancyGrid.from_file(path)
    with pytest.raises(PlannerError, match="image file not found"):
        OccupancyGrid.from_file(_write_yaml(tmp_path, "nothere.pgm"))
    with pytest.raises(PlannerError, match="not found"):
        OccupancyGrid.from_file(tmp_path / "absent.map")
    with pytest.raises(PlannerError, match="unknown map format"):
        OccupancyGrid.from_file(_write_yaml(tmp_path, "ok.png").rename(tmp_path / "m.txt"))
    with pytest.raises(PlannerError, match="resolution must be > 0"):
        OccupancyGrid.from_file(tmp_path / "ok.png", resolution=0)


@pytest.mark.parametrize(
    "header",
    [
        "P5\n{w} {h}\n255\n",
        "P5 # a comment after the magic\n# a whole comment line\n{w}\t{h} 255\r",
        "P5\n#x\n{w}\n{h}\n#y\n255 ",
    ],
)
@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (120, 200), (7, 1)])
def test_binary_pgm_reads_as_pillow_does(tmp_path, header, shape):
    """8-bit binary PGMs are read without PIL; the grey levels are PIL's, header comments and all."""
    from PIL import Image

    from planner.mapio import _image_gray

    rows, cols = shape
    pixels = np.random.default_rng(rows * cols).integers(0, 256, shape, dtype=np.uint8)
    path = tmp_path / "map.pgm"
    path.write_bytes(header.format(w=cols, h=rows).encode("ascii") + pixels.tobytes())
    expected = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64).mean(axis=2)
    gray = _image_gray(path)
    assert gray.shape == expected.shape and np.array_equal(gray, expected)


def test_pgm_files_the_fast_reader_does_not_take_still_read(tmp_path):
    """A 16-bit PGM, an ASCII PGM and a PGM with missing pixels go to PIL as before."""
    from planner.mapio import _binary_pgm, _image_gray

    wide = tmp_path / "wide.pgm"
    wide.write_bytes(b"P5\n2 1\n65535\n" + np.array([0, 65535], dtype=">u2").tobytes())
    ascii_ = tmp_path / "ascii.pgm"
    ascii_.write_bytes(b"P2\n2 1\n255\n0 255\n")
    for path in (wide, ascii_):
        assert _binary_pgm(path) is None
        assert np.array_equal(_image_gray(path), [[0.0, 255.0]])
    short = tmp_path / "short.pgm"
    short.write_bytes(b"P5\n4 4\n255\n" + bytes(3))
    assert _binary_pgm(short) is None
    with pytest.raises(PlannerError, match="unreadable image"):
        _image_gray(short)
