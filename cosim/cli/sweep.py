"""`cosim sweep SCENARIO|SWEEP.toml`: vary scenario keys, run every point on Dask, write a table.

Exit codes: 0 every run completed (ran to an outcome: goal reached, collision or stop time), 1 some
runs failed (each is a row with its error), 2 bad input, an unreachable scheduler or an unwritable
output folder (one line on stderr); interrupted, 1 as every `cosim` command (finished rows and
logs are kept, and the command says how many and how to `--resume`). `--dry-run` checks the sweep
as a run would and lists its runs without running them (0 or 2).
"""

from __future__ import annotations

import atexit
import gc
import sys
from pathlib import Path

_exit_registered = False


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="run a scenario over many parameter values on a Dask cluster",
        description=(
            "Run a scenario for every point of a parameter sweep on Dask (a local cluster, or any "
            "scheduler); write DIR/runs/<run-id>.mcap, DIR/results.csv and DIR/sweep.png."
        ),
    )
    parser.add_argument(
        "scenario", type=Path, help="scenario file (.toml), or a sweep file with [sweep] and [vary] tables"
    )
    parser.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=VALUES",
        help="a key to vary: KEY=V1,V2,... or KEY=START:STOP:COUNT (KEY=START:STOP for random/lhs); "
        "any key --set accepts; repeatable",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a key in every run, e.g. --set simulation.stop_time=60 (repeatable)",
    )
    parser.add_argument("--method", choices=("grid", "random", "lhs"), help="sampling (default: grid)")
    parser.add_argument("--samples", type=int, metavar="N", help="number of points for random and lhs")
    parser.add_argument("--seed", type=int, metavar="S", help="seed of random and lhs sampling (default 0)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=int, metavar="N", help="processes of the local cluster (default: one per core)"
    )
    where.add_argument(
        "--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786"
    )
    parser.add_argument(
        "--out", type=Path, metavar="DIR", help="sweep folder (default: logs/sweep-<scenario>-<timestamp>)"
    )
    parser.add_argument("--resume", action="store_true", help="skip runs already completed in DIR")
    parser.add_argument(
        "--replicates",
        type=int,
        metavar="N",
        help="run each point N times, each with its own lidar.seed derived from the point; "
        "DIR/aggregate.csv holds each point's counts by outcome and mean, std, min, max",
    )
    parser.add_argument(
        "--keep-logs",
        choices=("all", "failed", "none"),
        help="logs kept in DIR/runs: all (default), failed (runs that did not reach the goal) or "
        "none (a small outcome record per run instead, so --resume still checks each row)",
    )
    parser.add_argument("--no-plot", action="store_true", help="do not draw DIR/sweep.png")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no summary table")
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="check the sweep and list its runs (run id, varied values) without running them or writing DIR",
    )
    parser.set_defaults(handler=_handler)


def _freeze_at_exit() -> None:
    """At interpreter exit, move every object out of the cyclic collector's reach (`gc.freeze`).

    The sweep leaves Dask, tornado, numpy, Matplotlib and their caches in this process; the
    collections the interpreter makes while it finalises then scan them all (about 0.2 s) only to
    free memory the exit gives back anyway. Nothing is skipped that writes: atexit handlers still
    run, streams are still flushed and closed, and every file the sweep writes is closed before
    `run_sweep` returns. Only at exit, so a process that goes on after a sweep keeps collecting."""
    global _exit_registered
    if not _exit_registered:
        atexit.register(gc.freeze)
        _exit_registered = True


def resume_command(args, out_dir: Path) -> str:
    """The command line that finishes an interrupted sweep: its options, `--resume --out DIR`."""
    import shlex

    words = ["cosim", "sweep", str(args.scenario)]
    for vary in args.vary:
        words += ["--vary", vary]
    for override in args.overrides:
        words += ["--set", override]
    for option in ("method", "samples", "seed", "workers", "scheduler", "replicates", "keep_logs"):
        value = getattr(args, option)
        if value is not None:
            words += [f"--{option.replace('_', '-')}", str(value)]
    words += ["--no-plot"] * args.no_plot + ["--quiet"] * args.quiet
    return shlex.join([*words, "--out", str(out_dir), "--resume"])


def _handler(args) -> int:
    from cosim.sweep import build

    spec, options = build(
        args.scenario,
        args.vary,
        args.method,
        args.samples,
        args.seed,
        args.overrides,
        args.out,
        args.workers,
        args.scheduler,
        args.resume,
        args.replicates,
        args.keep_logs,
    )
    if args.dry_run:
        return _dry_run(spec, options)
    # `cosim` itself draws sweep.png in a plot process (`cosim.cli.plotter`), as `cosim run` draws
    # its PNG, forked as soon as the sweep is parsed (numpy imported, which it shares): it imports
    # matplotlib (~0.2 s of CPU) while this process imports Dask and the run stage on the other
    # core, instead of later, beside the fork server's warm-up and the cluster's start, which the
    # first runs wait for. (The local cluster's fork server starts in `run_sweep`, before the sweep
    # is planned: it warms up on the sweep's first run.)
    child = None
    if getattr(args, "program", False) and not args.no_plot:
        from cosim.cli.plotter import PlotProcess

        child = PlotProcess.start(drawer=_draw_png)
    try:
        return _sweep(args, spec, options, child)
    finally:
        if child is not None:  # no plot (an error, an interrupt, every run kept): it ends at once
            child.cancel()


def _draw_png(arguments: dict, png_path: Path):
    """The plot process's drawer (`cosim.sweep.plot.draw_png`), imported there only when it draws."""
    from cosim.sweep.plot import draw_png

    return draw_png(arguments, png_path)


def _sweep(args, spec, options, child) -> int:
    _freeze_at_exit()
    from cosim.sweep.engine import run_sweep

    try:
        result = run_sweep(
            spec,
            options,
            progress=not args.quiet,
            plot=not args.no_plot,
            exits=True,
            plotter=None if child is None else lambda: child,
        )
    except KeyboardInterrupt as interrupt:
        kept = getattr(interrupt, "sweep_kept", None)
        if kept is not None:
            print(f"cosim sweep: {kept}", file=sys.stderr)
            print(
                f"cosim sweep: to run the rest: {resume_command(args, interrupt.sweep_out)}", file=sys.stderr
            )
        raise
    if not args.quiet:
        print(result.summary())
    return result.exit_code


def _dry_run(spec, options) -> int:
    """What `cosim sweep` would run, checked as it checks it, one line a run; nothing is written."""
    from cosim.sweep.engine import check_options, plan
    from cosim.sweep.spec import display_value

    check_options(options)
    _, runs, name = plan(spec)
    print(f"{name}: {len(runs)} runs ({spec.method}) of {spec.scenario}")
    for run in runs:
        values = " ".join(
            f"{key}={display_value(value)}" for key, value in zip(spec.table_keys, run.values, strict=True)
        )
        print(f"{run.run_id}  {values}")
    return 0
