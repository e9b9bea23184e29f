"""String and Binary variables of an FMU: the path beside the float64 buffers.

A text value (an FMI String, `str`; an FMI 3.0 Binary, `bytes`) cannot travel in the master's float
buffers, so an FMU's String and Binary parameters, inputs and outputs are `TextPort`s of their own
(`FmuComponent.text_inputs`, ...), moved by `TextTransfer` with fmi(2|3)Get/SetString and
fmi3Get/SetBinary. A parameter takes its value at setup; an input keeps its start value (or one
staged with `FmuComponent.set_text`) until a connection feeds it; `System.connect` wires a text
output to a text input of the same type (String to String, Binary to Binary: nothing else converts),
and the consumer reads its producer's latest value before each of its own steps (after the
producer's most recent step, as for a number from an earlier component). A component with text
connections or text outputs is stepped by Python (the compiled kernel moves numbers only); its text
values after each step are in `FmuComponent.text_values`.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass

from cosim.errors import CosimError

TEXT_TYPES = ("String", "Binary")


@dataclass(frozen=True)
class TextPort:
    """A String or Binary variable: its name, type, value reference, start value, description."""

    name: str
    fmi_type: str  # "String" or "Binary"
    value_reference: int
    start: str | bytes
    description: str = ""


def text_start(variable) -> str | bytes:
    """A String or Binary variable's start (an FMI 3.0 Binary's is hex text), "" / b"" when absent."""
    start = variable.start
    if variable.type == "Binary":
        return bytes.fromhex(str(start)) if start not in (None, "") else b""
    return "" if start is None else str(start)


def check_text(port: TextPort, value: object, what: str) -> str | bytes:
    """`value` as `port` takes it: a `str` for a String, `bytes` (or hex text) for a Binary."""
    if port.fmi_type == "String" and isinstance(value, str):
        return value
    if port.fmi_type == "Binary":
        if isinstance(value, bytes | bytearray):
            return bytes(value)
        if isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError:
                pass
    wanted = "text" if port.fmi_type == "String" else "bytes or hex text"
    raise CosimError(f"{what}: the FMU's {port.fmi_type} '{port.name}' takes {wanted}, got {value!r:.80}")


class TextTransfer:
    """fmi(2|3)Get/SetString and fmi3Get/SetBinary of one instance (`function(name)` gives a C
    function's symbol; FMI 1.0 and 2.0 take no value count)."""

    def __init__(self, dll, version: int, handle, function) -> None:
        self._handle, self._version = handle, version
        vrs, size, c_int, c_void_p = (
            ctypes.POINTER(ctypes.c_uint32),
            ctypes.c_size_t,
            ctypes.c_int,
            ctypes.c_void_p,
        )
        texts = ctypes.POINTER(ctypes.c_char_p)
        counted = () if version < 3 else (size,)
        self._string = {
            direction: ctypes.CFUNCTYPE(c_int, c_void_p, vrs, size, texts, *counted)(
                (function(f"{direction}String"), dll)
            )
            for direction in ("Get", "Set")
        }
        self._binary = {}
        if version == 3:
            sizes, blobs = ctypes.POINTER(size), ctypes.POINTER(ctypes.c_void_p)
            for direction in ("Get", "Set"):
                prototype = ctypes.CFUNCTYPE(c_int, c_void_p, vrs, size, sizes, blobs, size)
                self._binary[direction] = prototype((function(f"{direction}Binary"), dll))

    def set(self, ports: Sequence[TextPort], values: Sequence[str | bytes]) -> int:
        """Send `values` to `ports`; the worst status of the calls."""
        status = 0
        for fmi_type in TEXT_TYPES:
            chosen = [(p, v) for p, v in zip(ports, values, strict=True) if p.fmi_type == fmi_type]
            if not chosen:
                continue
            n = len(chosen)
            refs = (ctypes.c_uint32 * n)(*(p.value_reference for p, _ in chosen))
            if fmi_type == "String":
                texts = (ctypes.c_char_p * n)(*(v.encode() for _, v in chosen))
                status = max(status, self._string["Set"](self._handle, refs, n, texts, *self._count(n)))
            else:
                buffers = [ctypes.create_string_buffer(bytes(v), max(1, len(v))) for _, v in chosen]
                sizes = (ctypes.c_size_t * n)(*(len(v) for _, v in chosen))
                blobs = (ctypes.c_void_p * n)(*(ctypes.addressof(b) for b in buffers))
                status = max(status, self._binary["Set"](self._handle, refs, n, sizes, blobs, n))
        return status

    def get(self, ports: Sequence[TextPort]) -> tuple[int, list[str | bytes]]:
        """(worst status, the values of `ports`), read with one call per type."""
        values: dict[str, str | bytes] = {}
        status = 0
        for fmi_type in TEXT_TYPES:
            chosen = [p for p in ports if p.fmi_type == fmi_type]
            if not chosen:
                continue
            n = len(chosen)
            refs = (ctypes.c_uint32 * n)(*(p.value_reference for p in chosen))
            if fmi_type == "String":
                texts = (ctypes.c_char_p * n)()
                status = max(status, self._string["Get"](self._handle, refs, n, texts, *self._count(n)))
                values.update(
                    (p.name, (t or b"").decode(errors="replace")) for p, t in zip(chosen, texts, strict=True)
                )
            else:
                sizes, blobs = (ctypes.c_size_t * n)(), (ctypes.c_void_p * n)()
                status = max(status, self._binary["Get"](self._handle, refs, n, sizes, blobs, n))
                values.update(
                    (p.name, ctypes.string_at(blob, size) if blob else b"")
                    for p, size, blob in zip(chosen, sizes, blobs, strict=True)
                )
        return status, [values[p.name] for p in ports]

    def _count(self, n: int) -> tuple[int, ...]:
        return () if self._version < 3 else (n,)
