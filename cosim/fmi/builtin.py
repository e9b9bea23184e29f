"""The project's own FMUs: where the built `.fmu` of each one is, building it when needed.

Each FMU exists as FMI 2.0 and as FMI 3.0 (`builtin_fmu(name, fmi_version=3)`), built from the
same C model. A wheel ships the FMUs prebuilt in `cosim/_fmus/` (FMI 3.0 in `cosim/_fmus/fmi3/`).
A source checkout (editable install) builds them on first use into a cache (`<repo>/build/fmus/`,
or `$NAVCOSIM_FMU_CACHE`; FMI 3.0 in its `fmi3/`) and rebuilds one when the hash of its sources
changes (checked by the files' times and sizes first: `build_if_stale`), so an edit to the C code
is picked up on the next call
whatever installed the package (pip never rebuilds an editable install; uv only with cache-keys).

A first run compiles the FMUs it uses and the C kernels it loads (`native.load`): `prepare`
starts all of those builds at once on a pool of compiler processes, one per core, and says so;
`builtin_fmu` and `native.load.load` then wait for the one they need. A free core takes the queued
build the run needs first (`_NeedOrderedPool`, `RUN_KERNELS`): the kernels that check the scenario
and the longest one, the FMUs in the order the run reads them, then the other kernels, so the
master's stepping kernel, loaded last, compiles while the run sets up.
"""

from __future__ import annotations

import fcntl
import heapq
import importlib.util
import itertools
import os
import threading
from collections.abc import Callable, Iterable
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import planner
from cosim.errors import CosimError, shorten
from native import load as native_load

if TYPE_CHECKING:  # imported when a build is started: concurrent.futures imports logging (~8 ms)
    from concurrent.futures import Future

GENERATION_TOOL = "navcosim"  # how the project FMUs' generationTool starts

PACKAGE_DIR = Path(__file__).resolve().parent.parent  # the `cosim` package
SHIPPED_DIR = PACKAGE_DIR / "_fmus"
SOURCE_ROOT = PACKAGE_DIR.parent / "fmus"
# The compiled kernels every scenario run loads (tests/fmi/test_fmu_build.py holds this list to what a
# run loads), in the order a first run starts their builds (`prepare`): the planner's distance
# transform and the world's distances, which check the scenario's start and goal before its FMUs are
# read; the planner's grid search, loaded right after the FMUs (~0.42 s of CPU: the settings of a
# scenario's planner and planner.plan's defaults only, planner/native/astar_general.c has the
# others); those three before the FMUs (`BEFORE_FMUS`). After the FMUs, the costmap, loaded with
# the grid search, and the master's stepping kernel, loaded last when the run starts (compiled
# while the run sets up).
BEFORE_FMUS = (
    Path(planner.__file__).parent / "native" / "distance.c",
    PACKAGE_DIR / "world" / "native" / "world.c",
    Path(planner.__file__).parent / "native" / "astar.c",
)
RUN_KERNELS = (
    *BEFORE_FMUS,
    PACKAGE_DIR / "navigation" / "native" / "costmap.c",
    PACKAGE_DIR / "core" / "native" / "kernel.c",
)


def documented_nan_variables(description) -> tuple[str, ...]:
    """The real outputs of a project FMU whose NaN is a value: those whose description in
    modelDescription.xml (the single source of an FMU's variables) says when they are NaN, such as
    VFH's steering_dir "(NaN when nothing is free)". () for an FMU another tool generated."""
    if not (description.generationTool or "").startswith(GENERATION_TOOL):
        return ()
    return tuple(
        variable.name
        for variable in description.modelVariables
        if variable.causality == "output"
        and variable.type in ("Real", "Float64")
        and "NaN" in (variable.description or "")
    )


@cache
def _build_module(source_root: Path) -> ModuleType:
    """`fmus/build.py` of a source checkout (not a Python package: it also runs inside setup.py)."""
    spec = importlib.util.spec_from_file_location("navcosim_fmu_build", source_root / "build.py")
    if spec is None or spec.loader is None:
        raise CosimError(f"cannot load the FMU build script {source_root / 'build.py'}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def remove_build_scratch() -> None:
    """Remove the temporary folder in which this process compiled the FMUs' shared C code (kept for
    its further builds, and removed at its exit): for a process that ends with `os._exit`, without
    its exit handlers (the sweep's fork server, which builds what its warm-up run needs), which
    would otherwise leave the folder behind. Nothing when it built nothing."""
    if _build_module.cache_info().currsize and _has_sources(SOURCE_ROOT):
        _build_module(SOURCE_ROOT).remove_glue_folder()


def _has_sources(source_root: Path) -> bool:
    return (source_root / "build.py").is_file() and (source_root / "common").is_dir()


def default_cache_dir() -> Path:
    """Where a source checkout keeps its built FMUs."""
    override = os.environ.get("NAVCOSIM_FMU_CACHE")
    return Path(override) if override else SOURCE_ROOT.parent / "build" / "fmus"


def known_names(source_root: Path = SOURCE_ROOT) -> list[str]:
    """Names of the project FMUs available in this installation."""
    if _has_sources(source_root):
        return _build_module(source_root).fmu_names(source_root)
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.fmu"))


def _is_known(name: str) -> bool:
    """`name in known_names()`; a source folder's name is told by one look at its
    modelDescription.xml (the listing of every folder is read only for another name)."""
    plain = isinstance(name, str) and name and "/" not in name and "\0" not in name
    if plain and not name.startswith(".") and _has_sources(SOURCE_ROOT):
        if (SOURCE_ROOT / name / "modelDescription.xml").is_file():
            return True
    return name in known_names()


FMI_VERSIONS = (2, 3)


def _check_version(fmi_version: int) -> int:
    if isinstance(fmi_version, bool) or fmi_version not in FMI_VERSIONS:
        raise CosimError(f"FMI version {fmi_version!r}: the project FMUs are built as FMI 2 and FMI 3")
    return int(fmi_version)


def version_dir(directory: Path, fmi_version: int) -> Path:
    """Where the FMUs of `fmi_version` are under a cache or shipped folder: FMI 2.0 in it, FMI 3.0 in
    its `fmi3/` subfolder (the layout of `fmus/build.py`)."""
    return directory if fmi_version == 2 else directory / "fmi3"


RACY_SECONDS = 2.0  # a source modified this close to its stamp may hide an edit from (mtime, size)


def _stat_lines(files: list[Path], source_root: Path) -> list[str]:
    """One line per source file: modification time [ns], size, path (relative to the source root, so
    a checkout copied with its times keeps its stamps): what the cheap check compares."""
    lines = []
    for path in files:
        if "__pycache__" in path.parts or not path.is_file():
            continue
        status = path.stat()
        name = path.relative_to(source_root) if path.is_relative_to(source_root) else path
        lines.append(f"{status.st_mtime_ns} {status.st_size} {name}")
    return lines


def _environment_line(model_dir: Path, fmi_version: int) -> str:
    """What the hash covers besides the files: the FMI header folder (fmpy's, else ours, as
    `fmus/build.py` chooses it; found without importing fmpy) and $CC."""
    headers = model_dir.parent / "common" / f"fmi{fmi_version}"
    spec = importlib.util.find_spec("fmpy")
    if spec is not None and spec.origin:
        shipped = Path(spec.origin).parent / "c-code"
        if (shipped / f"fmi{fmi_version}Functions.h").is_file():
            headers = shipped
    return f"env {headers} CC={os.environ.get('CC', '')}"


def _stamp_is_fresh(stamp: Path, target: Path, lines: list[str], environment: str) -> bool:
    """True when the stamp lists exactly these files with these times and sizes (and the same
    environment), and none of them was modified within RACY_SECONDS of the stamp's writing (an edit
    in the same clock tick as the build could keep both): the sources are those of the build."""
    try:
        recorded = stamp.read_text().splitlines()
        stamp_ns = stamp.stat().st_mtime_ns
        if not target.is_file():
            return False
    except OSError:
        return False
    if recorded[1:] != [environment, *lines]:
        return False
    newest = max((int(line.split(" ", 1)[0]) for line in lines), default=0)
    return newest < stamp_ns - RACY_SECONDS * 1e9


# The FMUs found fresh in this process, by (name, source root, cache folder, FMI version): None after
# the first check (which reads no more than it must), then the environment line, the paths the check
# depended on (every folder whose listing gives the source files, every source file, the stamp, the
# FMU) and their `_path_status` read before it. A sweep's worker checks the same four FMUs for every
# run; when nothing of that changed (no file added, removed, renamed or written: each changes a
# folder's or the file's time, size or inode), the answer is the same and the check (listing the
# folders, reading the stamp) is skipped.
_SEEN_FRESH: dict[tuple[str, Path, Path, int], tuple[str, tuple[str, ...], tuple] | None] = {}


def _path_status(paths: tuple[str, ...]) -> tuple | None:
    """(modification time [ns], size, inode) of each path; None when one cannot be read."""
    status = []
    for path in paths:
        try:
            found = os.stat(path)
        except OSError:
            return None
        status.append((found.st_mtime_ns, found.st_size, found.st_ino))
    return tuple(status)


def _source_folders(model_dir: Path) -> list[str]:
    """The folders whose listings `source_files` reads: the model's and `common/`, with their subfolders."""
    folders = []
    for top in (model_dir, model_dir.parent / "common"):
        folders.append(str(top))
        folders.extend(str(path) for path in sorted(top.rglob("*")) if path.is_dir())
    return folders


def _is_fresh(
    name: str, source_root: Path, folder: Path, fmi_version: int, environment: str | None = None
) -> bool:
    """Whether the FMU in `folder` (the cache's folder of `fmi_version`) is that of the sources, by
    its stamp's times and sizes (`_stamp_is_fresh`); False when that cannot tell. An FMU found
    fresh before in this process, with nothing it depends on changed since, is (`_SEEN_FRESH`).
    `environment`: `_environment_line` when the caller has it."""
    model_dir = source_root / name
    if environment is None:
        environment = _environment_line(model_dir, fmi_version)
    key = (name, source_root, folder, fmi_version)
    seen = _SEEN_FRESH.get(key)
    if seen is not None and seen[0] == environment and _path_status(seen[1]) == seen[2]:
        return True
    stamp, target = folder / f"{name}.stamp", folder / f"{name}.fmu"
    files = _build_module(source_root).source_files(model_dir, fmi_version)
    paths = status = None
    if key in _SEEN_FRESH:  # found fresh before: asked again, so worth keeping (a first check reads no more)
        # Read before the check: a change after this shows as a different status next time.
        paths = (*_source_folders(model_dir), *map(str, files), str(stamp), str(target))
        status = _path_status(paths)
    lines = _stat_lines(files, source_root)
    fresh = _stamp_is_fresh(stamp, target, lines, environment)
    if fresh:
        _SEEN_FRESH[key] = None if paths is None or status is None else (environment, paths, status)
    else:
        _SEEN_FRESH.pop(key, None)
    return fresh


def build_if_stale(name: str, source_root: Path, cache_dir: Path, fmi_version: int = 2) -> Path:
    """Build FMU `name` (FMI `fmi_version`) from `source_root` into `cache_dir` (FMI 3.0: its `fmi3/`
    subfolder) unless its stamp matches the sources.

    The stamp holds the SHA-256 of the sources (`source_hash`) and each source file's modification
    time and size. When every file's time and size match (and none is within RACY_SECONDS of the
    stamp, where an edit could keep both), the FMU is up to date without reading a source; otherwise
    the hash decides: equal, the stamp's times are renewed; different, the FMU is rebuilt.

    Safe with concurrent callers: one process builds under a file lock while the others wait,
    and the archive and stamp are renamed into place atomically.
    """
    build = _build_module(source_root)
    model_dir = source_root / name
    cache_dir = version_dir(cache_dir, _check_version(fmi_version))
    target, stamp = cache_dir / f"{name}.fmu", cache_dir / f"{name}.stamp"
    try:
        environment = _environment_line(model_dir, fmi_version)
        if _is_fresh(name, source_root, cache_dir, fmi_version, environment):
            return target
        cache_dir.mkdir(parents=True, exist_ok=True)
        with open(cache_dir / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            digest = build.source_hash(model_dir, fmi_version)
            recorded = stamp.read_text().splitlines()[:1] if stamp.is_file() else []
            if not (target.is_file() and recorded == [digest]):
                compile_safely = native_load.run_compiler
                build.build_fmu(model_dir, cache_dir, fmi_version=fmi_version, run_compiler=compile_safely)
            # Times read after the hash: a file edited in between hashes differently next time.
            lines = _stat_lines(build.source_files(model_dir, fmi_version), source_root)
            temporary_stamp = cache_dir / f".{name}.stamp.{os.getpid()}"
            temporary_stamp.write_text("\n".join([digest, environment, *lines]) + "\n")
            os.replace(temporary_stamp, stamp)
    except build.FmuBuildError as error:
        raise CosimError(f"building FMU {name}: {error}") from None
    except OSError as error:
        raise CosimError(f"building FMU {name} in {cache_dir}: {error.strerror or error}") from None
    return target


def builtin_fmu(name: str, fmi_version: int = 2) -> Path:
    """The built `.fmu` of project FMU `name` (e.g. "DifferentialDrive") as an FMI `fmi_version`
    (2 or 3) co-simulation FMU, built if needed. The FMI 3.0 build of a model has its arrays
    (waypoints, ranges, angles) as array variables; the FMI 2.0 build has them as scalars.

    Raises CosimError for an unknown name (listing the known ones), another FMI version or a failed
    build.
    """
    fmi_version = _check_version(fmi_version)
    if not _is_known(name):
        names = known_names()
        raise CosimError(f"unknown project FMU {shorten(name)!r}; known: {', '.join(names) or '(none)'}")
    if _has_sources(SOURCE_ROOT):
        cache_dir = default_cache_dir()
        key = (name, fmi_version, cache_dir)
        with _lock:
            pending = _pending.pop(key, None)
            checked = key in _fresh
            _fresh.discard(key)  # once: a later call checks again (the sources may change meanwhile)
        if pending is not None:
            return pending.result()  # started by `prepare`; its CosimError if the build failed
        if checked:
            return version_dir(cache_dir, fmi_version) / f"{name}.fmu"
        return build_if_stale(name, SOURCE_ROOT, cache_dir, fmi_version)
    return version_dir(SHIPPED_DIR, fmi_version) / f"{name}.fmu"


_pending: dict[tuple[str, int, Path], Future] = {}  # FMU builds `prepare` started, until used
_fresh: set[tuple[str, int, Path]] = set()  # FMUs `prepare` found up to date, until used
_lock = threading.Lock()


class _NeedOrderedPool:
    """Builds on one thread per core (each runs one compiler process at a time), where a free thread
    takes the queued build with the lowest rank, not the oldest: a first run queues its kernels at
    once and its FMUs when the scenario names them, and needs the FMUs before most of the kernels.
    The threads end when the builds do; the interpreter waits for them at exit, so no build is left
    half-done (each writes a temporary file and renames it: a reader never sees half of one)."""

    def __init__(self, workers: int) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self._threads = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="navcosim-build")
        self._queue: list[tuple] = []  # a heap of (rank, number, future, function, arguments)
        self._numbers = itertools.count()  # equal ranks in the order they came
        self._lock = threading.Lock()

    def submit(self, rank: tuple, function: Callable, *arguments) -> Future:
        """Queue `function(*arguments)` at `rank`; its future."""
        from concurrent.futures import Future

        future: Future = Future()
        with self._lock:
            heapq.heappush(self._queue, (rank, next(self._numbers), future, function, arguments))
        self._threads.submit(self._run_first)  # one turn of a thread for each build queued
        return future

    def _run_first(self) -> None:
        with self._lock:
            _, _, future, function, arguments = heapq.heappop(self._queue)
        if not future.set_running_or_notify_cancel():
            return
        try:
            result = function(*arguments)
        except BaseException as error:  # noqa: BLE001 - handed to whoever waits for the build
            future.set_exception(error)
        else:
            future.set_result(result)


class _Ranked:
    """The pool as an executor whose builds all get one rank (what `native.load.start_builds` takes)."""

    def __init__(self, pool: _NeedOrderedPool, rank: tuple) -> None:
        self._pool, self._rank = pool, rank

    def submit(self, function: Callable, *arguments) -> Future:
        return self._pool.submit(self._rank, function, *arguments)


_builders: _NeedOrderedPool | None = None


def _executor() -> _NeedOrderedPool:
    """The pool that runs the builds `prepare` starts: one compiler process per core at a time."""
    global _builders
    if _builders is None:
        _builders = _NeedOrderedPool(os.cpu_count() or 1)
    return _builders


def prepare(
    fmu_names: Iterable[str],
    fmi_version: int = 2,
    kernels: Iterable[Path] = RUN_KERNELS,
    announce: Callable[[str], None] | None = None,
) -> None:
    """Start building, side by side, each project FMU of `fmu_names` (FMI `fmi_version`) whose build
    is not up to date and each kernel of `kernels` not compiled yet; returns at once. A first run
    then waits for the longest build, not for their sum. Builds start in the order a run needs them
    (`_NeedOrderedPool`): the kernels given first that are in `BEFORE_FMUS`, then the FMUs in the
    order given, then the other kernels in the order given, whichever call of `prepare` queued
    them (a command that compiles only kernels, `cosim plan`, has them in its own order).
    `announce` gets one line per kind of build started ("building FMUs ...", "compiling kernels
    ..."); nothing when all are built. Errors come later, from the `builtin_fmu` or kernel load
    that waits for the failed build."""
    fmi_version = _check_version(fmi_version)
    kernels = [Path(path) for path in kernels if Path(path).is_file()]
    stale: list[str] = []
    cache_dir = default_cache_dir()
    if _has_sources(SOURCE_ROOT):
        folder = version_dir(cache_dir, fmi_version)
        known = set(known_names())
        for name in dict.fromkeys(fmu_names):
            key = (name, fmi_version, cache_dir)
            if name not in known or key in _pending:
                continue
            try:
                if _is_fresh(name, SOURCE_ROOT, folder, fmi_version):
                    with _lock:
                        _fresh.add(key)
                    continue
            except OSError:
                pass  # `build_if_stale` reports it
            stale.append(name)
    uncompiled = native_load.missing(kernels)
    if not (stale or uncompiled):
        return  # a warm start: a few `stat` calls and hashes of the kernel sources
    pool = _executor()
    with _lock:
        for number, name in enumerate(stale):
            _pending[(name, fmi_version, cache_dir)] = pool.submit(
                (1, number), build_if_stale, name, SOURCE_ROOT, cache_dir, fmi_version
            )
    early = {path.resolve() for path in BEFORE_FMUS}
    ahead = True  # the kernels given before any outside `BEFORE_FMUS` go before the FMUs
    started = []
    for number, source in enumerate(uncompiled):
        ahead = ahead and source in early
        started += native_load.start_builds([source], _Ranked(pool, (0 if ahead else 2, number)))
    if not native_load.compiler_found():
        announce = None  # the builds fail at once: their one-line error says it all
    if announce is not None and stale:
        announce(f"building FMUs {', '.join(stale)} (first use or changed sources) ...")
    if announce is not None and started:
        announce(f"compiling kernels {', '.join(p.stem for p in started)} (first use or changed sources) ...")


def build_all(fmi_versions: tuple[int, ...] = FMI_VERSIONS) -> list[Path]:
    """Build (or find up to date) every project FMU in each of `fmi_versions`; returns their paths."""
    return [builtin_fmu(name, version) for version in fmi_versions for name in known_names()]
