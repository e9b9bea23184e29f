"""One compiled stepping kernel for every system: FMUs stepped by C calls, Python components handed back.

The kernel (`cosim/core/native/kernel.c`, built and loaded by `native.load`) is written once and
reads the system from tables of integers and floats (C function and buffer addresses, connection and
transfer tables) that a run fills (`cosim.core.fast_loop.KernelTables`): no per-system code, and no
compiling at run time beyond the first build of the library on a machine (about a second; a wheel
ships it prebuilt).

The kernel steps the components of the master's plan in Gauss-Seidel (or Jacobi) order with the
Python loop's arithmetic (`value * scale + offset`, the same integer time base), so both give
bit-identical values. A component the kernel cannot step (a Python component, an FMU in a child
process) is handed back: the kernel returns at that component of that step, the master steps it
in Python, and the kernel resumes with the next component. It can also keep each FMU's buffers
after each of its steps (`record`) and watch a position: it returns after the first step whose
(x, y) is not finite, inside a circle (the goal zone) or outside another (the zone known free of
collisions), so a caller that checks those steps exactly never sees the loop run past one.

FMI calls go through the function pointers the tables hold: fmi2Set/Get<T>(instance, refs, count,
values), fmi3Set/Get<T>(..., values, value_count), fmi2DoStep(instance, t, h, fmi2True) and
fmi3DoStep(instance, t, h, true, &eventHandlingNeeded, &terminateSimulation, &earlyReturn,
&lastSuccessfulTime).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

# Return codes of `step_kernel` (first element of the result).
DONE, HAND_BACK, WATCH, FAILED = 0, 1, 2, 3
# Columns of the component table.
(
    C_KIND, C_PERIOD, C_VERSION, C_HANDLE, C_STEP, C_FLAGS, C_LAST_TIME, C_LINK_FIRST, C_LINK_COUNT,
    C_SET_FIRST, C_SET_COUNT, C_GET_FIRST, C_GET_COUNT, C_CHECK_FIRST, C_CHECK_COUNT,
    C_IN_ADDRESS, C_IN_COUNT, C_OUT_ADDRESS, C_OUT_COUNT, C_RECORD, C_RECORD_OFFSET,
) = range(21)  # fmt: skip
COMPONENT_COLUMNS = 21
KIND_IDLE, KIND_NATIVE, KIND_PYTHON = 0, 1, 2  # never stepped (constant outputs), by C calls, by Python
# Columns of the transfer-group table.
G_KIND, G_FUNCTION, G_REFERENCES, G_REFERENCE_COUNT, G_VALUE_COUNT, G_VALUES, G_DIRECT = range(7)
G_SLOT_FIRST, G_SLOT_COUNT = 7, 8
GROUP_COLUMNS = 9
KIND_REAL, KIND_INTEGER, KIND_BOOLEAN = 0, 1, 2
RESULT_SIZE = 7  # int64 elements of the result: code, step, position, component, call, status, kind
# Every group kind by its code (kernel.c's KIND_*): real double, integer int32, boolean, then FMI 3.0's
# other numeric types (an int64 or uint64 beyond 2^53 is read as NaN, for the output check to stop at).
KINDS = (
    "real",
    "integer",
    "boolean",
    "float32",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "uint32",
    "int64",
    "uint64",
)
(KIND_FLOAT32, KIND_INT8, KIND_UINT8, KIND_INT16) = range(3, 7)
(KIND_UINT16, KIND_UINT32, KIND_INT64, KIND_UINT64) = range(7, 11)
# Failure calls (as `NativeStep.fail`): 0 set, 1 doStep, 2 get, 3 asked to terminate, 4 not finite.


_SOURCE = Path(__file__).resolve().parent / "native" / "kernel.c"
_I64 = ctypes.c_int64
_POINTER = ctypes.c_void_p


class _Tables(ctypes.Structure):
    """The C kernel's `Tables`: the arrays' data pointers, in the order `_ARRAYS` names them."""

    _fields_ = [
        ("n", _I64),
        *[
            (name, _POINTER)
            for name in (
                "components", "step_sizes", "link_addresses", "link_numbers", "groups", "slot_addresses",
                "slot_scales", "checks", "history", "rows", "watch_addresses", "watch_numbers",
            )
        ],
    ]  # fmt: skip


# (name, dtype, columns: 0 = one-dimensional) of each table, in `step_kernel`'s argument order.
_ARRAYS = (
    ("components", np.int64, COMPONENT_COLUMNS),
    ("step_sizes", np.float64, 0),
    ("link_addresses", np.int64, 3),
    ("link_numbers", np.float64, 2),
    ("groups", np.int64, GROUP_COLUMNS),
    ("slot_addresses", np.int64, 0),
    ("slot_scales", np.float64, 0),
    ("checks", np.int64, 3),
    ("history", np.float64, 0),
    ("rows", np.int64, 0),
    ("watch_addresses", np.int64, 0),
    ("watch_numbers", np.float64, 0),
)
_LENGTHS = {"watch_addresses": 3, "watch_numbers": 6}
_function = None


def _kernel():
    """The C function, loaded (built on a machine's first use) once per process."""
    global _function
    if _function is None:
        from native.load import bind, load

        library = load(_SOURCE)
        if library.navcosim_tables_size() != ctypes.sizeof(_Tables):
            raise RuntimeError(f"{_SOURCE.name}: its Tables struct does not match kernel.py's _Tables")
        signature = (_I64, [_I64] * 6 + [ctypes.POINTER(_Tables), ctypes.POINTER(_I64)])
        _function = bind(library, {"navcosim_step_kernel": signature}).navcosim_step_kernel
    return _function


class Kernel:
    """`step_kernel` bound to one set of tables: their pointers taken once, so a call costs one
    ctypes call. The arrays must stay the same objects (change them in place)."""

    def __init__(self, *arrays: np.ndarray) -> None:
        if len(arrays) != len(_ARRAYS):
            raise TypeError(f"step_kernel takes {len(_ARRAYS)} tables, got {len(arrays)}")
        self._arrays = arrays  # the struct points into them: they live as long as this object
        pointers = []
        for array, (name, dtype, columns) in zip(arrays, _ARRAYS, strict=True):
            if not isinstance(array, np.ndarray) or array.dtype != dtype or not array.flags.c_contiguous:
                raise TypeError(f"step_kernel: {name} must be a C-contiguous {np.dtype(dtype)} array")
            if array.ndim != (2 if columns else 1) or (columns and array.shape[1] != columns):
                raise TypeError(
                    f"step_kernel: {name} must have shape ({'n, ' + str(columns) if columns else 'n,'})"
                )
            needed = _LENGTHS.get(name, len(arrays[0]) if name in ("step_sizes", "rows") else 0)
            if len(array) < needed:
                raise TypeError(f"step_kernel: {name} needs at least {needed} elements")
            pointers.append(array.ctypes.data)
        self._tables = _Tables(len(arrays[0]), *pointers)
        self._result = (_I64 * RESULT_SIZE)()
        self._function = _kernel()

    def __call__(
        self, first_step: int, steps: int, first_position: int, start_ns: int, h_ns: int, jacobi: bool
    ) -> tuple[int, int, int, int, int, int, int]:
        self._function(first_step, steps, first_position, start_ns, h_ns, jacobi, self._tables, self._result)
        return tuple(self._result)


def step_kernel(
    first_step, steps, first_position, start_ns, h_ns, jacobi,
    components, step_sizes, link_addresses, link_numbers, groups, slot_addresses, slot_scales,
    checks, history, rows, watch_addresses, watch_numbers,
):  # fmt: skip
    """Step from component `first_position` of step `first_step` up to the end of step
    `first_step + steps - 1`. Returns (code, step, position, component, call, status, kind):
    DONE (all steps ran; step = the next one), HAND_BACK (component `position` of step `step`
    needs Python), WATCH (the position after step `step - 1` is to be checked), FAILED (component
    `component` failed at step `step`: `call`, `status`, `kind` of the set/get group).

    For repeated calls on the same tables, `Kernel(tables...)(first_step, ...)` skips the checks."""
    kernel = Kernel(
        components, step_sizes, link_addresses, link_numbers, groups, slot_addresses, slot_scales,
        checks, history, rows, watch_addresses, watch_numbers,
    )  # fmt: skip
    return kernel(first_step, steps, first_position, start_ns, h_ns, jacobi)


def warm_up() -> None:
    """Load the kernel's library, building it first on a machine that has none (a build or install
    step can call it, so a first run does not compile)."""
    _kernel()
