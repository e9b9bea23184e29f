"""A Ctrl-C is never lost: `cosim.core.interrupt.sigint_blocked` (a process started that a Ctrl-C
must not end) leaves one that comes meanwhile to this process, and `raise_swallowed` raises again
one whose `Interrupted` Python dropped (raised in a weakref callback, which prints "Exception
ignored in ..." and goes on)."""

from __future__ import annotations

import gc
import os
import signal
import subprocess
import sys
import weakref

import pytest

from cosim.core import interrupt

CHILD = (
    "import signal, sys; sys.stdout.write(str(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])))"
)


def test_a_process_started_with_sigint_blocked_is_deaf_to_it_and_a_ctrl_c_here_is_kept():
    """Inside `sigint_blocked` this process's handler stays; a process started there begins with
    SIGINT blocked; a SIGINT that comes meanwhile reaches the handler (at once through another
    thread of this process, or when the block ends), however many threads the process has."""
    with interrupt.catching_signals():
        with pytest.raises(interrupt.Interrupted) as raised:
            with interrupt.sigint_blocked():
                assert signal.getsignal(signal.SIGINT) is interrupt._handle
                started = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True)
                os.kill(os.getpid(), signal.SIGINT)
                gc.collect()  # (bytecodes go by)
        assert raised.value.signal_name == "SIGINT"
    assert started.stdout == "True"


def test_the_block_puts_the_mask_back():
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with interrupt.sigint_blocked():
        assert signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == before


def _interrupt_in_a_weakref_callback() -> None:
    """SIGINT handled while Python runs a weakref callback: the `Interrupted` raised there is printed
    and dropped, and the caller goes on."""

    class Thing:
        pass

    thing = Thing()
    reference = weakref.ref(thing, lambda _: signal.raise_signal(signal.SIGINT))
    del thing  # (the callback runs here)
    assert reference() is None


def test_an_interrupt_dropped_in_a_callback_is_raised_again(monkeypatch):
    dropped = []  # what Python hands its hook for exceptions it cannot raise (it prints them)
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: dropped.append(unraisable.exc_value))
    with interrupt.catching_signals():
        interrupt.raise_swallowed()  # nothing raised yet: nothing to do
        _interrupt_in_a_weakref_callback()
        assert [type(error) for error in dropped] == [interrupt.Interrupted]
        with pytest.raises(interrupt.Interrupted):
            interrupt.raise_swallowed()
        with pytest.raises(interrupt.Interrupted):
            with interrupt.deferred():  # a run about to create its log stops there
                pytest.fail("the deferred block was entered")
    with interrupt.catching_signals():  # entered afresh: that interrupt is not raised again
        interrupt.raise_swallowed()


def test_outside_catching_signals_nothing_is_raised_again():
    interrupt.raise_swallowed()
