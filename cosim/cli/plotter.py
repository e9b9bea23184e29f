"""The PNG of `cosim run`, drawn by a child process that prepares while the run goes.

Importing matplotlib and loading its font (`cosim.logs.plot.prepare_drawing`, ~0.15 s of CPU)
does not depend on the run, so `cosim` forks a child for it before building the run: on a machine
with a free core it is done by the time the run ends. The run's `PlotData` (arrays: a few MB at
most) then goes to the child through a pipe, the child draws the PNG and answers with one line;
the parent waits for it. The child ignores SIGINT and SIGTERM (the parent decides), leaves with
`os._exit` (no clean-up of the parent's objects it shares), and gives up when the pipe closes
without data (the parent died); a parent that will not plot ends it (`cancel`). Only where
`os.fork` is safe and cheap (Linux), and only in `cosim` itself, never in a process that calls
`cosim.cli.main([...])`.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
from pathlib import Path


class PlotProcess:
    """A forked child that has imported matplotlib and waits for the data of one plot."""

    @classmethod
    def start(cls, drawer=None) -> PlotProcess | None:
        """The child, or None where there is none (no fork, or it failed): then draw in-process.
        `drawer(data, png_path)` draws (default: a run's PNG, `cosim.logs.plot.draw`)."""
        if not sys.platform.startswith("linux"):
            return None
        try:
            data_read, data_write = os.pipe()
            reply_read, reply_write = os.pipe()
        except OSError:
            return None
        for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
            stream.flush()
        try:
            pid = os.fork()
        except OSError:
            for fd in (data_read, data_write, reply_read, reply_write):
                os.close(fd)
            return None
        if pid == 0:
            os.close(data_write)
            os.close(reply_read)
            _child(data_read, reply_write, drawer)  # never returns
        os.close(data_read)
        os.close(reply_write)
        return cls(pid, data_write, reply_read, drawer)

    def __init__(self, pid: int, data_write: int, reply_read: int, drawer=None) -> None:
        self.pid = pid
        self._drawer = drawer
        self.exit_status: int | None = None  # the child's, once reaped (negative: killed by a signal)
        self._data = data_write
        self._reply = reply_read

    def draw(self, data, png_path: Path) -> str | None:
        """Have the child draw `data` (a `cosim.logs.plot.PlotData`) to `png_path`; None when it
        did, else why not. A child that died without answering is drawn for in this process."""
        payload = pickle.dumps((data, str(png_path)), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            with os.fdopen(self._data, "wb") as pipe:
                self._data = None
                pipe.write(payload)
            with os.fdopen(self._reply, "rb") as pipe:
                self._reply = None
                answer = pipe.read().decode(errors="replace")
        except OSError:
            answer = ""
        except BaseException:  # interrupted while it draws: it is ended before the caller cleans up
            self._kill()
            self._reap()
            raise
        self._reap()
        if answer == "ok":
            return None
        if answer.startswith("no plot: "):
            return answer.removeprefix("no plot: ")
        from cosim.logs.plot import draw  # the child failed: the parent draws

        (self._drawer or draw)(data, png_path)
        return None

    def cancel(self) -> None:
        """No plot (the run failed, or was refused): the child is ended at once, wherever its
        preparation is (it has written nothing), so an error exits without waiting for it."""
        if self._data is not None:
            self._kill()
        self._reap()

    def _kill(self) -> None:
        if self.pid:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def _reap(self) -> None:
        for fd in (self._data, self._reply):
            if fd is not None:
                os.close(fd)
        self._data = self._reply = None
        if self.pid:
            try:
                self.exit_status = os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])
            except ChildProcessError:
                pass
            self.pid = 0


def _child(data_read: int, reply_write: int, drawer=None) -> None:
    answer = "failed"
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        from cosim.logs.plot import draw, prepare_drawing

        prepare_drawing()
        with os.fdopen(data_read, "rb") as pipe:
            payload = pipe.read()
        if not payload:
            os._exit(0)
        data, png_path = pickle.loads(payload)
        (drawer or draw)(data, Path(png_path))
        answer = "ok"
    except OSError as error:
        answer = f"no plot: {error}"
    except Exception as error:
        from cosim.errors import CosimError

        answer = f"no plot: {error}" if isinstance(error, CosimError) else f"failed: {error!r}"
    finally:
        try:
            os.write(reply_write, answer.encode()[:4000])
        finally:
            os._exit(0)
