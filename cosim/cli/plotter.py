"""The PNG of `cosim run`, drawn by a child process that prepares while the run goes.

Importing matplotlib and loading its font (`cosim.logs.plot.prepare_drawing`, ~0.15 s of CPU)
does not depend on the run, so `cosim run` forks a child for it as soon as it knows it will plot,
before it loads the scenario and builds the run (`PlotProcess.start` with `outline_follows`; the
scenario follows, `PlotProcess.outline`): on a machine with a free core it is done by the time the
run ends. The child then drafts the figure from the scenario (`preview`: the map as the run will
log it, the view, the panels; `cosim.logs.plot.Draft` draws the map frame), forks a helper
(`PanelHelper`) that holds a copy of that draft and lays out the panels' likely texts, and lays
out the texts the legend most likely holds (`_warm`) meanwhile. The run's
trace (`cosim.logs.plot.trace_parts`: arrays, a few MB at most; or a `PlotData` where there is
no trace) then goes to the child through a pipe and on to the helper, which gather the data from
it themselves; the helper draws the panels while the child draws the run over the map, the legend
and the title and makes the PNG's rows of them in memory the two share; the helper copies its
panels into those rows, each of the two compresses a half of them, and the child writes the PNG
and answers with one NUL-ended text; the parent waits for it (not for the child's exit: it is
reaped if it has ended, else by the system). Whatever does not fit the draft, or a
helper that failed, is drawn afresh by the child (`cosim.logs.plot.draw`): always the same
picture. The child ignores SIGINT and SIGTERM (the parent decides), leaves with `os._exit` (no
clean-up of the parent's objects it shares), and gives up when the pipe closes without data (the
parent died: the helper then sees its own pipe close); a parent that will not plot ends it
(`cancel`). Only where `os.fork` is safe and
cheap (Linux), and only in `cosim` itself, never in a process that calls `cosim.cli.main([...])`.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import signal
import struct
import sys
from pathlib import Path
from types import SimpleNamespace


class PlotProcess:
    """A forked child that has imported matplotlib and waits for the data of one plot."""

    @classmethod
    def start(cls, scenario=None, drawer=None, outline_follows: bool = False) -> PlotProcess | None:
        """The child, or None where there is none (no fork, or it failed): then draw in-process.
        Given the run's `scenario` (`cosim.scenario.load.Scenario`), the child also drafts the
        figure while the run goes (`draft`). With `outline_follows`, the scenario comes later
        (`outline`): `cosim run` forks before it has loaded it, so that importing matplotlib
        starts ~0.1 s sooner. `drawer(data, png_path)`: another picture than a run's PNG
        (sweep.png's `cosim.sweep.plot.draw_png`), drawn from one frame, without a draft."""
        if not sys.platform.startswith("linux"):
            return None
        _reap_ended()
        for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
            stream.flush()
        forked = _fork_with_pipes()
        if forked is None:
            return None
        pid, (data_read, data_write), (reply_read, reply_write) = forked
        if pid == 0:
            os.close(data_write)
            os.close(reply_read)
            _own_group()
            _child(data_read, reply_write, _FOLLOWS if outline_follows else scenario, drawer)  # never returns
        _own_group(pid)  # here too: whichever runs first, the group exists when `_kill` ends it
        os.close(data_read)
        os.close(reply_write)
        process = cls(pid, data_write, reply_read, drawer)
        process._outline_due = outline_follows
        return process

    def __init__(self, pid: int, data_write: int, reply_read: int, drawer=None) -> None:
        self.pid = pid
        self._drawer = drawer
        self._outline_due = False  # started with `outline_follows`, and not sent it yet
        self.exit_status: int | None = None  # the child's, once reaped (negative: killed by a signal)
        self._data = data_write
        self._reply = reply_read

    def outline(self, scenario) -> None:
        """Send the run's `scenario` to a child started with `outline_follows`: what `preview`
        reads of it (`_outline`), from which the child drafts the figure once matplotlib is
        imported. None: no draft (the data is drawn afresh)."""
        if self._data is None or not self._outline_due:
            return
        self._outline_due = False
        payload = pickle.dumps(scenario and _outline(scenario), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            _write_all(self._data, struct.pack(">Q", len(payload)) + payload)
        except OSError:  # (the child is gone: `draw_source` finds it so and draws here)
            pass

    def ready(self) -> bool:
        """Whether the child is ready for a run's trace (`READY`), or has answered (or ended)."""
        return self._reply is not None and _readable(self._reply)

    def draw(self, data, png_path: Path) -> str | None:
        """Have the child draw `data` (a `cosim.logs.plot.PlotData`) to `png_path`; None when it
        did, else why not. A child that died without answering is drawn for in this process."""
        return self.draw_source(None, png_path, data)

    def draw_source(self, source, png_path: Path, data=None) -> str | None:
        """As `draw`, of the data `cosim.logs.plot.collect` gathers from `source` (a log or a
        `TraceSource`): the panels' part (`collect_signals`) is sent first, so that they are drawn
        while this process gathers the map's (`collect_map`: the plans, ~10 ms)."""
        from cosim.logs.plot import TraceSource, collect, collect_map, collect_signals, trace_parts

        # a run's trace goes as it is, in two parts, to a plot process ready for it (`READY`): it
        # gathers the data (`_plot_data`)
        traced = data is None and self._drawer is None and isinstance(source, TraceSource) and self.ready()
        if traced:
            parts = trace_parts(source.trace)
        elif data is None:
            data = collect_signals(source)
        mapped = source is None
        self.outline(None)  # (a child waiting for the scenario gets none: no draft)
        try:
            with os.fdopen(self._data, "wb") as pipe:
                self._data = None
                if self._drawer is not None:  # another picture: one frame
                    _send(pipe, (data, str(png_path)))
                elif traced:
                    _send(pipe, parts[0])
                    _send(pipe, (parts[1], str(png_path)))
                else:
                    _send(pipe, _panels_part(data))
                    if not mapped:
                        collect_map(data, source)
                        mapped = True
                    _send(pipe, (dataclasses.replace(data, series=[], modes=None), str(png_path)))
            with os.fdopen(self._reply, "rb") as pipe:
                self._reply = None
                answer, whole = _answer(pipe)
        except OSError:
            answer, whole = "", False
        except BaseException:  # interrupted while it draws: it is ended before the caller cleans up
            self._kill()
            self._reap()
            raise
        self._reap(wait=not whole)  # a child that answered ends by itself: its exit is not waited for
        if answer == "ok":
            return None
        if answer.startswith("no plot: "):
            return answer.removeprefix("no plot: ")
        from cosim.logs.plot import draw  # the child failed: the parent draws

        if self._drawer is not None:
            self._drawer(data, png_path)
            return None
        if traced:
            data, mapped = collect(source), True
        if not mapped:
            collect_map(data, source)
        draw(data, png_path)
        return None

    def cancel(self) -> None:
        """No plot (the run failed, or was refused): the child is ended at once, wherever its
        preparation is (it has written nothing), so an error exits without waiting for it."""
        if self._data is not None:
            self._kill()
        self._reap()

    def _kill(self) -> None:
        """End the child and its helper at once: they are the child's process group."""
        if self.pid:
            try:
                os.killpg(self.pid, signal.SIGKILL)
            except OSError:  # no such group (it could not be made): the child alone
                try:
                    os.kill(self.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass

    def _reap(self, wait: bool = True) -> None:
        """Close the pipes and reap the child; without `wait`, only if it has ended already (one
        that answered: it only exits, ~4 ms of freeing its memory, and the system reaps it once
        this process ends; `exit_status` then stays None)."""
        _close(self._data, self._reply)
        self._data = self._reply = None
        if self.pid:
            ended, self.exit_status = _reap_child(self.pid, wait)
            if not ended:
                _ENDING.append(self.pid)
            self.pid = 0


# Plot processes that answered but had not ended when their `PlotProcess` was done: reaped by the
# next `PlotProcess.start` of this process (a script or notebook that plots run after run keeps at
# most one such zombie, not one per run), or by the system once this process ends.
_ENDING: list[int] = []


def _reap_ended() -> None:
    for pid in list(_ENDING):
        if _reap_child(pid, wait=False)[0]:
            _ENDING.remove(pid)


def _fork_with_pipes() -> tuple[int, tuple[int, int], tuple[int, int]] | None:
    """Fork, with two new pipes both processes hold all ends of: (pid as `os.fork` gives it, the
    data pipe (read, write), made to hold a run's data at once, the answer pipe (read, write)), or
    None where a pipe or the fork cannot be made (nothing is left open)."""
    pipes: list[tuple[int, int]] = []
    try:
        pipes.append(os.pipe())
        pipes.append(os.pipe())
        _widen(pipes[0][1])
        pid = os.fork()
    except OSError:
        _close(*(fd for pipe in pipes for fd in pipe))
        return None
    return pid, pipes[0], pipes[1]


def _close(*fds: int | None) -> None:
    for fd in fds:
        if fd is not None:
            os.close(fd)


def _reap_child(pid: int, wait: bool = True) -> tuple[bool, int | None]:
    """Reap the child `pid`, waiting for it or only if it has ended: (whether it has ended, its exit
    code, None where it had been reaped already or has not ended)."""
    try:
        reaped, status = os.waitpid(pid, 0 if wait else os.WNOHANG)
    except ChildProcessError:
        return True, None
    return (True, os.waitstatus_to_exitcode(status)) if reaped else (False, None)


def _widen(pipe: int) -> None:
    """Make `pipe` hold a run's plot data (~0.6 MB) at once where Linux lets it (1 MB): the
    writer then sends it without waiting for the reader to take each 64 kB, a few ms of going
    back and forth between the two processes right after the run."""
    import fcntl

    try:
        fcntl.fcntl(pipe, getattr(fcntl, "F_SETPIPE_SZ", 1031), 1 << 20)
    except OSError:  # (a smaller limit: the pipe stays as it is)
        pass


def _own_group(pid: int = 0) -> None:
    """Make the plot process (`pid`, 0: this one) the leader of its own process group, which its
    helper joins, so that `PlotProcess._kill` ends both at once. It ignores the signals of the
    terminal's group anyway (the parent decides)."""
    try:
        os.setpgid(pid, 0)
    except OSError:  # (the child already runs in its group, or is gone)
        pass


def _write_all(fd: int, payload: bytes) -> None:
    view = memoryview(payload)
    while view:
        view = view[os.write(fd, view) :]


def _send(pipe, value) -> None:
    """One frame of the pipe to the plot process: its length (8 bytes) and `value` pickled."""
    payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    pipe.write(struct.pack(">Q", len(payload)) + payload)
    pipe.flush()


def _answer(pipe) -> tuple[str, bool]:
    """The plot process's answer (its text, ended by a NUL byte) and whether it was whole: read up
    to that byte, not to the pipe's end, which comes only once the process has exited."""
    answer = b""
    while b"\0" not in answer:
        more = pipe.read1(4096)
        if not more:
            return answer.lstrip(READY).decode(errors="replace"), False
        answer += more
    return answer.partition(b"\0")[0].lstrip(READY).decode(errors="replace"), True


def _frame(pipe) -> bytes:
    """The next frame's pickled bytes (`_send`), or b"" at the end of the pipe."""
    head = pipe.read(8)
    if len(head) < 8:
        return b""
    return pipe.read(struct.unpack(">Q", head)[0])


def _frame_from(fd: int) -> bytes:
    """As `_frame`, read from the descriptor `fd` itself (the pipe's later frames are read through
    a buffered file over it: nothing of them is read here)."""

    def read(count: int) -> bytes:
        parts = []
        while count:
            part = os.read(fd, count)
            if not part:
                return b""
            parts.append(part)
            count -= len(part)
        return b"".join(parts)

    head = read(8)
    return read(struct.unpack(">Q", head)[0]) if len(head) == 8 else b""


_FOLLOWS = object()  # the child's scenario: not known yet, sent by `PlotProcess.outline`


def _outline(scenario) -> SimpleNamespace:
    """What `preview` reads of `scenario`, as plain values: the plot process unpickles it without
    importing the scenario's own modules (`cosim.scenario`, ~25 ms there)."""
    return SimpleNamespace(
        source=scenario.source,
        name=scenario.name,
        map_file=scenario.map_file,
        map_resolution=scenario.map_resolution,
        map_origin=scenario.map_origin,
        start=tuple(scenario.start),
        goal=tuple(scenario.goal),
        planner=SimpleNamespace(expansion_distance=scenario.planner.expansion_distance),
        vehicle_type=scenario.vehicle_type,
        components=list(scenario.components),
    )


def _panels_part(data):
    """What the panels of `data` (a `PlotData`) need: the series, the mixer's modes, the avoider."""
    return type(data)("", series=data.series, modes=data.modes, avoider=data.avoider)


def _child(data_read: int, reply_write: int, scenario, drawer=None) -> None:
    answer = "failed"
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        from cosim.logs.plot import likely_texts, prepare_drawing

        prepare_drawing()
        if scenario is _FOLLOWS:  # (the parent sends it once loaded: `PlotProcess.outline`)
            outline = _frame_from(data_read)
            if not outline:
                os._exit(0)
            scenario = pickle.loads(outline)
        if scenario is not None and _run_ended(data_read):
            scenario = None  # drawn afresh
        drafted = None if scenario is None else draft(scenario)
        if drafted is not None and not _readable(data_read):
            _trace_reader()  # (before the helper's fork: it has it too)
            os.write(reply_write, READY)  # the run's trace is welcome: `PlotProcess.draw_source`
        helper = None
        if drafted is not None and range(drafted.rows)[LOWER] and _free_core():
            # forked first: the panels are the longer part after the run, their texts laid out first
            helper = PanelHelper.start(drafted, (data_read, reply_write))
            _warm(likely_texts(True), data_read)
            if helper is not None:
                _own_pages(drafted.pixels(), lambda: _readable(data_read))
                helper.own_rows(lambda: _readable(data_read))
        elif drafted is not None:  # it draws both parts, on a busy machine: the longest texts only
            _warm(likely_texts(True) + likely_texts(False, numbers=False), data_read)
            drafted.more_ticks(lambda: _readable(data_read))
        with os.fdopen(data_read, "rb") as pipe:
            panels = _frame(pipe)
            if not panels:
                os._exit(0)
            if drawer is None:
                if helper is not None:
                    helper.draw(panels)  # it draws the panels while the map's part comes
                mapped = _frame(pipe)
        if drawer is not None:  # another picture, in one frame: (data, png_path)
            data, png_path = pickle.loads(panels)
            drawer(data, Path(png_path))
        else:
            if not mapped:
                os._exit(0)
            _draw_run(pickle.loads(panels), pickle.loads(mapped), drafted, helper)
        answer = "ok"
    except OSError as error:
        answer = f"no plot: {error}"
    except Exception as error:
        from cosim.errors import CosimError

        answer = f"no plot: {error}" if isinstance(error, CosimError) else f"failed: {error!r}"
    finally:
        try:
            os.write(reply_write, answer.encode()[:4000] + b"\0")
            _keep_text()  # (answered: the parent does not wait for it)
        finally:
            os._exit(0)


def _keep_text() -> None:
    """Add the texts this process laid out to those kept for the next one (`cosim.logs.kept_text`),
    where it imported that (it drew): it leaves with `os._exit`, without the exit handler."""
    kept_text = sys.modules.get("cosim.logs.kept_text")
    if kept_text is not None:
        try:
            kept_text.keep()
        except Exception:  # noqa: BLE001 (not kept: laid out again next time)
            pass


def _draw_run(panels, mapped, drafted, helper) -> None:
    """The run's PNG from its two frames (`PlotProcess.draw_source`): over the draft where it fits
    (its panels by the helper, if any), else afresh."""
    from cosim.logs.plot import draw

    data, png_path = mapped
    data = _plot_data(panels, data)
    if drafted is None or not drafted.fits(data):
        if helper is not None:
            helper.cancel()
        draw(data, Path(png_path))
    elif helper is None:
        drafted.finish(data, Path(png_path))
    else:
        from cosim.logs.plot import png_rows

        drafted.draw_run(data, panels=TOP)
        # the PNG's rows made of this part, in the memory shared with the helper, which then
        # copies its panels into them and compresses their second half while this process
        # compresses the first (`PanelHelper.last_half`)
        png_rows(drafted.pixels(), into=helper.rows)
        helper.rows_made()
        pasted = helper.paste(drafted)
        if pasted:
            drafted.write(Path(png_path), helper.rows, helper.last_half)
            helper.leave()  # it ends after this process (its exit not waited for)
        else:  # the helper failed, or the two parts overlap: drawn afresh
            helper.cancel()
            draw(data, Path(png_path))


def _plot_data(panels, mapped=None):
    """The run's `PlotData` from the parts `PlotProcess.draw_source` sent: the panels' `PlotData`
    (`_panels_part`) and the rest of it (`mapped`), or the two parts of its trace
    (`cosim.logs.plot.trace_parts`), gathered here as the parent would have; without `mapped`,
    what the panels need only."""
    from cosim.logs.plot import TraceSource, collect, collect_signals, joined_trace
    from cosim.logs.plot_data import PlotData

    if isinstance(panels, PlotData):
        return (
            panels
            if mapped is None
            else dataclasses.replace(mapped, series=panels.series, modes=panels.modes)
        )
    if mapped is None:
        return collect_signals(TraceSource(joined_trace(panels)))
    return collect(TraceSource(joined_trace(panels, mapped)))


def _trace_reader() -> None:
    """Import what gathers the data from a run's trace (`_plot_data`: `cosim.logs.reader`, ~6 ms),
    once the draft is made (not before: the draft is the longer wait), while the run goes."""
    import cosim.logs.reader  # noqa: F401


# The plot process's first byte on its answer pipe, before the answer, once it is ready for the
# run's trace (`_child`: drafted, the log reader imported): then the parent sends the trace's parts
# and the plot process gathers the data; before, the parent gathers it itself (while the plot
# process still drafts, a busy machine) and sends the `PlotData`.
READY = b"\x01"


def _touch(shared) -> None:
    """Read a byte of each page of `shared` (memory shared with the helper): each page is mapped
    into this process then (~1 ms for the picture), not while the helper's pixels are copied."""
    import mmap

    int(shared.reshape(-1)[:: mmap.PAGESIZE].sum())


def _own_pages(pixels, stop=lambda: False) -> None:
    """Write each page of `pixels` (the canvas) with the bytes it holds, a few hundred at a time
    until `stop()` is true (asked before each). After the helper's fork the two processes share
    the canvas' pages until one writes to a page, which is then copied for it (~2.6 us a page
    here, ~1700 pages): done while the run goes, not page by page as the run's picture is drawn
    over them (the helper's panels ~4 ms, the map ~2 ms)."""
    import mmap

    import numpy as np

    flat = pixels.reshape(-1)
    every = np.concatenate((np.arange(0, flat.size, mmap.PAGESIZE), [flat.size - 1]))
    for start in range(0, every.size, 256):
        if stop():
            return
        at = every[start : start + 256]
        flat[at] = flat[at]  # (fancy indexing: a copy is read, then written back)


def _warm(texts: list, data_read: int) -> None:
    """Lay out `texts` (`cosim.logs.plot.likely_texts`) while the run goes, until its data is
    there to read on `data_read`: done ahead, laying out is a third of what drawing them costs
    after the run. All of them with a core to spare for it (the run keeps the other), else a few
    (~15 ms, beside the ~0.2 s of importing matplotlib)."""
    from cosim.logs.plot import warm_text

    warm_text(texts, lambda: _readable(data_read))


def _run_ended(data_read: int) -> bool:
    """Whether the run's data is there already (on `data_read`) once matplotlib is ready (a busy
    machine): then its picture is drawn afresh at once, ~10% less work than drafting it and
    finishing the draft."""
    return _readable(data_read)


def _readable(fd: int) -> bool:
    """Whether there is something to read on `fd` (or it is closed, or not a descriptor)."""
    import select

    try:
        return bool(select.select([fd], [], [], 0)[0])
    except (OSError, ValueError):
        return True


def _free_core() -> bool:
    """Whether the machine seems to have a core to spare for the helper (the load average of the
    last minute below the number of cores this process may use): on a busy machine the helper's
    fork and copy would only add their CPU time."""
    try:
        cores = len(os.sched_getaffinity(0))
        return cores >= 2 and os.getloadavg()[0] < cores
    except (AttributeError, OSError):
        return False


# The plot process draws the map, its legend and the title (~45 ms of CPU here), its helper the
# panels (~72 ms). Moving a panel to the plot process does not shorten the longer of the two: each
# process that draws a panel makes every panel's artists (they share the time axis's limits).
TOP, LOWER = slice(0, 0), slice(0, None)


class PanelHelper:
    """A fork of the plot process, made once its draft is ready, that draws the panels of the
    run's figure (`LOWER`) while the plot process draws the map, the legend and the title (`TOP`:
    no panel; `cosim.logs.plot.Draft.draw_run`: the two parts of the picture do not overlap, which
    `paste` checks). It gets the run's data as the plot process got it; once the plot process has
    made the PNG's rows of its part (`rows`, memory the two share: `rows_made`), the helper copies
    its panels into them, gives back their box, and compresses the rows' second half while the
    plot process compresses the first (`last_half`). It ends when its pipe closes without data
    (the plot process ended)."""

    @classmethod
    def start(cls, drafted, inherited: tuple[int, ...]) -> PanelHelper | None:
        """The helper of `drafted`, or None (no fork); `inherited`: the plot process's own pipe
        ends, closed in the helper."""
        import mmap

        import numpy as np

        height, width = drafted.pixels().shape[:2]
        try:
            shared = mmap.mmap(-1, height * (1 + 3 * width))
        except OSError:
            return None
        rows = np.frombuffer(shared, dtype=np.uint8).reshape(height, 1 + 3 * width)
        forked = _fork_with_pipes()
        if forked is None:
            return None
        pid, (data_read, data_write), (done_read, done_write) = forked
        if pid == 0:
            for fd in (data_write, done_read, *inherited):
                os.close(fd)
            _panels(drafted, data_read, done_write, rows)  # never returns
        os.close(data_read)
        os.close(done_write)
        return cls(pid, data_write, done_read, rows)

    def __init__(self, pid: int, data_write: int, done_read: int, rows) -> None:
        self.pid = pid
        self._data = data_write
        self._done = done_read
        self._answers = None  # the answer pipe, read as a file once `paste` waits
        self.rows = rows  # the PNG's rows (`cosim.logs.plot.png_rows`), shared with the helper

    def draw(self, payload: bytes) -> None:
        """Have the helper draw the panels of `payload` (the panels' part of the data, pickled, as
        the plot process got it); a helper that is gone answers nothing (`paste`)."""
        try:
            _write_all(self._data, struct.pack(">Q", len(payload)) + payload)
        except OSError:
            pass

    def own_rows(self, stop=lambda: False) -> None:
        """Write each page of `rows` ahead (zeros: `rows_made` fills them), until `stop()` is true:
        each page is made for both processes then (~1300), not while the rows are made. Only
        this process writes to them before `rows_made`."""
        import mmap

        flat = self.rows.reshape(-1)
        for start in range(0, flat.size, 256 * mmap.PAGESIZE):
            if stop():
                return
            flat[start : start + 256 * mmap.PAGESIZE : mmap.PAGESIZE] = 0

    def rows_made(self) -> None:
        """Tell the helper the PNG's rows of this part are in `rows`: it copies its panels into
        them (none of its pixels are there before)."""
        try:
            _write_all(self._data, b"r")
        except OSError:
            pass

    def leave(self) -> None:
        """Leave the helper, which has answered, to end once this process has ended (its pipe
        closes then): freeing its memory (a few ms of a core) then takes no core from this
        process' last steps, nor from the parent's once it has the answer."""
        if self._answers is not None:
            self._answers.close()
            self._answers = self._done = None
        self._data = None  # (left open: closed as this process ends)
        self.pid = 0

    def paste(self, drafted) -> bool:
        """Wait for the helper to have copied its panels into `rows`, and check that their box
        does not overlap what `drafted`'s part drew (`map_boxes`); whether it does not (else, or
        when the helper failed, the rows are not the picture)."""
        # what it drew, while the helper still draws
        boxes = drafted.map_boxes() + ([drafted.panels_box(TOP)] if range(drafted.rows)[TOP] else [])
        self._answers = os.fdopen(self._done, "rb")
        answer = self._answers.readline().decode(errors="replace").split()  # (not waiting for its exit)
        if len(answer) != 4:
            return False
        top, bottom, left, right = (int(value) for value in answer)
        for above, below, west, east in boxes:
            if top < below and above < bottom and left < east and west < right:
                return False
        return True

    def last_half(self) -> tuple[bytes, int] | None:
        """The second half of `rows` compressed by the helper (`cosim.logs.plot.deflate_half`:
        the stream and its checksum), once it has pasted; None if it failed to."""
        try:
            head = self._answers.readline().split()
            if len(head) != 2:
                return None
            length, checksum = (int(value) for value in head)
            body = self._answers.read(length)
        except (OSError, ValueError):
            return None
        return (body, checksum) if len(body) == length else None

    def cancel(self, wait: bool = True) -> None:
        """No panels wanted (or no more: they were pasted): the helper is ended (killed, wherever
        it is: after its answers it only exits) and reaped; without `wait`, only if it has ended
        already (its exit, a few ms of freeing its memory, is not waited for: the system reaps
        it once the plot process has ended)."""
        if self.pid:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if self._answers is not None:
            self._answers.close()
            self._answers = self._done = None
        _close(self._data, self._done)
        self._data = self._done = None
        if self.pid:
            _reap_child(self.pid, wait)
            self.pid = 0


def _panels(drafted, data_read: int, done_write: int, rows) -> None:
    """The helper (`PanelHelper`): prepares while the run goes, draws the panels of the data that
    comes on `data_read`, waits for the plot process's rows (b"r"), copies its panels into
    `rows`, answers their box on `done_write`, then compresses the second half of the rows and
    sends it ("length checksum\n" and the stream)."""
    answered = False
    try:
        from cosim.logs.plot import copy_rgb, deflate_half, likely_texts, png_halves

        _widen(done_write)  # (the compressed half, ~0.1 MB, written at once)
        _warm(likely_texts(False), data_read)
        _own_pages(drafted.pixels(), lambda: _readable(data_read))
        if not _readable(data_read):  # the shared pages mapped here too (read only: the plot
            _touch(rows)  # process writes them first), while the run goes
        drafted.more_ticks(lambda: _readable(data_read))
        pipe = os.fdopen(data_read, "rb")
        payload = _frame(pipe)
        if not payload:
            return
        drafted.draw_run(_plot_data(pickle.loads(payload)), False, LOWER)
        top, bottom, left, right = drafted.panels_box(LOWER)
        if pipe.read(1) != b"r":  # (the plot process draws afresh, or ended)
            return
        copy_rgb(rows[top:bottom, 1 + 3 * left : 1 + 3 * right], drafted.pixels()[top:bottom, left:right])
        _write_all(done_write, f"{top} {bottom} {left} {right}\n".encode())
        answered = True
        low, high = png_halves(len(rows))[1]
        body, checksum = deflate_half(rows[low:high], True)
        _write_all(done_write, f"{len(body)} {checksum}\n".encode() + body)
        _keep_text()  # (its part sent: the picture does not wait for it)
        pipe.read(1)  # until the plot process has ended (`PanelHelper.leave`), or kills this one
    except Exception:  # noqa: BLE001 (no answer: the plot process draws the panels itself)
        if not answered:
            try:
                os.write(done_write, b"\n")
            except OSError:
                pass
    finally:
        os._exit(0)


def draft(scenario):
    """The run's figure drafted from `preview(scenario)` (`cosim.logs.plot.Draft`), or None when
    that fails (the run's data is then drawn afresh: a draft is only ever a head start)."""
    from cosim.logs.plot import Draft

    try:
        return Draft(preview(scenario))
    except Exception:  # noqa: BLE001 (a scenario the guess does not cover: no draft, the same plot)
        return None


def preview(scenario):
    """What the plot of a run of `scenario` shows that is known before the run, as a
    `cosim.logs.plot.PlotData`: the map as the run logs it (the scenario's map, inflated by the
    planner's expansion distance; the resolution rounded to float32 as in the log), the view that
    shows it and the start and goal, a two-line title and, without data, the panels the default
    series of its components fill (speed and turning for a vehicle or mixer, the directions for
    pure pursuit or VFH, the lidar's minimum range, the distance to the goal). `Draft.fits` checks
    it against the run's own data."""
    import numpy as np

    from cosim.logs.plot import _extent, map_image, view_limits
    from cosim.logs.plot_data import PlotData, Series
    from cosim.world.distance import load_known_map
    from planner.grid import OccupancyGrid

    grid = load_known_map(scenario)
    expansion = scenario.planner.expansion_distance
    inflated = grid.inflate(expansion) if expansion > 0 else grid
    resolution = float(f"{float(np.float32(grid.resolution)):.7g}")
    logged = OccupancyGrid(grid.occupied, resolution, (float(grid.origin[0]), float(grid.origin[1])))
    extent = _extent(logged)
    x0, x1, y0, y1 = extent
    bounds = [np.array([[x0, y0], [x1, y1]]), np.array([scenario.start[:2]]), np.array([scenario.goal])]
    components = set(scenario.components)
    panels = []
    if components & {"vehicle", "mixer"}:
        turning = "rad" if scenario.vehicle_type == "bicycle" else "rad/s"
        panels += [("speed", "m/s"), ("turning", turning)]
    if components & {"pure_pursuit", "vfh"}:
        panels.append(("direction", "rad"))
    panels += [("range", "m"), ("goal", "m")]
    empty = np.zeros(0)
    return PlotData(
        f"{scenario.name}\n",
        image=map_image(logged, inflated),
        extent=extent,
        has_zone=inflated.shape == grid.shape,
        limits=view_limits(bounds),
        series=[Series(panel, unit, empty, empty, panel) for panel, unit in panels],
    )
