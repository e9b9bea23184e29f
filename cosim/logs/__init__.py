"""Stage 8, reading logs back: the indexed reader (`open_log`), info, plot, export and diff.

`open_log` and `Log` are imported lazily, so `cosim.logs.index` alone stays cheap."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cosim.logs.reader import Log, open_log

__all__ = ["Log", "open_log"]


def __getattr__(name: str):
    if name in __all__:
        from cosim.logs import reader

        return getattr(reader, name)
    raise AttributeError(f"module 'cosim.logs' has no attribute {name!r}")
