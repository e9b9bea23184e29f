"""An FMU in a child process: a crash, abort, exit() or hang of a foreign FMU ends the run with a
message naming it, instead of taking the orchestrator (and the log) down with it.

`IsolatedFmuComponent` takes `FmuComponent`'s arguments (plus `timeout`) and is used the same way.
The host reads the model description itself (ports, feedthrough, port-map errors are the same as
in-process, raised before any process exists); at `instantiate()` it starts
`python -m cosim.fmi.isolated_child`, which builds an `FmuComponent` from the same arguments and
loads the FMU with the same code, so values, checks (finite outputs) and messages are identical.

Exchange
--------
Both processes map one shared memory block (a memfd): a header with t and h [s], the FMI call the
child is in and the step handshake, then the component's input buffer, then its output buffer.
The host's `input_buffer`/`output_buffer` and the child's FmuComponent buffers ARE these views, so
the master writes inputs straight into the child's buffer and reads outputs from it: no copies.
Commands other than a step (instantiate, setup, ..., free: rare) are one datagram each way on a
Unix SOCK_SEQPACKET socket pair. String and Binary values (`cosim.fmi.text`) do not fit the float
buffers: a component with text inputs sends them in a TEXT datagram before each step (and at
initialisation), and one with text outputs asks for them with another after each step; the child's
answer holds its text outputs (JSON, a Binary as hex), at most MAX_PACKET bytes in all.

A step is a spin-then-block handshake through the header: the host writes t, h, "push the inputs
first" and then a new request sequence number; the child sets the inputs, calls doStep, gets the
outputs, writes the status and then the request's number as its reply number. Each waiter polls
the other's number for a short bounded time (the host HOST_SPIN for the reply; the child, right
after a step, CHILD_SPIN for the next request, which in a tight master loop follows within
microseconds), then announces "asleep" in the header, reads the number again, and blocks in a
read on the socket. The other side sends a one-byte HINT datagram only when its peer has announced
sleep; a HINT is only "look at the header" (a stale one costs a loop). A wake-up lost to x86's
store->load reordering between "asleep" and the sequence number is bounded: a blocked read times
out after SLICE (1 ms, SO_RCVTIMEO) and looks at the header again. A step error is sent as a
datagram before the reply number, and the status word says to read it.

Polling is bounded for the 2-core machines this runs on: the child polls after a step only while
the host has fewer children than usable cores, and a poll that runs out of time (a slow FMU, a busy
machine) turns polling off for the next COOLDOWN (64) steps of that side. With as many children as
cores (2 children on 2 cores: host + 2 pollers would fight for the cores), the children block after
a step, and the host prepares the child whose step comes next (the order of isolated steps is
learned from the steps themselves): while it waits for one child's reply it sets the next one's
W_PREPARE and wakes it, so that child polls for its request (giving its core away between polls)
while the other child steps, and its wake-up overlaps that step instead of adding to the round trip;
the host then gives its core away between its own polls too, for a prepared child queued on it.
`host_spin` and `child_spin` (attributes, seconds; None = these defaults) override it.

Measured (benchmarks/bench_isolation.py --baseline <the previous tree> --spin auto, extra us per
isolated component step over in-process, 2-core VM): vehicle isolated 5-10 (one blocking round
trip per step, before the spin-then-block handshake: 23.5-27.4); both isolated, this handshake
against the one without prepared children in the same run: 13.0/18.2, 13.9/18.0, 16.2/18.4,
13.2/17.9, 18.9/21.0. A blocking round trip costs two wake-ups through the kernel; a polled one
none. Why a socket at all, not a futex, for the blocking side: measured here, a Python-to-Python
round trip costs 8.7 us through a futex pair and 9.5 us through the socket pair, but the socket
gives what a futex does not: a kernel timeout without an extra poll call (SO_RCVTIMEO), and a dead
child shows at once as end-of-file.

Failures (each a one-line `CosimError` naming the component, the model, the FMI call and the
simulation time; the component is then FAILED and the child gone):
- the child ended during a call: killed by a signal (SIGSEGV, SIGABRT...) or exited (an FMU
  calling exit()); the call is the one the child recorded in the shared header before making it;
- a call did not return within `timeout` seconds: the child is killed with SIGKILL (only a
  process can stop a hung C call; threads and signals the FMU may ignore cannot);
- an FMU error status, a non-finite output, etc. inside the child: the child's `CosimError`
  message, verbatim;
- the child went over `max_memory` ([simulation] fmu_max_memory): the child sets it as its
  RLIMIT_DATA before it loads the FMU, so an allocation beyond it fails (malloc returns NULL, Python
  raises MemoryError). A MemoryError in the child, or a failure or death of the child whose peak
  resident memory (the kernel's ru_maxrss / VmHWM) came within the child's untouched data (what
  counts against RLIMIT_DATA but is not resident, measured when the limit was set) plus
  MEMORY_MARGIN of the limit, reads "exceeded fmu_max_memory (2 GiB)" with that peak. (Linux
  keeps ru_maxrss across execve, so a dead child's ru_maxrss is its own peak only above the host's
  resident size when it was started, which the child records: a host that large hides it.)
Unpacking the archive is a call of its own (UNPACK_TIMEOUT, not `timeout`): a large FMU is not
reported as an fmi2Instantiate that did not return. Every child unpacks into a folder the host
made (its TMPDIR), which the host removes once the child has ended, however it ended.
The child dies with the host (PR_SET_PDEATHSIG), ignores the terminal's Ctrl-C (the host handles
it and ends the run cleanly), and its stderr is kept in a file whose last line is added to a
crash message (and copied to the host's stderr on a clean end).
"""

from __future__ import annotations

import ctypes
import json
import mmap
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import weakref
from collections.abc import Collection, Mapping
from pathlib import Path

import numpy as np

import cosim
from cosim.core.component import Component, State
from cosim.core.interrupt import Interrupted, abandonable
from cosim.errors import CosimError
from cosim.fmi.archive import mib
from cosim.fmi.model_exchange import fmu_component
from cosim.fmi.types import TRANSFER_TYPES

DEFAULT_TIMEOUT = 10.0  # [s] longest FMI call ([simulation] fmu_timeout)
UNPACK_TIMEOUT = 600.0  # [s] for the child to unpack the archive (its size is limited before)
MEMORY_MARGIN = 64 << 20  # [bytes] see "Failures" in the module docstring
STARTUP_TIMEOUT = 120.0  # [s] for the child's Python to start and read the model description
FREE_TIMEOUT = 5.0  # [s] for a child to free its instance and exit before it is killed

# Shared memory: t [s], h [s] (doubles at 0, 8), then int32 words (`HEADER` indexes them as a
# memoryview of int32: word i at byte 4 i): the call the child is in, the step handshake (see the
# module docstring), and the child's spin budget [ns]; the input and output buffers (doubles)
# follow from BUFFERS_OFFSET on.
TIMES_OFFSET, CALL_OFFSET, BUFFERS_OFFSET = 0, 16, 64
W_CALL = 4  # int32 word of CALL_OFFSET
W_PUSH = 5  # host: 1 when the step pushes the inputs first
W_REQUEST = 6  # host: sequence number of the last step asked for
W_REPLY = 7  # child: sequence number of the last step done (after W_STATUS and the outputs)
W_STATUS = 8  # child: 0 the step went well, 1 its error datagram is on the socket
W_HOST_ASLEEP = 9  # host: 1 while it may block in read for the reply (wake it with HINT)
W_CHILD_ASLEEP = 10  # child: 1 while it may block in read for a request (wake it with HINT)
W_CHILD_SPIN = 11  # host: how long the child polls W_REQUEST after a step [ns]
W_PREPARE = 12  # host: "your request comes next": poll for it this long [ns], giving the core away
W_INHERITED = 13  # child: its ru_maxrss when it set its memory limit [KiB] (the host's, from exec)
W_PEAK = 14  # child: its peak resident memory [KiB] when it sent an error under a memory limit
W_UNTOUCHED = 15  # child: data not resident when it set its memory limit [KiB]
HEADER_WORDS = BUFFERS_OFFSET // 4
MAX_PACKET = 1 << 16

# Host -> child commands (first byte of a datagram; JSON arguments follow where needed).
STEP, STEP_PUSHED = b"s", b"S"  # doStep (after sending the inputs), then get the outputs
INSTANTIATE, SETUP, INITIALIZE, RESTRICT, TERMINATE, FREE = b"I", b"U", b"N", b"R", b"T", b"F"
EXCHANGE = b"X"  # send the inputs and get the outputs, no step (initialisation's second pass)
UNPACK = b"P"  # unpack the archive (before INSTANTIATE; timed apart, UNPACK_TIMEOUT)
SAVE_STATE, RESTORE_STATE = b"G", b"V"  # FmuComponent.save_state / restore_state (FMU state)
TEXT = b"E"  # JSON {"set": {input: value}, "send": bool}: stage (and send) text inputs; answer: outputs
# Child -> host: OK alone, or ERROR + the component's state (one byte) + the message (UTF-8);
# OUT_OF_MEMORY (a MemoryError in the child: its memory limit) + state + the CALL_* it was in + message.
OK, ERROR, OUT_OF_MEMORY = b"\x00", b"\x01", b"\x02"
# Either way: "look at the shared header" (a wake-up for a sleeping peer; may be stale: ignored).
HINT = b"w"

# Spin-then-block handshake of a step (see the module docstring); measured by
# benchmarks/bench_isolation.py. A blocked waiter wakes every SLICE to re-read the header, so a
# wake-up lost to store->load reordering between "asleep" and the sequence number costs <= SLICE.
HOST_SPIN = 30e-6  # [s] the host polls for the reply this long before it blocks
CHILD_SPIN = 30e-6  # [s] the child polls for the next request this long after a step
SLICE = 1e-3  # [s] receive timeout of a blocked waiter (both sides)
PREPARE_SPIN = 100e-6  # [s] a child told its request comes next polls this long (yielding its core)
COOLDOWN = 64  # steps without polling after a poll ran out of time (a slow FMU, a busy machine)
CORES = len(os.sched_getaffinity(0))
_live: set[int] = set()  # ids of this process's running children (`_Child`)
_last: list = [None]  # weak reference to the isolated component stepped last (learns the order)

# What the child is doing, as it records it in the shared header before each call.
CALL_IDLE, CALL_SET, CALL_STEP, CALL_GET = 0, 1, 2, 3
CALL_INSTANTIATE, CALL_SETUP, CALL_INITIALIZE, CALL_TERMINATE, CALL_FREE, CALL_LOAD = 4, 5, 6, 7, 8, 9
CALL_UNPACK = 10
CALL_STATE = 11


def memory_text(size: int) -> str:
    """An amount of memory [bytes] for a message: '2 GiB', '1.93 GiB', '300 MiB'."""
    if size >= 1 << 30:
        return f"{size >> 30} GiB" if size % (1 << 30) == 0 else f"{size / (1 << 30):.2f} GiB"
    return mib(size)


def _resident_peak(pid: int) -> int | None:
    """The peak resident memory [bytes] of a running process (VmHWM), or None."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def shared_size(inputs: int, outputs: int) -> int:
    """Bytes of the shared block for a component with these numbers of ports."""
    return BUFFERS_OFFSET + 8 * (max(1, inputs) + max(1, outputs))


def bind_buffers(component: Component, memory: mmap.mmap) -> None:
    """Make the component's input and output buffers (ctypes arrays and their NumPy views) views of
    the shared block. Values are not copied: the block's current contents become the buffers'."""
    inputs, outputs = len(component.inputs), len(component.outputs)
    output_offset = BUFFERS_OFFSET + 8 * max(1, inputs)
    component.input_cbuffer = (ctypes.c_double * max(1, inputs)).from_buffer(memory, BUFFERS_OFFSET)
    component.output_cbuffer = (ctypes.c_double * max(1, outputs)).from_buffer(memory, output_offset)
    component.input_buffer = np.ctypeslib.as_array(component.input_cbuffer)[:inputs]
    component.output_buffer = np.ctypeslib.as_array(component.output_cbuffer)[:outputs]


def json_text(value: str | bytes) -> str:
    """A String as itself, a Binary as hex text (as `cosim.fmi.text.check_text` takes it back)."""
    return value.hex() if isinstance(value, bytes) else value


def _json_values(values: Mapping[str, object]) -> dict[str, object]:
    """Parameter values for JSON: a Binary's bytes as hex text (`json_text`), the rest as they are."""
    return {name: json_text(value) if isinstance(value, bytes) else value for name, value in values.items()}


def _set_receive_timeout(sock: socket.socket, seconds: float) -> None:
    whole = int(seconds)
    sock.setsockopt(
        socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", whole, int((seconds - whole) * 1e6))
    )


class _Child:
    """The child process and its ends of the exchange; `close()` is also the GC finaliser."""

    def __init__(self, process: subprocess.Popen, sock: socket.socket, stderr, folder: str) -> None:
        self.process = process
        self.sock = sock
        self.stderr = stderr
        self.folder = folder  # its TMPDIR: the extracted FMU (removed once the child has ended)
        self.peak: int | None = None  # its peak resident memory [bytes], once reaped

    def reap(self) -> int:
        """Wait for the child to end; return its exit status as `Popen.returncode` gives it, and keep
        its peak resident memory (`peak`)."""
        process = self.process
        if process.returncode is None:
            try:
                _, status, usage = os.wait4(process.pid, 0)
            except ChildProcessError:  # reaped elsewhere (Popen.poll)
                process.wait()
            else:
                process.returncode = os.waitstatus_to_exitcode(status)
                self.peak = usage.ru_maxrss * 1024
        return process.returncode

    def kill(self) -> None:
        if self.process.returncode is None and self.process.poll() is None:
            self.process.kill()
        self.reap()

    def stderr_text(self) -> str:
        self.stderr.seek(0)
        return self.stderr.read().decode(errors="replace")

    def close(self) -> None:
        _live.discard(id(self))
        self.kill()
        self.sock.close()
        self.stderr.close()
        shutil.rmtree(self.folder, ignore_errors=True)


class IsolatedFmuComponent(Component):
    """An FMU (FMI 2.0 or 3.0 co-simulation, or Model Exchange) stepped in a child process; see the
    module docstring.

    Args: those of `FmuComponent` (path, name, parameters, port_map, period, feedthrough_override,
    nan_outputs, max_unpacked_size), `integration` (a Model Exchange FMU's solver settings, as
    `cosim.fmi.model_exchange.fmu_component` takes them), `timeout`: the longest an FMI call may
    take [s] before the child is killed and the call fails, and `max_memory`: the child's memory
    limit [bytes] (RLIMIT_DATA; None: none).
    """

    def __init__(
        self,
        path: str | Path,
        name: str,
        parameters: Mapping[str, float] | None = None,
        port_map: Mapping[str, object] | None = None,
        period: float = 0.0,
        feedthrough_override: Mapping[str, list[str]] | None = None,
        nan_outputs: Collection[str] = (),
        max_unpacked_size: int | None = None,
        timeout: float = DEFAULT_TIMEOUT,
        integration: Mapping[str, object] | None = None,
        max_memory: int | None = None,
    ) -> None:
        if not timeout > 0:
            raise CosimError(f"component '{name}': FMU timeout must be > 0 s, got {timeout}")
        if max_memory is not None and not max_memory > 0:
            raise CosimError(f"component '{name}': FMU memory limit must be > 0 bytes, got {max_memory}")
        self._arguments = {
            "path": str(path),  # the child starts in this working directory
            "name": name,
            "parameters": _json_values(parameters or {}),
            "port_map": dict(port_map or {}),
            "period": period,
            "feedthrough_override": {k: list(v) for k, v in (feedthrough_override or {}).items()},
            "nan_outputs": list(nan_outputs),
            "max_unpacked_size": max_unpacked_size,
            "integration": dict(integration) if integration else None,
        }
        # Reads and checks the description here, so bad input fails before any process starts.
        self.spec = fmu_component(**self._arguments)
        super().__init__(name, period=period)
        spec = self.spec
        self._set_ports(spec.inputs, spec.outputs, spec.parameters, spec.feedthrough)
        self.path = spec.path
        self.model_description = spec.model_description
        self.fmi_version = spec.fmi_version
        self.nan_outputs = spec.nan_outputs
        self.timeout = float(timeout)
        self.max_memory = None if max_memory is None else int(max_memory)
        self._memory_fd = os.memfd_create(f"navcosim-{name}", os.MFD_CLOEXEC)
        os.ftruncate(self._memory_fd, shared_size(len(self.inputs), len(self.outputs)))
        self._memory = mmap.mmap(self._memory_fd, 0)
        self._memory_fd_closer = weakref.finalize(self, os.close, self._memory_fd)  # unless started
        starts = self.input_buffer.copy(), self.output_buffer.copy()
        bind_buffers(self, self._memory)
        self.input_buffer[:], self.output_buffer[:] = starts
        self._times = (ctypes.c_double * 2).from_buffer(self._memory, TIMES_OFFSET)
        self._call = ctypes.c_int32.from_buffer(self._memory, CALL_OFFSET)
        self._header = memoryview(self._memory)[:BUFFERS_OFFSET].cast("i")
        self._sequence = 0
        # Polling budgets [s]; None: HOST_SPIN, and CHILD_SPIN while this process has fewer children
        # than usable cores (the host and the polling child each have a core), else 0 (block at once).
        self.host_spin: float | None = None
        self.child_spin: float | None = None
        self._cooldown = 0
        self._next = None  # weak reference to the isolated component stepped after this one
        self._child: _Child | None = None
        self._finalizer: weakref.finalize | None = None
        self._fd = -1
        self._push_pending = False
        self._time: float | None = None  # simulation time of the current call [s], for messages
        # String and Binary ports, as `FmuComponent`'s; their values cross in TEXT datagrams.
        self.text_inputs, self.text_outputs = spec.text_inputs, spec.text_outputs
        self.text_parameters = spec.text_parameters
        self.text_values = spec.text_values  # the spec's own dict: `set_text` checks and stages there
        self._text_feeds: dict[str, tuple[Component, str]] = {}
        self.text_listener = None  # as `FmuComponent.text_listener`
        self._text_step: float | None = None  # start [s] of the step whose text outputs are next read

    def variable_name(self, port: str) -> str:
        """The FMU variable behind a port."""
        return self.spec.variable_name(port)

    def allow_nan(self, *ports: str) -> None:
        """As `FmuComponent.allow_nan` (before `instantiate()`, which hands the set to the child)."""
        self._require("allow_nan", State.CREATED)
        self.spec.allow_nan(*ports)
        self.nan_outputs = self.spec.nan_outputs
        self._arguments["nan_outputs"] = sorted(self.nan_outputs)

    def describe(self) -> dict[str, str]:
        return {**self.spec.describe(), "isolation": "process"}

    @property
    def pid(self) -> int | None:
        """The child's process id while it runs."""
        return self._child.process.pid if self._child is not None else None

    # ---- the exchange ------------------------------------------------------------------------

    def _start(self) -> None:
        """Start the child and hand it the component's arguments; it answers once it has built
        its FmuComponent over the shared buffers (the FMU is not loaded yet)."""
        host_end, child_end = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        package_root = str(Path(cosim.__file__).resolve().parent.parent)
        environment = dict(os.environ)
        environment["PYTHONPATH"] = os.pathsep.join(
            filter(None, [package_root, os.environ.get("PYTHONPATH")])
        )
        stderr = tempfile.TemporaryFile(prefix=f"navcosim-{self.name}-stderr-")
        # The child's temporary files (the unpacked FMU) go here; the host removes it after the child.
        folder = tempfile.mkdtemp(prefix=f"navcosim-{self.name}-process-")
        environment["TMPDIR"] = folder
        command = [sys.executable, "-m", "cosim.fmi.isolated_child"]
        command += [str(child_end.fileno()), str(self._memory_fd), str(os.getpid())]
        command += [str(self.max_memory or 0)]
        try:
            process = subprocess.Popen(
                command,
                pass_fds=(child_end.fileno(), self._memory_fd),
                env=environment,
                stdin=subprocess.PIPE,  # the arguments, of any size (a datagram holds 64 KiB)
                stderr=stderr,
                start_new_session=True,  # the terminal's Ctrl-C goes to the host only
            )
        except OSError as error:
            host_end.close()
            stderr.close()
            shutil.rmtree(folder, ignore_errors=True)
            raise CosimError(f"FMU '{self.name}': cannot start its process: {error}") from None
        finally:
            child_end.close()
            self._memory_fd_closer()  # the child has its own descriptor; the mapping stays
        self._child = _Child(process, host_end, stderr, folder)
        _live.add(id(self._child))
        self._finalizer = weakref.finalize(self, self._child.close)
        self._fd = host_end.fileno()
        _set_receive_timeout(host_end, SLICE)
        self._call.value = CALL_LOAD  # the child's first job; it records its calls from then on
        try:
            process.stdin.write(json.dumps(self._arguments).encode())
            process.stdin.close()
        except OSError as error:  # the child ended before reading them
            reply = error
        else:
            reply = self._receive(STARTUP_TIMEOUT)
        if reply != OK:
            self._failed(reply, "load", STARTUP_TIMEOUT)
        self._call.value = CALL_IDLE

    def _receive_abandonable(self, timeout: float) -> bytes | OSError:
        """`_receive` that SIGINT/SIGTERM end (`Interrupted`; the child is killed)."""
        try:
            with abandonable:
                return self._receive(timeout)
        except Interrupted:
            self.state = State.FAILED
            self._child.kill()
            raise

    def _receive(self, timeout: float) -> bytes | OSError:
        """The child's next datagram other than a HINT, or the error that ended the wait
        (BlockingIOError after `timeout` seconds)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                packet = os.read(self._fd, MAX_PACKET)
            except BlockingIOError as error:  # one SLICE passed
                if time.monotonic() >= deadline:
                    return error
                continue
            except OSError as error:
                return error
            if packet != HINT:
                return packet

    def _exchange(self, packet: bytes, what: str, timeout: float | None = None) -> bytes:
        """Send one command and return the child's answer (after OK); raise on any failure. The
        command may take `timeout` seconds (None: `self.timeout`, an FMI call's limit)."""
        if len(packet) > MAX_PACKET:
            raise CosimError(f"FMU '{self.name}': {what} needs {len(packet)} bytes, more than {MAX_PACKET}")
        try:
            os.write(self._fd, packet)
        except OSError as error:
            reply = error
        else:
            reply = self._receive_abandonable(self.timeout if timeout is None else timeout)
        if not isinstance(reply, bytes) or reply[:1] != OK:
            self._failed(reply, what, timeout)
        return reply[1:]

    def _failed(self, reply: bytes | OSError, what: str, timeout: float | None = None) -> None:
        """Raise the `CosimError` for a failed exchange; a dead or hung child is ended first."""
        call = self._call_name(self._call.value, what)
        if what == "unpack" and call.endswith("(between FMI calls)"):
            call = self._call_name(CALL_UNPACK, what)  # a child too slow to record the call is unpacking
        when = f" at t = {self._time:.9g} s" if self._time is not None else ""
        model = f"FMU '{self.name}' (model {self.model_description.modelName}"
        child = self._child
        if isinstance(reply, bytes) and reply[:1] in (ERROR, OUT_OF_MEMORY):
            self.state = State(reply[1])
            message = reply[2:].decode(errors="replace")
            if reply[:1] == OUT_OF_MEMORY:  # the call the child was in, then the message
                call, message = self._call_name(reply[2], what), reply[3:].decode(errors="replace")
            peak = None
            if self.max_memory is not None:  # the child's own figure: it may have ended since
                peak = max(self._header[W_PEAK] * 1024, _resident_peak(child.process.pid) or 0) or None
            if reply[:1] == OUT_OF_MEMORY or self._near_memory_limit(peak):
                who = f"{model}, process {child.process.pid})"
                raise CosimError(self._over_memory(who, call, when, peak, message))
            raise CosimError(message)
        self.state = State.FAILED
        if isinstance(reply, BlockingIOError):
            child.kill()
            shutil.rmtree(child.folder, ignore_errors=True)
            if what == "unpack":
                limit, setting = f"{timeout or UNPACK_TIMEOUT:g} s", "its own limit, not fmu_timeout"
            else:
                limit, setting = f"{timeout or self.timeout:g} s", "fmu_timeout"
            raise CosimError(
                f"{model}, process {child.process.pid}) did not return from {call}{when} within {limit} "
                f"({setting}); its process was killed"
            )
        returncode = child.reap()
        shutil.rmtree(child.folder, ignore_errors=True)  # what it unpacked: it is gone
        if returncode < 0:
            number = -returncode
            try:
                name = f"{signal.Signals(number).name}, "
            except ValueError:
                name = ""
            what_happened = f"crashed with signal {number} ({name}{signal.strsignal(number)})"
        else:
            what_happened = f"ended its process with exit status {returncode} (exit() inside the FMU)"
        last_line = next((line for line in reversed(child.stderr_text().splitlines()) if line.strip()), "")
        detail = f"; its stderr: {' '.join(last_line.split())[:300]}" if last_line else ""
        who = f"{model}, process {child.process.pid})"
        # ru_maxrss is the child's own peak only above what exec handed down (the host's size).
        inherited = self._header[W_INHERITED] * 1024
        peak = child.peak if child.peak is not None and child.peak > inherited else None
        if self._near_memory_limit(peak):
            raise CosimError(self._over_memory(who, call, when, peak, what_happened) + detail)
        raise CosimError(f"{who} {what_happened} in {call}{when}{detail}")

    def _near_memory_limit(self, peak: int | None) -> bool:
        """Whether a failure with this peak resident memory [bytes] is the memory limit's doing."""
        if self.max_memory is None or peak is None:
            return False
        untouched = self._header[W_UNTOUCHED] * 1024
        return peak + untouched + MEMORY_MARGIN >= self.max_memory

    def _over_memory(self, who: str, call: str, when: str, peak: int | None, what: str) -> str:
        limit = memory_text(self.max_memory)
        reached = f"its peak resident memory {memory_text(peak)}; " if peak else ""
        return f"{who} exceeded fmu_max_memory ({limit}) in {call}{when}: {reached}{what}"

    def _call_name(self, call: int, what: str) -> str:
        """The FMI function(s) behind one of the child's recorded calls."""
        v = self.fmi_version
        if call in (CALL_SET, CALL_GET):
            ports = self.inputs if call == CALL_SET else self.outputs
            direction = "Set" if call == CALL_SET else "Get"
            used = {p.fmi_type for p in ports}  # every FMI type its ports move (`cosim.fmi.types`)
            return "/".join(f"fmi{v}{direction}{name}" for name in TRANSFER_TYPES[v] if name in used)
        return {
            CALL_STEP: f"fmi{v}DoStep",
            CALL_INSTANTIATE: f"fmi{v}Instantiate",
            CALL_SETUP: ("fmi2SetupExperiment / " if v == 2 else "") + f"fmi{v}Set* of the parameters",
            CALL_INITIALIZE: f"fmi{v}EnterInitializationMode / fmi{v}ExitInitializationMode",
            CALL_TERMINATE: f"fmi{v}Terminate",
            CALL_FREE: f"fmi{v}FreeInstance",
            CALL_LOAD: "reading the model description",
            CALL_UNPACK: "unpacking the FMU archive",
            CALL_STATE: f"fmi{v}GetFMUstate / fmi{v}SetFMUstate",
        }.get(call, f"{what} (between FMI calls)")

    # ---- lifecycle ---------------------------------------------------------------------------

    def instantiate(self) -> None:
        self._require("instantiate", State.CREATED)
        self._start()
        self._exchange(UNPACK, "unpack", UNPACK_TIMEOUT)
        self._exchange(INSTANTIATE, "instantiate")
        self.state = State.INSTANTIATED

    def setup(self, t0: float, parameters: Mapping[str, float], stop_time: float | None = None) -> None:
        self._require("setup", State.INSTANTIATED)
        self._time = float(t0)
        arguments = {"t0": float(t0), "parameters": _json_values(parameters), "stop_time": stop_time}
        arguments["push"] = self._push_pending
        self._push_pending = False
        self._exchange(SETUP + json.dumps(arguments).encode(), "setup")
        self.t0 = float(t0)
        self.state = State.SET_UP

    def initialize(self) -> None:
        self._require("initialize", State.SET_UP)
        self._exchange(INITIALIZE + (b"1" if self._push_pending else b"0"), "initialize")
        self._push_pending = False
        self.state = State.STEPPING

    def restrict_push(self, slots) -> None:
        """As `FmuComponent.restrict_push`, in the child."""
        self._exchange(RESTRICT + json.dumps([int(slot) for slot in slots]).encode(), "restrict_push")

    def state_support(self) -> str | None:
        return self.spec.state_support()

    def can_vary_step(self) -> bool:
        return self.spec.can_vary_step()

    def save_state(self) -> None:
        """As `FmuComponent.save_state`, in the child (the state stays there)."""
        self._require("save_state", State.STEPPING)
        self._exchange(SAVE_STATE, "save_state")

    def restore_state(self) -> None:
        """As `FmuComponent.restore_state`, in the child."""
        self._require("restore_state", State.STEPPING)
        self._exchange(RESTORE_STATE, "restore_state")

    # ---- text (`cosim.fmi.text`) ----------------------------------------------------------------

    def text_port(self, name: str, direction: str) -> str | None:
        return self.spec.text_port(name, direction)

    def set_text(self, name: str, value: str | bytes) -> None:
        """As `FmuComponent.set_text`; the value reaches the child with the next text inputs."""
        self.spec.set_text(name, value)

    def feed_text(self, name: str, producer: Component, output: str) -> None:
        self._text_feeds[name] = (producer, output)

    def push_text(self) -> None:
        if self.text_inputs:
            self._exchange_text(send=True)

    def _exchange_text(self, send: bool = False, inputs: bool = True) -> None:
        """One TEXT exchange: the text inputs (the fed ones from their producers) staged in the child,
        sent to the FMU now when `send` (else by the child's next step); its text outputs read back."""
        staged = {}
        if inputs:
            for name, (producer, output) in self._text_feeds.items():
                self.text_values[name] = producer.text_values[output]
            staged = {p.name: json_text(self.text_values[p.name]) for p in self.text_inputs}
        reply = self._exchange(TEXT + json.dumps({"set": staged, "send": send}).encode(), "text")
        outputs = json.loads(reply) if reply else {}
        for port in self.text_outputs:
            value = outputs[port.name]
            self.text_values[port.name] = bytes.fromhex(value) if port.fmi_type == "Binary" else value

    def push_inputs(self) -> None:
        if self.state not in (State.INSTANTIATED, State.SET_UP, State.STEPPING):
            self._require("push_inputs", State.INSTANTIATED, State.SET_UP, State.STEPPING)
        self._push_pending = True  # the inputs are already in the child's buffer; sent at the next call

    def do_step(self, t: float, h: float) -> None:
        if self.state is not State.STEPPING:
            self._require("do_step", State.STEPPING)
        if self.text_inputs:
            self._exchange_text()
        self._text_step = t
        times = self._times
        times[0] = t
        times[1] = h
        self._time = t
        header = self._header
        if self._push_pending:
            self._push_pending = False
            header[W_PUSH] = 1
        else:
            header[W_PUSH] = 0
        host_spin, child_spin = self.host_spin, self.child_spin
        if host_spin is None:
            host_spin = HOST_SPIN
        if child_spin is None:
            child_spin = CHILD_SPIN if len(_live) < CORES else 0.0
        header[W_CHILD_SPIN] = int(child_spin * 1e9)
        # The order of isolated steps, learned: the one stepped before this one is followed by it.
        last = _last[0]
        if last is not None and (previous := last()) is not None and previous is not self:
            if previous._next is None or previous._next() is not self:
                previous._next = weakref.ref(self)
        if last is None or last() is not self:
            _last[0] = weakref.ref(self)
        sequence = self._sequence = (self._sequence + 1) & 0x7FFFFFFF
        try:
            # Entered before the request is made: a signal that comes after it (the child may already
            # hang in the FMU) must end the wait, never only be recorded for the next step.
            with abandonable:  # SIGINT/SIGTERM end the wait: the child may hang in the FMU for good
                header[W_REQUEST] = sequence
                if header[W_CHILD_ASLEEP]:
                    try:
                        os.write(self._fd, HINT)
                    except OSError as error:  # the child is gone
                        self._failed(error, "step")
                if not child_spin and self._next is not None:
                    self._prepare_next()
                if header[W_REPLY] != sequence:
                    if host_spin and not self._cooldown:
                        # Poll first: a step of a small FMU takes a few us, less than a wake-up
                        # through the kernel. perf_counter is read every 16 polls (~0.1 us each).
                        clock = time.perf_counter
                        give_up = clock() + host_spin
                        polls = 0
                        # With as many children as cores, a child told its request comes next may
                        # be queued on this core: give it the core between polls.
                        pause = None if child_spin else os.sched_yield
                        while header[W_REPLY] != sequence:
                            polls += 1
                            if pause is not None:
                                pause()
                            if not polls & 15 and clock() >= give_up:
                                self._cooldown = COOLDOWN
                                self._wait_reply(sequence)
                                break
                    else:
                        self._cooldown -= self._cooldown > 0
                        self._wait_reply(sequence)
        except Interrupted:
            self._header[W_HOST_ASLEEP] = 0
            self.state = State.FAILED  # mid-step: the child is ended, never asked for more
            self._child.kill()
            raise
        if header[W_STATUS]:
            self._failed(self._receive_abandonable(self.timeout), "step")

    def _prepare_next(self) -> None:
        """Wake the child whose step follows this one, so that it polls for its request while
        this step runs instead of being woken through the kernel when the request comes."""
        following = self._next()
        if following is None or following._child is None or following.state is not State.STEPPING:
            return
        header = following._header
        header[W_PREPARE] = int(PREPARE_SPIN * 1e9)
        if header[W_CHILD_ASLEEP]:
            try:
                os.write(following._fd, HINT)
            except OSError:
                pass  # that child is gone: its own step reports it

    def _wait_reply(self, sequence: int) -> None:
        """Block until the child has done step `sequence`; raise when it dies or hangs (inside
        `abandonable`: a signal raises `Interrupted` here)."""
        header = self._header
        fd = self._fd
        deadline = time.monotonic() + self.timeout
        try:
            while True:
                header[W_HOST_ASLEEP] = 1
                if header[W_REPLY] == sequence:  # re-read after announcing: no lost wake-up
                    break
                try:
                    packet = os.read(fd, MAX_PACKET)
                except BlockingIOError as error:  # one SLICE passed
                    if header[W_REPLY] == sequence:
                        break
                    if time.monotonic() >= deadline:
                        packet = error
                    else:
                        continue
                if packet != HINT:  # end of file: the child is gone; or the timeout
                    header[W_HOST_ASLEEP] = 0
                    self._failed(packet, "step")
        except OSError as error:  # the socket failed
            header[W_HOST_ASLEEP] = 0
            self._failed(error, "step")
        header[W_HOST_ASLEEP] = 0

    def get_outputs(self) -> np.ndarray:
        if self.state is not State.STEPPING:
            self._require("get_outputs", State.STEPPING)
        if self._push_pending:  # inputs pushed after the last step: their outputs, without a step
            self._push_pending = False
            self._exchange(EXCHANGE, "get_outputs")
        if self.text_outputs:
            self._exchange_text(inputs=False)
        started, self._text_step = self._text_step, None
        if started is not None and self.text_listener is not None:
            self.text_listener(started)  # a recording (`cosim.record.text_signals`)
        return self.output_buffer  # the child has written them at the end of its step

    def terminate(self) -> None:
        self._require("terminate", State.SET_UP, State.STEPPING)
        self.state = State.TERMINATED
        self._exchange(TERMINATE, "terminate")

    def free(self) -> None:
        """Free the instance and end the child (killed when it does not exit in time); safe in
        every state and twice."""
        child, self._child = self._child, None
        if child is not None:
            if child.process.poll() is None:
                try:
                    os.write(self._fd, FREE)
                    self._receive(min(self.timeout, FREE_TIMEOUT))
                    child.process.wait(FREE_TIMEOUT)
                except (OSError, subprocess.TimeoutExpired):
                    pass
                text = child.stderr_text()
                if text and self.state is not State.FAILED:  # what the FMU wrote in a run that went well
                    sys.stderr.write(text)
            self._finalizer.detach()
            child.close()
        self._fd = -1
        self.state = State.FREED
