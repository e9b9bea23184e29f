"""`array_ports` makes its element ports knowing each element (no parsing of the name): the ports are
those `Port` makes from the same names, which parses them (`Port.array_name`, `Port.array_index`)."""

import math

import pytest

from cosim.core.component import Port, array_ports


@pytest.mark.parametrize(
    ("base", "count", "columns", "unit", "start"),
    [
        ("waypoints", 7, 2, "m", math.nan),
        ("ranges", 12, 0, "", 0.0),
        ("a[1]", 3, 0, "rad", 1.5),
        ("x", 0, 0, "", 0.0),
    ],
)
def test_array_ports_are_the_ports_of_their_names(base, count, columns, unit, start):
    made = array_ports(base, count, columns, unit, start)
    parsed = [Port(port.name, unit=unit, start=start) for port in made]
    assert [repr(port) for port in made] == [repr(port) for port in parsed]
    assert [(p.array_name, p.array_index) for p in made] == [(p.array_name, p.array_index) for p in parsed]
    assert len(made) == count * (columns or 1)
    assert all(port.is_array_element for port in made)
