"""Running a mutator's mutants through the real `cosim` entry point, each in a forked child.

A mutant is an argv for `cosim.cli.main`. Each runs in a child forked from the test process (its
imports and compiled schemas warm, so a mutant costs its own work only), with stdout and stderr
the child's real file descriptors 1 and 2 (what an FMU's C code writes lands there too), its own
process group and its own temporary folder. Up to `parallel` children run at once. A child that
has not ended after `timeout` seconds is a hang: its group is killed and the mutant fails. The
timeout only detects hangs; it bounds no speed.

`Outcome.problem()` is the contract every mutator checks: the command ends, with exit 0, 1 or 2,
no Python traceback on stderr, and on exit 2 one line per problem, `cosim: error: ...` (or
argparse's usage and error lines).
"""

from __future__ import annotations

import collections
import os
import signal
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

TRACEBACK = "Traceback (most recent call last)"
LINE_LIMIT = 2000  # characters of one error line beyond the paths it names
HANG = "hang"
CRASH = "crash"


@dataclass
class Mutant:
    argv: list[str]
    what: str  # how the mutant was made, for the failure message
    # A problem this mutant is expected to show (text found in `Outcome.problem()`'s) and why: a
    # bug left to another open issue. Any other problem still fails.
    known: tuple[str, str] | None = None


@dataclass
class Outcome:
    mutant: Mutant
    code: int | str  # the exit code, HANG or CRASH
    err: str
    seconds: float = 0.0  # wall time of the child

    def problem(self) -> str | None:
        """What breaks the contract, or None."""
        if self.code == HANG:
            return "hang: did not end"
        if self.code == CRASH:
            return f"died of a signal\n{self.err[-3000:]}"
        if TRACEBACK in self.err:
            return f"a traceback on stderr\n{self.err[-4000:]}"
        if self.code not in (0, 1, 2):
            return f"exit {self.code}\n{self.err[-3000:]}"
        if self.code == 2:
            lines = self.err.splitlines()
            errors = [line for line in lines if line.startswith("cosim: error: ")]
            if not errors:
                if any(line.startswith("cosim") and ": error: " in line for line in lines):
                    return None  # argparse: usage, then one error line
                return f"exit 2 without an error line\n{self.err[-3000:]}"
            if errors != lines[-len(errors) :]:
                return f"the error lines do not come last\n{self.err[-3000:]}"
            for line in errors:
                # The user's own arguments (paths) may be named whole, twice with an OS error.
                if len(line) > LINE_LIMIT + 2 * sum(len(arg) for arg in self.mutant.argv):
                    return f"an error line of {len(line)} characters: {line[:500]}"
        return None


def _child(argv: list[str], out: Path, err: Path, temporary: Path) -> None:
    """In the forked child: run `cosim argv` with fds 1 and 2 on files; never returns."""
    code = 70
    try:
        os.setpgid(0, 0)
        for fd, path in ((1, out), (2, err)):
            handle = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(handle, fd)
            os.close(handle)
        sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115
        sys.stderr = open(2, "w", closefd=False)  # noqa: SIM115
        tempfile.tempdir = str(temporary)
        os.environ["TMPDIR"] = str(temporary)
        from cosim.cli import main

        try:
            code = main(argv)
        except SystemExit as exit_:  # argparse
            code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        code = code if isinstance(code, int) and 0 <= code < 256 else 71
    except BaseException:  # what a user would see: the test fails on it
        traceback.print_exc()
        code = 70
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def warm_up(*argvs: list[str]) -> None:
    """Run these commands in this process first, so each child starts with their modules imported
    and their caches filled (a child then pays for its mutant only)."""
    import contextlib
    import io

    from cosim.cli import main

    for argv in argvs:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            main(argv)


def run_mutants(
    mutants: list[Mutant], work: Path, timeout: float = 120.0, parallel: int = 2
) -> list[Outcome]:
    """Run every mutant in its own forked child, `parallel` at a time; outcomes in mutant order."""
    work.mkdir(parents=True, exist_ok=True)
    outcomes: list[Outcome | None] = [None] * len(mutants)
    pending = collections.deque(enumerate(mutants))
    running: dict[int, tuple[int, float, Path]] = {}  # pid -> (index, start, folder)
    sys.stdout.flush()
    sys.stderr.flush()
    while pending or running:
        while pending and len(running) < parallel:
            index, mutant = pending.popleft()
            folder = work / f"m{index}"
            (folder / "tmp").mkdir(parents=True, exist_ok=True)
            pid = os.fork()
            if pid == 0:
                _child(mutant.argv, folder / "stdout", folder / "stderr", folder / "tmp")
            running[pid] = (index, time.monotonic(), folder)
        time.sleep(0.002)
        for pid, (index, start, folder) in list(running.items()):
            ended, status = os.waitpid(pid, os.WNOHANG)
            if ended == 0:
                if time.monotonic() - start < timeout:
                    continue
                try:
                    os.killpg(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                os.waitpid(pid, 0)
                code: int | str = HANG
            elif os.WIFSIGNALED(status):
                code = CRASH
            else:
                code = os.WEXITSTATUS(status)
            del running[pid]
            err = (folder / "stderr").read_text(errors="replace")
            outcomes[index] = Outcome(mutants[index], code, err, time.monotonic() - start)
    return outcomes


def report(name: str, outcomes: list[Outcome]) -> tuple[collections.Counter, list[str]]:
    """Counts by exit (and by command) printed in the test's output; the failures of unknown cause."""
    counts: collections.Counter = collections.Counter()
    failures = []
    for outcome in outcomes:
        command = outcome.mutant.argv[0]
        counts["mutants"] += 1
        counts[f"exit {outcome.code}"] += 1
        counts[f"{command} exit {outcome.code}"] += 1
        problem = outcome.problem()
        if problem is None:
            continue
        known = outcome.mutant.known
        if known is not None and known[0] in problem:
            counts["known"] += 1
            print(f"\nknown ({known[1]}): {outcome.mutant.what[:300]}: {problem.splitlines()[0][:300]}")
            continue
        counts["failures"] += 1
        failures.append(f"{outcome.mutant.what}\n  argv: {' '.join(outcome.mutant.argv)[:600]}\n  {problem}")
    print(f"\n{name}: " + ", ".join(f"{key}: {counts[key]}" for key in sorted(counts)))
    slowest = max(outcomes, key=lambda outcome: outcome.seconds)
    total = sum(outcome.seconds for outcome in outcomes)
    what = slowest.mutant.what[:200]
    print(f"{name}: {total:.1f} s in children, the slowest {slowest.seconds:.1f} s: {what}")
    return counts, failures
