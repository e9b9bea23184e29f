"""The `cosim` command line: one sub-command module per job (fmu, plan, run, system, log, ssp, sweep)."""

from __future__ import annotations

import argparse
import builtins
import gc
import importlib
import os
import sys
from pathlib import Path
from types import CodeType

from native.errors import NavcosimError
from native.load import NativeBuildError, build_folder

COMMANDS = ("fmu", "plan", "run", "system", "log", "ssp", "sweep")
# Commands whose process ends without the interpreter's teardown (`exit_program`).
QUICK_EXIT = ("run", "sweep")
_quick_exit = [False]


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The `cosim` parser with every sub-command, or only `command` (what `main` needs to run it:
    each sub-command module is imported to register it, so registering one imports one)."""
    parser = argparse.ArgumentParser(
        prog="cosim",
        description="Scenario co-simulation of mobile robots: plan, run, inspect logs.",
    )
    parser.add_argument("--version", action=_Version, help="print the installed navcosim's version and exit")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS if command is None else (command,):
        importlib.import_module(f"cosim.cli.{name}").register(subparsers)
    return parser


class _Version(argparse.Action):
    """`cosim --version`: the installed package's version (read only when asked, not at start-up),
    with the Python and fmpy versions a bug report needs."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import PackageNotFoundError, version

        def installed(name: str) -> str:
            try:
                return version(name)
            except PackageNotFoundError:
                return "not installed"

        python = ".".join(str(part) for part in sys.version_info[:3])
        print(f"navcosim {installed('navcosim')} (Python {python}, fmpy {installed('fmpy')})")
        parser.exit()


def main(argv: list[str] | None = None) -> int:
    """Run the CLI. Each handler returns its exit code; user errors exit 2 with one line per problem.

    SIGINT and SIGTERM at any moment exit 1 with one line (`cosim.core.interrupt`): a run that
    has opened its log finalises it first; before that nothing has been written.
    """
    from cosim.core.interrupt import Interrupted, catching_signals, raised

    if argv is None:
        _collect_young_objects_rarely()
        _dataclass_code(_command(sys.argv[1:])).install()
    try:
        try:
            # Called without arguments, main() is the program (`cosim`, `python -m cosim`): signals
            # stay handled until the process exits. Called with a list (tests, scripts), they are
            # given back.
            with catching_signals(until_exit=argv is None):
                arguments = sys.argv[1:] if argv is None else argv
                command = _command(arguments)
                parser = build_parser(command) if command else build_parser()
                args = parser.parse_args(argv)
                args.program = argv is None  # this process is `cosim`: it ends when the command does
                _quick_exit[0] = args.program and args.command in QUICK_EXIT
                return int(args.handler(args) or 0)
        except Exception as error:
            # An error after an interrupt was raised is that interrupt, turned into another error by
            # code it went through: C code that imports does so (a Ctrl-C while numpy was imported
            # became numpy's ImportError, its advice on a broken install, and a traceback).
            name = raised()
            if name is None or isinstance(error, BrokenPipeError):
                raise
            raise Interrupted(name) from error
    except NavcosimError as error:
        for line in str(error).splitlines() or [""]:  # a scenario's problems come all at once
            print(f"cosim: error: {line}", file=sys.stderr)
        return 2
    except NativeBuildError as error:  # no C compiler, or it failed: the kernels cannot be built
        print(f"cosim: error: {error}", file=sys.stderr)
        return 2
    except Interrupted as interrupt:
        print(f"cosim: interrupted ({interrupt.signal_name})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("cosim: interrupted (SIGINT)", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # The reader of our output went away (`cosim … | head`): stop quietly, as a shell tool does.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    finally:
        if argv is None:
            # The process ends now. Python's shutdown runs full collections over every object left
            # (~0.3 s of CPU after a run, more than the import floor's whole shutdown); frozen, they
            # are skipped, and the memory goes back to the system with the process. The log, the
            # FMUs and the output streams are closed and flushed without the collector.
            gc.freeze()
            _dataclass_code().save()


def exit_program(code: int):
    """End the `cosim` process with `code` (what `main()` returned). After a `QUICK_EXIT` command:
    the output flushed, the other threads joined and the exit handlers run as the interpreter's own
    exit does them, then `os._exit`, without the teardown that deallocates every module and object
    one by one (~20 ms after a run; its log, FMUs and PNG are closed and written by then). Any
    other command, or a run under a profiler or tracer (cProfile writes its figures after the
    program returns): `sys.exit(code)`."""
    if not _quick_exit[0] or sys.getprofile() is not None or sys.gettrace() is not None:
        sys.exit(code)
    import atexit
    import threading

    try:
        threading._shutdown()  # the non-daemon threads, and the executors' joins (`_register_atexit`)
        atexit._run_exitfuncs()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
    except BrokenPipeError:  # the reader went away: as `main` ends then
        code = 141
    except BaseException:  # noqa: BLE001 - an interrupt now: the interpreter's own exit does the rest
        sys.exit(code)
    os._exit(code)


def _collect_young_objects_rarely() -> None:
    """Let the cyclic garbage collector look at young objects every 20,000 allocations instead of
    Python's 700. A command sets up ~10^5 objects that live as long as the process (modules, every
    FMU's modelDescription with thousands of variables, the ports); with the default thresholds
    they were traversed again and again by collections that find almost nothing (~0.15 s of
    CPU of a `cosim run`). Garbage without cycles is freed at once as always; cycles now wait for
    a collection a little longer. Only for the program (`main()` without arguments), not for a
    process that calls `main([...])`."""
    gc.set_threshold(20_000, 20, 10)


class DataclassCode:
    """The code of the functions `dataclasses` generates for each class (`__init__`, `__repr__`,
    `__eq__`, ...), kept across processes. `dataclasses` compiles them from their source text for
    every class in every process (~50 classes in a `cosim run`, ~15 ms of its start); installed
    (`install`), the `exec` that `dataclasses` calls takes the code compiled before from the same
    text, read from `path` (one marshal file per command and bytecode version: each code object is
    unmarshalled when its text comes), and `save` writes what was compiled anew. The text alone
    makes the code (compiled as `exec` compiles it there: file name "<string>", no future flags
    inherited), so a class is the same whichever way its code came. Only for the program (`main()`
    without arguments), as the collector's settings."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.code: dict[str, CodeType | bytes] = {}  # text -> code, or its marshal bytes until used
        self.used: set[str] = set()
        self.compiled = 0  # texts compiled by this process (not found in the file)

    def install(self) -> None:
        """Read the file (a missing or unreadable one is an empty cache) and hook `dataclasses`."""
        import dataclasses
        import marshal

        try:
            with open(self.path, "rb") as stream:
                loaded = marshal.load(stream)
        except (OSError, EOFError, ValueError, TypeError):
            loaded = None
        if isinstance(loaded, dict):
            self.code = loaded
        dataclasses.exec = self.exec  # the module's global `exec` (it calls no other)

    def uninstall(self) -> None:
        import dataclasses

        if vars(dataclasses).get("exec") == self.exec:
            del dataclasses.exec

    def exec(self, source, globals=None, locals=None, /):  # noqa: A002 - `exec`'s own parameters
        """`builtins.exec`, with a source text's code from the cache (compiled and kept if new)."""
        if globals is None:  # as exec does: the caller's namespace
            frame = sys._getframe(1)
            globals = frame.f_globals  # noqa: A001
            locals = frame.f_locals if locals is None else locals  # noqa: A001
        if isinstance(source, str):
            source = self._code(source)
        return builtins.exec(source, globals, locals)

    def _code(self, text: str) -> CodeType:
        import marshal

        code = self.code.get(text)
        if type(code) is bytes:
            try:
                code = marshal.loads(code)
            except (EOFError, ValueError, TypeError):
                code = None
        if type(code) is not CodeType:
            code = compile(text, "<string>", "exec", dont_inherit=True)
            self.compiled += 1
        self.code[text] = code
        self.used.add(text)
        return code

    def save(self) -> None:
        """Write the cache when this process compiled code it did not find: what it read and made,
        or, when that is more than twice what it used, only what it used (a file grows with what
        its command needs, not without end); replaced whole, so concurrent processes each leave a
        complete file. A failure to write is ignored."""
        if not self.compiled:
            return
        import marshal

        texts = self.code if len(self.code) <= 2 * len(self.used) else self.used
        kept = {}
        for text in texts:
            code = self.code[text]
            kept[text] = code if type(code) is bytes else marshal.dumps(code)
        temporary = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(temporary, "wb") as stream:
                marshal.dump(kept, stream)
            os.replace(temporary, self.path)
            self.compiled = 0
        except (OSError, ValueError):
            try:
                os.unlink(temporary)
            except OSError:
                pass


_dataclass_codes: list[DataclassCode] = []


def _dataclass_code(command: str | None = None) -> DataclassCode:
    """The program's `DataclassCode` for `command` (None: the help, a typo), in the folder of the
    built kernels (`native.load.build_folder`). Made on the first call."""
    if not _dataclass_codes:
        from importlib.util import MAGIC_NUMBER

        tag = f"{command or 'cosim'}-{sys.implementation.cache_tag}-{MAGIC_NUMBER.hex()}"
        _dataclass_codes.append(DataclassCode(build_folder(Path(__file__)) / f"dataclass-code-{tag}.marshal"))
    return _dataclass_codes[0]


def _command(arguments: list[str]) -> str | None:
    """The sub-command `arguments` name first, or None (help, a typo, nothing): then the parser gets
    every sub-command, for the help text and argparse's "invalid choice" message."""
    first = arguments[0] if arguments else None
    return first if first in COMMANDS else None


if __name__ == "__main__":
    sys.exit(main())
