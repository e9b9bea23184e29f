"""`python -m cosim` and the `cosim` command.

The CLI's imports take a few tenths of a second; a Ctrl-C then (before `cosim.cli.main` handles
signals) ends with the same one line as later, not a KeyboardInterrupt traceback.
"""

import os
import sys

# numpy's OpenBLAS starts a thread per further core when numpy is imported, and each one spins for
# ~2^28 cycles (~50 ms of a core after the import, ~100 ms after each threaded call) before it
# sleeps: CPU time taken from the plot process, the sweep's fork server or a worker on the other
# core. With a timeout of 2^4 cycles they sleep at once; a threaded call wakes them as before. Set
# before numpy is imported, in the `cosim` program only (a user's own process keeps its setting).
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")


def run() -> None:
    try:
        from cosim.cli import exit_program, main

        code = main()  # (it handles signals once it has set up: before, its imports may be interrupted)
    except KeyboardInterrupt:
        print("cosim: interrupted (SIGINT)", file=sys.stderr)
        sys.exit(1)
    exit_program(code)


if __name__ == "__main__":
    run()
