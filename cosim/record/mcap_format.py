"""The MCAP record layout, declared once for navcosim's writer and its reader of whole or cut logs.

MCAP (https://mcap.dev/spec, little-endian) is the 8-byte magic, then records `opcode u8 | length
u64 | body`. A Message body is `channel u16 | sequence u32 | log_time u64 | publish_time u64 |
data`; a Chunk body is `start u64 | end u64 | uncompressed_size u64 | crc u32 | compression str
(u32 length + bytes) | records_length u64 | records`; a MessageIndex body is `channel u16 |
byte_length u32 | (log_time u64, offset u64)*`. Everything else is read and written with `mcap`'s
own record classes; these are the heads that the fast paths pack and unpack themselves
(cosim.record.writer, .batch and .live write them, cosim.logs.index and .recover read them).
"""

from __future__ import annotations

import struct

from mcap.opcode import Opcode

MAGIC = b"\x89MCAP0\r\n"

# Plain ints: the readers compare them once per record in their inner loops.
OP_HEADER = int(Opcode.HEADER)
OP_FOOTER = int(Opcode.FOOTER)
OP_SCHEMA = int(Opcode.SCHEMA)
OP_CHANNEL = int(Opcode.CHANNEL)
OP_MESSAGE = int(Opcode.MESSAGE)
OP_CHUNK = int(Opcode.CHUNK)
OP_MESSAGE_INDEX = int(Opcode.MESSAGE_INDEX)
OP_ATTACHMENT = int(Opcode.ATTACHMENT)
OP_METADATA = int(Opcode.METADATA)
OP_DATA_END = int(Opcode.DATA_END)

# opcode, body length
RECORD_HEAD = struct.Struct("<BQ")
# A Message body before its data: channel, sequence, log time, publish time.
MESSAGE_FIELDS = struct.Struct("<HIQQ")
# A whole Message record before its data (RECORD_HEAD, then MESSAGE_FIELDS): 31 bytes.
MESSAGE_HEAD = struct.Struct("<BQHIQQ")
MESSAGE_HEAD_SIZE = MESSAGE_HEAD.size
# A Chunk record up to its compression name: opcode, length, start, end, uncompressed size, crc.
CHUNK_HEAD = struct.Struct("<BQQQQI")
# A Chunk body up to its compression name: start, end, uncompressed size, crc, the name's length.
CHUNK_FIELDS = struct.Struct("<QQQII")
# A MessageIndex record before its pairs: opcode, length, channel, byte length of the (time, offset) pairs.
MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")
