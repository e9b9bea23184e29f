"""The project's own FMUs: where the built `.fmu` of each one is, building it when needed.

A wheel ships the FMUs prebuilt in `cosim/_fmus/`. A source checkout (editable install) builds
them on first use into a cache (`<repo>/build/fmus/`, or `$NAVCOSIM_FMU_CACHE`) and rebuilds one
when the hash of its sources changes, so an edit to the C code is picked up on the next call
whatever installed the package (pip never rebuilds an editable install; uv only with cache-keys).
"""

from __future__ import annotations

import fcntl
import importlib.util
import os
from functools import cache
from pathlib import Path
from types import ModuleType

from cosim.errors import CosimError

PACKAGE_DIR = Path(__file__).resolve().parent.parent  # the `cosim` package
SHIPPED_DIR = PACKAGE_DIR / "_fmus"
SOURCE_ROOT = PACKAGE_DIR.parent / "fmus"


@cache
def _build_module(source_root: Path) -> ModuleType:
    """`fmus/build.py` of a source checkout (not a Python package: it also runs inside setup.py)."""
    spec = importlib.util.spec_from_file_location("navcosim_fmu_build", source_root / "build.py")
    if spec is None or spec.loader is None:
        raise CosimError(f"cannot load the FMU build script {source_root / 'build.py'}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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


def build_if_stale(name: str, source_root: Path, cache_dir: Path) -> Path:
    """Build FMU `name` from `source_root` into `cache_dir` unless its stamp matches the sources.

    Safe with concurrent callers: one process builds under a file lock while the others wait,
    and the archive and stamp are renamed into place atomically.
    """
    build = _build_module(source_root)
    model_dir = source_root / name
    target, stamp = cache_dir / f"{name}.fmu", cache_dir / f"{name}.stamp"
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        with open(cache_dir / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            digest = build.source_hash(model_dir)
            if target.is_file() and stamp.is_file() and stamp.read_text().strip() == digest:
                return target
            build.build_fmu(model_dir, cache_dir)
            temporary_stamp = cache_dir / f".{name}.stamp.{os.getpid()}"
            temporary_stamp.write_text(digest + "\n")
            os.replace(temporary_stamp, stamp)
    except build.FmuBuildError as error:
        raise CosimError(f"building FMU {name}: {error}") from None
    except OSError as error:
        raise CosimError(f"building FMU {name} in {cache_dir}: {error.strerror or error}") from None
    return target


def builtin_fmu(name: str) -> Path:
    """The built `.fmu` of project FMU `name` (e.g. "DifferentialDrive"), built if needed.

    Raises CosimError for an unknown name (listing the known ones) or a failed build.
    """
    names = known_names()
    if name not in names:
        raise CosimError(f"unknown project FMU {name!r}; known: {', '.join(names) or '(none)'}")
    if _has_sources(SOURCE_ROOT):
        return build_if_stale(name, SOURCE_ROOT, default_cache_dir())
    return SHIPPED_DIR / f"{name}.fmu"


def build_all() -> list[Path]:
    """Build (or find up to date) every project FMU; returns their paths."""
    return [builtin_fmu(name) for name in known_names()]
