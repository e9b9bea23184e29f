"""The sweep's one door to the scenario and run stages.

Loading a scenario with overrides, checking that it builds, running it to a log and reading its
outcome as strings all go through here, so when `cosim.scenario.load` or `cosim.navigation.run`
change, the sweep follows them in this file alone. The same calls run on the client (to validate a
sweep before it starts) and on the workers (to run it).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import CosimError


@dataclass(frozen=True)
class RunOutput:
    """What a run that reached its end left: the log's `outcome` metadata (strings, SI units) and,
    when the run did not reach an outcome of its own (an FMU failed, it was interrupted), why."""

    outcome: dict[str, str]
    failure: str | None


def load(path: Path, overrides: tuple[str, ...] | list[str], check_world: bool = True):
    """The validated `Scenario` of `path` with `--set`-style overrides; `CosimError` (one line) if bad."""
    from cosim.scenario.load import load_scenario

    return load_scenario(path, list(overrides), check_world=check_world)


def raw_toml(text: str, source: str, overrides: tuple[str, ...] | list[str]) -> dict[str, Any]:
    """The scenario's TOML as parsed, with the overrides applied as `cosim run --set` applies them."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise CosimError(f"{source}: TOML syntax error: {error}") from None
    return with_overrides(raw, source, overrides)


def with_overrides(
    raw: dict[str, Any], source: str, overrides: tuple[str, ...] | list[str]
) -> dict[str, Any]:
    """`raw` (parsed scenario TOML, changed in place) with the overrides applied as `--set` applies them."""
    from cosim.scenario.load import apply_override

    for override in overrides:
        apply_override(raw, override, source)
    return raw


def check_builds(scenario) -> None:
    """Build the system of `scenario` without starting it: the map loads, a path is found, every FMU
    loads and every parameter and port exists. No FMU is instantiated and no log is written."""
    from cosim.navigation.build import build_run

    build_run(scenario)


def noise_levels(scenario) -> dict[str, float]:
    """The noise each seed key of `cosim.sweep.spec.NOISE_OF_SEED` seeds, in `scenario` (std [m])."""
    return {"lidar.noise": float(scenario.lidar.noise)}


def outcome_keys() -> tuple[str, ...]:
    """The keys of a log's `outcome` metadata, in the order the log writes them."""
    from cosim.navigation.outcome import Outcome, outcome_metadata

    return tuple(outcome_metadata(Outcome()))


def run(scenario, log_path: Path) -> RunOutput:
    """Run `scenario` to `log_path` without a progress bar. Raises `CosimError` for bad input (then
    no log, or one renamed `<name>.failed.mcap` when the run broke after the log was created)."""
    from cosim.navigation.outcome import outcome_metadata
    from cosim.navigation.run import run_scenario

    result = run_scenario(scenario, log_path, progress=False, trace=False)  # a sweep draws no run PNG
    outcome = outcome_metadata(result.outcome)
    failure = result.failure
    if failure is None and outcome.get("reason") == "interrupted":
        failure = "interrupted (the worker was asked to stop)"
    return RunOutput(outcome, failure)
