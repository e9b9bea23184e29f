"""Which connections between port types convert (`System.connect` refuses the others).

A port has a kind (`real`, `integer`, `boolean`: how the master's float64 buffers carry it) and, on
an FMU, the FMI type that moves it (`Port.fmi_type`: "Float32", "Int8", ..., "Int64" for an FMI 3.0
Enumeration, "Integer" for an FMI 2.0 one). Connections follow SSP's rule that a connection converts
without loss of meaning: equal types always connect; an integer feeds any float (exact up to 2^53)
and any integer type whose range holds the source type's range; a float feeds any float (Float64 to
Float32 rounds, as every FMI importer does); a Boolean feeds a Boolean or any number (false = 0,
true = 1, exact, as the project's own FMUs wire a `goal_reached` flag into a Real input). Float to
integer (which integer would 0.5 be?) and a number to a Boolean (which numbers are true?) are
refused. A port without an FMI type (a Python component's) connects to every type of its kind, and
an integer one to every float.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cosim.core.component import Port

# Value ranges of the integer types (FMI 2.0 Integer and Enumeration are C int: 32 bits).
INTEGER_RANGES = {
    "Int8": (-(2**7), 2**7 - 1),
    "UInt8": (0, 2**8 - 1),
    "Int16": (-(2**15), 2**15 - 1),
    "UInt16": (0, 2**16 - 1),
    "Int32": (-(2**31), 2**31 - 1),
    "UInt32": (0, 2**32 - 1),
    "Int64": (-(2**63), 2**63 - 1),
    "UInt64": (0, 2**64 - 1),
    "Integer": (-(2**31), 2**31 - 1),
}


def connection_problem(source: Port, target: Port) -> str | None:
    """Why output port `source` cannot feed input port `target`, or None when the connection
    converts (module docstring)."""
    source_type, source_kind = source.fmi_type, source.type
    target_type, target_kind = target.fmi_type, target.type
    if source_type and source_type == target_type or source_kind == "boolean":
        return None
    if target_kind == "boolean":
        return "only a Boolean feeds a Boolean"
    if target_kind == "real":
        return None  # float to float rounds as FMI importers do; an integer up to 2^53 is exact
    if source_kind == "real":
        return "a float cannot feed an integer (SSP converts integers to floats, not back)"
    wide, narrow = INTEGER_RANGES.get(source_type), INTEGER_RANGES.get(target_type)
    if wide is None or narrow is None or narrow[0] <= wide[0] and wide[1] <= narrow[1]:
        return None
    return (
        f"{target_type} [{narrow[0]}, {narrow[1]}] does not hold every {source_type} [{wide[0]}, {wide[1]}]"
    )
