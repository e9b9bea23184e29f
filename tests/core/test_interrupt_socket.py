"""`cosim.core.interrupt.signal_socket`: inside `catching_signals()` a socket that holds a byte from
the moment SIGINT/SIGTERM comes (the interpreter's wakeup fd, written before any Python handler
runs; the compiled kernel looks at it) until `take()` takes the signal; none when a wakeup fd was
set already (an event loop's), which is kept and put back."""

from __future__ import annotations

import os
import select
import signal
import socket

from cosim.core import interrupt


def _readable(fd: int) -> bool:
    return bool(select.select([fd], [], [], 0.0)[0])


def test_a_signal_leaves_a_byte_until_it_is_taken():
    with interrupt.catching_signals(), interrupt.deferred():
        fd = interrupt.signal_socket()
        assert fd >= 0 and not _readable(fd)
        os.kill(os.getpid(), signal.SIGINT)
        assert _readable(fd)  # (the handler has run too: the signal is pending)
        assert interrupt.pending()
        assert interrupt.take() == "SIGINT"
        assert not _readable(fd)
        assert interrupt.take() is None
    assert interrupt.signal_socket() == -1
    assert signal.set_wakeup_fd(-1) == -1  # put back as it was: none


def test_a_wakeup_fd_set_before_is_kept():
    reader, writer = socket.socketpair()
    writer.setblocking(False)
    with reader, writer:
        previous = signal.set_wakeup_fd(writer.fileno())
        try:
            with interrupt.catching_signals():
                assert interrupt.signal_socket() == -1
                assert signal.set_wakeup_fd(writer.fileno()) == writer.fileno()
        finally:
            assert signal.set_wakeup_fd(previous) == writer.fileno()
