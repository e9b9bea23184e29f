"""The CLI's frame: every sub-command is registered, user errors exit 2 with one line."""

import os
import subprocess
import sys

import pytest

from cosim.cli import COMMANDS, build_parser, main
from cosim.errors import CosimError
from planner.errors import NavcosimError, PlannerError


def test_every_subcommand_is_registered():
    help_text = build_parser().format_help()
    for name in COMMANDS:
        assert name in help_text


def test_project_errors_share_one_base():
    assert issubclass(CosimError, NavcosimError)
    assert issubclass(PlannerError, NavcosimError)


@pytest.mark.slow
def test_cli_runs_as_module_and_prints_help():
    result = subprocess.run([sys.executable, "-m", "cosim", "--help"], capture_output=True, text=True)
    assert result.returncode == 0
    assert "COMMAND" in result.stdout


def test_missing_command_is_a_usage_error():
    with pytest.raises(SystemExit) as exit_:
        main([])
    assert exit_.value.code == 2


LOUD_HANDLER = """
import sys
import cosim.cli as cli

def loud(args):
    for line in range(200_000):
        print("line", line)
    return 0

parser = cli.build_parser
def build_parser():
    built = parser()
    built.parse_args = lambda argv=None: type("Args", (), {"handler": staticmethod(loud)})()
    return built
cli.build_parser = build_parser
sys.exit(cli.main([]))
"""


@pytest.mark.slow
def test_closed_pipe_ends_quietly():
    """`cosim … | head -1` stops quietly: no BrokenPipeError traceback, SIGPIPE's exit status."""
    script = f"set -o pipefail; {sys.executable} -c '{LOUD_HANDLER}' | head -1"
    result = subprocess.run(["bash", "-c", script], capture_output=True, text=True)
    assert result.stdout == "line 0\n"
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 141


@pytest.mark.slow
@pytest.mark.parametrize("module", ["cosim.errors", "cosim.cli", "cosim.core.interrupt", "dataclasses"])
def test_an_interrupt_while_the_cli_imports_is_one_line(module):
    """Ctrl-C before `main` handles signals (during the CLI's imports, the first of them made by
    importing the `cosim` package before the program runs, and those `main` makes before it handles
    them): one line, exit 1."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "class Interrupting:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if name == {module!r}:\n"
        "            raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Interrupting())\n"
        "from cosim.__main__ import run\n"
        "run()\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stderr) == (1, "cosim: interrupted (SIGINT)\n")


@pytest.mark.slow
def test_the_quick_exit_still_joins_threads_runs_exit_handlers_and_flushes(tmp_path):
    """`exit_program` after a `cosim run` ends without the interpreter's teardown, but as its exit
    would: a running non-daemon thread finishes, exit handlers run, buffered output comes out, and
    the exit status is the command's."""
    script = (
        "import atexit, pathlib, sys, threading, time\n"
        "import cosim.cli as cli\n"
        "out = pathlib.Path(sys.argv[1])\n"
        "def late():\n"
        "    time.sleep(0.3)\n"
        "    (out / 'thread').write_text('joined')\n"
        "threading.Thread(target=late).start()\n"
        "atexit.register(lambda: (out / 'atexit').write_text('ran'))\n"
        "sys.stdout.write('buffered, no newline')\n"
        "cli._quick_exit[0] = True\n"
        "cli.exit_program(3)\n"
        "print('never')\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (3, "buffered, no newline", "")
    assert (tmp_path / "thread").read_text() == "joined" and (tmp_path / "atexit").read_text() == "ran"


def test_other_commands_exit_as_python_does(monkeypatch):
    """Without a `cosim run` before it, `exit_program` is `sys.exit`: the interpreter's own exit."""
    import cosim.cli as cli

    monkeypatch.setattr(cli, "_quick_exit", [False])
    with pytest.raises(SystemExit) as done:
        cli.exit_program(2)
    assert done.value.code == 2


def test_a_run_under_a_profiler_exits_as_python_does(monkeypatch):
    """Under a profiler (cProfile writes its figures after the program returns) the quick exit is
    `sys.exit` too."""
    import cosim.cli as cli

    monkeypatch.setattr(cli, "_quick_exit", [True])
    sys.setprofile(lambda *arguments: None)
    try:
        with pytest.raises(SystemExit) as done:
            cli.exit_program(1)
    finally:
        sys.setprofile(None)
    assert done.value.code == 1


@pytest.mark.slow
def test_the_program_has_openblas_threads_sleep_at_once_unless_told_otherwise():
    """`cosim` sets OPENBLAS_THREAD_TIMEOUT=4 before numpy is imported (OpenBLAS reads it when
    numpy loads it: its threads then sleep at once instead of spinning ~50 ms of a core); a value
    the user set stays."""
    script = (
        "import os, sys\n"
        "import cosim.__main__\n"
        "assert 'numpy' not in sys.modules\n"
        "print(os.environ['OPENBLAS_THREAD_TIMEOUT'])\n"
    )
    for given, expected in ((None, "4"), ("12", "12")):
        env = {key: value for key, value in os.environ.items() if key != "OPENBLAS_THREAD_TIMEOUT"}
        if given is not None:
            env["OPENBLAS_THREAD_TIMEOUT"] = given
        done = subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120
        )
        assert (done.returncode, done.stdout, done.stderr) == (0, f"{expected}\n", "")


def _converting(error: Exception | None):
    """A `cosim run` handler that is interrupted (SIGINT), where code it goes through turns the
    interrupt into `error` (as C code that imports does: a Ctrl-C while numpy is imported becomes
    numpy's ImportError); with `error` None, only `ImportError` is raised, no interrupt."""
    import signal

    def handler(args):
        if error is None:
            raise ImportError("not an interrupt")
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            raise error from None

    return handler


@pytest.mark.parametrize("error", [ImportError("numpy: broken install?"), RuntimeError("a callback failed")])
def test_an_error_that_an_interrupt_became_is_reported_as_the_interrupt(error, monkeypatch, capsys):
    from cosim.cli import run as run_command

    monkeypatch.setattr(run_command, "_handler", _converting(error))
    assert main(["run", "scenarios/warehouse_diff_drive_one_obstacle.toml"]) == 1
    assert capsys.readouterr().err == "cosim: interrupted (SIGINT)\n"


def test_an_error_without_an_interrupt_is_not_reported_as_one(monkeypatch):
    from cosim.cli import run as run_command

    monkeypatch.setattr(run_command, "_handler", _converting(None))
    with pytest.raises(ImportError, match="not an interrupt"):
        main(["run", "scenarios/warehouse_diff_drive_one_obstacle.toml"])
