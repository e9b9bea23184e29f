"""An FMU in this process (isolation = "none") that calls exit() ends the run as a failed FMU: exit
status 2 and one line naming it, with the log finalised, instead of a "successful" exit 0 mid-run.

exit() cannot be stopped, only watched: it runs the C library's exit handlers before the process
ends. While an FMU is instantiated in this process (`watch` .. `release`), one handler is
registered with glibc's __cxa_atexit under a key of its own; it receives exit()'s status. When no
FMU is left, at the interpreter's own exit (a Python atexit function: it runs before Python
finalises, and so before C exit handlers) and in a forked child, `__cxa_finalize(key)` removes it
(calling it once, disarmed). So it never runs after Python has finalised, and a normal end of the
process is never taken for an FMU's exit().

The handler runs inside exit(), in the thread that called it, on top of the FMU's C frames: it
finds which FMU called it from the call stack (backtrace + dladdr: the frames in the shared library
each instance loaded from its own folder, the outermost of them the FMI function that was called),
calls the hooks the run registered (`add_hook`: they finalise the log and word the line),
prints the line on stderr and ends the process with `os._exit(2)`. The process cannot go back to
its Python frames (the FMU called a function that does not return), so nothing else runs.

The child process of an isolated FMU turns this off (`enabled = False`): there, exit() must end the
child with its own status, which the host reports.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
import weakref
from collections.abc import Callable

enabled = True  # False in an isolated FMU's child process
FAILED = 2  # exit status of a run whose FMU called exit()

_live: dict[int, weakref.ref] = {}  # id -> FmuComponent instantiated in this process
_hooks: list[Callable[[str], str | None]] = []
_registered = [False]
_key = ctypes.c_char()  # its address is the handler's key (__cxa_atexit's dso_handle)
_HANDLER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int)


# glibc's Dl_info, four pointers: dli_fname (the shared object's path), dli_fbase, dli_sname (the
# nearest symbol's name), dli_saddr.
_DL_INFO = ctypes.c_void_p * 4
_FNAME, _SNAME = 0, 2


def _libc():
    libc = ctypes.CDLL(None)
    libc.__cxa_atexit.argtypes = (_HANDLER, ctypes.c_void_p, ctypes.c_void_p)
    libc.__cxa_finalize.argtypes = (ctypes.c_void_p,)
    libc.__cxa_finalize.restype = None
    libc.backtrace.argtypes = (ctypes.POINTER(ctypes.c_void_p), ctypes.c_int)
    libc.dladdr.argtypes = (ctypes.c_void_p, ctypes.POINTER(_DL_INFO))
    return libc


def watch(component) -> None:
    """Arm the handler while `component` (an FmuComponent with its unpacked folder) is instantiated."""
    if not enabled:
        return
    _live[id(component)] = weakref.ref(component)
    if not _registered[0]:
        if _LIBC.__cxa_atexit(_handler, None, ctypes.addressof(_key)) == 0:
            _registered[0] = True


def release(component) -> None:
    """`component` is freed; the last one disarms the handler."""
    if _live.pop(id(component), None) is not None and not _live:
        _disarm()


def _disarm() -> None:
    if _registered[0]:
        _registered[0] = False
        _LIBC.__cxa_finalize(ctypes.addressof(_key))  # calls the handler once (disarmed) and drops it


def add_hook(hook: Callable[[str], str | None]) -> None:
    """Until `remove_hook(hook)`, an FMU's exit() calls `hook(message)` before the process ends (the
    run finalises its log); what it returns (None: `message`) is the line printed."""
    _hooks.append(hook)


def remove_hook(hook: Callable[[str], str | None]) -> None:
    _hooks.remove(hook)


def _culprit() -> tuple[list, str]:
    """The live components whose library is on the call stack, and the FMI function of theirs that
    was called (the outermost of their frames); ([], "") when no FMU's code is on the stack.

    Instances of an FMU that may be instantiated more than once per process share one unpacked
    folder, so one mapped library (`cosim.fmi.archive.unpack_instance`): the stack tells the
    library, not which of its instances called exit(), and all of them are returned (in the order
    they were instantiated)."""
    folders: dict[str, list] = {}
    for reference in _live.values():
        component = reference()
        folder = getattr(component, "_unzip_dir", None)
        if folder:
            folders.setdefault(os.path.realpath(folder) + os.sep, []).append(component)
    frames = (ctypes.c_void_p * 256)()
    count = _LIBC.backtrace(frames, len(frames))
    found, function = [], ""
    info = _DL_INFO()
    for address in frames[:count]:
        # address - 1: inside the call instruction (after a call of exit(), which does not return,
        # the return address may already be the next function's first byte).
        if not address or not _LIBC.dladdr(address - 1, ctypes.byref(info)) or not info[_FNAME]:
            continue
        library = os.path.realpath(os.fsdecode(ctypes.string_at(info[_FNAME])))
        owners = next((c for folder, c in folders.items() if library.startswith(folder)), None)
        if owners is None:
            if found:
                break  # past the FMU's outermost frame
            continue
        found = owners
        if info[_SNAME]:
            function = ctypes.string_at(info[_SNAME]).decode(errors="replace")
    return found, function


NAMED = 3  # instances named in the line when several share the library that called exit()


def _message(status: int) -> str:
    components, function = _culprit()
    if not components:
        names = sorted(c.name for c in (r() for r in _live.values()) if c is not None)
        return (
            f"exit({status}) was called in this process outside the FMUs' code while FMU(s) "
            f'{", ".join(repr(n) for n in names)} ran in it (isolation = "none")'
        )
    model = components[0].model_description.modelName
    where = f" in {function}" if function else ""
    if len(components) == 1:
        who = f"FMU '{components[0].name}' (model {model})"
    else:
        names = ", ".join(repr(c.name) for c in components[:NAMED])
        more = f" and {len(components) - NAMED} more" if len(components) > NAMED else ""
        who = (
            f"one of the {len(components)} instances of FMU model {model} sharing one library "
            f"({names}{more}; the stack does not tell which)"
        )
    return (
        f"{who} ended the process with exit status {status} "
        f'(exit() inside the FMU; isolation = "none"){where}'
    )


def _exited(_argument, status: int) -> None:
    if not _registered[0]:
        return  # __cxa_finalize of a disarm
    _registered[0] = False
    try:
        message = _message(status)
    except BaseException as error:  # never let the report itself end it otherwise
        message = f'an FMU in this process called exit({status}) (isolation = "none"; {error!r})'
    line = message
    for hook in reversed(_hooks):
        try:
            line = hook(message) or line
        except BaseException as error:
            line = f"{message}; finalising the log failed: {' '.join(str(error).split())[:200]}"
    try:
        sys.stdout.flush()
        sys.stderr.write(f"cosim: error: {line}\n")
        sys.stderr.flush()
    finally:
        os._exit(FAILED)


try:
    _LIBC = _libc()
except (AttributeError, OSError):  # not glibc-like: exit() is not watched
    enabled = False
else:
    _handler = _HANDLER(_exited)  # kept alive for the life of the process
    atexit.register(_disarm)
    os.register_at_fork(after_in_child=_disarm)
