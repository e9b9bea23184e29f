"""The PNG of `cosim run` is drafted while the run goes (`cosim.logs.plot.Draft`, made by the plot
process of `cosim.cli.plotter` from the scenario): the map frame first, the run over it after. The
independent truth is `cosim.logs.plot.draw` of the same data, the one picture drawn in one go: the
draft's picture must be it pixel for pixel, whether the draft fits the run or not, and whether its
two parts (the map, the panels) are drawn by one process or by two and put together. The guess of
the frame from the scenario (`cosim.cli.plotter.preview`) must fit real runs of each kind."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import plotter
from cosim.cli.plotter import PanelHelper, preview
from cosim.logs import plot
from cosim.logs.plot_data import PlotData
from cosim.navigation.run import run_scenario
from cosim.scenario.load import load_scenario
from tests.logs.test_plot_trace import SCENARIOS  # the runs whose trace is drawn as their log

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow  # three runs, each picture drawn a few times, forks


@pytest.fixture(scope="module", params=sorted(SCENARIOS))
def run(request, tmp_path_factory):
    """(scenario, the plot's data of its run, as `cosim run` hands it to the plot process)."""
    file, overrides = SCENARIOS[request.param]
    scenario = load_scenario(REPO / "scenarios" / file, overrides)
    log_path = tmp_path_factory.mktemp(request.param) / f"{request.param}.mcap"
    result = run_scenario(scenario, log_path, trace=True)
    return scenario, plot.collect(plot.TraceSource(result.trace))


def _pixels(path: Path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(path)


def _drawn(data: PlotData, tmp_path: Path) -> np.ndarray:
    return _pixels(plot.draw(data, tmp_path / "drawn.png"))


def test_the_scenario_gives_the_frame_of_its_run(run):
    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    assert drafted.fits(data)
    assert drafted.rows == len({series.panel for series in data.series}) == 5


def test_the_outline_sent_to_the_plot_process_previews_as_the_scenario(run):
    """`cosim run` sends the plot process only what `preview` reads of the scenario (`_outline`,
    plain values): the same preview as from the scenario itself, picklable without its classes."""
    import pickle

    scenario, _ = run
    outline = pickle.loads(pickle.dumps(plotter._outline(scenario)))
    assert "cosim.scenario" not in pickle.dumps(plotter._outline(scenario)).decode("latin-1")
    expected, got = preview(scenario), preview(outline)
    for field in dataclasses.fields(PlotData):
        a, b = getattr(expected, field.name), getattr(got, field.name)
        if field.name == "series":
            assert [(s.panel, s.unit, s.label) for s in a] == [(s.panel, s.unit, s.label) for s in b]
        elif isinstance(a, np.ndarray):
            assert np.array_equal(a, b)
        else:
            assert a == b, field.name


def test_a_draft_that_fits_draws_the_picture_of_draw(run, tmp_path):
    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    assert drafted.fits(data)
    finished = _pixels(drafted.finish(data, tmp_path / "draft.png"))
    assert np.array_equal(finished, _drawn(data, tmp_path))


def test_a_draft_is_drawn_over_once(run, tmp_path):
    """The frame's pixels are drawn over (no copy of them is kept): a second picture from the same
    draft is refused, not drawn over the first one's."""
    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    drafted.draw_run(data, True, plotter.TOP)
    with pytest.raises(RuntimeError, match="drawn over once"):
        drafted.draw_run(data, False, plotter.LOWER)


@pytest.mark.parametrize("ahead", [0, 1, 7, None], ids=["drafted", "one more", "mid-round", "all"])
def test_ticks_made_ahead_while_the_run_goes_draw_the_same_picture(run, tmp_path, ahead):
    """A y axis of a panel makes `Y_TICKS_DRAFTED` ticks with the draft, then `more_ticks` makes
    one more per axis and round, asking `stop` before each tick, until it stops (after `ahead`
    ticks: None, every one): however many were made ahead, the picture is `draw`'s."""
    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    asked = []

    def stop() -> bool:
        asked.append(True)
        return ahead is not None and len(asked) > ahead

    drafted.more_ticks(stop)
    rows = drafted.rows
    if ahead is None:
        made = [plot.TICKS_AHEAD] * rows
    else:
        made = [plot.Y_TICKS_DRAFTED + ahead // rows + (row < ahead % rows) for row in range(rows)]
    assert [len(axes.yaxis.majorTicks) for axes in drafted.panel_axes] == made
    assert len(drafted.panel_axes[-1].xaxis.majorTicks) == plot.TICKS_AHEAD
    assert np.array_equal(_pixels(drafted.finish(data, tmp_path / "draft.png")), _drawn(data, tmp_path))


def test_a_draft_that_does_not_fit_draws_afresh(run, tmp_path):
    """A run that left the drafted view (here: a view half as wide), or has another number of
    panels: the picture is still `draw`'s."""
    scenario, data = run
    guess = preview(scenario)
    x0, x1, y0, y1 = guess.limits
    narrow = plot.Draft(dataclasses.replace(guess, limits=(x0, (x0 + x1) / 2, y0, y1)))
    fewer = plot.Draft(dataclasses.replace(guess, series=guess.series[:-1]))
    drawn = _drawn(data, tmp_path)
    for name, drafted in (("narrow", narrow), ("fewer", fewer)):
        assert not drafted.fits(data)
        assert np.array_equal(_pixels(drafted.finish(data, tmp_path / f"{name}.png")), drawn)


@pytest.mark.parametrize("split", [0, 1, 4], ids=["map|panels", "map+top|lower", "map+upper|bottom"])
def test_the_two_parts_drawn_apart_and_put_together_are_the_picture(run, tmp_path, split):
    """The map and title with the panels above `split` as one part, the panels from `split` down
    as the other, each drawn by its own copy of the draft (as the plot process and its helper
    draw them, split at 1): every pixel either part changed is inside its boxes, the boxes do not
    overlap, and the other part's box pasted into the map's picture gives `draw`'s picture."""
    scenario, data = run
    guess = preview(scenario)
    map_part, panels_part = plot.Draft(guess), plot.Draft(guess)
    frame = map_part.pixels().copy()
    above_split, below_split = slice(0, split), slice(split, None)
    map_part.draw_run(data, True, above_split)
    panels_part.draw_run(data, False, below_split)
    top, bottom, left, right = panels_part.panels_box(below_split)
    inside = np.zeros(frame.shape[:2], dtype=bool)
    inside[top:bottom, left:right] = True
    assert not ((panels_part.pixels() != frame).any(axis=2) & ~inside).any()
    inside[:] = False
    boxes = map_part.map_boxes() + ([map_part.panels_box(above_split)] if split else [])
    for above, below, west, east in boxes:
        inside[above:below, west:east] = True
        assert not (top < below and above < bottom and left < east and west < right)
    assert not ((map_part.pixels() != frame).any(axis=2) & ~inside).any()
    map_part.pixels()[top:bottom, left:right] = panels_part.pixels()[top:bottom, left:right]
    assert np.array_equal(_pixels(map_part.write(tmp_path / "pasted.png")), _drawn(data, tmp_path))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the helper is forked on Linux")
@pytest.mark.parametrize("its_half", [True, False], ids=["its half compressed", "both halves here"])
def test_the_panel_helper_draws_the_panels_in_a_fork(run, tmp_path, its_half):
    """As the plot process has it: the helper draws the panels while this process draws the map
    part and makes the PNG's rows of it in the memory they share; the helper copies its panels
    into them and compresses their second half (or, here, it is compressed again in this
    process): the PNG `draw` writes, byte for byte."""
    import os
    import pickle

    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    helper = PanelHelper.start(drafted, ())
    pid = helper.pid
    helper.draw(pickle.dumps(data))
    drafted.draw_run(data, panels=plotter.TOP)
    plot.png_rows(drafted.pixels(), into=helper.rows)
    helper.rows_made()
    assert helper.paste(drafted)
    compressed = helper.last_half()
    assert compressed is not None
    helped = drafted.write(tmp_path / "helped.png", helper.rows, lambda: compressed if its_half else None)
    drawn = plot.draw(data, tmp_path / "drawn.png")
    assert helped.read_bytes() == drawn.read_bytes()
    helper.cancel()  # after its answers: it ends by itself
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # reaped


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the helper is forked on Linux")
def test_a_helper_not_wanted_ends(run):
    import os

    scenario, _ = run
    helper = PanelHelper.start(plot.Draft(preview(scenario)), ())
    pid = helper.pid
    helper.cancel()
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # it saw its pipe close, ended and was reaped


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the helper is forked on Linux")
def test_a_helper_that_died_gives_no_pixels(run):
    """The plot process then draws the picture afresh (`cosim.cli.plotter`)."""
    import os
    import pickle
    import signal

    scenario, data = run
    drafted = plot.Draft(preview(scenario))
    helper = PanelHelper.start(drafted, ())
    os.kill(helper.pid, signal.SIGKILL)
    helper.draw(pickle.dumps(data))  # into a closed pipe: no error
    drafted.draw_run(data, panels=plotter.TOP)
    plot.png_rows(drafted.pixels(), into=helper.rows)
    helper.rows_made()  # (no error either)
    assert not helper.paste(drafted)
    assert helper.last_half() is None
    helper.cancel()
