"""A Ctrl-C is never lost: `cosim.core.interrupt.interrupts_blocked` (a process started that a
Ctrl-C or SIGTERM must not end) leaves one that comes meanwhile to this process, and
`raise_swallowed` raises again one whose `Interrupted` Python dropped (raised in a weakref
callback, which prints "Exception ignored in ..." and goes on)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import weakref

import pytest

from cosim.core import interrupt

CHILD = (
    "import signal, sys; blocked = signal.pthread_sigmask(signal.SIG_BLOCK, []); "
    "sys.stdout.write(str({signal.SIGINT, signal.SIGTERM} <= blocked))"
)


def test_a_process_started_with_interrupts_blocked_is_deaf_to_them_and_one_here_is_kept():
    """Inside `interrupts_blocked` this process's handlers stay; a process started there begins
    with SIGINT and SIGTERM blocked; a SIGINT that comes meanwhile reaches the handler (at once
    through another thread of this process, or when the block ends), however many threads the
    process has."""
    with interrupt.catching_signals():
        with pytest.raises(interrupt.Interrupted) as raised:
            with interrupt.interrupts_blocked():
                assert signal.getsignal(signal.SIGINT) is interrupt._handle
                started = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True)
                os.kill(os.getpid(), signal.SIGINT)
            # The kernel gives the signal to a thread that does not block it: another one of this
            # process at once, whose handler may run later (it waits for a core), or this one now.
            # Python runs the handler in this thread; it is waited for here, not lost.
            waited = time.monotonic() + 30.0
            while time.monotonic() < waited:
                time.sleep(0.001)
                interrupt.raise_swallowed()  # (raised where Python dropped it: a finalizer, a callback)
        assert raised.value.signal_name == "SIGINT"
    assert started.stdout == "True"


def test_the_block_puts_the_mask_back():
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with interrupt.interrupts_blocked():
        assert {signal.SIGINT, signal.SIGTERM} <= signal.pthread_sigmask(signal.SIG_BLOCK, [])
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


def test_an_interrupt_dropped_in_a_callback_is_raised_again_and_not_printed(monkeypatch):
    handed = []  # what Python hands its hook for exceptions it cannot raise (the hook prints them)
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: handed.append(unraisable.exc_value))
    with interrupt.catching_signals():
        interrupt.raise_swallowed()  # nothing raised yet: nothing to do
        _interrupt_in_a_weakref_callback()  # (it went on: the Interrupted was dropped there)
        assert handed == []  # not printed: it is raised again, or reported as the interrupt
        assert interrupt.raised() == "SIGINT"
        with pytest.raises(interrupt.Interrupted):
            interrupt.raise_swallowed()
        with pytest.raises(interrupt.Interrupted):
            with interrupt.deferred():  # a run about to create its log stops there
                pytest.fail("the deferred block was entered")
        _error_in_a_weakref_callback()
        assert [type(error) for error in handed] == [ValueError]  # any other goes to the hook
    with interrupt.catching_signals():  # entered afresh: that interrupt is not raised again
        interrupt.raise_swallowed()
    assert sys.unraisablehook is not None and _error_in_a_weakref_callback() is None
    assert [type(error) for error in handed] == [ValueError, ValueError]  # the hook put back


def _error_in_a_weakref_callback() -> None:
    class Thing:
        pass

    def fail(_):
        raise ValueError("a callback's own error")

    thing = Thing()
    reference = weakref.ref(thing, fail)
    del thing
    assert reference() is None


def test_outside_catching_signals_nothing_is_raised_again():
    interrupt.raise_swallowed()
