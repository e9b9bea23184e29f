"""The child process of an `IsolatedFmuComponent`:
`python -m cosim.fmi.isolated_child SOCKET MEMORY PARENT LIMIT`.

SOCKET is its end of the host's SOCK_SEQPACKET pair, MEMORY the descriptor of the shared block,
PARENT the host's process id, LIMIT its memory limit [bytes] (0: none), set as RLIMIT_DATA before
the FMU is read or loaded. Standard input holds `FmuComponent`'s arguments (JSON, up to its
end); the child builds the component over the shared buffers, answers OK, and serves one command
per datagram
(protocol in `cosim.fmi.isolated`) until FREE or until the host goes away. Before each FMI call it
records which call it makes in the shared header, so that if the call never returns (a crash, an
exit(), a hang) the host can say which one it was.
"""

from __future__ import annotations

import ctypes
import errno
import json
import mmap
import os
import signal
import socket
import struct
import sys
import time

from cosim.errors import CosimError
from cosim.fmi import exit_guard
from cosim.fmi import isolated as protocol
from cosim.fmi.component import FmuComponent
from cosim.fmi.model_exchange import fmu_component

_PR_SET_PDEATHSIG = 1


def _die_with(parent: int) -> None:
    """Be killed when the host ends, even while hung inside an FMU call (Linux)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # the host ended before prctl took effect
        os._exit(1)


_limited: list = [None]  # the shared header while a memory limit is set (`_record_peak`)


def _status(*keys: str) -> dict[str, int]:
    """Fields of /proc/self/status [KiB]."""
    values = {}
    with open("/proc/self/status") as status:
        for line in status:
            key, _, rest = line.partition(":")
            if key in keys:
                values[key] = int(rest.split()[0])
    return values


def _record_peak() -> None:
    """Before an error reply under a memory limit: the peak resident memory, for the host's verdict
    (the child may be gone before the host can look)."""
    header = _limited[0]
    if header is not None:
        try:
            header[protocol.W_PEAK] = _status("VmHWM").get("VmHWM", 0)
        except (OSError, MemoryError, ValueError):
            pass


def _error(component: FmuComponent | None, message: str) -> bytes:
    _record_peak()
    state = component.state if component is not None else 0
    return protocol.ERROR + bytes([int(state)]) + message.encode(errors="replace")[: protocol.MAX_PACKET - 2]


def _bug(component: FmuComponent, error: Exception) -> bytes:
    return _error(component, f"FMU '{component.name}' in its process: {type(error).__name__}: {error}")


def _out_of_memory(component: FmuComponent | None, call: int) -> bytes:
    """The reply to a MemoryError (the memory limit): the host words the message."""
    _record_peak()
    state = component.state if component is not None else 0
    return protocol.OUT_OF_MEMORY + bytes([int(state), call]) + b"MemoryError (an allocation failed)"


def _limit_memory(limit: int, header) -> None:
    """Cap the data this process may allocate (RLIMIT_DATA, hard and soft: the FMU cannot raise it)
    and record the data that counts against it but is not resident (for the host's verdict)."""
    if not limit:
        return
    import resource

    values = _status("VmData", "RssAnon")
    header[protocol.W_UNTOUCHED] = max(0, values.get("VmData", 0) - values.get("RssAnon", 0))
    # Linux keeps ru_maxrss across execve: the host's resident size when it started this process.
    header[protocol.W_INHERITED] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    resource.setrlimit(resource.RLIMIT_DATA, (limit, limit))
    _limited[0] = header


def serve(fd: int, memory: mmap.mmap) -> int:
    """Answer the host's commands on socket `fd`; return the exit status."""
    read, write = os.read, os.write
    try:
        component = fmu_component(**json.loads(sys.stdin.buffer.read()))
    except CosimError as error:
        write(fd, _error(None, str(error)))
        return 0
    except MemoryError:
        write(fd, _out_of_memory(None, protocol.CALL_LOAD))
        return 0
    except OSError as error:  # ENOMEM from a system call (an import listing a folder) under the limit
        if error.errno != errno.ENOMEM or _limited[0] is None:
            raise
        write(fd, _out_of_memory(None, protocol.CALL_LOAD))
        return 0
    protocol.bind_buffers(component, memory)
    write(fd, protocol.OK)
    times = (ctypes.c_double * 2).from_buffer(memory, protocol.TIMES_OFFSET)
    call = ctypes.c_int32.from_buffer(memory, protocol.CALL_OFFSET)
    header = memoryview(memory)[: protocol.BUFFERS_OFFSET].cast("i")
    W_REQUEST, W_REPLY, W_STATUS = protocol.W_REQUEST, protocol.W_REPLY, protocol.W_STATUS
    W_CHILD_ASLEEP, W_HOST_ASLEEP = protocol.W_CHILD_ASLEEP, protocol.W_HOST_ASLEEP
    W_PREPARE, pause = protocol.W_PREPARE, os.sched_yield
    HINT, MAX_PACKET = protocol.HINT, protocol.MAX_PACKET
    clock = time.perf_counter
    done = 0  # sequence number of the last step done
    polling = False  # right after a step: poll for the next request before blocking
    cooldown = 0  # steps left without polling after a poll ran out of time
    while True:
        if header[W_REQUEST] == done:
            spin = header[protocol.W_CHILD_SPIN]
            if polling and spin and not cooldown:
                polling = False
                give_up = clock() + spin * 1e-9
                polls = 0
                while header[W_REQUEST] == done:
                    polls += 1
                    if not polls & 15 and clock() >= give_up:
                        cooldown = protocol.COOLDOWN
                        break
                else:
                    continue
            prepare = header[W_PREPARE]
            if prepare:
                # Our request comes next (another child's step runs now): poll, giving the core
                # away between polls, as the host and the stepping child need theirs.
                header[W_PREPARE] = 0
                give_up = clock() + prepare * 1e-9
                while header[W_REQUEST] == done:
                    pause()
                    if clock() >= give_up:
                        break
                else:
                    continue
            header[W_CHILD_ASLEEP] = 1
            if header[W_REQUEST] != done:  # re-read after announcing: no lost wake-up
                header[W_CHILD_ASLEEP] = 0
                continue
            try:
                packet = read(fd, MAX_PACKET)
            except BlockingIOError:  # one SLICE passed: look again
                packet = HINT
            header[W_CHILD_ASLEEP] = 0
            if packet == HINT:
                continue
        else:  # the hot path: one macro step
            sequence = header[W_REQUEST]
            header[W_PREPARE] = 0  # set for this request, if at all (none is set during our step)
            try:
                if header[protocol.W_PUSH]:
                    call.value = protocol.CALL_SET
                    component.push_inputs()
                call.value = protocol.CALL_STEP
                component.do_step(times[0], times[1])
                call.value = protocol.CALL_GET
                component.get_outputs()
                header[W_STATUS] = 0
            except CosimError as error:
                write(fd, _error(component, str(error)))
                header[W_STATUS] = 1
            except MemoryError:
                write(fd, _out_of_memory(component, call.value))
                header[W_STATUS] = 1
            except Exception as error:  # a bug here, not the FMU's: still one line for the host
                write(fd, _bug(component, error))
                header[W_STATUS] = 1
            call.value = protocol.CALL_IDLE
            done = sequence
            header[W_REPLY] = sequence
            if header[W_HOST_ASLEEP]:
                write(fd, HINT)
            polling = True
            cooldown -= cooldown > 0
            continue
        try:
            if not packet:
                return 0  # the host has gone
            command, argument = packet[:1], packet[1:]
            answer = protocol.OK
            if command == protocol.UNPACK:
                call.value = protocol.CALL_UNPACK
                component.unpack()
            elif command == protocol.INSTANTIATE:
                call.value = protocol.CALL_INSTANTIATE
                component.instantiate()
            elif command == protocol.SETUP:
                arguments = json.loads(argument)
                if arguments["push"]:
                    call.value = protocol.CALL_SET
                    component.push_inputs()
                call.value = protocol.CALL_SETUP
                component.setup(arguments["t0"], arguments["parameters"], arguments["stop_time"])
            elif command == protocol.INITIALIZE:
                call.value = protocol.CALL_INITIALIZE
                component.enter_initialization()  # the inputs below are initial values
                if argument == b"1":
                    call.value = protocol.CALL_SET
                    component.push_inputs()
                call.value = protocol.CALL_INITIALIZE
                component.initialize()
                call.value = protocol.CALL_GET
                component.get_outputs()
            elif command == protocol.EXCHANGE:
                call.value = protocol.CALL_SET
                component.push_inputs()
                call.value = protocol.CALL_GET
                component.get_outputs()
            elif command == protocol.SAVE_STATE:
                call.value = protocol.CALL_STATE
                component.save_state()
            elif command == protocol.RESTORE_STATE:
                call.value = protocol.CALL_STATE
                component.restore_state()
            elif command == protocol.TEXT:
                request = json.loads(argument)
                for name, value in request["set"].items():
                    component.set_text(name, value)  # a Binary's as hex
                if request["send"]:
                    call.value = protocol.CALL_SET
                    component.push_text()
                outputs = {
                    p.name: protocol.json_text(component.text_values[p.name]) for p in component.text_outputs
                }
                answer = protocol.OK + json.dumps(outputs).encode()
            elif command == protocol.RESTRICT:
                component.restrict_push(json.loads(argument))
            elif command == protocol.TERMINATE:
                call.value = protocol.CALL_TERMINATE
                component.terminate()
            elif command == protocol.FREE:
                call.value = protocol.CALL_FREE
                component.free()
                call.value = protocol.CALL_IDLE
                write(fd, protocol.OK)
                return 0
            else:
                raise CosimError(f"isolated FMU '{component.name}': unknown command {command!r}")
            call.value = protocol.CALL_IDLE
            write(fd, answer)
        except CosimError as error:
            call.value = protocol.CALL_IDLE
            write(fd, _error(component, str(error)))
        except MemoryError:
            failed_in, call.value = call.value, protocol.CALL_IDLE
            write(fd, _out_of_memory(component, failed_in))
        except Exception as error:  # a bug here, not the FMU's: still one line for the host
            call.value = protocol.CALL_IDLE
            write(fd, _bug(component, error))


def main(argv: list[str]) -> int:
    fd, memory_fd, parent, limit = (int(value) for value in argv)
    exit_guard.enabled = False  # an exit() in the FMU ends this process with its status: the host says so
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the host decides how a run ends
    _die_with(parent)
    memory = mmap.mmap(memory_fd, 0)
    os.close(memory_fd)
    _limit_memory(limit, memoryview(memory)[: protocol.BUFFERS_OFFSET].cast("i"))
    seconds = protocol.SLICE  # a blocked read wakes this often to re-read the header
    with socket.socket(fileno=os.dup(fd)) as sock:  # the option is the socket's, shared by fd
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", 0, int(seconds * 1e6)))
    try:
        return serve(fd, memory)
    except (BrokenPipeError, ConnectionResetError):
        return 0  # the host has gone


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the instance is freed: skip the interpreter's teardown, the host waits for it
