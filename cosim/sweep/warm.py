"""Warm-up of a local cluster's fork server: its workers start with the run stage loaded and compiled.

A `LocalCluster` of the sweep starts its worker processes by forking them from one server process
(multiprocessing's "forkserver"), which imports the modules it is told to preload before it forks
anything. This module is one of them: when the sweep set `WARM_ENV` (the scenario path and the
overrides of its first run, as JSON) in the server's environment, importing it makes a short run of
that scenario (`WARM_STOP_TIME` simulated seconds) into a scratch folder, which imports the whole
run stage, loads every C kernel the run uses (building any that is missing) and loads the FMUs'
descriptions. Each forked worker inherits all of that, so the work is done once per sweep,
while the client is still importing Dask and planning, instead of once per worker in its first run.

Best effort: whatever goes wrong here is swallowed (the sweep's check of its first run, on a
worker, reports a bad scenario with its own message), and nothing is printed.
"""

from __future__ import annotations

import json
import os

WARM_ENV = "NAVCOSIM_SWEEP_WARM"
WARM_STOP_TIME = 0.5  # [s] of simulated time: a few lidar, controller and pose steps


def warm_up(scenario: str, overrides: list[str]) -> None:
    """Run `scenario` with `overrides` for `WARM_STOP_TIME` s into a scratch folder, then remove it."""
    import contextlib
    import shutil
    import tempfile
    from pathlib import Path

    import cosim.sweep.adapter as adapter

    folder = tempfile.mkdtemp(prefix="navcosim-warm-")
    try:
        with (
            open(os.devnull, "w") as sink,
            contextlib.redirect_stdout(sink),
            contextlib.redirect_stderr(sink),
        ):
            loaded = adapter.load(Path(scenario), [*overrides, f"simulation.stop_time={WARM_STOP_TIME}"])
            adapter.run(loaded, Path(folder) / "warm.mcap")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _from_environment() -> None:
    text = os.environ.pop(WARM_ENV, None)
    if not text:
        return
    try:
        request = json.loads(text)
        warm_up(str(request["scenario"]), [str(item) for item in request["overrides"]])
    except BaseException:  # noqa: BLE001 - a warm-up must never stop the fork server
        pass


_from_environment()
