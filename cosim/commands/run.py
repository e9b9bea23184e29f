"""`cosim run`: placeholder until its issue lands (owned by the helper building it)."""

from cosim.errors import CosimError


def register(subparsers) -> None:
    parser = subparsers.add_parser("run", help="(not built yet)")
    parser.set_defaults(handler=_handler)


def _handler(args) -> int:
    raise CosimError("'cosim run' is not built yet")
