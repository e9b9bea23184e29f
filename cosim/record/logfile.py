"""Claiming a log file: two runs never write one file, and an existing log is never overwritten by
accident.

`claim_log(path, force)` opens `path` for writing and holds an exclusive `flock` on it until the
file is closed, so a live run's log is recognisably in use. Without `force` the file is created
with O_EXCL: an existing file is refused. With `force` an existing file is truncated and reused,
unless another live run holds its lock. A device (`/dev/null`) is written as it is, never refused.

`claim_default_log(path)` is for default names (`[output].log`): when the name is taken it tries
`<stem>-1<suffix>`, `<stem>-2<suffix>`, … with O_EXCL each time, so runs started in the same
instant each get a file of their own.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import sys
from datetime import datetime
from pathlib import Path
from typing import BinaryIO

from cosim.errors import PATH_LIMIT, CosimError, shorten

MAX_NAME_TRIES = 1000  # `<stem>-1` … `<stem>-999` after the name itself


def default_log_path(pattern: str, name: str, now: datetime | None = None) -> Path:
    """`pattern` (`[output].log`) with {scenario} = `name` and {timestamp} (local time, to the
    millisecond: 20260131-142501-123) filled in. Runs that start in the same millisecond are kept
    apart when the file is created (`claim_default_log`)."""
    now = now or datetime.now()
    stamp = f"{now:%Y%m%d-%H%M%S}-{now.microsecond // 1000:03d}"
    return Path(pattern.format(scenario=name, timestamp=stamp))


_versions: dict[tuple[str, ...], str] = {}  # `navcosim_version()` by the `sys.path` it was found on


def navcosim_version() -> str:
    """The installed navcosim's version, as a log's metadata records it ("unknown" from a bare
    checkout). Looked up once per `sys.path` (a run's header asks twice)."""
    key = tuple(sys.path)
    known = _versions.get(key)
    if known is not None:
        return known
    found = dist_info_version("navcosim")
    if found is None:
        from importlib.metadata import PackageNotFoundError, version

        try:
            found = version("navcosim")
        except PackageNotFoundError:
            found = "unknown"
    _versions[key] = found
    return found


def dist_info_version(name: str) -> str | None:
    """`importlib.metadata.version(name)` when the first distribution it would find is an installed
    `<name>-*.dist-info` or `<name>*.egg-info` folder (a plain directory on `sys.path`, searched in
    its order as importlib.metadata searches it), read from its METADATA's (else PKG-INFO's) Version
    header; None otherwise (then importlib.metadata decides). `name`: lower-case letters and digits
    (a name importlib.metadata needs no normalising for). Importing importlib.metadata and its email
    parser is ~10-20 ms of a run's start."""
    if not (name.isalnum() and name.isascii() and name.islower()):
        return None
    for entry in sys.path:
        try:
            children = os.listdir(entry or ".")
        except NotADirectoryError:
            return None  # a zip archive on sys.path: importlib.metadata looks inside
        except OSError:
            continue
        for child in children:
            low = child.lower()
            if not low.endswith((".dist-info", ".egg-info")):
                continue
            if low.rpartition(".")[0].partition("-")[0] != name:
                continue
            # importlib.metadata reads a folder's METADATA, else its PKG-INFO (an editable
            # install's `<name>.egg-info` folder in the checkout has only PKG-INFO)
            folder = os.path.join(entry or ".", child)
            metadata = os.path.join(folder, "METADATA")
            if not os.path.isfile(metadata):
                metadata = os.path.join(folder, "PKG-INFO")
            try:
                with open(metadata, encoding="utf-8") as stream:
                    for line in stream:
                        if not line.strip():
                            return None
                        name, _, value = line.partition(":")
                        if name == "Version":
                            return value.strip()
            except OSError:
                return None
            return None
    return None


def claim_log(path: Path, force: bool = False) -> BinaryIO:
    """Open a new log at `path` (parents created), locked for this process; see the module doc."""
    path = Path(path)
    where = shorten(path, PATH_LIMIT)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        descriptor = _open(path, force)
    except FileExistsError:
        raise CosimError(f"{where}: already exists; give --force to overwrite it") from None
    except OSError as error:
        raise CosimError(f"{where}: cannot write the log ({error.strerror or error})") from None
    except ValueError as error:  # an embedded NUL byte
        raise CosimError(f"{where}: cannot write the log ({error})") from None
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(descriptor)
        raise CosimError(f"{where}: in use by another run that is still writing it") from None
    except OSError:
        pass  # a file system without locks: O_EXCL alone keeps default names apart
    try:
        if stat.S_ISREG(os.fstat(descriptor).st_mode):
            os.ftruncate(descriptor, 0)  # only now: truncating before the lock could cut a live log
        return os.fdopen(descriptor, "wb")
    except OSError as error:
        os.close(descriptor)
        raise CosimError(f"{where}: cannot write the log ({error.strerror or error})") from None


def claim_default_log(path: Path) -> tuple[Path, BinaryIO]:
    """Claim `path`, or the first free `<stem>-N<suffix>` beside it; returns the name and the file."""
    path = Path(path)
    suffix = "".join(path.suffixes[-1:])
    stem = path.name[: len(path.name) - len(suffix)]
    for number in range(MAX_NAME_TRIES):
        candidate = path if number == 0 else path.with_name(f"{stem}-{number}{suffix}")
        try:
            return candidate, claim_log(candidate)
        except CosimError:
            if not _exists(candidate):
                raise  # not a name clash: a real error (permissions, no space, …)
    raise CosimError(
        f"{shorten(path, PATH_LIMIT)}: this name and {MAX_NAME_TRIES - 1} numbered variants are all taken"
    )


def is_regular_file(path: Path) -> bool:
    """True for a regular file (not a device, FIFO or directory); False when nothing is there."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def _open(path: Path, force: bool) -> int:
    flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC
    if force:
        return os.open(path, flags, 0o666)
    try:
        return os.open(path, flags | os.O_EXCL, 0o666)
    except FileExistsError:
        # A device or a FIFO holds no log to lose: write it as it is (`--out /dev/null`).
        try:
            mode = os.stat(path).st_mode
        except OSError:
            raise FileExistsError(errno.EEXIST, "exists", str(path)) from None
        if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
            return os.open(path, os.O_WRONLY | os.O_CLOEXEC)
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path)) from None
        raise


def _exists(path: Path) -> bool:
    try:
        os.lstat(path)
    except (OSError, ValueError):
        return False
    return True
