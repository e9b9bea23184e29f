"""Compare two runs' logs: per signal the largest deviation over time, and the outcomes.

Time base: when a component's sample times are identical in both logs the values are compared
sample by sample; otherwise B is interpolated linearly onto A's sample times inside the time span
both logs cover (and the report says so). NaN in both at the same time counts as equal; NaN in
only one counts as an infinite deviation.

Angles: a signal whose unit is "rad" in either log (units come from the FMUs' model descriptions,
stored in the channel metadata) is compared modulo 2 pi, so a heading wrapped to (-pi, pi] and
one that is not agree; B is unwrapped before it is interpolated. A difference of at most pi is
taken as it is, so equal values stay exactly equal.

Text signals (String and Binary, `/text_signals/<component>`) hold each value until the next
record; they are equal when the held values agree at every record time of either log (no
tolerance applies); the report names the first time a text signal differs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cosim.logs.reader import Log

# outcome keys compared as text; the others are compared as numbers against the tolerance
OUTCOME_TEXT_KEYS = ("reached", "reason")
ANGLE_UNIT = "rad"  # signals in this unit are compared modulo 2 pi


@dataclass(frozen=True)
class SignalDeviation:
    component: str
    name: str
    max_deviation: float  # max |A - B| over the compared times
    at_time: float  # [s] where it occurs (NaN when nothing was compared)
    interpolated: bool  # B was interpolated onto A's times
    angle: bool = False  # compared modulo 2 pi (unit rad)


@dataclass
class DiffReport:
    tolerance: float
    deviations: list[SignalDeviation] = field(default_factory=list)
    only_in_a: list[str] = field(default_factory=list)  # "component.name"
    only_in_b: list[str] = field(default_factory=list)
    outcome_differences: list[tuple[str, str, str]] = field(default_factory=list)  # key, A, B
    text_differences: list[tuple[str, float]] = field(default_factory=list)  # "component.name", t [s]

    @property
    def exceeding(self) -> list[SignalDeviation]:
        return [item for item in self.deviations if not item.max_deviation <= self.tolerance]

    @property
    def differs(self) -> bool:
        """True when a signal or the outcome differs by more than the tolerance."""
        return bool(self.exceeding or self.outcome_differences or self.text_differences)


def diff_logs(log_a: Log, log_b: Log, tolerance: float) -> DiffReport:
    report = DiffReport(tolerance)
    for component in log_a.components:
        names_a = log_a.signals(component).names
        if component not in log_b.components:
            report.only_in_a += [f"{component}.{name}" for name in names_a]
            continue
        a, b = log_a.signals(component), log_b.signals(component)
        report.only_in_a += [f"{component}.{name}" for name in a.names if name not in b.names]
        report.only_in_b += [f"{component}.{name}" for name in b.names if name not in a.names]
        common = [name for name in a.names if name in b.names]
        same_times = np.array_equal(a.t_ns, b.t_ns)
        for name in common:
            angle = ANGLE_UNIT in (a.unit(name), b.unit(name))
            deviation, at_time = _max_deviation(a.t_ns, a[name], b.t_ns, b[name], same_times, angle)
            report.deviations.append(
                SignalDeviation(component, name, deviation, at_time, not same_times, angle)
            )
    for component in log_b.components:
        if component not in log_a.components:
            report.only_in_b += [f"{component}.{name}" for name in log_b.signals(component).names]
    _compare_text(log_a, log_b, report)
    report.outcome_differences = _outcome_differences(
        log_a.metadata.get("outcome"), log_b.metadata.get("outcome"), tolerance
    )
    report.deviations.sort(key=lambda item: (-_sort_key(item.max_deviation), item.component, item.name))
    return report


def _compare_text(log_a: Log, log_b: Log, report: DiffReport) -> None:
    for component in log_a.text_components:
        a = log_a.text_signals(component)
        if component not in log_b.text_components:
            report.only_in_a += [f"{component}.{name}" for name in a.names]
            continue
        b = log_b.text_signals(component)
        report.only_in_a += [f"{component}.{name}" for name in a.names if name not in b.names]
        report.only_in_b += [f"{component}.{name}" for name in b.names if name not in a.names]
        times = sorted(set(a.t.tolist()) | set(b.t.tolist()))
        for name in (name for name in a.names if name in b.names):
            values_a, values_b = a[name], b[name]
            for t in times:
                held_a = _held(a.t, values_a, t)
                if held_a != _held(b.t, values_b, t):
                    report.text_differences.append((f"{component}.{name}", t))
                    break
    for component in log_b.text_components:
        if component not in log_a.text_components:
            report.only_in_b += [f"{component}.{name}" for name in log_b.text_signals(component).names]


def _held(t: np.ndarray, values: list, at: float):
    """The value recorded last at or before `at` (None before the first record)."""
    index = int(np.searchsorted(t, at, side="right")) - 1
    return values[index] if index >= 0 else None


def _sort_key(value: float) -> float:
    return math.inf if math.isnan(value) else value


def _max_deviation(
    t_a: np.ndarray, a: np.ndarray, t_b: np.ndarray, b: np.ndarray, same_times: bool, angle: bool = False
) -> tuple[float, float]:
    """Largest |a - b| (modulo 2 pi for an angle) and the time [s] where it occurs; times are int64 ns."""
    t_a, difference = signal_difference(t_a, a, t_b, b, same_times, angle)
    if len(difference) == 0:
        return math.nan, math.nan
    deviation = np.abs(difference)
    deviation = np.where(np.isnan(deviation), np.inf, deviation)
    worst = int(np.argmax(deviation))
    return float(deviation[worst]), float(t_a[worst]) / 1e9


def signal_difference(
    t_a: np.ndarray, a: np.ndarray, t_b: np.ndarray, b: np.ndarray, same_times: bool, angle: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """A - B at the compared times (int64 ns; module docstring): equal values (NaN in both, the
    same infinity) give 0, NaN in one gives NaN; an angle's difference beyond pi is taken round
    the circle, into [-pi, pi)."""
    if not same_times:
        inside = (t_a >= t_b[0]) & (t_a <= t_b[-1]) if len(t_b) else np.zeros(len(t_a), dtype=bool)
        t_a, a = t_a[inside], a[inside]
        b = _interpolate(t_b, _unwrap(b) if angle else b, t_a)
    equal = (a == b) | (np.isnan(a) & np.isnan(b))  # inf == inf and NaN/NaN count as equal
    with np.errstate(invalid="ignore"):
        difference = a - b
        if angle:  # the difference on the circle; within pi the plain difference (exact when equal)
            wrapped = np.remainder(difference + math.pi, 2.0 * math.pi) - math.pi
            difference = np.where(np.abs(difference) > math.pi, wrapped, difference)
    return t_a, np.where(equal, 0.0, difference)


def _unwrap(values: np.ndarray) -> np.ndarray:
    """Angles [rad] without jumps of more than pi between finite samples (NaN and inf stay)."""
    finite = np.isfinite(values)
    result = values.astype(float, copy=True)
    result[finite] = np.unwrap(values[finite])
    return result


def _interpolate(t_ns: np.ndarray, values: np.ndarray, at_ns: np.ndarray) -> np.ndarray:
    """Linear interpolation at `at_ns`; a time that equals a sample takes that sample exactly
    (so NaN and inf survive), between samples a non-finite neighbour gives NaN."""
    last = len(t_ns) - 1
    right = np.clip(np.searchsorted(t_ns, at_ns), 0, last)
    left = np.clip(right - 1, 0, last)
    exact = t_ns[right] == at_ns
    span = (t_ns[right] - t_ns[left]).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        weight = np.where(span > 0, (at_ns - t_ns[left]) / np.where(span > 0, span, 1.0), 0.0)
        result = values[left] + weight * (values[right] - values[left])
    result[exact] = values[right[exact]]
    return result


def _outcome_differences(
    a: dict[str, str] | None, b: dict[str, str] | None, tolerance: float
) -> list[tuple[str, str, str]]:
    if a is None and b is None:
        return []
    a, b = a or {}, b or {}
    differences = []
    for key in sorted(set(a) | set(b)):
        value_a, value_b = a.get(key, "-"), b.get(key, "-")
        if value_a == value_b:
            continue
        if key not in OUTCOME_TEXT_KEYS:
            try:
                if abs(float(value_a) - float(value_b)) <= tolerance:
                    continue
            except ValueError:
                pass
        differences.append((key, value_a, value_b))
    return differences


def format_report(report: DiffReport, log_a: Log, log_b: Log, limit: int = 40) -> str:
    """The report as text lines for the terminal."""
    lines = [
        f"A: {log_a.path} ({log_a.scenario_name or '?'}, {log_a.duration:.3f} s)",
        f"B: {log_b.path} ({log_b.scenario_name or '?'}, {log_b.duration:.3f} s)",
    ]
    interpolated = sorted({item.component for item in report.deviations if item.interpolated})
    if interpolated:
        lines.append(
            f"time base: sample times differ for {', '.join(interpolated)}: B interpolated linearly "
            "onto A's times where both cover them"
        )
    else:
        lines.append("time base: identical sample times, compared sample by sample")
    exceeding = report.exceeding
    shown = exceeding[:limit] if exceeding else []
    if shown:
        lines.append(f"{'signal':<40} {'max |A-B|':>12}  at t [s]")
        for item in shown:
            label = item.component + "." + item.name + (" (mod 2 pi)" if item.angle else "")
            lines.append(f"{label:<40} {item.max_deviation:>12.6g}  {item.at_time:.3f}")
        if len(exceeding) > limit:
            lines.append(f"... and {len(exceeding) - limit} more signals above the tolerance")
    largest = max((_sort_key(item.max_deviation) for item in report.deviations), default=0.0)
    within = len(report.deviations) - len(exceeding)
    lines.append(
        f"{within} of {len(report.deviations)} common signals within tolerance {report.tolerance:g}"
        f" (largest deviation {largest:.6g})"
    )
    for label, names in (("only in A", report.only_in_a), ("only in B", report.only_in_b)):
        if names:
            lines.append(f"{label}: {', '.join(names[:20])}{' ...' if len(names) > 20 else ''}")
    for name, t in report.text_differences:
        lines.append(f"text {name}: differs from t = {t:.3f} s")
    for key, value_a, value_b in report.outcome_differences:
        lines.append(f"outcome {key}: A {value_a}  B {value_b}")
    if not report.outcome_differences:
        lines.append("outcome: equal")
    components = sorted({item.component for item in exceeding})
    verdict = (
        f"DIFFERENT ({', '.join(components) or ('text' if report.text_differences else 'outcome')})"
        if report.differs
        else "EQUAL within tolerance"
    )
    lines.append(f"result: {verdict}")
    return "\n".join(lines)
