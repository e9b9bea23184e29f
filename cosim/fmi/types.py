"""FMI variable types as navcosim carries them, and which connections between them convert.

Every numeric FMI type travels in the master's float64 buffers (`cosim.core.component`): FMI 1.0 and
2.0 Real, Integer, Enumeration and Boolean; FMI 3.0 Float32, Float64, Int8 to UInt64, Enumeration and
Boolean. A float64 holds every integer of magnitude up to 2^53 exactly, so all of them are exact
except Int64 and UInt64 values beyond that: such a value is refused (`CosimError`) where it would
enter a buffer (an output read, a start value) or leave one for the FMU (a parameter given as a
TOML integer), never rounded silently.

Each variable is transferred with the FMI function of its *transfer type*: its own type, except
an FMI 1.0 or 2.0 Enumeration (fmiSetInteger, fmi2SetInteger) and an FMI 3.0 Enumeration (fmi3SetInt64 /
fmi3GetInt64, as FMI 3.0 defines its enumerations as Int64).

Which connections between these types convert is `cosim.core.port_types`'s rule.
"""

from __future__ import annotations

import ctypes

from cosim.core.port_types import INTEGER_RANGES
from cosim.errors import CosimError

# FMI type -> port kind (the master's view: how the value is rounded on its way to the FMU).
KINDS = {
    "Real": "real",
    "Float64": "real",
    "Float32": "real",
    "Integer": "integer",
    "Enumeration": "integer",
    **{
        name: "integer" for name in ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
    },
    "Boolean": "boolean",
}
# The largest magnitude below which every integer is a float64.
EXACT_INTEGER = 2**53
# Transfer types per FMI version, in the order their calls are made each step.
TRANSFER_TYPES = {
    1: ("Real", "Integer", "Boolean"),
    2: ("Real", "Integer", "Boolean"),
    3: (
        "Float64",
        "Int32",
        "Boolean",
        "Float32",
        "Int8",
        "UInt8",
        "Int16",
        "UInt16",
        "UInt32",
        "Int64",
        "UInt64",
    ),
}
C_TYPES = {
    1: {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_uint8},  # fmiBoolean: a char
    2: {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int},
    3: {
        "Float64": ctypes.c_double,
        "Float32": ctypes.c_float,
        "Int8": ctypes.c_int8,
        "UInt8": ctypes.c_uint8,
        "Int16": ctypes.c_int16,
        "UInt16": ctypes.c_uint16,
        "Int32": ctypes.c_int32,
        "UInt32": ctypes.c_uint32,
        "Int64": ctypes.c_int64,
        "UInt64": ctypes.c_uint64,
        "Boolean": ctypes.c_bool,
    },
}
# Transfer types whose values a float64 may not hold exactly (checked where they enter a buffer).
WIDE = frozenset({"Int64", "UInt64"})


def transfer_type(version: int, declared: str) -> str:
    """The FMI type whose Set/Get functions move a variable of type `declared`."""
    if declared == "Enumeration":
        return "Integer" if version < 3 else "Int64"
    return declared


def check_integer(value: float | int, transfer: str, what: str) -> int:
    """`value` as the integer an FMU variable of transfer type `transfer` receives; `CosimError`
    naming `what` when it is not a whole number, lies outside the type's range, or is a float beyond
    2^53 (which integer it stood for is lost)."""
    if isinstance(value, float):
        if value != value or abs(value) == float("inf") or value != int(value):
            raise CosimError(f"{what}: must be an integer (the FMU's {transfer}), got {value}")
        if abs(value) > EXACT_INTEGER:
            raise CosimError(
                f"{what}: {int(value)} is beyond 2^53, where a float64 no longer holds every integer "
                f"(the FMU's {transfer} would receive a rounded value)"
            )
    number = int(value)
    bounds = INTEGER_RANGES.get(transfer)
    if bounds is not None and not bounds[0] <= number <= bounds[1]:
        raise CosimError(
            f"{what}: {number} is outside the range of the FMU's {transfer} [{bounds[0]}, {bounds[1]}]"
        )
    return number


def exact_as_float(value: int, declared: str, what: str) -> float:
    """An integer the FMU gave, as the float64 the buffers hold; `CosimError` beyond 2^53."""
    if abs(value) > EXACT_INTEGER:
        raise CosimError(
            f"{what} = {value} ({declared}) is beyond 2^53: a float64 signal cannot hold it exactly "
            "(navcosim carries numeric signals as float64)"
        )
    return float(value)
