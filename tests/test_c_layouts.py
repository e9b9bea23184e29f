"""Every table shared by a C kernel and its Python side agrees: struct sizes and field offsets
against the ctypes mirrors, and numbered columns and codes against the Python constants.

Each kernel library describes itself (`navcosim_layout`, planner/native/layout.h); this test reads
that description from the built library, so it checks what the compiler laid out, not what a
comment says.
"""

from __future__ import annotations

import ctypes
import importlib
from pathlib import Path

import pytest

from native import load as native

REPO = Path(__file__).resolve().parents[1]

# source -> ({C struct: "module:ctypes class"}, modules holding its constants)
LIBRARIES = {
    "cosim/core/native/kernel.c": ({"Tables": "cosim.core.kernel:_Tables"}, ("cosim.core.kernel",)),
    "cosim/world/native/world.c": (
        {
            "World": "cosim.world.kernels:WorldArrays",
            "Lidar": "cosim.world.kernels:LidarArrays",
            "Monitor": "cosim.world.kernels:MonitorArrays",
        },
        ("cosim.world.kernels",),
    ),
    "cosim/world/native/fleet.c": (
        {
            "Judge": "cosim.world.kernels:JudgeArrays",
            "BlockStep": "cosim.world.kernels:BlockStepArrays",
            "BlockCopy": "cosim.world.kernels:BlockCopyArrays",
            "BlockProgram": "cosim.world.kernels:BlockProgramArrays",
        },
        ("cosim.world.kernels",),
    ),
    "cosim/navigation/native/costmap.c": (
        {"Costmap": "cosim.navigation.costmap:_Arrays", "PlannerStep": "cosim.navigation.planner:_StepState"},
        ("cosim.navigation.planner",),
    ),
    "planner/native/astar.c": (
        {"WorkState": "planner.astar:WorkState", "Query": "planner.astar:Query"},
        ("planner.astar", "planner.searchspace"),
    ),
    "planner/native/hybrid.c": ({"HySearch": "planner.hybrid_search:_Search"}, ("planner.hybrid_search",)),
}


def _layout(source: str) -> dict[str, int]:
    library = native.load(REPO / source)
    function = library.navcosim_layout
    function.restype = ctypes.c_int64
    function.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.POINTER(ctypes.c_int64), ctypes.c_int64]
    count = function(None, None, 0)
    names, values = (ctypes.c_char_p * count)(), (ctypes.c_int64 * count)()
    assert function(names, values, count) == count
    layout = {name.decode(): value for name, value in zip(names, values, strict=True)}
    assert len(layout) == count, f"{source} describes an entry twice"
    return layout


def _python_constant(modules: tuple[str, ...], name: str):
    """The Python side of C constant `name`: the same name, private (`_H_BITS`) or without the
    C file's prefix (`HY_FOUND_AT_GOAL` -> `FOUND_AT_GOAL`)."""
    for module in map(importlib.import_module, modules):
        for candidate in (name, f"_{name}", name.removeprefix("HY_")):
            if hasattr(module, candidate):
                return getattr(module, candidate)
    raise AssertionError(f"no Python constant for C's {name} in {', '.join(modules)}")


@pytest.mark.parametrize("source", sorted(LIBRARIES))
def test_ctypes_mirrors_match_the_c_structs(source):
    structs, _ = LIBRARIES[source]
    layout = _layout(source)
    for c_name, target in structs.items():
        module, attribute = target.split(":")
        mirror = getattr(importlib.import_module(module), attribute)
        assert layout[f"sizeof {c_name}"] == ctypes.sizeof(mirror), f"sizeof {c_name} vs {target}"
        c_fields = {
            key.split(".", 1)[1]: value for key, value in layout.items() if key.startswith(f"{c_name}.")
        }
        python_fields = {name: getattr(mirror, name).offset for name, *_ in mirror._fields_}
        assert c_fields == python_fields, f"{c_name} (C) and {target} (ctypes) differ"


@pytest.mark.parametrize("source", sorted(name for name, (_, modules) in LIBRARIES.items() if modules))
def test_python_constants_match_the_c_ones(source):
    _, modules = LIBRARIES[source]
    constants = {k: v for k, v in _layout(source).items() if not k.startswith("sizeof ") and "." not in k}
    assert constants
    differing = {name: (value, _python_constant(modules, name)) for name, value in constants.items()}
    assert {name: pair for name, pair in differing.items() if pair[0] != pair[1]} == {}


def test_every_kernel_with_a_ctypes_struct_describes_itself():
    """A new kernel whose Python side mirrors a struct must be listed above (and define navcosim_layout)."""
    mirrored = set()
    for path in [*REPO.glob("cosim/**/*.py"), *REPO.glob("planner/**/*.py")]:
        if "ctypes.Structure)" in path.read_text():
            mirrored.add(path.relative_to(REPO).as_posix())
    listed = {
        target.split(":")[0].replace(".", "/") + ".py"
        for structs, _ in LIBRARIES.values()
        for target in structs.values()
    }
    assert mirrored <= listed


def test_the_recording_tables_are_described():
    """`cosim.core.kernel.pack_records` shares three numbered tables and the MCAP head offsets with
    kernel.c: each is in the library's description, so the constants test above holds them."""
    layout = _layout("cosim/core/native/kernel.c")
    for name in ("STREAM_COLUMNS", "FIELD_COLUMNS", "RAW_COLUMNS", "MAX_STREAMS", "MESSAGE_HEAD_BYTES"):
        assert name in layout
    columns = {"P_": "STREAM_COLUMNS", "F_": "FIELD_COLUMNS", "RAW_": "RAW_COLUMNS"}
    for prefix, total in columns.items():
        numbered = sorted(
            value for name, value in layout.items() if name.startswith(prefix) and name != total
        )
        assert numbered == list(range(layout[total])), prefix  # every column named, none twice
