"""Bounded decompression: a cut log whose last chunk is a zstd frame of zeros expanding to 1 GiB.

Two bombs after the readable part of a killed run's log (the log without its summary): a chunk
that declares the gigabyte (above the reader's limit: skipped unread) and one that declares 1 MiB
but expands to the gigabyte (the stream stops one byte past 1 MiB). `cosim log info` must print
the readable part with a one-line warning, in a child process whose peak memory stays far below
the gigabyte (measured by the kernel: `os.wait4`).
"""

from __future__ import annotations

import struct
import subprocess
import sys

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader

from cosim.logs import open_log
from cosim.logs.index import MAX_CHUNK_BYTES
from cosim.logs.recover import recover_log
from cosim.record.recorder import Recorder

EXPANDED = 2**30  # bytes of zeros in the bomb frame
STEPS = 300


@pytest.fixture(scope="module")
def zeros_frame() -> bytes:
    """A zstd frame of EXPANDED zero bytes, from a streaming compressor (never held expanded)."""
    compressor = zstandard.ZstdCompressor(level=1).compressobj(size=EXPANDED)
    block = bytes(2**20)
    frame = b"".join(
        [compressor.compress(block) for _ in range(EXPANDED // len(block))] + [compressor.flush()]
    )
    assert zstandard.frame_content_size(frame) == EXPANDED and len(frame) < 2**20
    return frame


def _chunk(frame: bytes, declared: int, t_ns: int) -> bytes:
    body = struct.pack("<QQQI", t_ns, t_ns, declared, 0) + struct.pack("<I", 4) + b"zstd"
    body += struct.pack("<Q", len(frame)) + frame
    return struct.pack("<BQ", 6, len(body)) + body


@pytest.fixture(scope="module")
def readable(tmp_path_factory):
    """A short log cut where a killed run's file ends: after its last chunk, before the summary."""
    path = tmp_path_factory.mktemp("bomb") / "base.mcap"
    with Recorder(path) as recorder:
        channel = recorder.signal_channel("vehicle", ["x", "y"])
        for k in range(STEPS):
            recorder.write_signals(channel, k * 10_000_000, np.array([k * 0.01, 1.0]))
    data = path.read_bytes()
    footer = len(data) - 8 - (1 + 8 + 20)  # the footer record, then the magic
    summary_start = struct.unpack_from("<Q", data, footer + 9)[0]
    return data[: summary_start - 13]  # without DataEnd (13 bytes), summary and footer


# Started from a fresh, small interpreter: a child forked from this (large) test process would
# count this process's resident pages in its own peak.
_MEASURE = """
import os, sys
pid = os.fork()
if pid == 0:
    os.execv(sys.executable, [sys.executable, "-m", "cosim", "log", "info", sys.argv[1]])
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[2], "w") as report:
    report.write(f"{os.waitstatus_to_exitcode(status)} {usage.ru_maxrss}")
"""


def _info_measured(path) -> tuple[int, str, str, int]:
    """`cosim log info` in a child: (exit code, stdout, stderr, peak resident memory [bytes])."""
    report = path.with_suffix(".rusage")
    completed = subprocess.run(
        [sys.executable, "-c", _MEASURE, str(path), str(report)], capture_output=True, text=True, check=True
    )
    code, peak_kib = (int(part) for part in report.read_text().split())
    return code, completed.stdout, completed.stderr, peak_kib * 1024


@pytest.mark.slow
@pytest.mark.parametrize("declared", [EXPANDED, 2**20], ids=["declares_1GiB", "declares_1MiB"])
def test_info_on_a_decompression_bomb_warns_and_shows_the_readable_part(
    readable, zeros_frame, tmp_path, declared
):
    bomb = tmp_path / "bomb.mcap"
    bomb.write_bytes(readable + _chunk(zeros_frame, declared, STEPS * 10_000_000))
    code, out, err, peak = _info_measured(bomb)
    assert code == 0, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert all(line.startswith(f"cosim: warning: {bomb}: ") for line in lines), err
    if declared > MAX_CHUNK_BYTES:
        expected = f"declares {EXPANDED} bytes uncompressed, above the limit of {MAX_CHUNK_BYTES}: skipped"
    else:
        expected = "the last chunk is unreadable (chunk expands beyond its declared 1048576 bytes)"
    assert sum(expected in line for line in lines) == 1, err
    assert "/signals/vehicle" in out and f"{STEPS} msgs" in out
    assert peak < EXPANDED // 4, f"peak memory {peak / 2**20:.0f} MiB"
    log = open_log(bomb)
    assert len(log.signals("vehicle").t) == STEPS
    recovery = recover_log(bomb)
    assert recovery.messages == STEPS
    with open(recovery.target, "rb") as stream:
        assert make_reader(stream).get_summary().statistics.message_count == STEPS
