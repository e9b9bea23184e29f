"""`sweep.png` is written from one draw of the canvas (`cosim.logs.plot.write_png`), not by
`savefig`: its pixels, read back by Pillow, must be the very pixels matplotlib's own `savefig`
(Pillow's encoder) writes for the same figure, in every layout the sweep draws (two keys on a grid
or scattered, one key, three keys, with replicates, with category values)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from test_sweep_report import KEYS, OUTCOME, _rows

from cosim.sweep.plot import DPI, plot_sweep, sweep_figure


def _one_key(replicates: int, seed: int) -> list[dict[str, str]]:
    rows = _rows(replicates=replicates, seed=seed)
    for index, row in enumerate(rows):
        row["lidar.noise"] = f"{0.01 * (index // replicates):g}"
    return rows


def _three_keys() -> list[dict[str, str]]:
    rows = _rows(seed=4)
    for index, row in enumerate(rows):
        row["lidar.noise"] = str(index % 2 * 0.05)
    return rows


def _categories() -> list[dict[str, str]]:
    rows = _rows(seed=5)
    names = {"0.1": "maps/a_long_category_name.yaml", "0.3": "b", "0.5": "c"}
    for row in rows:
        row[KEYS[0]] = names[row[KEYS[0]]]
    return rows


CASES = {
    "grid": (lambda: _rows(seed=6), KEYS, True, 1),
    "grid with replicates": (lambda: _rows(replicates=3, seed=2), KEYS, True, 3),
    "random": (lambda: _rows(seed=6), KEYS, False, 1),
    "one key": (lambda: _one_key(1, 6), ["lidar.noise"], True, 1),
    "one key with replicates": (lambda: _one_key(3, 3), ["lidar.noise"], True, 3),
    "three keys": (_three_keys, (*KEYS, "lidar.noise"), True, 1),
    "categories": (_categories, KEYS, True, 1),
}


# Each case draws its figure twice (~1 s): CI draws every layout, the quick loop none.
@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_sweep_png_has_the_pixels_savefig_writes(case, tmp_path):
    make_rows, keys, grid, replicates = CASES[case]
    rows = make_rows()
    title = f"{case}: sweep"
    written = plot_sweep(rows, keys, OUTCOME, tmp_path / "sweep.png", grid, title, replicates)
    assert written == tmp_path / "sweep.png"
    figure = sweep_figure(rows, keys, OUTCOME, grid, title, replicates)
    figure.savefig(tmp_path / "savefig.png", dpi=DPI)
    with Image.open(written) as ours, Image.open(tmp_path / "savefig.png") as theirs:
        assert ours.info.get("dpi") == pytest.approx(theirs.info.get("dpi"), abs=0.01)
        ours, theirs = np.asarray(ours.convert("RGB")), np.asarray(theirs.convert("RGB"))
    assert ours.shape == theirs.shape
    assert np.array_equal(ours, theirs)
    assert len(np.unique(ours.reshape(-1, 3), axis=0)) > 50  # a picture, not a blank page


def test_no_rows_no_png(tmp_path):
    assert plot_sweep([], KEYS, OUTCOME, tmp_path / "sweep.png", grid=True) is None
    assert not (tmp_path / "sweep.png").exists()


# Three figures drawn (~1.5 s).
@pytest.mark.slow
def test_sweep_png_has_the_same_bytes_drawn_again_after_another(tmp_path):
    """sweep.png's canvas keeps each text's layout for the process (`cosim.logs.plot.canvas_class`):
    a figure drawn again, after another one whose texts differ, with all of its own texts then laid
    out ahead, has the very bytes it had when drawn first."""
    make_rows, keys, grid, replicates = CASES["grid"]
    rows = make_rows()
    first = plot_sweep(rows, keys, OUTCOME, tmp_path / "first.png", grid, "grid: sweep", replicates)
    other_rows, other_keys, other_grid, other_replicates = CASES["one key with replicates"]
    plot_sweep(other_rows(), other_keys, OUTCOME, tmp_path / "other.png", other_grid, "", other_replicates)
    again = plot_sweep(rows, keys, OUTCOME, tmp_path / "again.png", grid, "grid: sweep", replicates)
    assert first.read_bytes() == again.read_bytes()
