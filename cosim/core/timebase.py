"""The integer time base of a co-simulation.

The macro step h is held as an integer number of nanoseconds; step k starts at
t_k = start + k * h exactly (`Master.time_ns`), and the float time handed to components is that
integer divided once by 1e9, so time never accumulates rounding: 2,000,000 steps of 1 ms end at
exactly 2000.0 s. A component's `period` is an integer multiple P of h (0 = every step); it is
stepped at the steps k with k % P == 0, by `do_step(t_k, P * h)`. Between its steps its outputs
hold their last values (sample and hold).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cosim.errors import CosimError

if TYPE_CHECKING:
    from fractions import Fraction

NS_PER_S = 1_000_000_000


def due_from(k: int, period: int) -> int:
    """The first step at or after step k at which a component of `period` steps is due."""
    return -(-k // period) * period


def seconds_to_ns(seconds: float | Fraction | int, what: str) -> int:
    """Convert a duration [s] to integer nanoseconds; `CosimError` if not a whole number of ns."""
    if isinstance(seconds, float):
        if not math.isfinite(seconds):
            raise CosimError(f"{what} must be finite, got {seconds}")
        # A float such as 0.001 is not exactly 1e6 ns; accept it when it is the nearest float.
        nanoseconds = round(seconds * NS_PER_S)
        if abs(nanoseconds - seconds * NS_PER_S) > 1e-6 * max(1.0, abs(seconds * NS_PER_S)):
            raise CosimError(f"{what} {seconds} s is not a whole number of nanoseconds")
        return nanoseconds
    from fractions import Fraction  # exact durations only (its import costs a run ~4 ms)

    if isinstance(seconds, bool) or not isinstance(seconds, int | Fraction):
        raise CosimError(f"{what} must be a number of seconds, got {seconds!r}")
    exact = Fraction(seconds) * NS_PER_S
    nanoseconds = round(exact)
    if exact != nanoseconds:
        raise CosimError(f"{what} {seconds} s is not a whole number of nanoseconds")
    return nanoseconds
