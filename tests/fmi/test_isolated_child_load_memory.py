"""An isolated FMU's child whose loading fails with ENOMEM from a system call (under its memory limit,
an import that lists a folder can fail so instead of raising MemoryError) replies "out of memory",
which the host words as the fmu_max_memory limit, instead of dying with a traceback."""

from __future__ import annotations

import errno
import io
import socket
from types import SimpleNamespace

import pytest

import cosim.fmi.isolated_child as child
from cosim.fmi import isolated as protocol


def _serve_failing_load(monkeypatch, error: Exception, limited: bool) -> bytes:
    def failing_load(**_):
        raise error

    monkeypatch.setattr(child, "fmu_component", failing_load)
    monkeypatch.setattr(child.sys, "stdin", SimpleNamespace(buffer=io.BytesIO(b"{}")))
    monkeypatch.setattr(child, "_limited", [[0] * 64 if limited else None])
    host, ours = socket.socketpair()
    with host, ours:
        assert child.serve(ours.fileno(), None) == 0
        return host.recv(4096)


def test_enomem_while_loading_under_a_limit_is_out_of_memory(monkeypatch):
    monkeypatch.setattr(child, "_status", lambda *keys: {"VmHWM": 1234})
    reply = _serve_failing_load(monkeypatch, OSError(errno.ENOMEM, "Cannot allocate memory"), limited=True)
    assert reply.startswith(protocol.OUT_OF_MEMORY)
    assert reply[2] == protocol.CALL_LOAD


def test_enomem_without_a_limit_and_other_errors_are_not_hidden(monkeypatch):
    with pytest.raises(OSError):
        _serve_failing_load(monkeypatch, OSError(errno.ENOMEM, "Cannot allocate memory"), limited=False)
    with pytest.raises(OSError):
        _serve_failing_load(monkeypatch, OSError(errno.EACCES, "Permission denied"), limited=True)
