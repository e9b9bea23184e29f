"""Writing what a command makes (a plot, a video, a table, a recovered log, an archive) safely.

Nothing outside the path the user named is written, and nothing that exists is destroyed: an
existing file is refused unless the user said `--force`; a directory, a device node, a FIFO or a
socket is refused whatever the flag (writing "through" `/dev/full` and then unlinking it on failure
once deleted the device node); the content goes to a temporary file beside the target, renamed
over it only when complete, so a failure leaves the target as it was and removes only the
temporary. The run's own log is different (`cosim.record.logfile.claim_log`): it is written in
place while the run goes, locked, so a reader can follow it.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from cosim.errors import PATH_LIMIT, CosimError, shorten


def checked_output(path: str | Path, force: bool = False) -> Path:
    """`path` as a place to write a new file: CosimError (one line) for anything that is not a
    regular file, and for an existing one without `force`."""
    path = Path(path)
    where = shorten(path, PATH_LIMIT)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return path
    except (OSError, ValueError) as error:
        reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
        raise CosimError(f"{where}: cannot write here ({reason})") from None
    if stat.S_ISDIR(mode):
        raise CosimError(f"{where}: is a folder; name a file to write")
    if not stat.S_ISREG(mode):
        raise CosimError(f"{where}: is not a regular file (a device, FIFO or socket); name a file to write")
    if not force:
        raise CosimError(f"{where}: already exists; give --force to overwrite it")
    return path


@contextmanager
def atomic_output(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside `path` (same suffix, so writers that choose a format by it
    still do) to write the whole output to; on success it is renamed to `path`, on any failure it
    is removed and `path` is left as it was. OSError while writing becomes one CosimError line."""
    path = checked_output(path, force)
    where = shorten(path, PATH_LIMIT)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        descriptor, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    except OSError as error:
        raise CosimError(f"{where}: cannot write here ({error.strerror or error})") from None
    os.close(descriptor)
    temporary = Path(name)
    try:
        yield temporary
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # as a plainly created file, not mkstemp's 0600
        checked_output(path, force)  # nothing took the name meanwhile
        os.replace(temporary, path)
    except OSError as error:
        raise CosimError(f"{where}: cannot write ({error.strerror or error})") from None
    finally:
        temporary.unlink(missing_ok=True)
