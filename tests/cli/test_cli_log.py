"""`cosim log info|plot|export|diff` through the CLI entry point (exit codes, output, files)."""

from __future__ import annotations

import numpy as np
import pytest
from log_synthetic import COMPONENTS, METADATA, STEP_NS, write_log
from mcap_ros2.writer import Writer as Ros2Writer

from cosim.cli import main
from cosim.logs.export import read_csv


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    return {
        "a": write_log(folder / "a.mcap"),
        "same": write_log(folder / "same.mcap"),
        "vfh_changed": write_log(folder / "vfh_changed.mcap", change={"vfh": 1e-3}),
        "failed": write_log(folder / "failed.mcap", outcome={"reached": "false", "reason": "collision"}),
    }


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """An MCAP written by another tool: a ROS 2 String topic, no navcosim signals."""
    target = tmp_path_factory.mktemp("foreign") / "chatter.mcap"
    with open(target, "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data")
        for k in range(5):
            writer.write_message("/chatter", schema, {"data": "hi"}, log_time=k * 10**8, publish_time=k)
        writer.finish()
    return target


def test_info_reports_what_ran(runs, capsys):
    assert main(["log", "info", str(runs["a"].path)]) == 0
    out = capsys.readouterr().out
    assert "synthetic_quarter_circle" in out and "complete" in out
    assert "reached true" in out and "reason goal" in out
    fmu = METADATA["fmu/vehicle"]
    assert fmu["guid"] in out and fmu["model_name"] in out and fmu["generation_tool"] in out
    odom_line = next(line for line in out.splitlines() if line.strip().startswith("/odom "))
    assert "120 msgs" in odom_line and f"{1e9 / STEP_NS:.2f} Hz" in odom_line
    assert "5.950 s" in out  # duration of 120 steps of 50 ms


def test_plot_run_writes_a_png(runs, tmp_path):
    """The run loop's entry point: default signals, folders created."""
    from cosim.logs.plot import plot_run

    png = plot_run(runs["a"].path, tmp_path / "x" / "run.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_plot_command_with_chosen_signals(runs, tmp_path, capsys):
    chosen = tmp_path / "chosen.png"
    args = ["log", "plot", str(runs["a"].path), "--png", str(chosen), "--signals"]
    assert main([*args, "vfh.ranges[1]", "mixer.mode"]) == 0
    assert chosen.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main([*args, "vfh.ranges[1]"]) == 2  # the picture is kept: drawing again needs --force
    assert "already exists; give --force" in capsys.readouterr().err
    args.insert(-1, "--force")
    assert main([*args, "vfh.nope"]) == 2
    assert "no signal 'nope'" in capsys.readouterr().err
    assert main([*args, "novariable"]) == 2
    assert "expected COMPONENT.VARIABLE" in capsys.readouterr().err


def test_export_csv_and_npz_equal_the_recording_to_the_bit(runs, tmp_path):
    run = runs["a"]
    assert main(["log", "export", str(run.path), "--to", "csv", "--out", str(tmp_path)]) == 0
    for component, names in COMPONENTS.items():
        read_names, t_ns, values = read_csv(tmp_path / f"a-{component}.csv")
        assert read_names == names
        np.testing.assert_array_equal(t_ns, run.t_ns)
        assert values.tobytes() == run.signals[component].tobytes()
    assert (
        main(
            [
                "log",
                "export",
                str(run.path),
                "--to",
                "npz",
                "--component",
                "vfh",
                "mixer",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    data = np.load(tmp_path / "a-signals.npz")
    assert sorted(data.files) == sorted(
        f"{c}.{k}" for c in ("vfh", "mixer") for k in ("t", "t_ns", "values", "names")
    )
    assert data["vfh.values"].tobytes() == run.signals["vfh"].tobytes()
    assert list(data["vfh.names"]) == COMPONENTS["vfh"]
    np.testing.assert_array_equal(data["mixer.t_ns"], run.t_ns)


def test_diff_of_a_run_against_itself_is_zero(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["same"].path), "--tolerance", "0"]) == 0
    out = capsys.readouterr().out
    assert "largest deviation 0" in out and "EQUAL" in out


def test_diff_names_the_changed_component(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["vfh_changed"].path)]) == 1
    out = capsys.readouterr().out
    flagged = [
        line.split()[0] for line in out.splitlines() if line.startswith("vfh.") or line.startswith("mixer.")
    ]
    before, after = runs["a"].signals["vfh"], runs["vfh_changed"].signals["vfh"]
    changed = [
        f"vfh.{name}"
        for column, name in enumerate(COMPONENTS["vfh"])
        if not np.array_equal(before[:, column], after[:, column], equal_nan=True)  # inf + 1e-3 is inf
    ]
    assert len(changed) == 3 and sorted(flagged) == sorted(changed)
    assert "DIFFERENT (vfh)" in out
    # within a tolerance above the change: equal
    assert (
        main(["log", "diff", str(runs["a"].path), str(runs["vfh_changed"].path), "--tolerance", "0.002"]) == 0
    )


def test_diff_reports_outcome_differences(runs, capsys):
    assert main(["log", "diff", str(runs["a"].path), str(runs["failed"].path)]) == 1
    out = capsys.readouterr().out
    assert "outcome reached: A true  B false" in out and "outcome reason: A goal  B collision" in out


def test_diff_interpolates_different_time_bases(runs, tmp_path, capsys):
    """A run cut at half time: B is interpolated onto A's times where both exist; equal there."""
    shorter = write_log(tmp_path / "short.mcap", steps=60)
    assert main(["log", "diff", str(runs["a"].path), str(shorter.path), "--tolerance", "0"]) == 0
    out = capsys.readouterr().out
    assert "B interpolated linearly onto A's times" in out and "largest deviation 0" in out


@pytest.mark.parametrize("action", ["info", "plot", "export", "diff"])
def test_bad_inputs_give_one_line_and_exit_2(tmp_path, capsys, action):
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("just some text\n")
    args = {
        "info": [str(not_mcap)],
        "plot": [str(not_mcap)],
        "export": [str(not_mcap), "--to", "csv"],
        "diff": [str(not_mcap), str(not_mcap)],
    }[action]
    assert main(["log", action, *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cosim: error:") and "not an MCAP file" in err
    assert (
        main(["log", action, *[str(tmp_path / "missing.mcap") if a == str(not_mcap) else a for a in args]])
        == 2
    )
    assert "no such log file" in capsys.readouterr().err


def test_foreign_mcap_partial_output_or_one_line(foreign, tmp_path, capsys):
    assert main(["log", "info", str(foreign)]) == 0
    out = capsys.readouterr().out
    assert "/chatter" in out and "not a navcosim run log" in out
    assert main(["log", "plot", str(foreign), "--png", str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").exists()
    assert main(["log", "export", str(foreign), "--to", "csv", "--out", str(tmp_path)]) == 2
    assert "no navcosim signal channels" in capsys.readouterr().err


def test_info_shows_the_overrides_the_run_applied(tmp_path, capsys):
    """A real run with two --set overrides: log info names them (the attached scenario.toml is the
    file as given, so without them the log would not say what ran)."""
    from pathlib import Path

    scenario = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    log = tmp_path / "over.mcap"
    sets = ["--set", "simulation.stop_time=0.3", "--set", "vfh.safety_distance=0.6"]
    assert main(["run", str(scenario), "--out", str(log), "--no-plot", *sets]) == 1
    capsys.readouterr()
    assert main(["log", "info", str(log)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("--set"))
    assert "simulation.stop_time=0.3" in line and "vfh.safety_distance=0.6" in line
    assert (
        main(["run", str(scenario), "--out", str(tmp_path / "plain.mcap"), "--no-plot", sets[0], sets[1]])
        == 1
    )
    capsys.readouterr()
    assert main(["log", "info", str(tmp_path / "plain.mcap")]) == 0
    assert "vfh.safety_distance" not in capsys.readouterr().out


def _png(path):
    from PIL import Image

    with Image.open(path) as image:
        return image.size, image.info.get("dpi"), np.asarray(image.convert("RGB"))


def _colour_pixels(pixels, colour: str) -> int:
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int(np.all(pixels == rgb, axis=2).sum())


def test_plot_overlays_runs_each_in_its_colour_named_by_its_stem(runs, tmp_path, capsys):
    from cosim.logs import plot, plot_map
    from cosim.logs.reader import open_log

    out = tmp_path / "both.png"
    a, b = runs["a"].path, runs["failed"].path
    assert main(["log", "plot", str(a), str(b), "--png", str(out)]) == 0
    _, _, pixels = _png(out)
    for index in (0, 1):  # each trajectory in its run's colour (opaque lines)
        assert _colour_pixels(pixels, plot_map.run_colour(index)) >= 50
    with open_log(a) as log_a, open_log(b) as log_b:
        figure = plot.build_figure([plot.collect(log_a), plot.collect(log_b)])
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert "a" in labels and "failed" in labels
    # every panel has one line per run, in the runs' colours
    for axes in figure.axes[1:]:
        colours = {line.get_color() for line in axes.get_lines()}
        assert {plot_map.run_colour(0), plot_map.run_colour(1)} <= colours
    title = figure.get_suptitle().splitlines()
    assert title[0] == "2 runs overlaid" and title[1].startswith("a: goal reached")
    assert title[2] == "failed: goal NOT reached (collision)"
    assert main(["log", "plot", str(a), str(b)]) == 2  # several logs need a --png to name the picture
    assert "--png" in capsys.readouterr().err


def test_diff_png_plots_the_signals_that_differ(runs, tmp_path, capsys):
    from cosim.logs.diff import diff_logs
    from cosim.logs.diff_plot import diff_figure
    from cosim.logs.reader import open_log

    out = tmp_path / "diff.png"
    a, b = runs["a"], runs["vfh_changed"]
    assert main(["log", "diff", str(a.path), str(b.path), "--png", str(out)]) == 1
    assert f"wrote {out}" in capsys.readouterr().out and out.exists()
    with open_log(a.path) as log_a, open_log(b.path) as log_b:
        figure = diff_figure(diff_logs(log_a, log_b, 1e-9), log_a, log_b)
    titles = [axes.get_title(loc="left") for axes in figure.axes]
    # the signals that differ, from the written arrays (inf + 1e-3 is inf: equal)
    before, after = a.signals["vfh"], b.signals["vfh"]
    changed = [
        name
        for column, name in enumerate(COMPONENTS["vfh"])
        if not np.array_equal(before[:, column], after[:, column], equal_nan=True)
    ]
    assert len(figure.axes) == 2 * len(changed)
    assert sorted(title.split(":")[0] for title in titles[::2]) == sorted(f"vfh.{name}" for name in changed)
    for left, right in zip(figure.axes[::2], figure.axes[1::2], strict=True):
        name = left.get_title(loc="left").split(":")[0].removeprefix("vfh.")
        column = COMPONENTS["vfh"].index(name)
        expected = before[:, column] - after[:, column]
        expected[np.isnan(before[:, column]) & np.isnan(after[:, column])] = 0.0  # NaN in both: equal
        (line,) = right.get_lines()[:1]
        np.testing.assert_allclose(line.get_ydata(), expected, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(line.get_xdata(), a.t_ns / 1e9)
        assert len(left.get_lines()) >= 2  # A and B
    # two equal runs: a picture that says so
    assert main(["log", "diff", str(a.path), str(runs["same"].path), "--png", str(out), "--force"]) == 0


def test_dpi_and_size_set_the_pictures_pixels(runs, tmp_path, capsys):
    png = tmp_path / "sized.png"
    assert (
        main(["log", "plot", str(runs["a"].path), "--png", str(png), "--size", "800x500", "--dpi", "60"]) == 0
    )
    size, dpi, _ = _png(png)
    assert size == (800, 500) and np.allclose(dpi, (60, 60), atol=0.01)
    assert main(["log", "plot", str(runs["a"].path), "--png", str(png), "--force", "--dpi", "55"]) == 0
    size, dpi, _ = _png(png)
    assert size == (15 * 55, round(9.5 * 55)) and np.allclose(dpi, (55, 55), atol=0.01)  # 15 x 9.5 in
    diff = tmp_path / "diff.png"
    args = ["log", "diff", str(runs["a"].path), str(runs["vfh_changed"].path), "--png", str(diff)]
    assert main([*args, "--size", "640x480"]) == 1
    assert _png(diff)[0] == (640, 480)
    gif = tmp_path / "small.gif"
    assert (
        main(["log", "animate", str(runs["a"].path), "--out", str(gif), "--size", "320x240", "--quiet"]) == 0
    )
    from PIL import Image

    with Image.open(gif) as image:
        assert image.size == (320, 240)
    capsys.readouterr()
    odd = ["log", "animate", str(runs["a"].path), "--out", str(tmp_path / "odd.mp4"), "--size", "321x240"]
    assert main(odd) == 2 and "even" in capsys.readouterr().err
    assert main(["log", "plot", str(runs["a"].path), "--png", str(png), "--force", "--dpi", "0"]) == 2
    with pytest.raises(SystemExit) as stopped:
        main(["log", "plot", str(runs["a"].path), "--size", "800"])
    assert stopped.value.code == 2 and "WIDTHxHEIGHT" in capsys.readouterr().err


def test_signals_plot_keeps_the_logs_units(tmp_path, capsys):
    """Chosen signals of a real run: each panel's axis says the unit the log's channel metadata
    holds (read with the mcap package)."""
    import json
    from pathlib import Path

    from mcap.reader import make_reader

    from cosim.logs import plot
    from cosim.logs.reader import open_log
    from cosim.record.rosmsg import COMPONENT_KEY, SIGNAL_NAMES_KEY, SIGNAL_UNITS_KEY

    scenario = Path(__file__).resolve().parents[2] / "scenarios" / "warehouse_diff_drive_no_obstacle.toml"
    log = tmp_path / "units.mcap"
    assert (
        main(["run", str(scenario), "--out", str(log), "--no-plot", "--set", "simulation.stop_time=0.5"]) == 1
    )
    chosen = ["vehicle.v_actual", "vehicle.theta", "pure_pursuit.lookahead_x"]
    units = {}
    with open(log, "rb") as handle:
        for channel in make_reader(handle).get_summary().channels.values():
            if SIGNAL_UNITS_KEY in channel.metadata:
                names = json.loads(channel.metadata[SIGNAL_NAMES_KEY])
                for name, unit in zip(names, json.loads(channel.metadata[SIGNAL_UNITS_KEY]), strict=True):
                    units[f"{channel.metadata[COMPONENT_KEY]}.{name}"] = unit
    assert [units[name] for name in chosen] == ["m/s", "rad", "m"]
    png = tmp_path / "chosen.png"
    assert main(["log", "plot", str(log), "--png", str(png), "--signals", *chosen]) == 0
    with open_log(log) as read:
        figure = plot.build_figure(plot.collect(read, chosen))
    assert [axes.get_ylabel() for axes in figure.axes[1:]] == [f"[{units[name]}]" for name in chosen]
