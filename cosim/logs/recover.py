"""`cosim log recover`: rewrite a cut log as a complete, indexed MCAP of everything readable in it.

A run killed by SIGKILL (or a file cut at any byte) has no summary and no footer, and readers that
need them (rosbags, `mcap`'s indexed reader, `ros2 bag`) refuse it. `recover_log` walks the file
with `cosim.logs.index` (bounded decompression, the prefix of a chunk cut short) and writes:

- the header of the source (its profile and library);
- every schema and channel record that survived, as top-level records before the first chunk
  that needs them;
- each complete chunk that decompresses to its declared size and passes its CRC, byte for byte,
  with message indexes rebuilt from its records; the complete records of a chunk cut short (and
  top-level messages of an unchunked file) as a new zstd chunk;
- every metadata and attachment record that survived;
- then DataEnd, the summary (schemas, channels, statistics, chunk/attachment/metadata indexes),
  its offsets and the footer (`cosim.record.writer.ChunkWriter`).

Messages of a channel whose channel record was lost cannot be decoded by any reader and are left
out; so are chunks that do not decompress (each is named in `Recovery.dropped`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard

from cosim.errors import CosimError
from cosim.logs import index as log_index
from cosim.logs.index import LogIndex
from cosim.record.mcap_format import MESSAGE_FIELDS, OP_CHANNEL, OP_MESSAGE, OP_SCHEMA, RECORD_HEAD
from cosim.record.output import atomic_output
from cosim.record.writer import ChunkWriter


@dataclass
class Recovery:
    """What `recover_log` wrote."""

    source: Path
    target: Path
    was_complete: bool  # the source had its footer already
    problem: str | None  # why the source's walk stopped early (None: it did not)
    messages: int = 0
    channels: int = 0
    start_time: float = 0.0  # [s] log time of the first message written
    end_time: float = 0.0  # [s] of the last
    chunks_copied: int = 0  # complete chunks written byte for byte
    chunks_rebuilt: int = 0  # chunks written anew from complete records (a cut chunk's prefix)
    metadata: int = 0
    attachments: int = 0
    dropped: list[str] = field(default_factory=list)  # what could not be kept, and why


def default_target(source: Path) -> Path:
    """`run.mcap` -> `run.recovered.mcap` beside it."""
    return source.with_suffix(".recovered.mcap")


def recover_log(source: str | Path, target: str | Path | None = None, force: bool = False) -> Recovery:
    """Write everything readable in `source` to `target` (default `default_target`) as a complete,
    indexed MCAP (an existing `target` only with `force`; see cosim.record.output). Raises
    CosimError (one line) for a file that is not MCAP at all."""
    source = Path(source)
    target = Path(target) if target is not None else default_target(source)
    if not source.is_file():
        raise CosimError(f"{source}: no such log file")
    if target.exists() and target.resolve() == source.resolve():
        raise CosimError(f"{source}: the recovered log must not overwrite its source (give --out)")
    log = log_index.read_index(source)
    recovery = Recovery(source, target, log.complete, log.problem, dropped=list(log.skipped))
    with atomic_output(target, force) as temporary:
        with open(source, "rb") as handle, open(temporary, "wb") as out:
            _write(handle, log, ChunkWriter(out), recovery)
    return recovery


def _write(handle, log: LogIndex, writer: ChunkWriter, recovery: Recovery) -> None:
    header = log.header
    profile = header.profile if header is not None else _guess_profile(log)
    writer.start(profile=profile, library=header.library if header is not None else "navcosim log recover")
    known_schemas: set[int] = set()
    known_channels: set[int] = set()
    _register(writer, log, log.schemas.values(), log.channels.values(), known_schemas, known_channels)
    writer.write_definitions()
    first, last, used = None, None, set()
    for block in log.blocks:
        where = f"chunk at byte {block.record_offset}" if block.record_offset >= 0 else "top-level messages"
        try:
            records = log_index.block_bytes(handle, block)
        except (zstandard.ZstdError, RuntimeError, ValueError) as error:
            recovery.dropped.append(f"{where}: unreadable ({error})")
            continue
        schemas, channels, messages = _walk_records(records)
        _register(writer, log, schemas, channels, known_schemas, known_channels)
        kept = [message for message in messages if message[0] in known_channels]
        if len(kept) < len(messages):
            lost = sorted({message[0] for message in messages} - known_channels)
            recovery.dropped.append(
                f"{where}: {len(messages) - len(kept)} messages of channels {lost} without a channel record"
            )
        if not kept:
            continue
        entries = np.array(kept, dtype=np.uint64)  # channel, log time, offset, size
        if block.record_offset >= 0 and not block.partial and len(kept) == len(messages):
            handle.seek(block.record_offset)
            index = {
                int(channel): entries[entries[:, 0] == channel][:, 1:3]
                for channel in np.unique(entries[:, 0])
            }
            writer.copy_chunk(
                handle.read(block.record_length), index, block.compression, block.data_size, len(records)
            )
            recovery.chunks_copied += 1
        else:
            _rebuild(writer, records, entries)
            recovery.chunks_rebuilt += 1
        recovery.messages += len(kept)
        used.update(int(channel) for channel in np.unique(entries[:, 0]))
        low, high = int(entries[:, 1].min()), int(entries[:, 1].max())
        first = low if first is None else min(first, low)
        last = high if last is None else max(last, high)
    writer.flush()
    for record in log.metadata:
        writer.add_metadata(record.name, dict(record.metadata))
    for record in log.attachments:
        writer.add_attachment(
            record.create_time, record.log_time, record.name, record.media_type, bytes(record.data)
        )
    writer.finish()
    recovery.channels = len(used)
    recovery.metadata, recovery.attachments = len(log.metadata), len(log.attachments)
    recovery.start_time = (first or 0) / 1e9
    recovery.end_time = (last or 0) / 1e9


def _guess_profile(log: LogIndex) -> str:
    """A file cut before its header was complete: "ros2" when every channel is ROS 2 CDR."""
    channels = list(log.channels.values())
    return "ros2" if channels and all(channel.message_encoding == "cdr" for channel in channels) else ""


def _register(writer: ChunkWriter, log: LogIndex, schemas, channels, known_schemas, known_channels) -> None:
    """Register schemas and channels not registered yet, keeping their ids (the messages refer to
    them); a channel whose schema was lost is left out (schema 0, "no schema", is kept)."""
    for schema in schemas:
        if schema.id not in known_schemas:
            writer.register_schema(schema.name, schema.encoding, bytes(schema.data), schema_id=schema.id)
            known_schemas.add(schema.id)
            log.schemas.setdefault(schema.id, schema)
    for channel in channels:
        if channel.id in known_channels or (channel.schema_id and channel.schema_id not in known_schemas):
            continue
        writer.register_channel(
            channel.topic,
            channel.message_encoding,
            channel.schema_id,
            dict(channel.metadata),
            channel_id=channel.id,
        )
        known_channels.add(channel.id)
        log.channels.setdefault(channel.id, channel)


def _walk_records(records: bytes) -> tuple[list, list, list[tuple[int, int, int, int]]]:
    """Schemas, channels and (channel, log time, offset, record size) of each message, of the
    complete records in `records`."""
    from mcap.records import Channel, Schema

    schemas, channels, messages = [], [], []
    offset, size = 0, len(records)
    while offset + RECORD_HEAD.size <= size:
        opcode, length = RECORD_HEAD.unpack_from(records, offset)
        body = offset + RECORD_HEAD.size
        if body + length > size:
            break
        if opcode == OP_MESSAGE and length >= MESSAGE_FIELDS.size:
            channel, _, log_time, _ = MESSAGE_FIELDS.unpack_from(records, body)
            messages.append((channel, log_time, offset, RECORD_HEAD.size + length))
        elif opcode == OP_SCHEMA:
            schemas.append(log_index.parse_record(Schema, records[body : body + length]))
        elif opcode == OP_CHANNEL:
            channels.append(log_index.parse_record(Channel, records[body : body + length]))
        offset = body + length
    return schemas, channels, messages


def _rebuild(writer: ChunkWriter, records: bytes, entries: np.ndarray) -> None:
    """Write the message records listed in `entries` (channel, time, offset, size) as a new chunk."""
    order = np.argsort(entries[:, 2], kind="stable")
    entries = entries[order]
    view = memoryview(records)
    packed = b"".join(view[int(offset) : int(offset + size)] for offset, size in entries[:, 2:4].tolist())
    offsets = np.zeros(len(entries), dtype=np.int64)
    np.cumsum(entries[:-1, 3].astype(np.int64), out=offsets[1:])
    writer.add_records(packed, entries[:, 0].astype(np.int64), entries[:, 1], offsets)
    writer.flush()
