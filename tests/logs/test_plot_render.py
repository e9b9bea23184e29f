"""How `cosim.logs.plot.draw` renders: the shortcuts it takes past matplotlib's axes (ticks only
inside the view, the panels' grid lines and tick marks drawn as two lines per axis) must give
the pixels matplotlib's own axes give, and the PNG must show every part of the picture in its
colour. matplotlib, drawing the same figure the plain way, is the truth."""

from __future__ import annotations

import gc

import numpy as np
import pytest
from PIL import Image

from cosim.logs import plot, plot_data


def _data(panels: int = 5) -> plot_data.PlotData:
    """A small run's picture: a walled map with an inflated zone, an obstacle, a plan, a driven
    trajectory partly under VFH, start and goal, and `panels` panels of signals (one with two)."""
    occupied = np.zeros((40, 60), dtype=bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    occupied[15:25, 28:32] = True
    zone = np.zeros_like(occupied)
    zone[1:4, 1:-1] = zone[-4:-1, 1:-1] = zone[12:28, 25:35] = True
    grid = type("Grid", (), {"shape": occupied.shape, "occupied": occupied})
    inflated = type("Grid", (), {"shape": occupied.shape, "occupied": occupied | zone})
    t = np.linspace(0.0, 30.0, 3001)
    x, y = 5.0 + 0.8 * t, 10.0 + 6.0 * np.sin(t / 9.0)
    trajectory = np.column_stack((x, y))
    mode = np.where((t > 8.0) & (t < 12.5), plot_data.MODE_AVOID, 0)
    values = [0.8 + 0.1 * np.sin(t), 0.3 * np.cos(t / 3.0), np.sin(t / 4.0), 2.0 + np.cos(t / 2.0), 30.0 - t]
    series = [
        plot_data.Series(f"signal {index}", "m", t, value, f"panel {index}")
        for index, value in enumerate(values[:panels])
    ]
    series.insert(1, plot_data.Series("second signal of panel 0", "m", t, 0.5 * values[0], "panel 0"))
    data = plot_data.PlotData(
        "synthetic: goal reached at t = 30.0 s\nsynthetic.mcap",
        image=plot.map_image(grid, inflated),
        extent=(0.0, 30.0, 0.0, 20.0),
        has_zone=True,
        obstacles=[np.array([[20.0, 4.0], [21.0, 4.0], [21.0, 5.0], [20.0, 5.0]])],
        plans=[(0.0, np.array([[5.0, 10.0], [12.0, 14.0], [20.0, 15.0], [29.0, 12.0]]))],
        reverse=[np.zeros(3, dtype=bool)],
        trajectory=trajectory,
        mode_points={plot_data.MODE_AVOID: trajectory[mode == plot_data.MODE_AVOID]},
        start=(5.0, 10.0, 0.5),
        goal=(29.0, 12.0),
        tolerance=0.6,
        limits=(-0.9, 30.9, -0.9, 20.9),
        series=series,
        modes=(t, mode),
    )
    return data


def _pixels(path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"))


@pytest.mark.parametrize("panels", [5, 2, 1])
def test_the_shortcuts_draw_the_pixels_of_matplotlibs_own_axes(panels, tmp_path, monkeypatch):
    drawn = _pixels(plot.draw(_data(panels), tmp_path / "drawn.png"))

    # matplotlib's way: its default locator, its axes drawing their grid and tick marks, the
    # upper panels' x axes with their labels hidden
    def plain_ticks(panel_axes):
        for axes in panel_axes:
            axes.grid(alpha=plot.GRID_ALPHA)
        for axes in panel_axes[:-1]:
            axes.tick_params(labelbottom=False)

    monkeypatch.setattr(plot, "_ticks_in_view", lambda axes: None)
    monkeypatch.setattr(plot, "_panel_ticks", plain_ticks)
    plain = _pixels(plot.draw(_data(panels), tmp_path / "plain.png"))
    assert drawn.shape == plain.shape
    assert np.array_equal(drawn, plain)


@pytest.mark.parametrize("panels", [5, 1])
def test_axis_labels_placed_from_the_tick_labels_measured_once_are_where_matplotlib_puts_them(
    panels, tmp_path, monkeypatch
):
    """An axis places its label from the boxes its draw measured (`_label_boxes_once`), not
    measured again: the same pixels as matplotlib's own steps (every axis label of the map and
    the panels; the panels' y labels sit left of tick labels of different widths)."""
    drawn = _pixels(plot.draw(_data(panels), tmp_path / "drawn.png"))
    monkeypatch.setattr(plot, "_label_boxes_once", lambda axis: None)
    plain = _pixels(plot.draw(_data(panels), tmp_path / "plain.png"))
    assert np.array_equal(drawn, plain)


def _has(pixels: np.ndarray, colour: str, at_least: int = 4) -> bool:
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int(np.all(pixels == rgb, axis=2).sum()) >= at_least


def test_the_png_shows_every_part_in_its_colour(tmp_path):
    path = plot.draw(_data(), tmp_path / "run.png")
    with Image.open(path) as image:
        assert image.format == "PNG" and image.mode == "RGB"
        # 15 x 9.5 inches (five panels of 1.9 in) at the plot's dpi, recorded in the file
        assert image.size == (15 * plot.DPI, round(9.5 * plot.DPI))
        assert np.allclose(image.info["dpi"], (plot.DPI, plot.DPI), atol=0.01)
    pixels = _pixels(path)
    for colour in (
        "#1d4ed8",
        "#2a9d8f",
        "#e76f51",
        plot_data.MODE_COLORS[plot_data.MODE_AVOID],
        "#1f77b4",
        "#ff7f0e",
    ):
        assert _has(pixels, colour), f"no {colour} pixels"  # plan, start, goal, VFH points, signals
    assert _has(pixels, "#262626", 100)  # occupied cells, 0.15 grey
    zone = 255 * (plot_data.ZONE_RGBA[3] * np.array(plot_data.ZONE_RGBA[:3]) + 1.0 - plot_data.ZONE_RGBA[3])
    assert int(np.all(np.abs(pixels - zone) <= 1, axis=2).sum()) >= 100  # the inflated zone
    # the shading's entry: its box in the shading's colour at alpha 0.3 over white, opaque
    face = np.array([int(plot_data.MODE_COLORS[plot_data.MODE_AVOID][i : i + 2], 16) for i in (1, 3, 5)])
    assert int(np.all(np.abs(pixels - (0.3 * face + 0.7 * 255)) <= 1, axis=2).sum()) >= 100


@pytest.mark.parametrize("enabled", [True, False])
def test_drawing_leaves_the_garbage_collector_as_it_found_it(enabled, tmp_path):
    was = gc.isenabled()
    try:
        (gc.enable if enabled else gc.disable)()
        plot.draw(_data(1), tmp_path / "one.png")
        assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()


@pytest.mark.parametrize("shape", [(1, 1), (7, 13), (64, 300)])
def test_write_png_is_read_back_by_pillow_as_written(shape, tmp_path):
    pixels = np.random.default_rng(sum(shape)).integers(0, 256, (*shape, 3), dtype=np.uint8)
    path = tmp_path / "random.png"
    plot.write_png(path, pixels[:, ::-1], 72.0)  # a strided view, as the canvas' RGB is
    with Image.open(path) as image:
        image.verify()
    with Image.open(path) as image:
        assert image.mode == "RGB" and image.size == (shape[1], shape[0])
        assert np.allclose(image.info["dpi"], (72.0, 72.0), atol=0.01)
        assert np.array_equal(np.asarray(image), pixels[:, ::-1])


@pytest.mark.parametrize("shape", [(1, 1), (2, 5), (7, 13), (301, 64)])
@pytest.mark.parametrize("made_before", [False, True])
def test_write_png_stream_decompresses_with_its_checksum(shape, made_before, tmp_path):
    """zlib itself (which checks the stream's Adler-32, put together from the two halves') reads
    the PNG's image data back as the rows: a filter byte 0 and the RGB bytes of each row."""
    import struct
    import zlib

    pixels = np.random.default_rng(shape[0]).integers(0, 256, (*shape, 4), dtype=np.uint8)
    path = tmp_path / "random.png"
    plot.write_png(path, pixels, 72.0, plot.png_rows(pixels) if made_before else None)
    data, chunks, at = path.read_bytes(), {}, 8
    while at < len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        chunks[data[at + 4 : at + 8]] = data[at + 8 : at + 8 + length]
        at += 12 + length
    rows = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), dtype=np.uint8).reshape(shape[0], -1)
    assert np.all(rows[:, 0] == 0)
    assert np.array_equal(rows[:, 1:].reshape(*shape, 3), pixels[:, :, :3])


def test_a_png_whose_second_half_was_compressed_elsewhere_is_the_same_file(tmp_path):
    """`write_png` given its rows' second half compressed (`deflate_half`, as the panel helper
    sends it), or a function that gives None (the helper failed: compressed here): the same bytes
    as compressed here in two threads."""
    pixels = np.random.default_rng(3).integers(0, 256, (101, 37, 4), dtype=np.uint8)
    pixels[20:70] = 255  # (flat rows, as a plot mostly is)
    rows = plot.png_rows(pixels)
    low, high = plot.png_halves(len(rows))[1]
    half = plot.deflate_half(rows[low:high], True)
    written = []
    for name, last_half in (("here", None), ("given", lambda: half), ("failed", lambda: None)):
        path = tmp_path / f"{name}.png"
        plot.write_png(path, pixels, 72.0, rows, last_half)
        written.append(path.read_bytes())
    assert written[0] == written[1] == written[2]
    assert np.array_equal(np.asarray(Image.open(tmp_path / "given.png")), pixels[:, :, :3])


def test_copy_rgb_fills_a_window_of_png_rows_pixel_by_pixel():
    """As the plot process pastes its helper's panels into the PNG's rows: a window of columns of
    some rows gets each pixel's R, G, B bytes (the 4th byte left out), the rest is untouched."""
    rng = np.random.default_rng(3)
    rows = rng.integers(0, 256, (20, 1 + 3 * 30), dtype=np.uint8)
    pixels = rng.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    expected = rows.copy()
    for row in range(4, 15):
        for column in range(7, 25):
            expected[row, 1 + 3 * column : 4 + 3 * column] = pixels[row, column, :3]
    plot.copy_rgb(rows[4:15, 1 + 3 * 7 : 1 + 3 * 25], pixels[4:15, 7:25])
    assert np.array_equal(rows, expected)


@pytest.mark.parametrize("lengths", [(0, 0), (0, 9), (9, 0), (1, 1), (5552, 70000), (100_000, 3)])
def test_adler32_of_two_strings_is_zlibs_of_both(lengths):
    import zlib

    rng = np.random.default_rng(sum(lengths))
    first, second = (rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in lengths)
    combined = plot._adler32_combine(zlib.adler32(first), zlib.adler32(second), len(second))
    assert combined == zlib.adler32(first + second)
    ones = b"\xff" * lengths[1]  # the largest bytes: the sums wrap most often
    assert plot._adler32_combine(zlib.adler32(first), zlib.adler32(ones), len(ones)) == zlib.adler32(
        first + ones
    )


def test_the_figures_renderer_draws_as_matplotlibs_own(monkeypatch):
    """The run's figure's renderer (`plot._canvas_class`: texts laid out once per process, or
    ahead by `warm_text`, each font's size set once per text, its height metrics kept) against
    matplotlib's own Agg canvas: the same pixels, rotated texts (the y labels) included, and the
    same again once every layout is kept."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    def pixels() -> np.ndarray:
        return np.asarray(plot.build_figure(_data()).canvas.buffer_rgba()).copy()

    kept = [dict(cache) for cache in (plot._TEXT_SIZES, plot._TEXT_GLYPHS, plot._FONT_HEIGHTS)]
    try:
        for cache in (plot._TEXT_SIZES, plot._TEXT_GLYPHS, plot._FONT_HEIGHTS):
            cache.clear()
        plot.warm_text(plot.likely_texts(False)[:40])
        first, again = pixels(), pixels()
    finally:
        for cache, entries in zip(
            (plot._TEXT_SIZES, plot._TEXT_GLYPHS, plot._FONT_HEIGHTS), kept, strict=True
        ):
            cache.clear()
            cache.update(entries)
    monkeypatch.setattr(plot, "_canvas_class", lambda: FigureCanvasAgg)
    plain = pixels()
    assert np.array_equal(first, plain)
    assert np.array_equal(again, plain)


@pytest.fixture
def kept_file(tmp_path, monkeypatch):
    """Text layouts kept in a file of `tmp_path` (not the build folder's), this process's layouts
    (kept and in the renderer's caches) dropped before and after."""
    from cosim.logs import kept_text

    caches = (plot._TEXT_SIZES, plot._TEXT_GLYPHS, plot._FONT_HEIGHTS)
    saved = [dict(cache) for cache in caches]
    path = tmp_path / "text-layouts.pickle"
    monkeypatch.setattr(kept_text, "kept_path", lambda: path)
    kept_text.forget()
    for cache in caches:
        cache.clear()
    yield path
    kept_text.forget()
    for cache, entries in zip(caches, saved, strict=True):
        cache.clear()
        cache.update(entries)


def test_texts_laid_out_by_an_earlier_process_draw_matplotlibs_pixels(kept_file, monkeypatch):
    """A figure drawn with every text's size and glyphs read from the kept file (as a later
    process reads what an earlier one laid out: this process's own layouts dropped) has the
    pixels of matplotlib's own Agg canvas, the y labels' rotated texts included."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from cosim.logs import kept_text

    def pixels() -> np.ndarray:
        return np.asarray(plot.build_figure(_data()).canvas.buffer_rgba()).copy()

    laid_out = pixels()
    kept_text.keep()
    assert kept_file.exists()
    kept_text.forget()
    for cache in (plot._TEXT_SIZES, plot._TEXT_GLYPHS):
        cache.clear()
    found = {"sizes": 0, "glyphs": 0}
    sizes, glyphs = kept_text.size_of, kept_text.glyphs_of

    def size_of(*args):
        size = sizes(*args)
        found["sizes"] += size is not None
        return size

    def glyphs_of(*args):
        kept = glyphs(*args)
        found["glyphs"] += kept is not None
        return kept

    monkeypatch.setattr(kept_text, "size_of", size_of)
    monkeypatch.setattr(kept_text, "glyphs_of", glyphs_of)
    from_file = pixels()
    assert found["sizes"] > 20 and found["glyphs"] > 20  # (the ticks' labels, legend, panel texts)
    monkeypatch.setattr(plot, "_canvas_class", lambda: FigureCanvasAgg)
    plain = pixels()
    assert np.array_equal(laid_out, plain)
    assert np.array_equal(from_file, plain)


def test_kept_text_layouts_are_merged_capped_and_refused_when_stale(kept_file, monkeypatch):
    """The file holds what two processes added (the second reads the first's), at most `KEPT`
    texts, those no process used for longest dropped first; one of another format, a broken one,
    or a layout kept for another version of the font file (its size or time changed) is not used."""
    import os
    import pickle

    from matplotlib.backends.backend_agg import get_hinting_flag
    from matplotlib.font_manager import FontProperties

    from cosim.logs import kept_text

    prop, flags = FontProperties(size=9.0), get_hinting_flag()
    kept_text.remember_size("first", prop, 110, flags, (30.0, 11.0, 2.0))
    kept_text.keep()
    kept_text.forget()  # another process
    assert kept_text.size_of("first", prop, 110, flags) == (30.0, 11.0, 2.0)
    kept_text.remember_size("second", prop, 110, flags, (40.0, 11.0, 2.0))
    kept_text.remember_glyphs("second", prop, 110, flags, [(3, 0.0, 0.0), (4, 6.5, 0.0)])
    kept_text.keep()
    kept_text.forget()
    assert kept_text.size_of("first", prop, 110, flags) == (30.0, 11.0, 2.0)
    assert kept_text.glyphs_of("second", prop, 110, flags) == ((3, 0.0, 0.0), (4, 6.5, 0.0))
    assert kept_text.size_of("second", prop, 110.5, flags) is None  # another dpi

    monkeypatch.setattr(kept_text, "KEPT", 3)
    for number in range(5):
        kept_text.remember_size(f"text {number}", prop, 110, flags, (float(number), 1.0, 0.0))
    kept_text.keep()
    kept_text.forget()
    held = [text for text in ["first", "second", *(f"text {n}" for n in range(5))]
            if kept_text.size_of(text, prop, 110, flags) is not None]  # fmt: skip
    assert held == ["text 2", "text 3", "text 4"]

    kept_text.forget()  # another process, which uses text 2: kept longer than text 3 then
    kept_text.size_of("text 2", prop, 110, flags)
    kept_text.remember_size("text 5", prop, 110, flags, (5.0, 1.0, 0.0))
    kept_text.keep()
    kept_text.forget()
    held = [text for text in (f"text {n}" for n in range(6)) if kept_text.size_of(text, prop, 110, flags)]
    assert held == ["text 2", "text 4", "text 5"]

    header, entries = pickle.loads(kept_file.read_bytes())
    (font,) = entries
    older = tuple((path, face, size, mtime - 1) for path, face, size, mtime in font)  # the font changed since
    kept_file.write_bytes(pickle.dumps((header, {older: entries[font]})))
    kept_text.forget()
    assert kept_text.size_of("text 5", prop, 110, flags) is None
    for payload in (pickle.dumps((("another format", None, None), entries)), b"\x80\x05broken"):
        kept_file.write_bytes(payload)
        kept_text.forget()
        assert kept_text.size_of("text 5", prop, 110, flags) is None
    kept_text.remember_size("after", prop, 110, flags, (1.0, 1.0, 0.0))  # written afresh over it
    kept_text.keep()
    kept_text.forget()
    assert kept_text.size_of("after", prop, 110, flags) == (1.0, 1.0, 0.0)
    partials = [name for name in os.listdir(kept_file.parent) if name.startswith(f".{kept_file.name}.")]
    assert partials == [f".{kept_file.name}.lock"]  # (the writers' lock; no partial file left)

    gone = kept_file.parent / "removed" / "native" / kept_file.name  # (a build folder removed meanwhile)
    monkeypatch.setattr(kept_text, "kept_path", lambda: gone)
    kept_text.remember_size("not written", prop, 110, flags, (1.0, 1.0, 0.0))
    kept_text.keep()
    assert not gone.parent.parent.exists()
