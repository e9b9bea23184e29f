"""An FMU's model description: the archive checked, fmpy's parse of modelDescription.xml, and the two
caches that spare parsing it again.

`read_description` checks the archive before anything is extracted: a zip file, its total
uncompressed size under the limit (`cosim.fmi.archive`; default 1 GiB, `max_unpacked_size` raises
it), a modelDescription.xml, an FMI version navcosim runs (1.0, 2.0, 3.0), and the binary of the
interface it declares for this platform; anything else is a one-line `CosimError`.

Caches: the parse is made once per file version in a process (`_parsed_description`, keyed by the
resolved path, modification time and size), and a project FMU's parse is also kept on disk beside
it for the next process (`_kept_description`: a pickle, written aside and renamed). Checked archives
are remembered per file version and size limit (`checked_description`). Failures are never
remembered; a changed file is another key. Callers treat every description as read-only.
"""

from __future__ import annotations

import os
import zipfile
from functools import cache
from pathlib import Path
from typing import NamedTuple

import fmpy
from fmpy.model_description import ModelVariable

from cosim.errors import CosimError
from cosim.fmi.archive import check_unpacked_size


class CheckedDescription(NamedTuple):
    """A checked FMU's description (fmpy's, read-only) and its major FMI version (1, 2 or 3)."""

    model_description: object
    fmi_version: int


@cache
def fmi1_variable_step(path: str, mtime_ns: int, size: int) -> bool:
    """canHandleVariableCommunicationStepSize of an FMI 1.0 co-simulation FMU (its Capabilities
    element under Implementation/CoSimulation_StandAlone or CoSimulation_Tool)."""
    from xml.etree import ElementTree

    with zipfile.ZipFile(path) as archive:
        root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    capabilities = root.find("Implementation/*/Capabilities")
    return capabilities is not None and capabilities.get("canHandleVariableCommunicationStepSize") in {
        "true",
        "1",
    }


def file_identity(path: Path) -> tuple[int, int]:
    status = path.stat()
    return status.st_mtime_ns, status.st_size


@cache
def _parsed_description(path: str, mtime_ns: int, size: int):
    """fmpy's parse of an FMU's modelDescription.xml, once per file version: describing a system and
    then building it reads every FMU twice, and a 2000-variable description takes ~25 ms to parse.
    A project FMU's parse is also kept on disk beside it (`_kept_description`). Callers treat the
    result as read-only."""
    kept = _kept_description(Path(path))
    if kept is not None:
        description = _read_kept(kept, path)
        if description is not None:
            return description
    description = fmpy.read_model_description(path)
    if kept is not None:
        _keep(kept, path, description)
    return description


_KEPT_FORMAT = b"navcosim fmpy description 3"  # 3: pickled from cosim.fmi.description


def _kept_description(path: Path) -> Path | None:
    """Where the parse of `path` is kept: beside a project FMU in the FMU build cache
    (`cosim.fmi.builtin`, a folder navcosim writes and whose binaries it runs anyway), else nowhere
    (a user's FMU is parsed each time: nothing is written next to it). Unpickling fmpy's objects
    takes a fifth of parsing the XML again (`_KeptVariable`; and no lxml import, no schema
    validation: the file was validated when it was parsed)."""
    from cosim.fmi.builtin import default_cache_dir

    try:
        cache = default_cache_dir().resolve()
    except OSError:
        return None
    if path.parent != cache and path.parent != cache / "fmi3":
        return None
    return path.with_name(f".{path.stem}.description.pickle")


def kept_unpacked(path: Path) -> Path | None:
    """Where a project FMU's files for its instances stay extracted (`cosim.fmi.archive.unpack_instance`),
    named by this file version (modification time, size, inode); None for any other FMU."""
    kept = _kept_description(path)
    if kept is None:
        return None
    try:
        status = os.stat(path)
    except OSError:
        return None
    return path.with_name(f".{path.stem}.unpacked-{status.st_mtime_ns}-{status.st_size}-{status.st_ino}")


def _kept_key(path: str) -> bytes:
    """What the kept parse must have been made from: this file (time, size, inode) and fmpy version."""
    status = os.stat(path)
    version = getattr(fmpy, "__version__", "")
    return b" ".join(
        [_KEPT_FORMAT, version.encode(), *(str(n).encode() for n in (status.st_mtime_ns, status.st_size))]
        + [str(status.st_ino).encode()]
    )


def _read_kept(kept: Path, path: str):
    """The kept parse of `path`, or None (none, another file version, another fmpy, unreadable)."""
    import pickle

    try:
        with open(kept, "rb") as stream:
            if stream.readline().rstrip(b"\n") != _kept_key(path):
                return None
            return pickle.load(stream)
    except Exception:  # noqa: BLE001 - whatever is wrong with the kept copy, the FMU is parsed again
        return None


def _keep(kept: Path, path: str, description) -> None:
    """Keep the parse beside the FMU (written aside and renamed: readers never see half of it); a
    failure only means the next run parses again."""
    import io
    import pickle

    partial = kept.with_name(f"{kept.name}.{os.getpid()}")
    try:
        payload = io.BytesIO()
        _kept_pickler(payload, protocol=pickle.HIGHEST_PROTOCOL).dump(description)
        partial.write_bytes(_kept_key(path) + b"\n" + payload.getvalue())
        os.replace(partial, kept)
    except Exception:  # noqa: BLE001 - not kept; nothing else changes
        partial.unlink(missing_ok=True)


def read_description(path: Path, max_unpacked_size: int | None = None) -> CheckedDescription:
    """Check the archive and return fmpy's model description; one-line `CosimError` otherwise."""
    if not path.is_file():
        raise CosimError(f"FMU '{path}' not found")
    if not zipfile.is_zipfile(path):
        raise CosimError(f"FMU '{path}' is not a zip archive (corrupt file or not an FMU)")
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            check_unpacked_size(path, archive, max_unpacked_size)
    except (zipfile.BadZipFile, OSError) as error:
        raise CosimError(f"FMU '{path}' cannot be read: {error}") from None
    if "modelDescription.xml" not in names:
        raise CosimError(f"FMU '{path}' has no modelDescription.xml")
    try:
        description = _parsed_description(str(path.resolve()), *file_identity(path))
    except Exception as error:  # fmpy raises plain Exceptions with multi-line text
        from cosim.fmi.diagnose import dangling_reference  # (and its XML parser) only for a broken FMU

        problem = dangling_reference(path) if isinstance(error, IndexError | KeyError) else None
        first_line = problem or " ".join(str(error).split())[:300]
        raise CosimError(f"FMU '{path}': invalid modelDescription.xml: {first_line}") from None
    version = int(str(description.fmiVersion).split(".")[0])
    if version not in (1, 2, 3):
        raise CosimError(
            f"FMU '{path}' is FMI {description.fmiVersion}; navcosim supports FMI 1.0, 2.0 and 3.0"
        )
    # The binary of the interface a component uses by default: co-simulation when the FMU has it
    # (`cosim.fmi.model_exchange` checks the Model Exchange binary of an FMU run as one).
    interface = description.coSimulation or description.modelExchange
    if interface is None:
        raise CosimError(f"FMU '{path}' (model {description.modelName}) declares no FMI interface")
    platform = fmpy.platform if version < 3 else fmpy.platform_tuple
    binary = f"binaries/{platform}/{interface.modelIdentifier}{fmpy.sharedLibraryExtension}"
    if binary not in names:
        identifier = interface.modelIdentifier
        from cosim.fmi.diagnose import missing_binary

        raise CosimError(missing_binary(path, names, platform, identifier, fmpy.sharedLibraryExtension))
    return CheckedDescription(description, version)


# Checked archives (`read_description`), keyed by the file's resolved path and version (modification
# time and size) and the unpacked-size limit (`file_key`). A sweep's worker reads the same few FMUs
# once per run.
_DESCRIPTIONS: dict[tuple, CheckedDescription] = {}
_KEPT = 32


def remember(cache: dict, key: tuple, value):
    """Put `value` in `cache` under `key`, dropping the oldest entry beyond the last `_KEPT`."""
    if len(cache) >= _KEPT:
        cache.pop(next(iter(cache)))
    cache[key] = value
    return value


def file_key(path: Path, max_unpacked_size: int | None) -> tuple | None:
    """The key of this file version and size limit; None when the file cannot be looked at (then
    `read_description` says what is wrong)."""
    try:
        return (str(path.resolve()), *file_identity(path), max_unpacked_size)
    except (OSError, RuntimeError):
        return None


def checked_description(path: Path, max_unpacked_size: int | None, key: tuple | None) -> CheckedDescription:
    """`read_description(path, max_unpacked_size)`, once per `key` (`file_key`) in a process."""
    if key is not None and key in _DESCRIPTIONS:
        return _DESCRIPTIONS[key]
    checked = read_description(path, max_unpacked_size)
    return checked if key is None else remember(_DESCRIPTIONS, key, checked)


def _variable_defaults() -> dict[str, object]:
    """fmpy's `ModelVariable` fields and their defaults."""
    import attr

    return {
        a.name: a.default.factory() if isinstance(a.default, attr.Factory) else a.default
        for a in attr.fields(ModelVariable)
    }


class _KeptVariable(ModelVariable):
    """fmpy's `ModelVariable` as a kept description has it: only the fields that differ from the
    defaults are in the instance (a `__dict__`; the defaults are class attributes, which shadow
    fmpy's slots), so unpickling one is a dict update instead of fmpy's forty-odd slot assignments
    (a 2000-variable description: ~3 ms instead of ~13 ms). Read-only like every parsed description
    here: the list defaults are shared."""

    def __getstate__(self) -> dict:
        return dict(self.__dict__)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)


for _name, _default in _variable_defaults().items():
    setattr(_KeptVariable, _name, _default)


def _new_kept_variable() -> _KeptVariable:
    """An empty `_KeptVariable` (unpickling: its state follows)."""
    return object.__new__(_KeptVariable)


def _kept_pickler(stream, protocol: int):
    """A pickler that writes a description's `ModelVariable`s as `_KeptVariable`s."""
    import pickle

    defaults = _variable_defaults()

    class Pickler(pickle.Pickler):
        def reducer_override(self, obj):
            if type(obj) is not ModelVariable:
                return NotImplemented
            state = {}
            for name, default in defaults.items():
                value = getattr(obj, name)
                if value is not default and (type(value) is not type(default) or value != default):
                    state[name] = value
            return _new_kept_variable, (), state

    return Pickler(stream, protocol=protocol)
