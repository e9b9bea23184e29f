"""`cosim log animate`: frame count from duration, fps and speed; the vehicle drawn where the log
says it was; the MP4 path without ffmpeg and bad arguments end in one line and exit 2."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from PIL import Image

from cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> Path:
    log = tmp_path_factory.mktemp("animate") / "short.mcap"
    code = main(
        ["run", str(SCENARIO), "--out", str(log), "--no-plot", "--quiet", "--set", "simulation.stop_time=6"]
    )
    assert code == 1  # the stop time comes before the goal
    return log


def _log_span(path: Path) -> tuple[float, float]:
    """First and last message time [s], from the MCAP summary (the mcap package, not our reader)."""
    with open(path, "rb") as handle:
        statistics = make_reader(handle).get_summary().statistics
    return statistics.message_start_time / 1e9, statistics.message_end_time / 1e9


def test_gif_has_one_frame_per_speed_over_fps_seconds(short_run, tmp_path, capsys):
    out = tmp_path / "run.gif"
    fps, speed = 10.0, 2.0
    assert main(["log", "animate", str(short_run), "--out", str(out), "--fps", "10", "--speed", "2"]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    start, end = _log_span(short_run)
    expected = math.floor((end - start) * fps / speed + 1e-9) + 1  # every speed/fps s from the start
    if not math.isclose((end - start) * fps / speed % 1.0, 0.0, abs_tol=1e-6):
        expected += 1  # and the run's end time, between two
    with Image.open(out) as gif:
        assert gif.n_frames == expected
        assert gif.info["duration"] == pytest.approx(1000 / fps, abs=10)  # GIF stores 10 ms units
        gif.seek(0)
        first = np.array(gif.convert("RGB"), dtype=int)
        gif.seek(gif.n_frames - 1)
        last = np.array(gif.convert("RGB"), dtype=int)
    assert np.any(first != last)  # something moved


def test_vehicle_is_drawn_at_its_logged_pose(short_run):
    from cosim.logs import open_log
    from cosim.logs.animate import FOLLOW_COLOR, HEIGHT, _rgb, _Scene

    with open_log(short_run) as log:
        scene = _Scene(log)
        vehicle = log.signals("vehicle")
        mode = log.signals("mixer")["mode"]
    assert not np.any(mode), "the first 6 s follow the plan: the footprint has the follow colour"
    for k in (0, len(vehicle.t) // 2, len(vehicle.t) - 1):
        frame = scene.render(float(vehicle.t[k]))
        px, py = scene.axes.transData.transform((vehicle["x"][k], vehicle["y"][k]))
        # Pixel beside the centre (the heading line runs through the centre), inside the footprint.
        behind = np.array([-np.cos(vehicle["theta"][k]), np.sin(vehicle["theta"][k])])
        column, row = np.rint(np.array([px, HEIGHT - py]) + 2 * behind).astype(int)
        colour = frame[row, column, :3].astype(int)
        assert np.abs(colour - _rgb(FOLLOW_COLOR)).max() < 40, (k, colour)


def test_mp4_without_ffmpeg_is_one_line_and_exit_2(short_run, tmp_path, capsys, monkeypatch):
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name: None)
    out = tmp_path / "run.mp4"
    assert main(["log", "animate", str(short_run), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "ffmpeg" in err and len(err.splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize(
    "extra, message",
    [(["--fps", "0"], "--fps"), (["--speed", "-1"], "--speed"), (["--out", "run.avi"], ".avi")],
)
def test_bad_arguments_are_one_line_and_exit_2(short_run, tmp_path, capsys, extra, message):
    arguments = ["log", "animate", str(short_run), "--out", str(tmp_path / "run.gif"), *extra]
    assert main(arguments) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
