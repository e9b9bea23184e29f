"""`cosim log info|plot|animate|export|diff|recover LOG`: inspect a run's MCAP log without another tool."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cosim.errors import CosimError
from cosim.record.output import atomic_output, checked_output


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "log",
        help="inspect run logs (MCAP): info, plot, animate, export, diff, recover, layout",
        description="Inspect a run's MCAP log: summary, plots, signal tables, comparison of two runs, "
        "recovery of a cut log.",
    )
    commands = parser.add_subparsers(dest="log_command", required=True, metavar="ACTION")

    info = commands.add_parser("info", help="duration, topics, scenario, outcome, FMUs, completeness")
    info.add_argument("log", type=Path, help="run log (.mcap)")
    info.set_defaults(handler=_info)

    plot = commands.add_parser(
        "plot",
        help="a robot run: trajectory over the map and signals over time; any other log: its "
        "signals over time (PNG); several robot runs: overlaid, each in its own colour",
    )
    plot.add_argument("log", type=Path, nargs="+", help="run log (.mcap); several overlay in one picture")
    plot.add_argument(
        "--signals",
        nargs="+",
        metavar="COMPONENT.VAR",
        help="signals to plot over time, e.g. vehicle.v_actual vfh.steering_dir (or comma-separated; "
        "default for a robot run: speed, turn rate or steering angle, VFH steering direction, minimum "
        "range, distance to goal; for a log without map, goal or trajectory: every signal)",
    )
    plot.add_argument(
        "--png",
        type=Path,
        metavar="OUT",
        help="output image (default: LOG with .png; needed for several logs)",
    )
    _image_options(plot, "the plot's own size")
    plot.add_argument("--force", action="store_true", help="overwrite the image if it exists")
    plot.set_defaults(handler=_plot)

    animate = commands.add_parser(
        "animate", help="the run as a video over the map (GIF, or MP4 with ffmpeg installed)"
    )
    animate.add_argument("log", type=Path, help="run log (.mcap)")
    animate.add_argument("--out", type=Path, required=True, metavar="OUT", help="run.gif or run.mp4")
    animate.add_argument("--fps", type=float, default=20.0, help="video frames per second (20)")
    animate.add_argument(
        "--speed", type=float, default=10.0, help="simulated seconds per second of video (10)"
    )
    _image_options(animate, "720x480", default_dpi="80")
    animate.add_argument("--quiet", action="store_true", help="no progress bar")
    animate.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    animate.set_defaults(handler=_animate)

    export = commands.add_parser("export", help="signals as CSV (one file per component) or NPZ")
    export.add_argument("log", type=Path, help="run log (.mcap)")
    export.add_argument("--component", nargs="+", metavar="NAME", help="components to export (default: all)")
    export.add_argument("--to", choices=("csv", "npz"), required=True, help="table format")
    export.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: the log's folder)")
    export.add_argument("--force", action="store_true", help="overwrite tables that exist")
    export.set_defaults(handler=_export)

    diff = commands.add_parser(
        "diff",
        help="per-signal maximum deviation and outcome differences; exit 1 above the tolerance",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Compare two run logs signal by signal. Exit 0 when every common signal and the\n"
        "outcome agree within --tolerance, 1 when not (use it to gate a swapped FMU in CI), 2 on bad input.",
    )
    diff.add_argument("log_a", type=Path, metavar="LOG_A")
    diff.add_argument("log_b", type=Path, metavar="LOG_B")
    diff.add_argument(
        "--tolerance", type=float, default=1e-9, metavar="X", help="largest allowed |A-B| (1e-9)"
    )
    diff.add_argument(
        "--png",
        type=Path,
        metavar="OUT",
        help="also plot the signals that differ: A and B over time, and A - B",
    )
    _image_options(diff, "the plot's own size")
    diff.add_argument("--force", action="store_true", help="overwrite --png if it exists")
    diff.set_defaults(handler=_diff)

    recover = commands.add_parser(
        "recover",
        help="rewrite a cut log (killed run) as a complete, indexed MCAP that every reader opens",
        description="Write everything readable in a log cut short (no summary or footer, e.g. after "
        "SIGKILL) as a complete, indexed MCAP: schemas, channels, messages, metadata and attachments.",
    )
    recover.add_argument("log", type=Path, metavar="IN", help="run log (.mcap), cut or complete")
    recover.add_argument(
        "--out", type=Path, metavar="OUT", help="recovered log (default: IN with .recovered.mcap)"
    )
    recover.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    recover.set_defaults(handler=_recover)

    layout = commands.add_parser(
        "layout",
        help="a Foxglove layout made for the log: every robot's map, plan, scan, pose, goal and "
        "speed in its own colour, the camera over the log's map",
    )
    layout.add_argument("log", type=Path, help="run log (.mcap), of a robot or a fleet")
    layout.add_argument(
        "--out", type=Path, metavar="OUT", help="layout file (default: LOG with .layout.json)"
    )
    layout.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    layout.set_defaults(handler=_layout)


def _image_options(parser, default_size: str, default_dpi: str = "110") -> None:
    parser.add_argument(
        "--dpi", type=float, metavar="N", help=f"pixels per inch: the size of text and lines ({default_dpi})"
    )
    parser.add_argument(
        "--size", type=_size, metavar="WxH", help=f"image size in pixels, e.g. 1600x900 ({default_size})"
    )


def _size(text: str) -> tuple[int, int]:
    width, x, height = text.lower().partition("x")
    if x and width.strip().isdigit() and height.strip().isdigit():
        size = int(width), int(height)
        if 16 <= min(size) and max(size) <= 20_000:
            return size
    raise argparse.ArgumentTypeError(
        f"expected WIDTHxHEIGHT in pixels (16 to 20000 each), e.g. 1600x900, got {text!r}"
    )


def _dpi(args, default: float) -> float:
    if args.dpi is None:
        return default
    if not (10 <= args.dpi <= 1000):
        raise CosimError(f"--dpi must be between 10 and 1000, got {args.dpi:g}")
    return args.dpi


def _open(path: Path):
    """Open a log, print its warnings, and turn any failure to read it into one line."""
    from cosim.logs.reader import open_log

    try:
        log = open_log(path)
    except CosimError:
        raise
    except Exception as error:  # a malformed file must not end in a traceback
        raise CosimError(f"{path}: cannot read the log ({type(error).__name__}: {error})") from None
    for warning in log.warnings:
        print(f"cosim: warning: {path}: {warning}", file=sys.stderr)
    return log


def _guard(path: Path, action):
    try:
        return action()
    except CosimError:
        raise
    except Exception as error:
        raise CosimError(f"{path}: cannot read the log ({type(error).__name__}: {error})") from None


def _info(args) -> int:
    from cosim.logs.info import format_info

    log = _open(args.log)
    print(_guard(args.log, lambda: format_info(log)))
    return 0


def _plot(args) -> int:
    from cosim.logs.plot import DPI, skip_matplotlib_docstrings
    from cosim.logs.signal_plot import plot_any

    skip_matplotlib_docstrings()  # this process draws and exits: no help() text needed
    if len(args.log) > 1 and args.png is None:
        raise CosimError("several logs are overlaid in one picture: name it with --png OUT.png")
    dpi = _dpi(args, DPI)
    png = checked_output(args.png or args.log[0].with_suffix(".png"), args.force)
    logs = [_open(path) for path in args.log]
    signals = [name for text in args.signals for name in text.split(",") if name] if args.signals else None
    with atomic_output(png, args.force) as temporary:
        _guard(args.log[0], lambda: plot_any(logs, temporary, signals, dpi, args.size))
    print(f"wrote {png}")
    return 0


def _animate(args) -> int:
    from cosim.logs.animate import DPI, HEIGHT, WIDTH, animate_log

    checked_output(args.out, args.force)
    dpi, size = _dpi(args, DPI), args.size or (WIDTH, HEIGHT)
    log = _open(args.log)
    with atomic_output(args.out, args.force) as temporary:
        video = _guard(
            args.log, lambda: animate_log(log, temporary, args.fps, args.speed, not args.quiet, dpi, size)
        )
    width, height = video.size
    print(f"wrote {args.out} ({video.frames} frames, {width} x {height} px, {video.seconds:.1f} s)")
    return 0


def _export(args) -> int:
    from cosim.logs.export import export_signals

    log = _open(args.log)
    out_dir = args.out or args.log.parent
    for path in _guard(args.log, lambda: export_signals(log, out_dir, args.to, args.component, args.force)):
        print(f"wrote {path}")
    text = [name for name in log.text_components if not args.component or name in args.component]
    if args.to == "npz" and text:
        print(f"text signals of {', '.join(text)} left out of the .npz (--to csv writes them)")
    return 0


def _diff(args) -> int:
    from cosim.logs.diff import diff_logs, format_report

    if not args.tolerance >= 0:
        raise CosimError(f"--tolerance must be >= 0, got {args.tolerance}")
    if args.png is not None:
        from cosim.logs.plot import DPI, skip_matplotlib_docstrings

        skip_matplotlib_docstrings()
        dpi = _dpi(args, DPI)
        checked_output(args.png, args.force)
    log_a, log_b = _open(args.log_a), _open(args.log_b)
    report = _guard(args.log_a, lambda: diff_logs(log_a, log_b, args.tolerance))
    print(format_report(report, log_a, log_b))
    if args.png is not None:
        from cosim.logs.diff_plot import plot_diff

        with atomic_output(args.png, args.force) as temporary:
            _guard(args.log_a, lambda: plot_diff(report, log_a, log_b, temporary, dpi, args.size))
        print(f"wrote {args.png}")
    return 1 if report.differs else 0


def _recover(args) -> int:
    from cosim.logs.recover import recover_log

    recovery = _guard(args.log, lambda: recover_log(args.log, args.out, args.force))
    for note in recovery.dropped:
        print(f"cosim: warning: {args.log}: {note}", file=sys.stderr)
    state = "complete already" if recovery.was_complete else f"cut: {recovery.problem}"
    print(
        f"wrote {recovery.target}: {recovery.messages} messages on {recovery.channels} channels, "
        f"t = {recovery.start_time:.3f} .. {recovery.end_time:.3f} s, {recovery.metadata} metadata, "
        f"{recovery.attachments} attachments ({recovery.chunks_copied} chunks copied, "
        f"{recovery.chunks_rebuilt} rebuilt; the source was {state})"
    )
    return 0


def _layout(args) -> int:
    import json

    from cosim.logs.layout import foxglove_layout, robot_namespaces

    out = checked_output(args.out or args.log.with_suffix(".layout.json"), args.force)
    log = _open(args.log)
    layout = _guard(args.log, lambda: foxglove_layout(log))
    with atomic_output(out, args.force) as temporary:
        Path(temporary).write_text(json.dumps(layout, indent=1) + "\n", encoding="utf-8")
    robots = [name for name, _ in robot_namespaces(log)]
    what = f"{len(robots)} robots" if log.robots else "the robot"
    print(f"wrote {out} ({what}; Foxglove: Layouts -> Import from file...)")
    return 0
