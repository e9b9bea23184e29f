"""A zip bomb for the tests of archive limits (FMUs and SSPs): written, not compressed."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

from cosim.fmi.archive import MIB


def write_zip_bomb(path: Path, entry_size: int) -> None:
    """A zip holding one deflated entry of `entry_size` zero bytes, written without compressing
    them: deflate after a full flush codes each MiB of zeros identically, so one coded MiB is
    repeated. The CRC is computed honestly, so the archive is valid: it WOULD unpack."""
    compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = compressor.compress(bytes(MIB)) + compressor.flush(zlib.Z_FULL_FLUSH)
    assert block == compressor.compress(bytes(MIB)) + compressor.flush(zlib.Z_FULL_FLUSH)
    tail = compressor.flush(zlib.Z_FINISH)
    blocks = entry_size // MIB
    crc = 0
    for _ in range(blocks):
        crc = zlib.crc32(bytes(MIB), crc)
    compressed = len(block) * blocks + len(tail)
    name = b"resources/padding.bin"
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0, crc, compressed, entry_size, len(name), 0)
    with path.open("wb") as out:
        out.write(local + name)
        for _ in range(blocks):
            out.write(block)
        out.write(tail)
        directory_at = out.tell()
        central = struct.pack(
            "<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 0, crc, compressed, entry_size,
            len(name), 0, 0, 0, 0, 0, 0,
        )  # fmt: skip
        out.write(central + name)
        size = out.tell() - directory_at
        out.write(struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, size, directory_at, 0))
