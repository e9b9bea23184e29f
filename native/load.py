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
  the same library at once each get a whole one;
- `start_builds` compiles several missing ones side by side on an executor (a first run's kernels),
  and `load` then waits for the one it needs.

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
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # not imported at run time: concurrent.futures imports logging (~8 ms)
    from concurrent.futures import Executor, Future

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
_pending: dict[Path, Future] = {}  # builds started by `start_builds`, until `load` takes them
_found: dict[Path, Path] = {}  # libraries `missing` found built, until `load` takes them (once)
_lock = threading.Lock()
# Compilers are started under this lock, and a fork (from another thread) waits for it: a process
# forked while `subprocess` holds a compiler's pipes open in this one would keep their write ends,
# and the build would wait for that process to end (`cosim run` forks its plotter, which lives as
# long as the run). `subprocess` itself forks without the hooks, so starting under it is safe.
_spawning = threading.RLock()


def _after_fork_in_child() -> None:
    """A forked process has none of its parent's build threads: their builds (`_pending`) would
    never finish here, and `_lock` may have been held by one of them. The child forgets them and
    builds (or finds, if the parent's build has landed) what it loads itself; the cache's rename
    keeps two processes building one library apart. (`cosim run`'s plot process drafts its figure
    with the distance kernel while a first run's builds go on.)"""
    global _lock, _pending
    _lock = threading.Lock()
    _pending = {}
    _spawning.release()


os.register_at_fork(
    before=_spawning.acquire, after_in_parent=_spawning.release, after_in_child=_after_fork_in_child
)


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


def compiler_found() -> bool:
    """Whether `compiler()` names a program that exists (a first use then says what it compiles;
    without one, the build's own one-line error is all a user sees)."""
    try:
        words = shlex.split(compiler())
    except (NativeBuildError, ValueError):
        return False
    return bool(words) and shutil.which(words[0]) is not None


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


def run_compiler(command: list[str], cwd: str | Path | None = None) -> subprocess.CompletedProcess:
    """`subprocess.run(command, capture_output=True, text=True, cwd=cwd)`, safe to call from a thread
    of a process that forks (see `_spawning`). OSError if the command cannot be started."""
    with _spawning:
        process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd
        )
    stdout, stderr = process.communicate()
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


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


def build_folder(anchor: Path) -> Path:
    """Where the kernels of the package holding `anchor` (a file in it) are built when no shipped
    one is found: the first folder after the shipped one (`$NAVCOSIM_NATIVE_CACHE`, else
    `<repo>/build/native/` in a source checkout, else `~/.cache/navcosim/native/`). Other per-user
    build products of a command may be kept there too; it may not exist yet."""
    dirs = _cache_dirs(Path(anchor).resolve())
    return (dirs[1:] or dirs)[0]


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
            done = run_compiler(command)
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


def _find(source: Path) -> Path | None:
    """The built library of `source` in the first cache folder that holds it, or None."""
    name = library_name(source)
    return next((d / name for d in _cache_dirs(source) if (d / name).is_file()), None)


def _build_into_cache(source: Path) -> Path:
    """Build `source` into the first writable cache folder; the library's path."""
    dirs = _cache_dirs(source)
    for directory in dirs[1:] or dirs:
        try:
            return build(source, directory)
        except OSError:
            continue  # not writable: the next one
    raise NativeBuildError(f"no writable folder to build {source.name} into: {dirs[-1]}")


def missing(sources) -> list[Path]:
    """The resolved `sources` whose library is neither loaded, nor being built, nor in a cache."""
    found = []
    for source in sources:
        source = Path(source).resolve()
        with _lock:
            if source in _loaded or source in _pending:
                continue
        built = _find(source)
        if built is None:
            found.append(source)
        else:
            with _lock:
                _found[source] = built  # `load` need not hash the sources again
    return found


def start_builds(sources, executor: Executor) -> list[Path]:
    """Start building, on `executor`, each of `sources` that no cache holds yet, so that a later
    `load` waits for it instead of compiling it then: a process that needs several kernels compiles
    them side by side (and beside other work) instead of one after the other. Returns the sources
    whose build was started (none when all are built: a warm start costs one `stat` per source)."""
    started = []
    for source in sources:
        source = Path(source).resolve()
        with _lock:
            if source in _loaded or source in _pending or _find(source) is not None:
                continue
            _pending[source] = executor.submit(_build_into_cache, source)
        started.append(source)
    return started


def load(source: str | Path) -> ctypes.CDLL:
    """The loaded library of `source` (a `.c` file), built first if no cache holds it (or waited
    for, when `start_builds` started its build). Once per process."""
    source = Path(source).resolve()
    library = _loaded.get(source)
    if library is not None:
        return library
    with _lock:
        pending = _pending.pop(source, None)
        found = _found.pop(source, None)
    if pending is not None:
        path = pending.result()  # its NativeBuildError, if the build failed (a later load tries again)
    elif found is not None and found.is_file():
        path = found
    else:
        path = _find(source) or _build_into_cache(source)
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
