"""`python -m cosim` and the `cosim` command.

The CLI's imports take a few tenths of a second; a Ctrl-C then (before `cosim.cli.main` handles
signals) ends with the same one line as later, not a KeyboardInterrupt traceback.
"""

import sys


def run() -> None:
    try:
        from cosim.cli import exit_program, main
    except KeyboardInterrupt:
        print("cosim: interrupted (SIGINT)", file=sys.stderr)
        sys.exit(1)
    exit_program(main())


if __name__ == "__main__":
    run()
