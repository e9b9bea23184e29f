"""Limits on what an FMU archive may unpack to, checked before anything is extracted.

An FMU is a zip archive; deflate packs a run of zeros about 1000:1, so a 2 MB file can hold a 2 GiB
entry that would fill the disk (or the memory of a tmpfs) when extracted. The archive's central
directory declares every entry's uncompressed size, and Python's `zipfile` (which fmpy's extraction
uses) never writes more than the declared size of an entry, so the sum of the declared sizes bounds
what extraction can write: checking it refuses such an archive without inflating a byte.
"""

from __future__ import annotations

import zipfile
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
