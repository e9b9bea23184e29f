"""Index an MCAP file record by record, complete or cut short, and pull message payloads in bulk.

Why not `mcap`'s readers: the indexed reader needs the summary that a killed run never wrote, and
the streaming readers decode every message into a Python object (too slow for signals). This walk
reads the top-level records in file order like `mcap.stream_reader.NonSeekingReader`, skips over
chunk bodies (they are decompressed only when asked for), and stops at the first record that is
cut short or malformed: everything before it is a complete, usable part of the log; of a chunk
cut short, the records that its compressed prefix still holds are kept. Record bodies other than
chunks and message indexes are parsed with `mcap`'s own record classes.

Decompression is bounded, so a hostile or broken file cannot take the memory or the time of the
machine: a chunk declaring more than `MAX_CHUNK_BYTES` uncompressed is skipped (with a note in
`LogIndex.skipped`), and chunks are decompressed as streams that stop one byte past their
declared size (a chunk that expands further is an error, not an allocation). A chunk's CRC, when
it has one, is checked.

The record layout is declared in `cosim.record.mcap_format` (shared with the writer).
"""

from __future__ import annotations

import io
import os
import stat
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.records import Attachment, Channel, Header, Metadata, Schema

from cosim.errors import CosimError, wrong_file_message
from cosim.record.mcap_format import (
    CHUNK_FIELDS,
    MAGIC,
    MESSAGE_FIELDS,
    MESSAGE_HEAD_SIZE,
    OP_ATTACHMENT,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_METADATA,
    OP_SCHEMA,
    RECORD_HEAD,
)

_zstd = zstandard.ZstdDecompressor()
MAX_CHUNK_BYTES = 256 * 2**20  # largest uncompressed chunk read [bytes]; navcosim writes ~0.5 MiB


@dataclass
class Block:
    """A run of messages: a chunk (compressed records) or top-level messages of an unchunked file."""

    data_offset: int  # file offset of the records
    data_size: int  # bytes in the file
    uncompressed_size: int
    compression: str  # "zstd", "lz4" or "" (stored)
    index: dict[int, np.ndarray] = field(default_factory=dict)  # channel -> (n, 2) uint64 (time, offset)
    indexed: bool = False  # True once the message indexes after the chunk were read completely
    crc: int = 0  # CRC-32 of the uncompressed records (0: none)
    record_offset: int = -1  # file offset of the Chunk record (its opcode); -1 for top-level messages
    record_length: int = 0  # bytes of the whole Chunk record
    partial: bool = False  # the file ends inside this chunk: only a prefix of its records is there
    usable_size: int = -1  # of a partial chunk: bytes of its complete records (-1: not walked yet)


@dataclass
class LogIndex:
    path: Path
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    blocks: list[Block] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    attachments: list[Attachment] = field(default_factory=list)
    complete: bool = False  # the footer was read
    problem: str | None = None  # why the walk stopped early
    skipped: list[str] = field(default_factory=list)  # chunks left out, and why


def parse_record(record_class, body: bytes):
    """A record body (bytes after opcode and length) as an `mcap.records` object."""
    return record_class.read(ReadDataStream(io.BytesIO(body)))


def read_index(path: Path) -> LogIndex:
    """Walk `path`; raises CosimError when it is not an MCAP file at all."""
    path = Path(path)
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; it is refused just below.
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as error:
        raise CosimError(f"{path}: cannot open the log ({error.strerror})") from None
    except ValueError as error:  # an embedded NUL byte
        raise CosimError(f"{path}: cannot open the log ({error})") from None
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        raise CosimError(f"{path}: not a regular file (a folder, device or FIFO), not a log")
    os.set_blocking(descriptor, True)
    handle = os.fdopen(descriptor, "rb")
    with handle:
        file_size = path.stat().st_size
        magic = handle.read(len(MAGIC))
        if file_size == 0:
            raise CosimError(f"{path}: empty file, not an MCAP log (the run wrote nothing)")
        if magic != MAGIC:
            raise CosimError(
                wrong_file_message(path, "an MCAP log") or f"{path}: not an MCAP file (bad magic bytes)"
            )
        log = LogIndex(path)
        try:
            _walk(handle, file_size, log)
        except (struct.error, ValueError, UnicodeDecodeError, EOFError) as error:
            log.problem = f"malformed record ({error})"
        if log.blocks and not log.blocks[-1].indexed:
            _reindex_last(handle, log)
    return log


def _walk(handle, file_size: int, log: LogIndex) -> None:
    position = len(MAGIC)
    raw_messages: list[tuple[int, int, int]] = []  # (channel, time, offset) of top-level messages
    raw_block: Block | None = None
    current: Block | None = None  # the chunk that the message indexes being read belong to
    while True:
        head = handle.read(RECORD_HEAD.size)
        if len(head) < RECORD_HEAD.size:
            log.problem = "the file ends without a footer"
            break
        opcode, length = RECORD_HEAD.unpack(head)
        body_start = position + RECORD_HEAD.size
        if body_start + length > file_size:
            log.problem = "the last record is cut short"
            if opcode == OP_CHUNK:
                _salvage_chunk(handle, position, body_start, file_size, log)
            break
        if opcode != OP_MESSAGE_INDEX:
            if current is not None:
                current.indexed = True
            current = None
        if opcode == OP_CHUNK:
            current = _admit(_read_chunk_head(handle, position, body_start, length), position, log)
        elif opcode == OP_MESSAGE:
            channel, _, log_time, _ = MESSAGE_FIELDS.unpack(handle.read(MESSAGE_FIELDS.size))
            if raw_block is None or raw_block.data_offset + raw_block.data_size != position:
                raw_block = _finish_raw(log, raw_block, raw_messages)
                raw_block = Block(position, 0, 0, "")
            raw_messages.append((channel, log_time, position - raw_block.data_offset))
            raw_block.data_size = body_start + length - raw_block.data_offset
            raw_block.uncompressed_size = raw_block.data_size
        elif opcode == OP_MESSAGE_INDEX:
            body = handle.read(length)
            if current is not None:
                channel, byte_length = struct.unpack_from("<HI", body)
                entries = np.frombuffer(body, dtype="<u8", count=byte_length // 8, offset=6).reshape(-1, 2)
                current.index[channel] = entries
        elif opcode == OP_FOOTER:
            log.complete = True
            log.problem = None
            break
        else:
            body = handle.read(length)
            if opcode == OP_SCHEMA:
                schema = parse_record(Schema, body)
                log.schemas[schema.id] = schema
            elif opcode == OP_CHANNEL:
                channel_record = parse_record(Channel, body)
                log.channels[channel_record.id] = channel_record
            elif opcode == OP_METADATA:
                log.metadata.append(parse_record(Metadata, body))
            elif opcode == OP_ATTACHMENT:
                log.attachments.append(parse_record(Attachment, body))
            elif opcode == OP_HEADER:
                log.header = parse_record(Header, body)
            elif opcode == OP_DATA_END and raw_block is not None:
                raw_block = _finish_raw(log, raw_block, raw_messages)
        position = body_start + length
        handle.seek(position)
    _finish_raw(log, raw_block, raw_messages)


def _admit(block: Block, position: int, log: LogIndex) -> Block | None:
    """Add a chunk to the log unless its declared size is above the limit (then None)."""
    if block.uncompressed_size > MAX_CHUNK_BYTES:
        log.skipped.append(
            f"chunk at byte {position} declares {block.uncompressed_size} bytes uncompressed, above the "
            f"limit of {MAX_CHUNK_BYTES}: skipped"
        )
        return None
    log.blocks.append(block)
    return block


def _read_chunk_head(handle, position: int, body_start: int, length: int) -> Block:
    start, end, uncompressed_size, crc, name_length = CHUNK_FIELDS.unpack(handle.read(CHUNK_FIELDS.size))
    compression = handle.read(name_length).decode()
    (records_length,) = struct.unpack("<Q", handle.read(8))
    data_offset = body_start + CHUNK_FIELDS.size + name_length + 8
    if data_offset + records_length > body_start + length:
        raise ValueError("chunk records overrun the chunk record")
    return Block(
        data_offset,
        records_length,
        uncompressed_size,
        compression,
        crc=crc,
        record_offset=position,
        record_length=RECORD_HEAD.size + length,
    )


def _salvage_chunk(handle, position: int, body_start: int, file_size: int, log: LogIndex) -> None:
    """The file ends inside a chunk: keep its available compressed prefix as a partial block,
    whose complete records `_reindex_last` indexes."""
    handle.seek(body_start)
    head = handle.read(CHUNK_FIELDS.size)
    if len(head) < CHUNK_FIELDS.size:
        return
    _, _, uncompressed_size, crc, name_length = CHUNK_FIELDS.unpack(head)
    name, size = handle.read(name_length), handle.read(8)
    if len(name) < name_length or len(size) < 8:
        return
    data_offset = body_start + CHUNK_FIELDS.size + name_length + 8
    available = min(struct.unpack("<Q", size)[0], file_size - data_offset)
    if available > 0:
        compression = name.decode(errors="replace")
        block = Block(data_offset, available, uncompressed_size, compression, crc=crc, partial=True)
        _admit(block, position, log)


def _finish_raw(log: LogIndex, block: Block | None, messages: list[tuple[int, int, int]]) -> None:
    """Close a run of top-level messages as one stored block with its own index."""
    if block is None or not messages:
        return None
    entries = np.array(messages, dtype=np.uint64)
    for channel in np.unique(entries[:, 0]):
        block.index[int(channel)] = entries[entries[:, 0] == channel][:, 1:]
    block.indexed = True
    log.blocks.append(block)
    messages.clear()
    return None


def _reindex_last(handle, log: LogIndex) -> None:
    """The last chunk of a cut file may lack (some of) its message indexes, or be cut itself:
    rebuild its index by walking its complete records; drop the chunk when it does not
    decompress or holds no complete message."""
    block = log.blocks[-1]
    try:
        records = block_bytes(handle, block)
    except (zstandard.ZstdError, RuntimeError, ValueError) as error:
        log.blocks.pop()
        log.problem = f"{log.problem or 'cut file'}; the last chunk is unreadable ({error})"
        return
    index: dict[int, list[tuple[int, int]]] = {}
    offset = 0
    while offset + RECORD_HEAD.size <= len(records):
        opcode, length = RECORD_HEAD.unpack_from(records, offset)
        body = offset + RECORD_HEAD.size
        if body + length > len(records):
            break  # a partial chunk's last record, cut short
        if opcode == OP_MESSAGE and length >= MESSAGE_FIELDS.size:
            channel, _, log_time, _ = MESSAGE_FIELDS.unpack_from(records, body)
            index.setdefault(channel, []).append((log_time, offset))
        elif opcode == OP_CHANNEL:
            channel_record = parse_record(Channel, records[body : body + length])
            log.channels.setdefault(channel_record.id, channel_record)
        elif opcode == OP_SCHEMA:
            schema = parse_record(Schema, records[body : body + length])
            log.schemas.setdefault(schema.id, schema)
        offset = body + length
    if block.partial:
        block.usable_size = offset
    block.index = {channel: np.array(entries, dtype=np.uint64) for channel, entries in index.items()}
    block.indexed = True
    if not index:
        log.blocks.pop()


def _decompress(data: bytes, compression: str, size: int, partial: bool) -> bytes:
    """The records of a chunk declaring `size` uncompressed bytes, decompressed as a stream that
    stops one byte past `size`; of a partial chunk, whatever its prefix holds."""
    if compression == "zstd":
        with _zstd.stream_reader(data, read_across_frames=True) as reader:
            records = reader.read(size + 1)
    elif compression == "lz4":
        records = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    elif compression == "":
        records = data[: size + 1]
    else:
        raise ValueError(f"unsupported chunk compression {compression!r}")
    if len(records) > size:
        raise ValueError(f"chunk expands beyond its declared {size} bytes")
    if len(records) < size and not partial:
        raise ValueError(f"chunk holds {len(records)} bytes, not its declared {size}")
    return records


def block_bytes(handle, block: Block) -> bytes:
    """The uncompressed records of a block (of a partial chunk: its complete records); raises
    ValueError for a block that is cut, corrupt or expands beyond its declared size."""
    handle.seek(block.data_offset)
    data = handle.read(block.data_size)
    if len(data) != block.data_size:
        raise ValueError("block is cut short")
    if block.record_offset < 0 and not block.partial:
        return data  # top-level messages of an unchunked file
    records = _decompress(data, block.compression, block.uncompressed_size, block.partial)
    if block.partial:
        return records[: block.usable_size] if block.usable_size >= 0 else records
    if block.crc and zlib.crc32(records) != block.crc:
        raise ValueError(f"chunk at byte {block.record_offset} fails its CRC check")
    return records


def records_of(handle, log: LogIndex, block: Block) -> bytes:
    """`block_bytes`, with a broken block as a one-line CosimError that names the file."""
    try:
        return block_bytes(handle, block)
    except (zstandard.ZstdError, RuntimeError, ValueError) as error:
        raise CosimError(f"{log.path}: unreadable chunk ({error})") from None


def discover_channels_in_blocks(handle, log: LogIndex) -> None:
    """A cut file has no summary: channels and schemas live only inside the chunks. Walk the
    records of each chunk that holds messages of a channel not seen yet."""
    for block in log.blocks:
        if all(channel in log.channels for channel in block.index):
            continue
        records = records_of(handle, log, block)
        offset = 0
        while offset + RECORD_HEAD.size <= len(records):
            opcode, length = RECORD_HEAD.unpack_from(records, offset)
            body = records[offset + RECORD_HEAD.size : offset + RECORD_HEAD.size + length]
            if opcode == OP_SCHEMA:
                schema = parse_record(Schema, body)
                log.schemas.setdefault(schema.id, schema)
            elif opcode == OP_CHANNEL:
                channel_record = parse_record(Channel, body)
                log.channels.setdefault(channel_record.id, channel_record)
            offset += RECORD_HEAD.size + length


def fixed_payloads(
    handle, log: LogIndex, layouts: dict[int, tuple[int, int]]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """For each channel in `layouts` ({channel: (skip, width)}): log times [ns] (int64, n) and
    bytes `skip:skip+width` of every payload as an (n, width) uint8 array, in time order.

    One pass over the chunks, each decompressed once. Vectorised per chunk: the message index
    gives record offsets, and a sliding-window view of the decompressed chunk turns the gather
    into one fancy-indexing copy per channel."""
    times: dict[int, list[np.ndarray]] = {channel: [] for channel in layouts}
    rows: dict[int, list[np.ndarray]] = {channel: [] for channel in layouts}
    for block in log.blocks:
        wanted = [channel for channel in layouts if len(block.index.get(channel, ()))]
        if not wanted:
            continue
        records = np.frombuffer(records_of(handle, log, block), dtype=np.uint8)
        lengths_view = np.lib.stride_tricks.sliding_window_view(records, 8)
        for channel in wanted:
            skip, width = layouts[channel]
            entries = block.index[channel]
            offsets = entries[:, 1].astype(np.int64)
            if offsets.max() + MESSAGE_HEAD_SIZE + skip + width > len(records):
                raise CosimError(f"{log.path}: message index of channel {channel} points past its chunk")
            lengths = lengths_view[offsets + 1].view("<u8")[:, 0]
            if np.any(lengths < MESSAGE_FIELDS.size + skip + width):
                raise CosimError(f"{log.path}: messages of channel {channel} are shorter than their schema")
            windows = np.lib.stride_tricks.sliding_window_view(records, width)
            rows[channel].append(windows[offsets + MESSAGE_HEAD_SIZE + skip])
            times[channel].append(entries[:, 0].astype(np.int64))
    result = {}
    for channel, (_, width) in layouts.items():
        if not rows[channel]:
            result[channel] = (np.zeros(0, dtype=np.int64), np.zeros((0, width), dtype=np.uint8))
            continue
        all_times = np.concatenate(times[channel])
        all_rows = np.concatenate(rows[channel]) if len(rows[channel]) > 1 else rows[channel][0]
        if np.any(np.diff(all_times) < 0):
            order = np.argsort(all_times, kind="stable")
            all_times, all_rows = all_times[order], all_rows[order]
        result[channel] = (all_times, all_rows)
    return result


def iter_payloads(handle, log: LogIndex, channels: set[int]):
    """(channel, log time [ns], payload bytes) of the given channels, block by block, in time
    order within each block."""
    for block in log.blocks:
        wanted = [entries for channel, entries in block.index.items() if channel in channels and len(entries)]
        if not wanted:
            continue
        records = records_of(handle, log, block)
        entries = np.concatenate(wanted)
        entries = entries[np.argsort(entries[:, 0], kind="stable")]
        for log_time, offset in entries.tolist():
            (length,) = struct.unpack_from("<Q", records, offset + 1)
            channel = struct.unpack_from("<H", records, offset + 9)[0]
            yield channel, log_time, records[offset + MESSAGE_HEAD_SIZE : offset + RECORD_HEAD.size + length]
