"""SIGINT and SIGTERM, at any moment of a run: an exception before a log exists, a flag after.

`catching_signals()` routes both signals to one handler for as long as it is entered (the CLI
enters it first thing; `run_scenario` enters it too, so library callers get the same behaviour).
Outside `deferred()` a signal raises `Interrupted` wherever the main thread is: nothing has been
written yet, so unwinding is the whole clean-up. Inside `deferred()` (from just before the log
is created until it is closed) a signal only records its name; the run loop polls `take()` and
stops at the next step with outcome "interrupted", so the log is finalised, never cut. A signal
that arrives inside `deferred()` after the loop stopped polling is raised when the block ends.
For the `cosim` command the handlers stay in place until the process exits (`until_exit`).

`Interrupted` derives from `KeyboardInterrupt`, so `except Exception` in any library on the way
up does not swallow it; the CLI turns it into one line on stderr and exit code 1. Where it is
swallowed nonetheless (raised in a weakref callback or a finalizer, which Python drops) it is
raised again at the next point that asks (`raise_swallowed`), and an error that follows it (C code
that turned it into its own) is reported as the interrupt (`raised`). A process started that
neither signal may end (the sweep's fork server) starts with both blocked (`interrupts_blocked`).
"""

from __future__ import annotations

import os
import signal
import socket
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A run stopped by SIGINT or SIGTERM; `signal_name` is "SIGINT" or "SIGTERM"."""

    def __init__(self, signal_name: str) -> None:
        super().__init__(signal_name)
        self.signal_name = signal_name


class _State:
    installed = False  # inside catching_signals() on the main thread
    deferring = 0  # nesting of deferred()
    waiting = False  # in a wait that may be abandoned (for a child process's FMU call): raise there too
    pending: str | None = None  # a signal received while deferring, not yet taken
    raised: str | None = None  # the signal whose `Interrupted` `_handle` raised last (`raise_swallowed`)
    # Python's signal wakeup socket while inside catching_signals(): the interpreter writes a byte
    # to `wakeup` the moment a signal comes (before any Python handler runs), so C code can see
    # that one came (`signal_socket`); None when another wakeup fd was set (kept) or off the main thread.
    wakeup: tuple[socket.socket, socket.socket] | None = None


_state = _State()


def _handle(number: int, frame) -> None:
    name = signal.Signals(number).name
    if _state.deferring:
        _state.pending = _state.pending or name
        if not _state.waiting:
            return
    _state.raised = name
    raise Interrupted(name)


def _unraisable(hook):
    """Python's hook for an exception it cannot raise (in a weakref callback, a finalizer), which
    prints it: `hook`, but for an `Interrupted` (`_handle` raised it there), which is raised again
    where the program goes on (`raise_swallowed`) or reported by the `cosim` command (`raised`):
    no "Exception ignored in ..." traceback before the one line that says so."""

    def unraisable(information) -> None:
        if not isinstance(information.exc_value, Interrupted):
            hook(information)

    return unraisable


def raise_swallowed() -> None:
    """Raise `Interrupted` again for a signal whose `Interrupted` was raised where nothing passes an
    exception on, so that the program went on as if no key had been pressed: Python prints and
    drops an exception raised in a weakref callback, a finalizer or a garbage collection callback
    ("Exception ignored in ..."), which the main thread runs between any two of its steps (the
    import machinery's module locks have such a callback: a Ctrl-C while Dask was imported was lost
    so). Called at points the program reaches only if every `Interrupted` raised so far was
    swallowed (the `cosim` command ends on one that reaches it): `deferred` on entry, a sweep as it
    starts and between its results. Nothing to do outside `catching_signals`, or when none was
    raised since it was entered."""
    if _state.installed and _state.raised is not None:
        raise Interrupted(_state.raised)


def raised() -> str | None:
    """The signal whose `Interrupted` `_handle` raised last since `catching_signals` was last entered
    ("SIGINT"/"SIGTERM"), whatever became of it; None if none was."""
    return _state.raised


@contextmanager
def interrupts_blocked() -> Iterator[None]:
    """SIGINT and SIGTERM blocked in this thread while a process is started that they must not end
    (the local cluster's fork server, whose workers the sweep ends itself: a Ctrl-C in a terminal,
    or a SIGTERM to the process group, reaches them too): a process inherits the blocked signals
    across fork and exec, and is deaf to them until it sets its own dispositions (the fork server
    ignores them, as its workers then do). This process's handlers stay as they are: a signal
    meanwhile reaches them through another thread at once, or through this one when the block
    ends. (Ignoring SIGINT here instead, the disposition being the whole process's, dropped a
    Ctrl-C that came during a start.) Inside, nothing may unblock them: multiprocessing's resource
    tracker, which blocks and then unblocks them around its own start, is started before
    (`multiprocessing.resource_tracker.ensure_running`). Where signals cannot be blocked (not
    POSIX), nothing is done."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    held = set(SIGNALS)
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, held - set(blocked))  # (blocked already: left so)


class _Abandonable:
    """`with abandonable:` a wait inside `deferred()` that a signal ends at once (`Interrupted`; the
    signal stays pending for `take`): an FMU hung in a child process keeps the run from reaching its
    next step. A class, not a generator: it wraps every isolated FMU step (0.5 us against 3 us)."""

    __slots__ = ()

    def __enter__(self) -> None:
        _state.waiting = True

    def __exit__(self, *exc_info) -> None:
        _state.waiting = False


abandonable = _Abandonable()


@contextmanager
def catching_signals(until_exit: bool = False) -> Iterator[None]:
    """Route SIGINT/SIGTERM to this module while inside; the previous handlers come back after.

    `until_exit`: the block is the whole program (the `cosim` command). After it, a signal exits
    at once with status 1 (standard streams flushed first), so one that arrives while the
    interpreter shuts down neither prints a traceback nor ends the process as killed (-15).
    Off the main thread (where Python cannot set handlers) this does nothing.
    """
    if _state.installed or threading.current_thread() is not threading.main_thread():
        yield  # already routed by an outer block, or not ours to route
        return
    previous = {number: signal.signal(number, _handle) for number in SIGNALS}
    _state.installed, _state.pending, _state.raised = True, None, None
    _open_wakeup()
    unraisable = sys.unraisablehook
    sys.unraisablehook = _unraisable(unraisable)
    try:
        yield
    finally:
        _state.installed = False
        sys.unraisablehook = unraisable
        _close_wakeup()
        for number, handler in previous.items():
            signal.signal(number, _exit_now if until_exit else handler)


def _open_wakeup() -> None:
    """Python's signal wakeup fd to a socket of ours, unless one is set already (an event loop's)."""
    try:
        pair = socket.socketpair()
    except OSError:
        return
    for end in pair:
        end.setblocking(False)
    try:
        old = signal.set_wakeup_fd(pair[1].fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):
        old = None
    if old != -1:  # someone else's (put it back), or none could be set
        if old is not None:
            signal.set_wakeup_fd(old)
        for end in pair:
            end.close()
        return
    _state.wakeup = pair


def _close_wakeup() -> None:
    if _state.wakeup is None:
        return
    signal.set_wakeup_fd(-1)
    for end in _state.wakeup:
        end.close()
    _state.wakeup = None


def signal_socket() -> int:
    """The file descriptor of a socket that holds a byte from the moment a signal comes until
    `take()` (C code can look without the interpreter: the compiled kernel's polled sweeps), or -1
    when there is none (then nobody can tell without asking `pending`)."""
    return -1 if _state.wakeup is None else _state.wakeup[0].fileno()


def _drain() -> None:
    """Empty the wakeup socket (its bytes are the signals `take` takes)."""
    if _state.wakeup is None:
        return
    try:
        while _state.wakeup[0].recv(64):
            pass
    except (BlockingIOError, InterruptedError):
        pass
    except OSError:
        pass


def _exit_now(number: int, frame) -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # closed, broken pipe, or interrupted mid-write: exit regardless
            pass
    os._exit(1)


@contextmanager
def deferred() -> Iterator[None]:
    """Inside, a signal is only recorded (see `take`); a signal nobody took is raised at the end.
    One whose `Interrupted` was swallowed before is raised again on entry (`raise_swallowed`)."""
    if not _state.deferring:
        raise_swallowed()
    _state.deferring += 1
    try:
        yield
    finally:
        _state.deferring -= 1
    if not _state.deferring and _state.pending is not None:
        raise Interrupted(take())


def take() -> str | None:
    """The name of a signal received while deferring ("SIGINT"/"SIGTERM"), once; None if none."""
    name, _state.pending = _state.pending, None
    if name is not None:
        # Its byte (and those of any signal before it) is taken with it; a byte whose handler has
        # not run yet stays for the next look only if it came after this (rare: then that signal
        # is noticed at the next block, not the next sweep).
        _drain()
    return name


def pending() -> bool:
    """Whether a signal was received while deferring and is not taken yet (a wait in the run's
    thread that is not `abandonable`, e.g. the live view's pause, ends on it)."""
    return _state.pending is not None
