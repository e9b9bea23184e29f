"""Compiled kernels in C: a `.c` file of the project built into a shared library and loaded with ctypes.

The hot loops of a run (grid A*, Hybrid A*, the lidar, distances, the costmap, the master's stepping
kernel) are C99 files beside the Python module that calls them. C instead of a JIT: a run loads a
built library in well under a millisecond, where a JIT costs every process its import and target
set-up (numba: ~0.7 s on a 2-core machine) and a fresh install minutes of compiling; the C compiler
is already required for the project's FMUs.

`load(source)` returns the library of one `.c` file (it may `#include` headers of the same folder),
building it when needed:
- its name carries a hash of the source, its headers and the flags, so an edit or new flags give a
  new library (an editable install is never rebuilt by pip);
- a wheel ships them prebuilt (`setup.py` builds every kernel into `<package>/_native/`);
- otherwise they go to `$NAVCOSIM_NATIVE_CACHE`, else `<repo>/build/native/` in a source checkout,
  else `~/.cache/navcosim/native/`: written to a temporary file, then renamed, so processes building
  the same library at once each get a whole one.

Floating point: `-O2 -ffp-contract=off` and no fast-math, so every `+ - * / sqrt` is the IEEE
operation the source says, in its order (no fused multiply-add): results do not depend on the
compiler's mood, and equal those of any other IEEE implementation doing the same operations.

Standard library only: `setup.py` imports this file in pip's isolated build environment.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

# An undeclared function is an error everywhere (GCC >= 14 already makes it one; older compilers
# would only warn, and a kernel calling a function as int-returning computes garbage).
FLAGS = (
    "-std=c99", "-O2", "-ffp-contract=off", "-fPIC", "-shared", "-Wall", "-Wextra",
    "-Werror=implicit-function-declaration",
)  # fmt: skip
LINK = ("-lm",)
SHIPPED = "_native"  # <package>/_native/: a wheel's prebuilt libraries
SUFFIX = ".dylib" if sys.platform == "darwin" else ".so"
_INCLUDE = re.compile(rb'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)
_loaded: dict[Path, ctypes.CDLL] = {}


class NativeBuildError(Exception):
    """A kernel could not be built (no compiler, compile error). One-line message.

    Not a `NavcosimError` on purpose: the user did nothing wrong; but its message says what to do."""


def compiler() -> str:
    """The C compiler: `$CC`, else the first of cc, gcc, clang on PATH."""
    chosen = os.environ.get("CC")
    if chosen:
        return chosen
    for name in ("cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return found
    raise NativeBuildError(
        "no C compiler found (cc, gcc or clang on PATH, or $CC): navcosim compiles its kernels "
        "and FMUs from C on first use"
    )


def _sources(source: Path) -> list[Path]:
    """The `.c` file and the local headers it includes (recursively, same folder tree)."""
    seen: list[Path] = []
    todo = [source]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.append(path)
        for name in _INCLUDE.findall(path.read_bytes()):
            header = (path.parent / name.decode()).resolve()
            if header.is_file():
                todo.append(header)
    return seen


def library_name(source: Path) -> str:
    """`<stem>-<hash>.so`: the hash of the sources and flags (not of the compiler: a wheel's
    prebuilt library must be found on a machine without one)."""
    digest = hashlib.sha256()
    for path in _sources(source):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(" ".join(FLAGS + LINK).encode())
    return f"{source.stem}-{digest.hexdigest()[:16]}{SUFFIX}"


def _top_package(source: Path) -> Path:
    """The top-level package folder that holds `source` (planner/native/x.c -> planner)."""
    folder, top = source.parent, None
    while folder != folder.parent:
        if (folder / "__init__.py").is_file():
            top = folder
        elif top is not None:
            break
        folder = folder.parent
    if top is None:
        raise NativeBuildError(f"{source} is not inside a Python package")
    return top


def _cache_dirs(source: Path) -> list[Path]:
    """Where to look for a built library, in order; the first writable one after the shipped
    folder is where a missing one is built."""
    override = os.environ.get("NAVCOSIM_NATIVE_CACHE")
    if override:
        return [Path(override)]
    package = _top_package(source)
    dirs = [package / SHIPPED]
    if (package.parent / "pyproject.toml").is_file():  # a source checkout (editable install)
        dirs.append(package.parent / "build" / "native")
    cache_home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    dirs.append(cache_home / "navcosim" / "native")
    return dirs


def build(source: Path, out_dir: Path, cc: str | None = None) -> Path:
    """Compile `source` into `out_dir/<library_name>`; the path."""
    cc = cc or compiler()
    target = out_dir / library_name(source)
    out_dir.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{source.stem}-", suffix=SUFFIX, dir=out_dir)
    os.close(handle)
    try:
        command = [cc, *FLAGS, "-o", temporary, str(source), *LINK]
        try:
            done = subprocess.run(command, capture_output=True, text=True)
        except OSError as error:
            raise NativeBuildError(f"cannot run the C compiler {cc}: {error.strerror or error}") from None
        if done.returncode != 0:
            lines = done.stderr.splitlines()
            first = next((line for line in lines if " error: " in line), lines[0] if lines else "")
            first = first.replace(str(source), source.name)
            raise NativeBuildError(f"compiling {source.name} failed: {first[:300]}")
        os.replace(temporary, target)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
    return target


def load(source: str | Path) -> ctypes.CDLL:
    """The loaded library of `source` (a `.c` file), built first if no cache holds it. Once per process."""
    source = Path(source).resolve()
    library = _loaded.get(source)
    if library is not None:
        return library
    dirs = _cache_dirs(source)
    name = library_name(source)
    path = next((d / name for d in dirs if (d / name).is_file()), None)
    if path is None:
        for directory in dirs[1:] or dirs:
            try:
                path = build(source, directory)
                break
            except OSError:
                continue  # not writable: the next one
        else:
            raise NativeBuildError(f"no writable folder to build {source.name} into: {dirs[-1]}")
    library = ctypes.CDLL(str(path))
    _loaded[source] = library
    return library


def bind(library: ctypes.CDLL, signatures: dict, hold_gil: bool = False) -> ctypes.CDLL:
    """`library` with the functions of `signatures` ({name: (restype, argtypes)}) typed; with
    `hold_gil`, a view of it whose calls keep the GIL (`ctypes.PyDLL`: kernels that use buffers
    shared across calls, which another thread must not enter meanwhile). Typed once per view."""
    if hold_gil:
        library = ctypes.PyDLL(library._name, handle=library._handle)
    for name, (restype, argtypes) in signatures.items():
        function = getattr(library, name)
        function.restype = restype
        function.argtypes = argtypes
    return library


def build_all(packages: dict[Path, Path]) -> list[Path]:
    """Build every kernel (each `*.c` in a folder named `native`) of the source package folders
    in `packages` into the `_native/` of the package folder each maps to. For `setup.py` (wheels)."""
    built = []
    for source_package, target_package in packages.items():
        for source in sorted(source_package.rglob("native/*.c")):
            built.append(build(source.resolve(), target_package / SHIPPED))
    return built
