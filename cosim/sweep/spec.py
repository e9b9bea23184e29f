"""What a sweep varies and how it samples: `--vary` texts, sweep TOML files, grid/random/LHS points.

A varied key is any key `cosim run --set` accepts; its values come in one of three forms:
- `KEY=V1,V2,...`: these values (each in TOML syntax; a bare word is a string).
- `KEY=START:STOP:COUNT`: COUNT evenly spaced values from START to STOP inclusive (integers when
  START and STOP are integers and every value is a whole number; floats rounded to 12 significant
  digits so 0.1 steps print as 0.3, not 0.30000000000000004).
- `KEY=START:STOP` (random and lhs only): the interval [START, STOP], continuous for floats, every
  integer in it when START and STOP are integers.

Methods: `grid` runs every combination (first key slowest); `random` draws `samples` points, each key
independently and uniformly (numpy's default generator seeded with `seed`); `lhs` draws a Latin
hypercube of `samples` points (`scipy.stats.qmc.LatinHypercube`, seeded with `seed`): along every
key, each of `samples` equal strata of [0, 1) holds exactly one point, mapped onto the interval or
onto the list of values. The same specification gives the same points.

Replicates (`--replicates N`): each point runs N times, each time with another value of every seed
key of the scenario (`SEED_KEYS`), derived from the point alone (`replicate_seeds`): the same point
gets the same N seeds in any sweep, and the seeds of one point are distinct.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import CosimError

METHODS = ("grid", "random", "lhs")
SIGNIFICANT_DIGITS = 12
# Most runs of one sweep, checked before any point is made: each run is a task, a results row and a
# log (about 2 MB for a warehouse scenario), so more would fill the scheduler and the disk first.
MAX_POINTS = 100_000
# The scenario keys that seed a random source. The lidar's range noise is the only random source of
# a run (the rest is deterministic), and `lidar.seed` seeds it alone; it matters only when
# `lidar.noise` > 0.
SEED_KEYS = ("lidar.seed",)
NOISE_OF_SEED = {"lidar.seed": "lidar.noise"}  # the key whose value 0 makes the seed irrelevant
SEED_LIMIT = 1 << 31  # replicate seeds are drawn from [0, 2^31)
KEEP_LOGS = ("all", "failed", "none")


@dataclass(frozen=True)
class Dimension:
    """One varied key: either a list of values or an interval [low, high]."""

    key: str
    text: str  # as the user wrote it, for messages
    values: tuple[Any, ...] | None = None
    interval: tuple[float, float] | None = None
    integer: bool = False  # an interval of integers

    def describe(self) -> str:
        return f"--vary {self.key}={self.text}"


@dataclass(frozen=True)
class SweepSpec:
    """What to run: the scenario, the base overrides (`--set`) and how the varied keys are sampled."""

    scenario: Path
    dimensions: tuple[Dimension, ...]
    method: str = "grid"
    samples: int | None = None
    seed: int = 0
    overrides: tuple[str, ...] = ()
    replicates: int = 1  # runs per point, each with its own seeds (`replicate_seeds`)

    @property
    def keys(self) -> tuple[str, ...]:
        """The varied keys."""
        return tuple(dimension.key for dimension in self.dimensions)

    @property
    def seed_keys(self) -> tuple[str, ...]:
        """The keys each replicate sets (none without replicates)."""
        return SEED_KEYS if self.replicates > 1 else ()

    @property
    def table_keys(self) -> tuple[str, ...]:
        """The columns of a run's values in results.csv: the varied keys, then with replicates
        `replicate` (0 to N-1) and each seed key."""
        return (*self.keys, "replicate", *self.seed_keys) if self.replicates > 1 else self.keys


@dataclass
class SweepOptions:
    """How to run it (a sweep file may give these too; the command line wins)."""

    out: Path | None = None
    workers: int | None = None
    scheduler: str | None = None
    resume: bool = False
    keep_logs: str = "all"  # all | failed (runs that did not reach the goal) | none
    extra: dict[str, Any] = field(default_factory=dict)


def toml_value(value: Any) -> str:
    """`value` in TOML syntax, as an override's right-hand side."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise CosimError(f"a varied value must be finite, got {value}")
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise CosimError(f"cannot write {value!r} as a TOML value")


def display_value(value: Any) -> str:
    """A varied value as the results table shows it (strings bare, the rest in TOML syntax)."""
    return value if isinstance(value, str) else toml_value(value)


def _tidy(value: float) -> float:
    return float(f"{value:.{SIGNIFICANT_DIGITS}g}")


def _parse_value(text: str) -> Any:
    """One value as `--set` reads it: TOML syntax, or else the bare word as a string."""
    text = text.strip()
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        raise CosimError(f"the value {text[:40]}... is nested too deeply") from None


def _split_top_level(text: str, separator: str) -> list[str]:
    """Split on `separator` outside brackets, braces and quotes (so `[3.5, 20.0]` stays one value)."""
    parts, depth, quote, current = [], 0, None, []
    for char in text:
        if quote:
            quote = None if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == separator and depth == 0:
            parts.append("".join(current))
            current = []
            continue
        current.append(char)
    parts.append("".join(current))
    return parts


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def parse_vary(text: str) -> Dimension:
    """`KEY=V1,V2,...`, `KEY=START:STOP:COUNT` or `KEY=START:STOP`; `CosimError` when malformed."""
    key, separator, spec = text.partition("=")
    key, spec = key.strip(), spec.strip()
    if not separator or not key or not spec:
        raise CosimError(
            f"--vary {text}: expected KEY=V1,V2,... or KEY=START:STOP:COUNT, e.g. --vary lidar.noise=0:0.1:5"
        )
    if len(_split_top_level(spec, ",")) == 1 and len(_split_top_level(spec, ":")) > 1:
        return _range(key, spec, _split_top_level(spec, ":"))
    items = [item.strip() for item in _split_top_level(spec, ",")]
    if any(not item for item in items):
        raise CosimError(f"--vary {key}={spec}: an empty value in the list")
    return Dimension(key, spec, values=tuple(_parse_value(item) for item in items))


def _range(key: str, spec: str, parts: list[str]) -> Dimension:
    where = f"--vary {key}={spec}"
    if len(parts) not in (2, 3):
        raise CosimError(f"{where}: bad range: expected START:STOP:COUNT or START:STOP")
    start, stop = (_parse_value(part) for part in parts[:2])
    if not (_is_number(start) and _is_number(stop)) or not all(map(math.isfinite, (start, stop))):
        raise CosimError(f"{where}: bad range: START and STOP must be finite numbers")
    if len(parts) == 2:
        if not start < stop:
            raise CosimError(f"{where}: bad range: START must be < STOP for an interval")
        integer = isinstance(start, int) and isinstance(stop, int)
        return Dimension(key, spec, interval=(start, stop), integer=integer)
    count = _parse_value(parts[2])
    if not isinstance(count, int) or isinstance(count, bool) or count < 1:
        raise CosimError(f"{where}: bad range: COUNT must be an integer >= 1, got '{parts[2].strip()}'")
    if count > MAX_POINTS:
        raise CosimError(f"{where}: COUNT {count} is more than a sweep runs ({MAX_POINTS})")
    return Dimension(key, spec, values=_linspace(start, stop, count))


def _linspace(start: float, stop: float, count: int) -> tuple[Any, ...]:
    points = np.linspace(start, stop, count)
    if isinstance(start, int) and isinstance(stop, int) and np.all(points == np.round(points)):
        return tuple(int(round(point)) for point in points)
    return tuple(_tidy(float(point)) for point in points)


def dimension_from_toml(key: str, value: Any, where: str) -> Dimension:
    """A `[vary]` entry of a sweep file: a list of values, a string in `--vary` syntax, or a table
    `{ start, stop, count }` (`count` left out: an interval, for random and lhs)."""
    if isinstance(value, list):
        if not value:
            raise CosimError(f"{where}: [vary] {key}: the list is empty")
        return Dimension(key, toml_value(value), values=tuple(value))
    if isinstance(value, str):
        return parse_vary(f"{key}={value}")
    if isinstance(value, dict):
        unknown = set(value) - {"start", "stop", "count"}
        if unknown or "start" not in value or "stop" not in value:
            raise CosimError(f"{where}: [vary] {key}: expected {{ start = ..., stop = ..., count = ... }}")
        parts = [toml_value(value["start"]), toml_value(value["stop"])]
        if "count" in value:
            parts.append(toml_value(value["count"]))
        return _range(key, ":".join(parts), parts)
    raise CosimError(f"{where}: [vary] {key}: expected a list, a 'START:STOP:COUNT' string or a table")


def is_sweep_file(path: Path) -> bool:
    """A TOML file with a top-level [sweep] table (a scenario has none). Not one when it cannot be
    read or parsed (nested too deeply included): the scenario loader then says why."""
    try:
        return isinstance(tomllib.loads(path.read_text(encoding="utf-8")).get("sweep"), dict)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError):
        return False


def read_sweep_file(path: Path) -> tuple[dict[str, Any], SweepOptions]:
    """The fields of a sweep file (scenario, vary, method, samples, seed, set) and its options (out,
    workers, scheduler). Paths in it are relative to the file's folder."""
    source = str(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CosimError(f"{source}: no such sweep file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise CosimError(f"{source}: cannot read: {error}") from None
    except tomllib.TOMLDecodeError as error:
        raise CosimError(f"{source}: TOML syntax error: {error}") from None
    unknown = set(raw) - {"sweep", "vary"}
    if unknown:
        raise CosimError(
            f"{source}: unknown section [{sorted(unknown)[0]}] (a sweep file has [sweep], [vary])"
        )
    table = raw.get("sweep", {})
    known = {"scenario", "method", "samples", "seed", "set", "out", "workers", "scheduler"}
    known |= {"replicates", "keep_logs"}
    for key in table:
        if key not in known:
            from cosim.scenario.schema import did_you_mean

            raise CosimError(f"{source}: [sweep] {key}: unknown key{did_you_mean(key, known)}")
    base = path.resolve().parent
    if not isinstance(table.get("scenario"), str):
        raise CosimError(f"{source}: [sweep] scenario: missing (the scenario file, relative to this file)")
    overrides = table.get("set", [])
    if not isinstance(overrides, list) or not all(isinstance(item, str) for item in overrides):
        raise CosimError(f"{source}: [sweep] set: expected a list of 'key=value' strings")
    vary = raw.get("vary", {})
    if not isinstance(vary, dict):
        raise CosimError(f"{source}: [vary]: expected a table of key = values")
    fields = {
        "scenario": base / table["scenario"],
        "dimensions": [dimension_from_toml(key, value, source) for key, value in _flat(vary)],
        "method": _typed(table, "method", str, source),
        "samples": _typed(table, "samples", int, source),
        "seed": _typed(table, "seed", int, source),
        "overrides": list(overrides),
        "replicates": _typed(table, "replicates", int, source),
    }
    out = _typed(table, "out", str, source)
    options = SweepOptions(
        out=base / out if out is not None else None,
        workers=_typed(table, "workers", int, source),
        scheduler=_typed(table, "scheduler", str, source),
    )
    keep_logs = _typed(table, "keep_logs", str, source)
    if keep_logs is not None:
        options.keep_logs = checked_keep_logs(keep_logs, f"{source}: [sweep] keep_logs")
    return fields, options


def checked_keep_logs(value: str, where: str = "--keep-logs") -> str:
    if value not in KEEP_LOGS:
        raise CosimError(f"{where} {value}: expected all, failed or none")
    return value


def _flat(table: dict, prefix: str = "") -> list[tuple[str, Any]]:
    """`[vary]` keys may be quoted dotted names (`"lidar.noise" = ...`) or nested tables."""
    items = []
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and not ({"start", "stop"} <= set(value)):
            items.extend(_flat(value, f"{name}."))
        else:
            items.append((name, value))
    return items


def _typed(table: dict, key: str, kind: type, source: str) -> Any:
    value = table.get(key)
    if value is not None and (not isinstance(value, kind) or isinstance(value, bool)):
        raise CosimError(f"{source}: [sweep] {key}: must be {'an integer' if kind is int else 'a string'}")
    return value


def make_spec(
    scenario: Path,
    dimensions: Sequence[Dimension],
    method: str = "grid",
    samples: int | None = None,
    seed: int | None = None,
    overrides: Sequence[str] = (),
    replicates: int | None = None,
) -> SweepSpec:
    """Check the combination of options; the keys are checked later, against the scenario."""
    replicates = 1 if replicates is None else replicates
    if replicates < 1:
        raise CosimError(f"--replicates {replicates}: must be >= 1")
    if method not in METHODS:
        from cosim.scenario.schema import did_you_mean

        raise CosimError(f"--method {method}: expected grid, random or lhs{did_you_mean(method, METHODS)}")
    if not dimensions:
        raise CosimError("nothing to vary: give at least one --vary KEY=V1,V2,... or KEY=START:STOP:COUNT")
    seen: set[str] = set()
    for dimension in dimensions:
        if dimension.key in seen:
            raise CosimError(f"{dimension.describe()}: {dimension.key} is varied twice")
        seen.add(dimension.key)
        if replicates > 1 and dimension.key in SEED_KEYS:
            raise CosimError(
                f"{dimension.describe()}: --replicates {replicates} sets {dimension.key} in every run; "
                "vary it or replicate, not both"
            )
    if method == "grid":
        if samples is not None:
            raise CosimError("--samples applies to --method random and lhs; a grid runs every combination")
        for dimension in dimensions:
            if dimension.values is None:
                raise CosimError(
                    f"{dimension.describe()}: a grid needs a list or START:STOP:COUNT, not an interval"
                )
        size = math.prod(len(dimension.values) for dimension in dimensions)
        if size * replicates > MAX_POINTS:
            shape = " x ".join(str(len(dimension.values)) for dimension in dimensions)
            times = f" x {replicates} replicates" if replicates > 1 else ""
            raise CosimError(
                f"the grid has {size * replicates} points ({shape}{times}), more than a sweep runs "
                f"({MAX_POINTS}); vary fewer values, or sample with --method lhs --samples N"
            )
    elif samples is None or samples < 1:
        raise CosimError(f"--method {method} needs --samples N (N >= 1)")
    elif samples * replicates > MAX_POINTS:
        times = f" x --replicates {replicates}" if replicates > 1 else ""
        raise CosimError(f"--samples {samples}{times}: more than a sweep runs ({MAX_POINTS})")
    if seed is not None and seed < 0:
        raise CosimError(f"--seed {seed}: must be >= 0")
    return SweepSpec(
        Path(scenario), tuple(dimensions), method, samples, seed or 0, tuple(overrides), replicates
    )


def replicate_seeds(point: Sequence[str], count: int) -> list[int]:
    """`count` distinct seeds in [0, 2^31) for the replicates of the point whose varied overrides
    are `point`: from SHA-256 of the point and a counter, so they depend on the point alone."""
    seeds: list[int] = []
    counter = 0
    while len(seeds) < count:
        text = "navcosim replicate\0" + "\0".join(point) + f"\0{counter}"
        seed = int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little") % SEED_LIMIT
        counter += 1
        if seed not in seeds:
            seeds.append(seed)
    return seeds


def vary_dimensions(vary: Mapping[str, Any] | Sequence[str] | None) -> list[Dimension]:
    """The Python API's `vary`: `{"lidar.noise": [0.0, 0.1], "lidar.seed": "0:3:4"}` or a list of
    `--vary` texts."""
    if vary is None:
        return []
    if isinstance(vary, Mapping):
        return [dimension_from_toml(key, value, "vary") for key, value in vary.items()]
    if isinstance(vary, str):
        return [parse_vary(vary)]
    return [parse_vary(text) for text in vary]


def sample_points(spec: SweepSpec) -> list[tuple[Any, ...]]:
    """The sweep's points, one tuple of values (in the order of `spec.dimensions`) per run."""
    dimensions = spec.dimensions
    if spec.method == "grid":
        return [tuple(point) for point in itertools.product(*(d.values for d in dimensions))]
    count = spec.samples
    if spec.method == "random":
        generator = np.random.default_rng(spec.seed)
        columns = [_draw_random(d, count, generator) for d in dimensions]
    else:
        from scipy.stats import qmc

        unit = qmc.LatinHypercube(d=len(dimensions), rng=np.random.default_rng(spec.seed)).random(count)
        columns = [_from_unit(d, unit[:, i]) for i, d in enumerate(dimensions)]
    return [tuple(column[i] for column in columns) for i in range(count)]


def _draw_random(dimension: Dimension, count: int, generator: np.random.Generator) -> list[Any]:
    if dimension.values is not None:
        return [dimension.values[i] for i in generator.integers(0, len(dimension.values), count)]
    low, high = dimension.interval
    if dimension.integer:
        return [int(v) for v in generator.integers(low, high + 1, count)]
    return [_tidy(float(v)) for v in generator.uniform(low, high, count)]


def _from_unit(dimension: Dimension, unit: np.ndarray) -> list[Any]:
    """Map points of [0, 1) onto the dimension, keeping equal strata equal in size."""
    if dimension.values is not None:
        indices = np.minimum((unit * len(dimension.values)).astype(int), len(dimension.values) - 1)
        return [dimension.values[i] for i in indices]
    low, high = dimension.interval
    if dimension.integer:
        return [int(v) for v in np.minimum(low + np.floor(unit * (high - low + 1)), high)]
    return [_tidy(float(low + u * (high - low))) for u in unit]
