"""Limits on what an FMU archive may unpack to, checked before anything is extracted, and the
folders instances are unpacked into (`unpack_instance`).

An FMU is a zip archive; deflate packs a run of zeros about 1000:1, so a 2 MB file can hold a 2 GiB
entry that would fill the disk (or the memory of a tmpfs) when extracted. The archive's central
directory declares every entry's uncompressed size, and Python's `zipfile` (which fmpy's extraction
uses) never writes more than the declared size of an entry, so the sum of the declared sizes bounds
what extraction can write: checking it refuses such an archive without inflating a byte.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import threading
import zipfile
from collections.abc import Callable
from pathlib import Path

from cosim.errors import CosimError

MIB = 1 << 20
DEFAULT_MAX_UNPACKED_SIZE = 1 << 30  # [bytes] 1 GiB; scenarios raise it with [simulation] fmu_max_size
# Entries of one archive: each is a file (an inode) and a system call when extracted; an FMU or an
# SSP holds tens to hundreds, a zip of 10^6 empty entries is a few tens of MB.
MAX_ENTRIES = 10_000


def mib(size: int) -> str:
    """`size` [bytes] in MiB as a limit message says it: whole MiB from 10 MiB up, else with as many
    decimals as it takes to be non-zero (a 0.4 MiB limit is not "0 MiB"), exact bytes below 1 KiB."""
    if size < 1024:
        return f"{size} bytes"
    value = size / MIB
    if value >= 10:
        return f"{value:,.0f} MiB"
    decimals = 1
    while round(value, decimals) == 0 or (decimals < 6 and abs(round(value, decimals) - value) > value / 20):
        decimals += 1
    return f"{value:.{decimals}f} MiB"


def unpacked_size(archive: zipfile.ZipFile) -> int:
    """The total uncompressed size [bytes] the archive's entries declare."""
    return sum(info.file_size for info in archive.infolist())


def unpack_problem(archive: zipfile.ZipFile, limit: int | None = None) -> str | None:
    """Why `archive` must not be extracted (more than `MAX_ENTRIES` entries, or more than `limit`
    bytes, default `DEFAULT_MAX_UNPACKED_SIZE`, declared in all), or None."""
    limit = DEFAULT_MAX_UNPACKED_SIZE if limit is None else limit
    entries = archive.infolist()
    if len(entries) > MAX_ENTRIES:
        return f"has {len(entries):,} entries, more than the limit of {MAX_ENTRIES:,}"
    total = unpacked_size(archive)
    if total > limit:
        largest = max(entries, key=lambda info: info.file_size)
        return (
            f"would unpack to {mib(total)} ('{largest.filename[:200]}' alone "
            f"{mib(largest.file_size)}), more than the limit of {mib(limit)}"
        )
    return None


def check_unpacked_size(path: Path, archive: zipfile.ZipFile, limit: int | None = None) -> None:
    """Raise `CosimError` when `archive` (the file at `path`) has too many entries or its entries
    unpack to more than `limit` bytes (default `DEFAULT_MAX_UNPACKED_SIZE`): `unpack_problem`."""
    problem = unpack_problem(archive, limit)
    if problem is not None:
        hint = SIZE_HINT if problem.startswith("would") else "not extracted"
        raise CosimError(f"FMU '{path}' {problem}; {hint}")


SIZE_HINT = "not extracted (raise the limit with [simulation] fmu_max_size, in MiB, if you trust it)"


class _Shared:
    """One extraction of an archive, shared by the instances using it, removed with the last."""

    def __init__(self, folder: str) -> None:
        self.folder = folder
        self.users = 0


_shared: dict[tuple, _Shared] = {}
_shared_lock = threading.Lock()


def unpack_instance(
    path: Path, include: Callable[[str], bool], prefix: str, shareable: bool, kept: Path | None = None
) -> tuple[str, Callable[[], None]]:
    """A folder holding the members of the FMU at `path` that `include` accepts, for one instance,
    and the function that gives it back (call it once, when the instance is freed).

    An FMU that may be instantiated more than once per process (FMI's
    `canBeInstantiatedOnlyOncePerProcess="false"`: it keeps no state in its shared library) is
    extracted once per process and its instances share the folder (so the loader maps its library
    once): a fleet of 50 robots unzipped and deleted 200 folders, ~10 ms each on this machine's
    disk, for four FMUs. Any other FMU gets its own folder (its library loaded as a library of its
    own, so static state stays per instance). Errors of the extraction propagate (`unpack_problem`
    was checked before).

    `kept`: for a shareable FMU in a folder navcosim owns (a project FMU in its build cache), where
    its extraction stays for the next process (`cosim.fmi.description.kept_unpacked`: named by the
    file's version, so a rebuilt FMU is extracted anew): unpacking and deleting the four FMUs of a
    run cost ~6 ms of its CPU. Extracted aside and renamed into place, so a folder there is whole;
    it is never deleted (an instance of another process may be using it)."""
    import fmpy

    if shareable and kept is not None:
        if not kept.is_dir():
            folder = tempfile.mkdtemp(prefix=f"{kept.name}.", dir=kept.parent)
            try:
                fmpy.extract(str(path), unzipdir=folder, include=include)
                os.rename(folder, kept)
            except OSError:
                shutil.rmtree(folder, ignore_errors=True)
                if not kept.is_dir():  # (else another process renamed its copy first)
                    raise
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)
                raise
        return str(kept), _keep_folder
    if not shareable:
        folder = tempfile.mkdtemp(prefix=prefix)
        try:
            fmpy.extract(str(path), unzipdir=folder, include=include)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        return folder, lambda: shutil.rmtree(folder, ignore_errors=True)
    stat = os.stat(path)
    key = (os.path.realpath(path), stat.st_size, stat.st_mtime_ns, include)
    with _shared_lock:
        entry = _shared.get(key)
        if entry is None:
            folder = tempfile.mkdtemp(prefix=f"navcosim-shared-{Path(path).stem[:40]}-")
            try:
                fmpy.extract(str(path), unzipdir=folder, include=include)
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)
                raise
            entry = _shared[key] = _Shared(folder)
        entry.users += 1
    released = False

    def release() -> None:
        nonlocal released
        with _shared_lock:
            if released:
                return
            released = True
            entry.users -= 1
            if entry.users == 0:
                _shared.pop(key, None)
                shutil.rmtree(entry.folder, ignore_errors=True)

    return entry.folder, release


def _keep_folder() -> None:
    """The release of a kept extraction (`unpack_instance`): it stays."""


@atexit.register
def _remove_shared() -> None:
    """Folders of instances never freed (a run that raised before `free`)."""
    for entry in list(_shared.values()):
        shutil.rmtree(entry.folder, ignore_errors=True)
    _shared.clear()
