"""The PNG of `cosim run` is drawn from the run's in-memory trace (`RunTrace`), not by reading the
log back: it must show exactly what the plot of the log shows (`cosim log plot`). The log, read by
`cosim.logs.reader`, is the independent truth here: every array the plot draws is compared, and the
two PNGs pixel by pixel."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import CosimError
from cosim.logs import plot, plot_data
from cosim.logs.reader import open_log
from cosim.navigation.run import run_scenario
from cosim.record import recorder
from cosim.scenario.load import load_scenario

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = {
    # VFH takes over (mode shading and points), a still obstacle, scans
    "one_obstacle": ("warehouse_diff_drive_one_obstacle.toml", ["simulation.stop_time=30"]),
    # moving obstacles (tracks), stopped before the goal (the end marker), replanning
    "moving_short": ("warehouse_moving_crossing.toml", ["simulation.stop_time=12"]),
    # the bicycle's steering panel
    "bicycle_short": ("warehouse_bicycle_one_obstacle.toml", ["simulation.stop_time=8"]),
}


@pytest.fixture(scope="module", params=sorted(SCENARIOS))
def run(request, tmp_path_factory):
    name = request.param
    file, overrides = SCENARIOS[name]
    scenario = load_scenario(REPO / "scenarios" / file, overrides)
    log_path = tmp_path_factory.mktemp(name) / f"{name}.mcap"
    result = run_scenario(scenario, log_path)
    assert result.trace is not None and result.trace.complete and not result.trace.dropped
    return result


def _same(a, b, where: str) -> None:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, f"{where}: shape {a.shape} != {b.shape}"
        assert a.dtype.kind == b.dtype.kind, f"{where}: dtype {a.dtype} != {b.dtype}"
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"{where} differs"
    elif dataclasses.is_dataclass(a):
        for item in dataclasses.fields(a):
            _same(getattr(a, item.name), getattr(b, item.name), f"{where}.{item.name}")
    elif isinstance(a, dict):
        assert sorted(a) == sorted(b), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            _same(a[key], b[key], f"{where}[{key}]")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), f"{where}: {len(a)} items != {len(b)}"
        for index, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{index}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def test_trace_gives_the_arrays_the_log_gives(run):
    from_trace = plot.collect(plot.TraceSource(run.trace))
    with open_log(run.log_path) as log:
        from_log = plot.collect(log)
    _same(from_trace, from_log, "plot")
    # the picture has its parts (so the comparison compared something)
    assert from_log.image is not None and from_log.trajectory is not None and from_log.plan is not None
    assert len(from_log.series) >= 5 and from_log.obstacles
    name = run.log_path.stem
    if name == "one_obstacle":
        assert plot_data.MODE_AVOID in from_log.mode_points
    if name == "moving_short":
        assert from_log.tracks and from_log.end is not None and from_log.end[2] == "stop_time"
    if name == "bicycle_short":
        assert any(series.unit == "rad" and "steering" in series.label for series in from_log.series)


def test_the_trace_parts_a_plot_process_gets_give_the_arrays_the_log_gives(run):
    """`cosim run` pickles its trace's two parts to its plot process, which gathers the data from
    them (`trace_parts`, `joined_trace`): the panels' part alone, and both."""
    import pickle

    panels, mapped = (pickle.loads(pickle.dumps(part, protocol=5)) for part in plot.trace_parts(run.trace))
    with open_log(run.log_path) as log:
        from_log = plot.collect(log)
        signals_only = plot.collect_signals(log)
    _same(plot.collect(plot.TraceSource(plot.joined_trace(panels, mapped))), from_log, "parts")
    _same(plot.collect_signals(plot.TraceSource(plot.joined_trace(panels))), signals_only, "panels' part")
    assert from_log.plans and from_log.series


def test_trace_and_log_draw_the_same_pixels(run, tmp_path):
    from matplotlib.image import imread

    from_trace = plot.plot_trace(run.trace, tmp_path / "trace.png")
    from_log = plot.plot_run(run.log_path, tmp_path / "log.png")
    assert np.array_equal(imread(from_trace), imread(from_log))


def test_trace_keeps_every_signal_the_default_plot_may_draw():
    wanted = plot.SPEED + plot.STEERING + plot.TURNING + [(c, n) for c, n, _ in plot.DIRECTIONS]
    wanted += [("mixer", "mode"), ("vehicle", "x"), ("vehicle", "y"), ("vehicle", "theta")]
    for component, name in wanted:
        assert name in recorder.TRACE_SIGNALS.get(component, ()), f"{component}.{name} not traced"


def test_a_trace_past_its_limit_is_dropped_and_the_run_plots_its_log(tmp_path, monkeypatch, capsys):
    from cosim.cli import main

    monkeypatch.setattr(recorder, "TRACE_LIMIT", 1000)
    scenario = REPO / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    log_path = tmp_path / "long.mcap"
    result = run_scenario(load_scenario(scenario, ["simulation.stop_time=3"]), log_path)
    assert result.trace.dropped and not result.trace.signal_blocks and not result.trace.poses
    with pytest.raises(CosimError, match="trace was dropped"):
        plot.TraceSource(result.trace)
    out = tmp_path / "cli.mcap"
    args = ["run", str(scenario), "--out", str(out), "--set", "simulation.stop_time=3", "--quiet"]
    assert main(args) == 1  # stopped before the goal
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_obstacle_shapes_and_tracks_of_every_kind_match_the_log(tmp_path):
    """Circles, rectangles (a yaw through its quaternion) and polygons (a vertex mean), moving:
    the trace's obstacles and tracks are the reader's, to the bit."""
    from cosim.world.shapes import Circle, Polygon, Rectangle

    path = tmp_path / "obstacles.mcap"
    with recorder.Recorder(path) as log:
        for step in range(4):
            shift = 0.1 * step / 3.0
            log.write_obstacles(
                step * 100_000_000,
                [
                    Circle((1.0 + shift, 2.0), 0.3),
                    Rectangle((4.0, 5.0 - shift), (1.0, 0.5), yaw=0.7),
                    Polygon(((0.0, 0.0), (1.0 / 3.0, 0.1 + shift), (0.2, 0.9))),
                ],
            )
        trace = log.trace
    source = plot.TraceSource(trace)
    with open_log(path) as read:
        tracks, shapes = read.obstacle_tracks(), read.obstacles()
        _same(source.obstacle_tracks(), tracks, "tracks")
        assert len(tracks) == 3 and all(len(track) == 4 for track in tracks)
        _same(
            [np.asarray(s.polygon()) for s in source.obstacles()],
            [np.asarray(s.polygon()) for s in shapes],
            "shapes",
        )


@pytest.mark.parametrize("range_max", [10.0, float("inf")], ids=["finite range_max", "infinite range_max"])
def test_a_batch_of_sweeps_keeps_the_shortest_ranges_of_each_sweep_kept_alone(range_max):
    """`RunTrace.add_scans` (the rows `scan_rows` holds) against `add_scan` of each row: every
    kind of row (NaN bins, beams without a return, ranges below range_min or past range_max, a
    row without any range at or above range_min) gives the same shortest range, bit for bit."""
    rng = np.random.default_rng(7)
    rows = rng.uniform(0.05, 12.0, (40, 16)).astype(np.float32)
    rows[rng.random(rows.shape) < 0.2] = np.nan
    rows[rng.random(rows.shape) < 0.2] = np.inf
    rows[3] = np.inf  # no return at all
    rows[4] = np.nan  # no measurement at all
    rows[5] = 0.01  # every range below range_min
    rows[6] = 11.5  # every range past a finite range_max
    rows[7, :8], rows[7, 8:] = 0.01, np.inf
    times = list(range(1000, 1000 + len(rows)))
    batch, alone = recorder.RunTrace(Path("batch.mcap")), recorder.RunTrace(Path("alone.mcap"))
    batch.add_scans(times, rows, 0.1, range_max)
    for t, row in zip(times, rows, strict=True):
        alone.add_scan(t, row, 0.1, range_max)
    assert batch.scan_t_ns == alone.scan_t_ns
    assert np.array_equal(np.array(batch.scan_minima), np.array(alone.scan_minima), equal_nan=True)
    assert [type(value) for value in batch.scan_minima] == [type(value) for value in alone.scan_minima]
    assert batch._values == alone._values
