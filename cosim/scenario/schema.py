"""Typed reading of one TOML table with errors that name the file and the key path.

`TableReader` pulls keys out of a parsed TOML table one at a time, checking type and range; what
is left at `finish()` is an unknown key, reported with a "did you mean". Every error is one line:
`scenarios/x.toml: [vfh].robot_radius: must be >= 0, got -1`.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable, Iterable
from typing import Any

from cosim.errors import QUOTE_LIMIT, CosimError, shorten

__all__ = ["QUOTE_LIMIT", "REQUIRED", "TableReader", "describe", "did_you_mean", "is_number", "shorten"]

REQUIRED = object()


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """' (did you mean 'x'?)' for the closest candidate, or '' when nothing is close."""
    if len(name) > QUOTE_LIMIT:  # no name that long is close to a key, and matching it is slow
        return ""
    import difflib  # only for an error message: not imported by a run that has none

    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def describe(value: Any) -> str:
    """A value as the user wrote it, for error messages; at most `QUOTE_LIMIT` characters."""
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' * (len(value) != 1)}: {_preview(value)}"
    return _preview(value)


def _preview(value: Any) -> str:
    """TOML-like text of `value`, cut at `QUOTE_LIMIT` characters; nested lists are walked only as
    far as the text goes, so a huge or deeply nested value costs no more than a short one."""
    parts: list[str] = []
    size = 0

    def emit(text: str) -> None:
        nonlocal size
        parts.append(text)
        size += len(text)

    def walk(item: Any, depth: int) -> None:
        if size > QUOTE_LIMIT:
            return
        if isinstance(item, list):
            if depth > 8:
                emit("[…]")
                return
            emit("[")
            for index, element in enumerate(item):
                if index:
                    emit(", ")
                walk(element, depth + 1)
                if size > QUOTE_LIMIT:
                    return
            emit("]")
        elif isinstance(item, dict):
            emit("{…}")
        elif isinstance(item, bool):
            emit("true" if item else "false")
        elif isinstance(item, str):
            emit(f"'{item[: QUOTE_LIMIT + 1]}'")
        elif isinstance(item, datetime.date | datetime.time):  # a TOML date or time, as written
            emit(item.isoformat())
        elif isinstance(item, int) and item.bit_length() > 256:  # str() of a huge int is slow or refused
            emit(f"an integer of about {int(item.bit_length() * math.log10(2)) + 1} digits")
        else:
            emit(repr(item)[: QUOTE_LIMIT + 1])

    walk(value, 0)
    return shorten("".join(parts))


def is_number(value: Any) -> bool:
    """A TOML integer or float (a boolean is not a number)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def as_float(value: int | float) -> float:
    """`value` as a float; integers beyond the float range become +-inf (so "must be finite")."""
    try:
        return float(value)
    except OverflowError:
        return math.copysign(math.inf, value)


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
        key = '""' if key == "" else shorten(key) if key else key  # "" is a key TOML allows
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
        number = as_float(value)
        if not math.isfinite(number):
            raise self.error(key, f"must be finite, got {describe(value)}")
        self._check_range(key, number, minimum, maximum, exclusive_minimum)
        return number

    def integer(
        self, key: str, default: Any = REQUIRED, minimum: int | None = None, maximum: int | None = None
    ) -> int:
        value = self.raw(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.error(key, f"must be an integer, got {describe(value)}")
        self._check_range(key, value, minimum, maximum, False)
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
            raise self.error(
                key, f"must be one of {listed}, got {describe(value)}{did_you_mean(value, choices)}"
            )
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
        numbers = tuple(as_float(item) for item in value)
        if not all(math.isfinite(item) for item in numbers):
            raise self.error(key, "must hold finite numbers")
        return numbers

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
        where = f"{self.where}.{shorten(key)}" if self.where else f"[{shorten(key)}]"  # a section
        return TableReader(self.source, where, self.raw(key, {}))

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
                raise self.error(key, f"must be > {minimum:g}, got {_number_text(value)}")
            if value < minimum:
                raise self.error(key, f"must be >= {minimum:g}, got {_number_text(value)}")
        if maximum is not None and value > maximum:
            raise self.error(key, f"must be <= {maximum:g}, got {_number_text(value)}")


def _number_text(value: float) -> str:
    """A number for a range message: integers as written (however large), floats with %g."""
    return describe(value) if isinstance(value, int) else f"{value:g}"
