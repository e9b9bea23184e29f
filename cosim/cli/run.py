"""`cosim run SCENARIO|SYSTEM.ssp`: run a scenario (or an SSP archive), print the summary, write the
MCAP log and a PNG beside it.

Exit codes: 0 goal reached (an FMU-only SSP: the run completed), 1 not reached (stop time,
collision, interrupted), 2 bad input or a failed FMU (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cosim.errors import CosimError


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run a scenario co-simulation and log it to MCAP",
        description="Run a scenario (TOML): plan, step the FMUs and the lidar, log every signal to MCAP.",
    )
    parser.add_argument(
        "scenario",
        type=Path,
        help="scenario file (.toml), e.g. scenarios/example_commented.toml, or an SSP 1.0 archive (.ssp)",
    )
    parser.add_argument(
        "--out", type=Path, help="log file (default: [output].log, logs/<scenario>-<timestamp>.mcap)"
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key, e.g. --set vfh.robot_radius=0.6 (repeatable; same validation)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.add_argument(
        "--max-steps",
        type=_positive_int,
        metavar="N",
        help="allow up to N macro steps (default: [simulation].max_steps, 100000000)",
    )
    parser.add_argument("--no-plot", action="store_true", help="do not draw the PNG beside the log")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no summary table")
    parser.add_argument(
        "--live",
        action="store_true",
        help="stream every channel to a Foxglove WebSocket server while the run goes (open "
        "ws://127.0.0.1:PORT in Foxglove); paced at --realtime 1 unless told otherwise. A "
        "geometry_msgs/PoseStamped a client publishes on /goal_pose sets a new goal (replanned); "
        "services /navcosim/pause, resume, step, speed and goal control the run",
    )
    parser.add_argument("--port", type=int, default=8765, help="the live view's port (8765; 0: any free one)")
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="the live view's address (127.0.0.1; another one lets other hosts watch and control the run)",
    )
    parser.add_argument(
        "--live-token",
        nargs="?",
        const="",
        metavar="TOKEN",
        help="with --live: clients must give ?token=TOKEN in the URL (or Authorization: Bearer). "
        "Without TOKEN: $NAVCOSIM_LIVE_TOKEN, else a random one (printed in the URL); a TOKEN on "
        "the command line is visible to other users (ps)",
    )
    parser.add_argument(
        "--realtime",
        type=float,
        metavar="R",
        help="pace the run at R x the wall clock (default with --live: 1; without: as fast as possible)",
    )
    parser.add_argument(
        "--linger",
        type=float,
        metavar="SECONDS",
        help="with --live: keep serving this long after the run (default: until Ctrl-C)",
    )
    parser.set_defaults(handler=_handler)


def _live_sink(args, step: float = 0.01):
    """The sink of --live / --realtime (None: neither), after checking their values. `step` [s]:
    the run's macro step (the live view's single step)."""
    if args.realtime is not None and not args.realtime > 0:
        raise CosimError(f"--realtime must be > 0, got {args.realtime}")
    if args.linger is not None and not args.linger >= 0:
        raise CosimError(f"--linger must be >= 0, got {args.linger}")
    if not args.live:
        if (
            args.linger is not None
            or args.port != 8765
            or args.host != "127.0.0.1"
            or args.live_token is not None
        ):
            raise CosimError("--port, --host, --live-token and --linger need --live")
        if args.realtime is None:
            return None
        from cosim.record.live import Pacer

        return Pacer(args.realtime)
    if not 0 <= args.port <= 65535:
        raise CosimError(f"--port must be 0..65535, got {args.port}")
    token = _live_token(args.live_token)
    loopback = _is_loopback(args.host)
    from cosim.record.live import FoxgloveLive

    live = FoxgloveLive(
        args.port, 1.0 if args.realtime is None else args.realtime, args.host, token=token, step=step
    )
    if not loopback:
        guard = "only clients with the token" if token else "anyone who reaches it; give --live-token"
        print(
            f"cosim: warning: --host {args.host} is not a loopback address: {guard} can watch and "
            "control the run (unencrypted ws://)",
            file=sys.stderr,
            flush=True,
        )
    print(f"live view: {live.url} (Foxglove: Open connection, WebSocket)", file=sys.stderr, flush=True)
    return live


def _live_token(given: str | None) -> str | None:
    """--live-token's token: None (no token), the one given, $NAVCOSIM_LIVE_TOKEN, or a new one."""
    if given is None:
        return None
    import secrets

    token = given or os.environ.get("NAVCOSIM_LIVE_TOKEN", "") or secrets.token_urlsafe(18)
    if not all(c.isalnum() or c in "-._~" for c in token):
        raise CosimError("--live-token: use letters, digits and - . _ ~ only (it goes into a URL)")
    return token


def _is_loopback(host: str) -> bool:
    """Whether every address `host` names is a loopback one (one line, exit 2, if none)."""
    import ipaddress
    import socket

    try:
        addresses = {info[4][0] for info in socket.getaddrinfo(host, None, proto=socket.IPPROTO_TCP)}
    except (OSError, UnicodeError) as error:
        raise CosimError(f"--host {host!r}: not an address of this machine ({error})") from None
    return all(ipaddress.ip_address(address.split("%")[0]).is_loopback for address in addresses)


def _announce(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _tqdm_version_without_metadata() -> None:
    """Before the progress bar's first import of tqdm: tqdm's package imports `tqdm.version`, which
    asks importlib.metadata for tqdm's version (importing it and its email parser: ~8 ms of a run
    that shows the bar). When tqdm's installed dist-info gives the version directly (the string
    importlib.metadata would give: `cosim.record.logfile.dist_info_version`), `tqdm.version` is a
    module holding it; otherwise tqdm finds its version itself."""
    if "tqdm" in sys.modules or "tqdm.version" in sys.modules:
        return
    from types import ModuleType

    from cosim.record.logfile import dist_info_version

    version = dist_info_version("tqdm")
    if version is None:
        return
    module = ModuleType("tqdm.version", "`tqdm` version, as its installed dist-info names it.")
    module.__version__ = version
    sys.modules[module.__name__] = module


def _handler(args) -> int:
    if not args.quiet:
        _tqdm_version_without_metadata()
    if args.scenario.suffix.lower() == ".ssp":
        return _run_ssp(args)
    program = getattr(args, "program", False)
    if program:
        from cosim import hold_collector

        hold_collector()  # until the run's loop starts (`cosim.release_collector`)
    plotter = _plot_process() if program and not args.no_plot else None
    try:
        return _run_scenario(args, plotter)
    finally:
        if plotter is not None:
            plotter.cancel()  # a no-op after it drew


def _plot_process():
    """The plot process (`cosim.cli.plotter`), forked as early as it can be: before the run's
    modules are imported, its kernels and FMUs built (whose threads import modules: the child then
    holds none of their threads or locks) and the live view's server started, so that matplotlib
    is imported and the figure drafted while all that and the run go. numpy is imported first:
    both processes use it, and the child then inherits it. The scenario follows once loaded
    (`PlotProcess.outline`)."""
    import numpy  # noqa: F401

    from cosim.cli.plotter import PlotProcess

    return PlotProcess.start(outline_follows=True)


def _run_scenario(args, plotter) -> int:
    from cosim.fmi.builtin import prepare

    announce = None if args.quiet else _announce
    prepare((), announce=announce)  # the kernels, compiled while the modules that load them import
    from cosim.scenario.load import check_scenario_world, load_scenario

    overrides = list(args.overrides)
    if args.max_steps is not None:
        overrides.append(f"simulation.max_steps={args.max_steps}")
    # The FMUs the file names start building before the start and goal are checked (which loads
    # kernels that may still be compiling).
    scenario = load_scenario(args.scenario, overrides, check_world=False, fleet=True)
    if plotter is not None and (hasattr(scenario, "robots") or not scenario.plot):
        plotter.cancel()  # a fleet's plot is drawn here (`_plot_fleet`); or no plot
        plotter = None
    elif plotter is not None:
        plotter.outline(scenario)
    if hasattr(scenario, "robots"):  # a fleet ([[robots]]): cosim.navigation.fleet
        by_version: dict[int, list[str]] = {}  # the robots' project FMUs, built side by side
        for robot in scenario.robots:
            by_version.setdefault(robot.scenario.fmi_version, []).extend(robot.scenario.project_fmus)
        for version, fmus in by_version.items():
            prepare(fmus, version, kernels=(), announce=announce)
        check_scenario_world(scenario)
        from cosim.navigation.fleet import run_fleet_command

        plot = scenario.first.plot and not args.no_plot
        sink = _live_sink(args, scenario.first.macro_step)
        try:
            code = run_fleet_command(
                args, scenario, (lambda path: _plot_fleet(path, args.quiet)) if plot else None, sink
            )
            if args.live and code != 2:
                wait = "until Ctrl-C" if args.linger is None else f"for {args.linger:g} s"
                print(f"live view: run ended; serving {sink.url} {wait}", file=sys.stderr, flush=True)
                sink.linger(args.linger)
            return code
        finally:
            if args.live:
                sink.stop()
    prepare(scenario.project_fmus, scenario.fmi_version, kernels=(), announce=announce)
    check_scenario_world(scenario)
    from cosim.navigation.outcome import avoider_name, format_summary
    from cosim.navigation.run import run_scenario

    sink = _live_sink(args, scenario.macro_step)
    try:
        goals = sink if args.live else None  # a client's /goal_pose, the control services
        result = run_scenario(
            scenario,
            args.out,
            progress=not args.quiet,
            sink=sink,
            force=args.force,
            goals=goals,
            trace=scenario.plot and not args.no_plot,  # the plot's in-memory copy, only for a plot
        )
        if not args.quiet:
            print(
                format_summary(
                    scenario.name, result.outcome, result.log_path, result.wall_time, avoider_name(scenario)
                )
            )
            if result.ended:
                print(f"ended: {result.ended}")
        if result.failure is not None:
            print(
                f"cosim: error: {result.failure}; log (up to the failure): {result.log_path}", file=sys.stderr
            )
            return 2
        if scenario.plot and not args.no_plot:
            _plot(result.log_path, args.quiet, result.trace, getattr(args, "program", False), plotter)
        if args.live and result.outcome.reason != "interrupted":
            wait = "until Ctrl-C" if args.linger is None else f"for {args.linger:g} s"
            print(f"live view: run ended; serving {sink.url} {wait}", file=sys.stderr, flush=True)
            sink.linger(args.linger)
        return result.exit_code
    finally:
        if args.live:
            sink.stop()


def _run_ssp(args) -> int:
    if args.live or args.realtime is not None:
        raise CosimError(f"{args.scenario}: --live and --realtime run scenario files (.toml), not SSP")
    from cosim.ssp.run import SspRunResult, run_ssp, summary

    overrides = list(args.overrides)
    if args.max_steps is not None:  # as for a scenario
        overrides.append(f"simulation.max_steps={args.max_steps}")
    result = run_ssp(args.scenario, args.out, overrides, progress=not args.quiet, force=args.force)
    if isinstance(result, SspRunResult):
        if not args.quiet:
            print(summary(result))
    else:  # an SSP navcosim exported: the scenario's run
        from cosim.navigation.outcome import avoider_name, format_summary

        scenario, result = result
        if not args.quiet:
            print(
                format_summary(
                    scenario.name, result.outcome, result.log_path, result.wall_time, avoider_name(scenario)
                )
            )
        if result.failure is None and scenario.plot and not args.no_plot:
            _plot(result.log_path, args.quiet)
    if result.failure is not None:
        print(f"cosim: error: {result.failure}; log (up to the failure): {result.log_path}", file=sys.stderr)
        return 2
    return result.exit_code


def _plot(log_path: Path, quiet: bool, trace=None, program: bool = False, plotter=None) -> None:
    """Draw the PNG beside the log: from the run's in-memory trace when it has one (the same picture
    as from the log, without reading it back), else from the log. In `cosim` itself (`program`),
    the ~10^5 objects of matplotlib and the figure are never walked by the cyclic collector: it is
    off while they are made, and they are frozen (`gc.freeze`) before it is on again (~25 ms
    of collections otherwise, just before the process exits). `plotter` (`cosim.cli.plotter`)
    draws it when given."""
    from cosim import hold_collector, release_collector

    if program:
        hold_collector()
    try:
        _draw_plot(log_path, quiet, trace, plotter)
    finally:
        release_collector()  # a no-op unless held


def _draw_plot(log_path: Path, quiet: bool, trace, plotter) -> None:
    try:
        from cosim.logs import plot
    except ImportError:
        print("cosim: note: no plot (cosim.logs.plot is not available)", file=sys.stderr)
        return

    def draw_source(source, partial: Path) -> str | None:
        if plotter is not None:
            return plotter.draw_source(source, partial)
        plot.skip_matplotlib_docstrings()  # this process draws and exits: no help() text needed
        plot.draw(plot.collect(source), partial)
        return None

    def draw(partial: Path) -> str | None:
        if trace is not None and not trace.dropped:
            return draw_source(plot.TraceSource(trace), partial)
        from cosim.logs.reader import open_log

        with open_log(log_path) as log:
            return draw_source(log, partial)

    _png_beside(log_path, quiet, draw)


def _plot_fleet(log_path: Path, quiet: bool) -> None:
    """Draw a fleet run's PNG beside its log, from the log (`cosim.logs.fleet_plot`)."""

    def draw(partial: Path) -> None:
        from cosim.logs.fleet_plot import plot_fleet
        from cosim.logs.plot import skip_matplotlib_docstrings
        from cosim.logs.reader import open_log

        skip_matplotlib_docstrings()
        with open_log(log_path) as log:
            plot_fleet(log, partial)

    _png_beside(log_path, quiet, draw)


def _png_beside(log_path: Path, quiet: bool, draw) -> None:
    """The log's PNG (same stem) from `draw(partial)`, which returns None or why it drew nothing.
    Drawn beside and renamed into place, so an interrupt never leaves half a PNG; a failure is a
    note, not an error (the run and its log stand)."""
    png_path = log_path.with_suffix(".png")
    partial = png_path.with_name(f".{png_path.stem}.{os.getpid()}.png")
    try:
        if (problem := draw(partial)) is not None:
            print(f"cosim: note: no plot: {problem}", file=sys.stderr)
            return
        os.replace(partial, png_path)
    except (CosimError, OSError) as error:
        print(f"cosim: note: no plot: {error}", file=sys.stderr)
        return
    finally:
        partial.unlink(missing_ok=True)
    if not quiet:
        print(f"plot: {png_path}")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text[:80]!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value
