"""`codegen._references` makes the value-reference array `(c_uint32 * n)(*references)` makes, also
for references that do not fit in 32 unsigned bits (wrapped as ctypes wraps them).

Truth: the ctypes constructor itself."""

import ctypes

import pytest

from cosim.fmi.codegen import _references


@pytest.mark.parametrize(
    "references",
    [[], [0], [0, 1, 2**32 - 1], list(range(2003)), [7] * 5, [-1, 3], [2**33 + 5], [2**31, 2**31 - 1]],
)
def test_the_array_is_the_constructors(references):
    made = _references(references)
    truth = (ctypes.c_uint32 * len(references))(*references)
    assert type(made) is type(truth) and list(made) == list(truth)
