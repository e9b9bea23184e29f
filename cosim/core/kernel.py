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
DONE, HAND_BACK, WATCH, FAILED, POLL = 0, 1, 2, 3, 4
# Columns of the component table.
(
    C_KIND, C_PERIOD, C_VERSION, C_HANDLE, C_STEP, C_FLAGS, C_LAST_TIME, C_LINK_FIRST, C_LINK_COUNT,
    C_SET_FIRST, C_SET_COUNT, C_GET_FIRST, C_GET_COUNT, C_CHECK_FIRST, C_CHECK_COUNT,
    C_IN_ADDRESS, C_IN_COUNT, C_OUT_ADDRESS, C_OUT_COUNT, C_RECORD, C_RECORD_OFFSET,
    C_RECORD_IN_FIRST, C_RECORD_IN_COUNT,
) = range(23)  # fmt: skip
COMPONENT_COLUMNS = 23
# Never stepped (constant outputs), by FMI calls, by Python (or, with a C_STEP, by that C call on
# its state until it hands a step to Python: the replanning planner's), by one C call on its inputs
# x, y, theta (a sweep: the lidar's, `KernelTables`; C_FLAGS 1 returns POLL before it, 2 only when
# a signal came or the watch needs a look: `KernelTables.poll_on_signals`).
KIND_IDLE, KIND_NATIVE, KIND_PYTHON, KIND_SWEEP = 0, 1, 2, 3
# Columns of the transfer-group table.
G_KIND, G_FUNCTION, G_REFERENCES, G_REFERENCE_COUNT, G_VALUE_COUNT, G_VALUES, G_DIRECT = range(7)
G_SLOT_FIRST, G_SLOT_COUNT = 7, 8
# A setter group of float64 scalars may send only the values that changed since its last set:
# G_SENT the address of its float64 array (1 + 2 x count: valid flag, last sent, changed values),
# G_SENT_REFERENCES of its uint32 array (count: changed references); 0: it sends every value.
G_SENT, G_SENT_REFERENCES = 9, 10
# G_RUNS: the address of its run table (int64: the count of runs, then RUN_COLUMNS per run: first
# position, end, producer, the producer's stamp when last compared), by which it compares after a
# kernel call's first set only the runs whose producer stepped since (kernel.c's `set_changed`);
# 0: every value at every set.
G_RUNS = 11
GROUP_COLUMNS = 12
RUN_FROM, RUN_TO, RUN_PRODUCER, RUN_SEEN = range(4)
RUN_COLUMNS = 4
KIND_REAL, KIND_INTEGER, KIND_BOOLEAN = 0, 1, 2
RESULT_SIZE = 7  # int64 elements of the result: code, step, position, component, call, status, kind
R_STEP = 1  # the result's step: also written at the start of each step, so it is the step under way
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

# The recording's message records (`pack_records`): an MCAP Message record's head (opcode u8,
# record length u64, channel u16, sequence u32, log time u64, publish time u64), and its byte offsets.
MESSAGE_HEAD_BYTES, MESSAGE_FIELD_BYTES, OPCODE_MESSAGE = 31, 22, 5
HEAD_LENGTH, HEAD_CHANNEL, HEAD_SEQUENCE, HEAD_LOG_TIME, HEAD_PUBLISH_TIME = 1, 9, 11, 15, 23
# Columns of the stream table: kind, channel, first sequence, record bytes, template address,
# times address (uint64 per message), matrix address (float64 rows), matrix columns, stamps (0-2)
# and their byte offsets, the stream's first field-table row and count.
(
    P_KIND, P_CHANNEL, P_SEQUENCE, P_SIZE, P_TEMPLATE, P_TIMES, P_MATRIX, P_MATRIX_COLUMNS,
    P_STAMP_COUNT, P_STAMP_FIRST, P_STAMP_SECOND, P_FIELD_FIRST, P_FIELD_COUNT,
) = range(13)  # fmt: skip
STREAM_COLUMNS = 13
STREAM_NONE, STREAM_FIXED, STREAM_RAW = 0, 1, 2
MAX_STREAMS = 1024  # streams of one pack at most
F_OFFSET, F_COLUMN, F_COUNT = range(3)  # field table: record byte offset, matrix column, float64 count
FIELD_COLUMNS = 3
RAW_CHANNEL, RAW_SEQUENCE, RAW_TIME, RAW_START, RAW_SIZE = range(5)  # raw table: one row per message
RAW_COLUMNS = 5


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
                "slot_scales", "checks", "history", "rows", "watch_addresses", "watch_numbers", "stamps",
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
    ("stamps", np.int64, 0),  # [0] kernel calls so far, [1 + i] steps component i took in the kernel
)
_LENGTHS = {"watch_addresses": 3, "watch_numbers": 6}
_function = None


_packer = None


def _kernel():
    """The C function, loaded (built on a machine's first use) once per process."""
    global _function, _packer
    if _function is None:
        from native.load import bind, load

        library = load(_SOURCE)
        if library.navcosim_tables_size() != ctypes.sizeof(_Tables):
            raise RuntimeError(f"{_SOURCE.name}: its Tables struct does not match kernel.py's _Tables")
        signature = (_I64, [_I64] * 6 + [ctypes.POINTER(_Tables), ctypes.POINTER(_I64)])
        pack = (_I64, [_I64, _POINTER, _I64] + [_POINTER] * 5 + [_I64] + [_POINTER] * 3)
        bound = bind(library, {"navcosim_step_kernel": signature, "navcosim_pack_records": pack})
        _packer = bound.navcosim_pack_records
        _function = bound.navcosim_step_kernel
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
            needed = len(arrays[0]) + 1 if name == "stamps" else needed
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
    checks, history, rows, watch_addresses, watch_numbers, stamps,
):  # fmt: skip
    """Step from component `first_position` of step `first_step` up to the end of step
    `first_step + steps - 1`. Returns (code, step, position, component, call, status, kind):
    DONE (all steps ran; step = the next one), HAND_BACK (component `position` of step `step`
    needs Python), WATCH (the position after step `step - 1` is to be checked), FAILED (component
    `component` failed at step `step`: `call`, `status`, `kind` of the set/get group), POLL (a
    sweep whose C_FLAGS is 1 is due at `position` of step `step`: the caller looks, then calls
    again from there, which steps it).

    For repeated calls on the same tables, `Kernel(tables...)(first_step, ...)` skips the checks."""
    kernel = Kernel(
        components, step_sizes, link_addresses, link_numbers, groups, slot_addresses, slot_scales,
        checks, history, rows, watch_addresses, watch_numbers, stamps,
    )  # fmt: skip
    return kernel(first_step, steps, first_position, start_ns, h_ns, jacobi)


def pack_records(
    order: np.ndarray,
    streams: np.ndarray,
    fields: np.ndarray,
    raw: np.ndarray,
    blob: bytes,
    size: int,
    out: bytearray | None = None,
) -> tuple[bytearray | memoryview, np.ndarray, np.ndarray, np.ndarray]:
    """MCAP Message records of held messages, in write order, built in C (kernel.c's
    `navcosim_pack_records`): `order` (int64) the stream number of each message; `streams` the
    stream table (int64, STREAM_COLUMNS per stream number: a fixed-layout stream's template record
    with its stamps and float64 fields written per message from its times and matrix rows, or
    STREAM_RAW); `fields` the field table (FIELD_COLUMNS); `raw` the raw messages' table
    (RAW_COLUMNS, in their order) with their payloads in `blob`; `size` the records' total bytes.
    Returns (records, offsets, channels, times) as `ChunkWriter.add_records` takes them. The
    addresses in the tables must point at live arrays of the right length (the caller's). `out`:
    a buffer of at least `size` bytes to write the records into (records is then a view of its
    first `size` bytes: a caller packing again and again skips allocating and zeroing them)."""
    _kernel()
    count = len(order)
    if len(streams) > MAX_STREAMS:
        raise ValueError(f"pack_records: {len(streams)} streams, at most {MAX_STREAMS}")
    tables = [np.ascontiguousarray(table, dtype=np.int64) for table in (order, streams, fields, raw)]
    if out is None or len(out) < size:
        out = bytearray(size)
    records = out if len(out) == size else memoryview(out)[:size]
    offsets = np.empty(count, dtype=np.int64)
    channels = np.empty(count, dtype=np.int64)
    times = np.empty(count, dtype=np.uint64)
    written = _packer(
        count,
        tables[0].ctypes.data,
        len(tables[1]),
        tables[1].ctypes.data,
        tables[2].ctypes.data,
        tables[3].ctypes.data,
        blob,
        (ctypes.c_char * size).from_buffer(out) if size else None,
        size,
        offsets.ctypes.data,
        channels.ctypes.data,
        times.ctypes.data,
    )
    if written != size:
        raise ValueError(f"pack_records: the records are {written} bytes, not the {size} expected")
    return records, offsets, channels, times


def warm_up() -> None:
    """Load the kernel's library, building it first on a machine that has none (a build or install
    step can call it, so a first run does not compile)."""
    _kernel()
