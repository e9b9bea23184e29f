"""`cosim run` draws its PNG in a child forked before the run (`cosim.cli.plotter`): the same pixels
as drawn in-process, its problems reported as the in-process drawing reports them, and no child
left behind whatever happens."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.cli.plotter import PlotProcess
from cosim.logs import plot

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "scenarios" / "example_commented.toml"
SHORT = ["--set", "simulation.stop_time=3"]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the child is forked on Linux")


@pytest.fixture(scope="module")
def cosim_run(tmp_path_factory):
    """`cosim run` as a user runs it (the program: the child draws), and its log."""
    log = tmp_path_factory.mktemp("plotter") / "run.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(EXAMPLE), "--out", str(log), *SHORT],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert completed.returncode in (0, 1), completed.stderr
    assert "Traceback" not in completed.stderr and "note" not in completed.stderr, completed.stderr
    assert f"plot: {log.with_suffix('.png')}" in completed.stdout
    return log


def _data(log: Path) -> plot.PlotData:
    from cosim.logs.reader import open_log

    with open_log(log) as opened:
        return plot.collect(opened)


def _ends_by_itself(pid: int) -> bool:
    """A child that answered exits by itself, not waited for by `PlotProcess` (it may still be
    freeing its memory): whether it ends, with status 0 (reaped here), or was reaped already."""
    try:
        return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0
    except ChildProcessError:
        return True


def _not_running(pid: int) -> bool:
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True  # reaped: no zombie either
    return False


@pytest.mark.slow
def test_the_child_draws_what_this_process_draws(cosim_run, tmp_path: Path):
    png = cosim_run.with_suffix(".png")
    assert not list(cosim_run.parent.glob(".*.png"))  # the partial file was renamed into place
    here = plot.plot_run(cosim_run, tmp_path / "here.png")
    assert png.read_bytes() == here.read_bytes()


@pytest.mark.slow
def test_a_plot_process_draws_and_is_gone(cosim_run, tmp_path: Path):
    process = PlotProcess.start()
    pid = process.pid
    png = tmp_path / "deep" / "x.png"
    assert process.draw(_data(cosim_run), png) is None
    assert png.read_bytes() == plot.plot_run(cosim_run, tmp_path / "y.png").read_bytes()
    assert _ends_by_itself(pid)


@pytest.mark.slow
def test_a_plot_process_that_ended_unwaited_is_reaped_by_the_next_start(cosim_run, tmp_path: Path):
    """A script that plots run after run keeps no zombie per run: the next `PlotProcess.start`
    reaps the one the last draw did not wait for."""
    from cosim.cli import plotter

    process = PlotProcess.start()
    pid = process.pid
    assert process.draw(_data(cosim_run), tmp_path / "x.png") is None
    assert pid in plotter._ENDING or _not_running(pid)  # left to end by itself, or ended already
    deadline = time.monotonic() + 60
    while Path(f"/proc/{pid}").exists() and _state(pid) != "Z" and time.monotonic() < deadline:
        time.sleep(0.01)  # until it has exited (a zombie until someone reaps it)
    following = PlotProcess.start()
    following.cancel()
    assert pid not in plotter._ENDING
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # reaped: not ours to wait for any more


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return ""


@pytest.mark.slow
def test_a_problem_of_the_child_is_its_answer(cosim_run, tmp_path: Path):
    (tmp_path / "file").write_text("not a folder")
    data, png = _data(cosim_run), tmp_path / "file" / "x.png"
    with pytest.raises(OSError) as here:
        plot.draw(data, png)
    process = PlotProcess.start()
    pid = process.pid
    assert process.draw(data, png) == str(here.value)
    assert _ends_by_itself(pid)


def test_a_cancelled_child_is_ended_at_once(tmp_path: Path):
    process = PlotProcess.start()
    pid = process.pid
    process.cancel()
    assert process.exit_status == -signal.SIGKILL  # not left to finish importing matplotlib
    assert _not_running(pid)
    process.cancel()  # twice: nothing left to do


@pytest.mark.slow
def test_a_run_that_fails_to_build_leaves_no_child(tmp_path: Path):
    log = tmp_path / "refused.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(EXAMPLE), "--out", str(log), "--quiet"]
        + ["--set", "goal.x=0.1", "--set", "goal.y=0.1"],
        capture_output=True,
        text=True,
    )
    assert completed.returncode == 2, completed.stderr
    assert "inside an obstacle" in completed.stderr and "Traceback" not in completed.stderr
    assert not log.exists() and not log.with_suffix(".png").exists()
    assert _processes_naming(str(log)) == []


@pytest.mark.slow
def test_a_child_that_fails_is_drawn_for_here(cosim_run, tmp_path: Path, monkeypatch):
    parent = os.getpid()
    draw = plot.draw

    def draw_here_only(data, png_path, *options):  # options: dpi, size
        if os.getpid() != parent:
            raise RuntimeError("a bug in the child")
        return draw(data, png_path, *options)

    monkeypatch.setattr(plot, "draw", draw_here_only)
    process = PlotProcess.start()
    assert process.draw(_data(cosim_run), tmp_path / "x.png") is None
    assert (tmp_path / "x.png").read_bytes() == plot.plot_run(cosim_run, tmp_path / "y.png").read_bytes()


def _processes_naming(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and text in (entry / "cmdline").read_bytes().decode(errors="replace"):
                found.append(int(entry.name))
        except OSError:
            pass
    return found


@pytest.mark.slow
@pytest.mark.parametrize("signal_number", [signal.SIGINT, signal.SIGTERM])
def test_a_signalled_run_leaves_no_child(signal_number, tmp_path: Path):
    """SIGINT/SIGTERM to the whole process group (a terminal's Ctrl-C, `timeout`): the child ignores
    them, the run ends "interrupted" and still plots (as without the child), and no process is left."""
    log = tmp_path / "interrupted.mcap"
    command = [sys.executable, "-m", "cosim", "run", str(EXAMPLE), "--out", str(log), "--quiet"]
    process = subprocess.Popen(
        [*command, "--set", "simulation.macro_step=0.0001"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    while not log.exists() and process.poll() is None:
        time.sleep(0.1)
    assert process.poll() is None, process.communicate()[1]
    time.sleep(0.5)
    os.killpg(process.pid, signal_number)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 1, err
    assert "Traceback" not in err
    assert log.with_suffix(".png").exists()
    assert _processes_naming(str(log)) == []


@pytest.mark.slow
def test_an_interrupt_while_the_child_draws_ends_the_child(cosim_run, tmp_path: Path, monkeypatch):
    """A signal in the parent while it waits for the picture (`cosim.core.interrupt` raises there):
    the child is ended before the exception leaves `draw`, so the caller's clean-up (unlinking the
    partial PNG) is not followed by the child writing it."""
    parent = os.getpid()
    draw = plot.draw

    def slow_in_the_child(data, png_path):
        if os.getpid() != parent:
            time.sleep(60)
        return draw(data, png_path)

    def interrupt(number, frame):
        raise KeyboardInterrupt

    monkeypatch.setattr(plot, "draw", slow_in_the_child)
    process = PlotProcess.start()
    pid = process.pid
    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.5)
        with pytest.raises(KeyboardInterrupt):
            process.draw(_data(cosim_run), tmp_path / "x.png")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert process.exit_status == -signal.SIGKILL
    assert _not_running(pid)
    assert not (tmp_path / "x.png").exists()


def _counting_afresh(monkeypatch, marker: Path) -> None:
    """`plot.draw` in a forked process leaves `marker`: the picture was drawn afresh, not drafted;
    in this process, `marker` with the suffix ".here": the child failed."""
    parent = os.getpid()
    draw = plot.draw

    def counted(data, png_path, *options):
        (marker if os.getpid() != parent else marker.with_suffix(".here")).touch()
        return draw(data, png_path, *options)

    monkeypatch.setattr(plot, "draw", counted)


@pytest.fixture(scope="module")
def traced_run(tmp_path_factory):
    """A run of the same scenario in this process: its in-memory trace and its log."""
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    scenario = load_scenario(EXAMPLE, ["simulation.stop_time=3"])
    result = run_scenario(scenario, tmp_path_factory.mktemp("traced") / "run.mcap")
    assert result.trace is not None and not result.trace.dropped
    return result


@pytest.mark.slow
@pytest.mark.parametrize("helped", [True, False], ids=["helper", "alone"])
@pytest.mark.parametrize("later", [False, True], ids=["given", "sent later"])
def test_a_drafted_picture_is_the_picture_of_the_log(cosim_run, tmp_path: Path, monkeypatch, helped, later):
    """The child drafts from the scenario (given when it starts, or sent once loaded, as `cosim
    run` does), gets the panels' part first and the map's after (`draw_source`), with or without
    its helper: the log's own picture, and not drawn afresh."""
    from cosim.logs.reader import open_log

    with open_log(cosim_run) as log:
        _draw_drafted(log, cosim_run, tmp_path, monkeypatch, helped, later)


@pytest.mark.slow
@pytest.mark.parametrize("helped", [True, False], ids=["helper", "alone"])
def test_a_drafted_picture_of_a_trace_is_the_picture_of_its_log(
    traced_run, tmp_path: Path, monkeypatch, helped
):
    """As `cosim run` draws it: from the run's trace, sent as its two parts (`trace_parts`), of
    which the child and its helper gather the data themselves: the log's own picture."""
    parent = os.getpid()
    gather = plot.collect_signals

    def gathered_here_not(source, *args, **options):
        if isinstance(source, plot.TraceSource):  # (the log's picture is drawn here to compare)
            assert os.getpid() != parent, "the parent gathered the trace's data: the child was not ready"
        return gather(source, *args, **options)

    monkeypatch.setattr(plot, "collect_signals", gathered_here_not)
    source = plot.TraceSource(traced_run.trace)
    _draw_drafted(source, traced_run.log_path, tmp_path, monkeypatch, helped, True, wait_ready=True)


def _draw_drafted(
    source, log: Path, tmp_path: Path, monkeypatch, helped: bool, later: bool, wait_ready: bool = False
) -> None:
    from cosim.cli import plotter
    from cosim.scenario.load import load_scenario

    monkeypatch.setattr(plotter, "_free_core", lambda: helped)
    monkeypatch.setattr(plotter, "_run_ended", lambda data_read: False)  # (however slow this machine)
    _counting_afresh(monkeypatch, tmp_path / "afresh")
    scenario = load_scenario(EXAMPLE, ["simulation.stop_time=3"])
    if later:
        process = PlotProcess.start(outline_follows=True)
        process.outline(scenario)
    else:
        process = PlotProcess.start(scenario)
    pid = process.pid
    waited = time.monotonic()
    while wait_ready and not process.ready() and time.monotonic() - waited < 60:
        time.sleep(0.01)  # (as after a run: the child has drafted while it went)
    assert process.draw_source(source, tmp_path / "x.png") is None
    assert not (tmp_path / "afresh").exists() and not (tmp_path / "afresh.here").exists()
    assert (tmp_path / "x.png").read_bytes() == plot.plot_run(log, tmp_path / "y.png").read_bytes()
    assert _ends_by_itself(pid)


@pytest.mark.slow
def test_a_child_whose_scenario_never_came_draws_afresh(cosim_run, tmp_path: Path, monkeypatch):
    """Started to wait for the scenario (`outline_follows`) and given the data without it: no
    draft, the picture drawn afresh, the log's picture."""
    from cosim.logs.reader import open_log

    _counting_afresh(monkeypatch, tmp_path / "afresh")
    process = PlotProcess.start(outline_follows=True)
    pid = process.pid
    with open_log(cosim_run) as log:
        assert process.draw_source(log, tmp_path / "x.png") is None
    assert (tmp_path / "afresh").exists()
    assert (tmp_path / "x.png").read_bytes() == plot.plot_run(cosim_run, tmp_path / "y.png").read_bytes()
    assert _ends_by_itself(pid)


@pytest.mark.slow
def test_a_child_that_was_ready_after_the_run_draws_afresh(cosim_run, tmp_path: Path, monkeypatch):
    """The run's data came before matplotlib was ready (a busy machine): no draft, drawn afresh
    at once, the log's picture."""
    from cosim.logs.reader import open_log
    from cosim.scenario.load import load_scenario

    prepare = plot.prepare_drawing

    def slowly():  # (in the child) until the parent has sent the data
        time.sleep(1.0)
        prepare()

    monkeypatch.setattr(plot, "prepare_drawing", slowly)
    _counting_afresh(monkeypatch, tmp_path / "afresh")
    process = PlotProcess.start(outline_follows=True)
    process.outline(load_scenario(EXAMPLE, ["simulation.stop_time=3"]))
    with open_log(cosim_run) as log:
        assert process.draw_source(log, tmp_path / "x.png") is None
    assert (tmp_path / "afresh").exists()
    assert (tmp_path / "x.png").read_bytes() == plot.plot_run(cosim_run, tmp_path / "y.png").read_bytes()


def test_a_child_waiting_for_its_scenario_is_ended_at_once():
    """A run that will not plot after all (a fleet, `[output] plot = false`, a failure while
    loading) ends the child that waits for the scenario, wherever it is."""
    process = PlotProcess.start(outline_follows=True)
    pid = process.pid
    process.cancel()
    assert process.exit_status == -signal.SIGKILL
    assert _not_running(pid)


@pytest.mark.slow
def test_a_run_without_plot_in_its_scenario_leaves_no_child(tmp_path: Path):
    """`[output] plot = false`: the child forked before the scenario was read is ended; no PNG."""
    log = tmp_path / "unplotted.mcap"
    completed = subprocess.run(
        [sys.executable, "-m", "cosim", "run", str(EXAMPLE), "--out", str(log), *SHORT]
        + ["--set", "output.plot=false"],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert completed.returncode in (0, 1), completed.stderr
    assert "plot:" not in completed.stdout and "Traceback" not in completed.stderr
    assert log.exists() and not log.with_suffix(".png").exists()
    assert _processes_naming(str(log)) == []


@pytest.mark.slow
def test_a_draft_that_does_not_fit_is_drawn_afresh(cosim_run, tmp_path: Path, monkeypatch):
    """A scenario whose map frame is not the run's (another inflation: another map image): the
    helper's panels are not used, the picture is drawn afresh, and it is the log's picture."""
    from cosim.cli import plotter
    from cosim.logs.reader import open_log
    from cosim.scenario.load import load_scenario

    monkeypatch.setattr(plotter, "_free_core", lambda: True)
    _counting_afresh(monkeypatch, tmp_path / "afresh")
    other = load_scenario(EXAMPLE, ["simulation.stop_time=3", "planner.expansion_distance=0.5"])
    process = PlotProcess.start(other)
    with open_log(cosim_run) as log:
        assert process.draw_source(log, tmp_path / "x.png") is None
    assert (tmp_path / "afresh").exists()
    assert (tmp_path / "x.png").read_bytes() == plot.plot_run(cosim_run, tmp_path / "y.png").read_bytes()


def _children_of(parent: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit():
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                if int(fields[1]) == parent and fields[0] != "Z":
                    found.append(int(entry.name))
        except OSError:
            pass
    return found


def _gone(pid: int) -> bool:
    """No such process, or only its exit status left (a zombie, about to be reaped by init)."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


@pytest.mark.slow
def test_a_cancelled_child_ends_its_helper_too(monkeypatch):
    """A run that fails after the child drafted and forked its helper: both are ended at once (the
    child's process group), none is left waiting."""
    from cosim.cli import plotter
    from cosim.scenario.load import load_scenario

    monkeypatch.setattr(plotter, "_free_core", lambda: True)
    process = PlotProcess.start(load_scenario(EXAMPLE, ["simulation.stop_time=3"]))
    helpers: list[int] = []
    for _ in range(600):  # the child imports matplotlib and drafts first (a few 0.1 s)
        helpers = _children_of(process.pid)
        if helpers:
            break
        time.sleep(0.05)
    assert helpers, "the child made no helper"
    assert os.getpgid(helpers[0]) == os.getpgid(process.pid) == process.pid != os.getpgid(0)
    process.cancel()
    assert process.exit_status == -signal.SIGKILL
    for _ in range(200):  # SIGKILL is delivered when the helper is next scheduled
        if _gone(helpers[0]):
            break
        time.sleep(0.05)
    assert _gone(helpers[0])


@pytest.mark.slow
def test_the_plot_process_registers_no_3d_axes_and_sets_as_matplotlib_does():
    """`cosim.logs.plot.prepare_drawing` (the plot process) imports matplotlib without its 3-D
    toolkit and without each artist class's `set()` signature: the toolkit stays importable, and
    `set()` sets what matplotlib's own does (the pixels: `test_the_child_draws_what_this_process_draws`)."""
    code = (
        "import sys\n"
        "from cosim.logs import plot\n"
        "plot.prepare_drawing()\n"
        "import matplotlib.projections as projections\n"
        "print('3d' in projections.get_projection_names(), 'mpl_toolkits.mplot3d' in sys.modules)\n"
        "from mpl_toolkits.mplot3d import Axes3D\n"
        "print(Axes3D.name)\n"
        "from matplotlib.lines import Line2D\n"
        "line = Line2D([0], [0])\n"
        "line.set(color='red', lw=3, zorder=4)\n"
        "print(line.get_color(), line.get_linewidth(), line.get_zorder())\n"
    )
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.split("\n")[:3] == ["False False", "3d", "red 3.0 4"]
    assert "Warning" not in completed.stderr


def test_owning_the_canvas_pages_ahead_keeps_its_pixels_and_stops_when_asked():
    """`_own_pages` writes each page of the canvas with its own bytes: in a forked process (whose
    pages the parent shares until written), drawing over them afterwards copies no more pages;
    the pixels are unchanged; it stops when asked (before each few hundred pages)."""
    import resource

    import numpy as np

    from cosim.cli import plotter

    pixels = np.random.default_rng(1).integers(0, 256, (1045, 1650, 4), dtype=np.uint8)
    kept = pixels.copy()
    asked = []
    plotter._own_pages(pixels, lambda: asked.append(True) or len(asked) > 2)
    assert len(asked) == 3 and np.array_equal(pixels, kept)
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # (the child: counts the pages copied when the whole canvas is drawn over)
        try:
            plotter._own_pages(pixels)
            same = np.array_equal(pixels, kept)
            before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            pixels[...] = 9
            copied = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
            os.write(write, f"{int(same)} {copied}".encode())
        finally:
            os._exit(0)
    os.close(write)
    with os.fdopen(read) as answer:
        same, copied = answer.read().split()
    os.waitpid(pid, 0)
    assert same == "1" and int(copied) < 50  # (~1700 pages without)
    assert np.array_equal(pixels, kept)  # the parent's own pages untouched
