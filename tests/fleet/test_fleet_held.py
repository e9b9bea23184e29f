"""`_held` (a robot's rows per step of a block) against its definition step by step: at step k the
row of the component's latest step k' <= k in the block (k' % period == 0), else the last value."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.navigation.fleet import _held


def _by_definition(rows, first, count, period, last):
    out = []
    for k in range(first, first + count):
        due = [j for j in range(first, k + 1) if j % period == 0]
        out.append(rows[len(due) - 1] if due else last)
    return np.array(out, dtype=float).reshape(count, len(last))


@pytest.mark.parametrize("period", [1, 2, 3, 10])
@pytest.mark.parametrize("first", [0, 1, 7, 20, 29])
@pytest.mark.parametrize("count", [1, 5, 10])
def test_held_rows_are_the_latest_step_of_the_component(period, first, count):
    steps = [k for k in range(first, first + count) if k % period == 0]
    rows = np.arange(len(steps) * 3, dtype=float).reshape(len(steps), 3) + 100.0 * first
    last = np.array([-1.0, -2.0, -3.0])
    for _ in range(2):  # twice: the row indices made once are reused as they were
        held = _held(rows, first, count, period, last)
        assert held.tolist() == _by_definition(rows, first, count, period, last).tolist()
