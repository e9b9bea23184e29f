"""Typed reading of one TOML table with errors that name the file and the key path.

`TableReader` pulls keys out of a parsed TOML table one at a time, checking type and range; what
is left at `finish()` is an unknown key, reported with a "did you mean". Every error is one line:
`scenarios/x.toml: [vfh].robot_radius: must be >= 0, got -1`.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable
from typing import Any

from cosim.errors import CosimError

REQUIRED = object()


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """' (did you mean 'x'?)' for the closest candidate, or '' when nothing is close."""
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def describe(value: Any) -> str:
    """A value as the user wrote it, for error messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"'{value}'"
    if isinstance(value, dict):
        return "a table"
    return repr(value)


def is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class TableReader:
    """Reads the keys of one table; `where` is its printable path, e.g. `[vfh]` or `[[obstacles]][2]`."""

    def __init__(self, source: str, where: str, table: Any):
        self.source = source
        self.where = where
        if not isinstance(table, dict):
            raise CosimError(f"{source}: {where}: must be a table, got {describe(table)}")
        self.table = table
        self.used: set[str] = set()

    def error(self, key: str | None, problem: str) -> CosimError:
        if not self.where:  # the top level: its keys are the sections
            return CosimError(f"{self.source}: [{key}]: {problem}")
        where = f"{self.where}.{key}" if key else self.where
        return CosimError(f"{self.source}: {where}: {problem}")

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str, default: Any = REQUIRED) -> Any:
        self.used.add(key)
        if key not in self.table:
            if default is REQUIRED:
                raise self.error(key, "missing required key")
            return default
        return self.table[key]

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive_minimum: bool = False,
    ) -> float:
        """A finite number (TOML integer or float) in [minimum, maximum] (or (minimum, ...])."""
        value = self.raw(key, default)
        if value is None:
            return value
        if not is_number(value):
            raise self.error(key, f"must be a number, got {describe(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, f"must be finite, got {value}")
        self._check_range(key, value, minimum, maximum, exclusive_minimum)
        return value

    def integer(self, key: str, default: Any = REQUIRED, minimum: int | None = None) -> int:
        value = self.raw(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.error(key, f"must be an integer, got {describe(value)}")
        self._check_range(key, value, minimum, None, False)
        return value

    def boolean(self, key: str, default: Any = REQUIRED) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, got {describe(value)}")
        return value

    def string(self, key: str, default: Any = REQUIRED, choices: tuple[str, ...] | None = None) -> str:
        value = self.raw(key, default)
        if value is None:
            return value
        if not isinstance(value, str):
            raise self.error(key, f"must be a string, got {describe(value)}")
        if choices is not None and value not in choices:
            listed = ", ".join(f"'{c}'" for c in choices)
            raise self.error(key, f"must be one of {listed}, got '{value}'{did_you_mean(value, choices)}")
        return value

    def numbers(self, key: str, default: Any = REQUIRED, length: int | None = None) -> tuple[float, ...]:
        """A list of finite numbers, of exactly `length` items when given."""
        value = self.raw(key, default)
        if value is None:
            return value
        return self.check_numbers(key, value, length)

    def check_numbers(self, key: str, value: Any, length: int | None) -> tuple[float, ...]:
        if not isinstance(value, list) or not all(is_number(item) for item in value):
            raise self.error(key, f"must be a list of numbers, got {describe(value)}")
        if length is not None and len(value) != length:
            raise self.error(key, f"must have {length} numbers, got {len(value)}")
        if not all(math.isfinite(item) for item in value):
            raise self.error(key, "must hold finite numbers")
        return tuple(float(item) for item in value)

    def interval(
        self, key: str, default: Any = REQUIRED, minimum: float | None = None
    ) -> tuple[float, float]:
        """[low, high] with low <= high (and low >= minimum)."""
        low_high = self.numbers(key, default, length=2)
        low, high = low_high
        if low > high:
            raise self.error(key, f"low {low:g} > high {high:g}")
        if minimum is not None and low < minimum:
            raise self.error(key, f"low must be >= {minimum:g}, got {low:g}")
        return low, high

    def table_of(self, key: str) -> TableReader:
        return TableReader(self.source, f"{self.where}.{key}", self.raw(key, {}))

    def finish(self, extra_allowed: Callable[[str], bool] | None = None) -> None:
        """Raise on the first key nobody read (an unknown key)."""
        for key in self.table:
            if key in self.used or (extra_allowed is not None and extra_allowed(key)):
                continue
            kind = "unknown section" if not self.where else "unknown key"
            raise self.error(key, f"{kind}{did_you_mean(key, self.used)}")

    def _check_range(
        self, key: str, value: float, minimum: float | None, maximum: float | None, exclusive_minimum: bool
    ) -> None:
        if minimum is not None:
            if exclusive_minimum and value <= minimum:
                raise self.error(key, f"must be > {minimum:g}, got {value:g}")
            if value < minimum:
                raise self.error(key, f"must be >= {minimum:g}, got {value:g}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"must be <= {maximum:g}, got {value:g}")
