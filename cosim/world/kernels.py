"""The C kernels of `cosim.world` (native/world.c, and a fleet's native/fleet.c), loaded with
`native.load` on first use.

`library()` returns world.c's loaded library with every function's `argtypes`/`restype` set once;
`fleet_library()` fleet.c's (contacts, judging, a fleet's Python components a block).
`LidarArrays` and `WorldArrays` mirror the structs of world.c: the long-lived arrays (as cached
addresses) and constants of one lidar or one world, filled once, so a call passes the struct's
address and a few numbers (a world's query is packed into the struct: a call of one argument;
so one `WorldDistance` serves one thread at a time). The arrays must stay alive and in place as
long as the struct is used: `ArrayRefs.pointer` keeps a reference to each array it takes the
address of.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from native.load import bind, load

SOURCE = Path(__file__).parent / "native" / "world.c"
FLEET_SOURCE = Path(__file__).parent / "native" / "fleet.c"
_library: ctypes.CDLL | None = None
_fleet_library: ctypes.CDLL | None = None

_p = ctypes.c_void_p
_i64 = ctypes.c_int64
_f64 = ctypes.c_double


class WorldArrays(ctypes.Structure):
    """`World` of world.c: the grid and the unknown shapes of a `WorldDistance`, and the query."""

    _fields_ = [
        ("occupied", _p), ("rows", _i64), ("cols", _i64),
        ("x_min", _f64), ("y_min", _f64), ("x_max", _f64), ("y_max", _f64), ("resolution", _f64),
        ("circles", _p), ("n_circles", _i64),
        ("vertices", _p), ("starts", _p), ("n_starts", _i64),
        ("x", _f64), ("y", _f64), ("row", _i64), ("col", _i64), ("offset", _f64), ("field", _f64),
    ]  # fmt: skip

    # The query fields x .. field, in order, for `struct.pack_into` (one call, cheaper than as many
    # ctypes arguments or field assignments).
    QUERY = "=ddqqdd"


class LidarArrays(ctypes.Structure):
    """`Lidar` of world.c: the grid, beams, noise buffers, shapes, scratch and output of a `Lidar`."""

    _fields_ = [
        ("occupied_up", _p), ("rows", _i64), ("cols", _i64),
        ("origin_x", _f64), ("origin_y", _f64), ("resolution", _f64),
        ("range_min", _f64), ("range_max", _f64),
        ("beam_angles", _p), ("count", _i64),
        ("angle_jitter", _p), ("range_jitter", _p),
        ("circles", _p), ("n_circles", _i64),
        ("segments", _p), ("n_segments", _i64),
        ("vertices", _p), ("starts", _p), ("n_starts", _i64),
        ("directions", _p), ("ranges", _p), ("clearance", _p),
    ]  # fmt: skip


class MonitorArrays(ctypes.Structure):
    """`Monitor` of world.h (world.c's, shared with fleet.c): a static world's position checks
    (`OutcomeMonitor.check_positions`): the world's struct, its centre field and the polygons'
    bounding circles, the vehicle and goal, the monitor's state (read and written back by each
    call), why the last call stopped, and the positions and times of a call (rows x, y, t of a
    3 x capacity array)."""

    _fields_ = [
        ("world", _p), ("centre_field", _p), ("bounds", _p), ("n_bounds", _i64),
        ("radius", _f64), ("goal_x", _f64), ("goal_y", _f64), ("tolerance", _f64), ("speed", _f64),
        ("last_x", _f64), ("last_y", _f64), ("distance", _f64), ("min_clearance", _f64),
        ("anchor_x", _f64), ("anchor_y", _f64), ("anchor_t", _f64), ("anchor_bound", _f64),
        ("reason", _i64), ("points", _p), ("capacity", _i64),
    ]  # fmt: skip


class JudgeArrays(ctypes.Structure):
    """`Judge` of fleet.c: one robot of `fleet_judge` (a fleet's block of steps judged in C): its
    monitor's struct, whether it is judged there, the numbers of its outcome, deadlock rule and
    monitor that the judging changes (kept in the struct while it is), the rule's constants, and
    the step and reason that ended it."""

    _fields_ = [
        ("monitor", _p), ("active", _i64), ("last_x", _f64), ("last_y", _f64),
        ("distance", _f64), ("recovery_time", _f64), ("stopped_time", _f64), ("deadlocked_at", _f64),
        ("best", _f64), ("best_time", _f64), ("progress_deadlocked_at", _f64),
        ("deadlock_after", _f64), ("goal_x", _f64), ("goal_y", _f64), ("time", _f64),
        ("stopped_speed", _f64), ("progress", _f64), ("recover", _f64),
        ("moved", _f64), ("event", _i64), ("reason", _i64),
    ]  # fmt: skip


class BlockCopyArrays(ctypes.Structure):
    """`BlockCopy` of fleet.c: one copy of `fleet_python_block`'s gathers, `count` values into
    consecutive inputs from outputs `stride` values apart, times `scale` when `multiply`, plus
    `offset` when `add`."""

    _fields_ = [
        ("source", _p), ("target", _p), ("count", _i64), ("stride", _i64),
        ("multiply", _i64), ("add", _i64), ("scale", _f64), ("offset", _f64),
    ]  # fmt: skip


class BlockStepArrays(ctypes.Structure):
    """`BlockStep` of fleet.c: one component of `fleet_python_block` (a fleet's Python components
    stepped in one call a block): its period, kind (BLOCK_*), gather (a stretch of the copies),
    and what steps it (a lidar's struct, inputs and the other robots' circles; a C step and its
    state)."""

    _fields_ = [
        ("period", _i64), ("kind", _i64), ("first_copy", _i64), ("copies", _i64),
        ("lidar", _p), ("inputs", _p), ("robot_rows", _p), ("robots", _i64),
        ("c_step", _p), ("state", _p),
    ]  # fmt: skip


class BlockProgramArrays(ctypes.Structure):
    """`BlockProgram` of fleet.c: `fleet_python_block_threads`'s program, its steps and copies, the
    chained entries chain by chain (`members`, chain c from `firsts[c]` to `firsts[c + 1]`), two
    scratch arrays of one value a chain, the thread pool (`block_pool_new`; NULL: one thread) and
    the fewest chains due that use it, and the state of the step under way (the kernel's)."""

    _fields_ = [
        ("steps", _p), ("n", _i64), ("copies", _p), ("members", _p), ("firsts", _p), ("chains", _i64),
        ("cursor", _p), ("due", _p), ("pool", _p), ("min_chains", _i64),
        ("open", _i64), ("k", _i64), ("start", _i64), ("end", _i64), ("t", _f64),
    ]  # fmt: skip


class KernelJobArrays(ctypes.Structure):
    """`KernelJob` of fleet.c: one call of the master's stepping kernel (`navcosim_step_kernel`, by
    its address) from `first_step` for `steps` steps on one set of its tables (`Kernel`'s struct)
    into its result (`block_pool_kernels`)."""

    _fields_ = [
        ("function", _p), ("first_step", _i64), ("steps", _i64), ("start_ns", _i64), ("h_ns", _i64),
        ("tables", _p), ("result", _p),
    ]  # fmt: skip


# `fleet_python_block`'s kinds of component: stepped by Python (handed back before its gather), a
# lidar swept in C, a component with a C step (handed back when that says so), the copies only.
BLOCK_PYTHON, BLOCK_LIDAR, BLOCK_C_STEP, BLOCK_COPIES = 0, 1, 2, 3


# `world_check_positions`'s reasons: none (all steps checked), collision, goal reached, and a step
# it leaves to Python (a cell off the grid).
CHECK_GOING, CHECK_COLLISION, CHECK_GOAL, CHECK_PYTHON = 0, 1, 2, 3


class ArrayRefs:
    """Addresses of arrays checked once (dtype, C order), each array kept alive by this object."""

    def __init__(self) -> None:
        self._held: list[np.ndarray] = []

    def pointer(self, array: np.ndarray, dtype, writable: bool = False) -> int:
        if array.dtype != np.dtype(dtype) or not array.flags.c_contiguous:
            raise TypeError(f"a kernel needs a C-contiguous {np.dtype(dtype)} array, got {array.dtype}")
        if writable and not array.flags.writeable:
            raise TypeError("a kernel writes this array: it must be writable")
        self._held.append(array)
        return array.ctypes.data


class Bound:
    """Base of an object whose kernel struct holds addresses of its own arrays (`_bind` builds the
    struct and everything derived from it, named in `_BOUND`): a copy or a pickle leaves those
    out and binds anew, to its own arrays, instead of carrying addresses into the original's."""

    _BOUND: tuple[str, ...] = ()

    def _bind(self) -> None:
        raise NotImplementedError

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        for name in self._BOUND:
            state.pop(name, None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind()


def pointer(array: np.ndarray, dtype) -> int:
    """The address of a per-call array after the same checks (no reference kept: the caller's)."""
    if array.dtype != np.dtype(dtype) or not array.flags.c_contiguous:
        raise TypeError(f"a kernel needs a C-contiguous {np.dtype(dtype)} array, got {array.dtype}")
    return array.ctypes.data


def library() -> ctypes.CDLL:
    """world.c built (if needed) and loaded, its functions typed; once per process."""
    global _library
    if _library is None:
        _library = bind(
            load(SOURCE),
            {
                "world_polygon_distance": (_f64, [_f64, _f64, _p, _i64, _i64]),
                "world_distance": (_f64, [_p]),
                "lidar_measure": (None, [_p, _f64, _f64, _p, _i64, _p]),
                "lidar_scan": (None, [_p, _f64, _f64, _f64]),
                "lidar_clearance": (None, [_p, _i64, _i64, _p]),
                "world_hypot": (_f64, [_f64, _f64]),
                "world_check_positions": (_i64, [_p, _i64]),
            },
        )
    return _library


def fleet_library() -> ctypes.CDLL:
    """fleet.c (a fleet's kernels, a library of their own: a run without a fleet never compiles
    them) built (if needed) and loaded, its functions typed, world.c's position checks and lidar
    sweep (`library()`) registered with it; once per process."""
    global _fleet_library
    if _fleet_library is None:
        world = library()
        fleet = bind(
            load(FLEET_SOURCE),
            {
                "fleet_use_world": (None, [_p, _p]),
                "fleet_gaps": (None, [_p, _i64, _i64, _p, _p, _i64, _p, _p, _p, _p]),
                "fleet_judge": (_i64, [_p, _i64, _p, _p, _p, _p, _p, _i64, _p]),
                "fleet_python_block": (_i64, [_p, _i64, _i64, _i64, _f64, _p]),
                "fleet_python_block_threads": (_i64, [_p, _i64, _i64, _f64]),
                "block_pool_new": (_p, [_i64]),
                "block_pool_free": (None, [_p]),
                "block_pool_kernels": (None, [_p, _p, _i64]),
            },
        )
        fleet.fleet_use_world(ctypes.cast(world.world_check_positions, _p), ctypes.cast(world.lidar_scan, _p))
        _fleet_library = fleet
    return _fleet_library
