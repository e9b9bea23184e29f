"""What travels to the workers: the scenario and every file it names, and each run's identity.

Workers need not share the client's file system. Every string value of a run's scenario TOML (after
its overrides) that names an existing file, relative to the scenario's folder or absolute, goes
into the bundle with its bytes, and so does the image a ROS map YAML names. On a worker the files
are laid out again under a private folder with the same relative paths, so relative names in the
scenario resolve as they do on the client; an absolute name is redirected there by an override
when the worker has no identical file at that path.

A run's id is a hash of the scenario text, the bytes of the files it uses and its overrides, so
`--resume` recognises a run whatever sweep it came from and the same sweep gives the same ids.
"""

from __future__ import annotations

import copy
import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cosim.sweep.adapter as adapter

RUN_ID_LENGTH = 16  # hex digits of the SHA-256: 64 bits, collisions negligible for any sweep


@dataclass(frozen=True)
class FileReference:
    """A file the scenario names: the key holding the name ("vehicle.fmu", None for a map's image),
    the name as written, and the file's path relative to the bundle root."""

    key: str | None
    written: str
    relative: str


@dataclass
class Bundle:
    """The scenario and its files, keyed by path relative to `root` (the client's common folder)."""

    root: str
    scenario: str  # relative path of the scenario file
    files: dict[str, bytes] = field(default_factory=dict)
    digests: dict[str, str] = field(default_factory=dict)  # relative path -> SHA-256 hex

    @property
    def digest(self) -> str:
        text = "\n".join(f"{name} {self.digests[name]}" for name in sorted(self.digests))
        return hashlib.sha256(text.encode()).hexdigest()

    def materialize(self, folder: Path) -> None:
        """Write every file under `folder` at its relative path."""
        for name, data in self.files.items():
            target = folder / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)


@dataclass(frozen=True)
class Run:
    """One run of a sweep: its place in sweep order, its id, the varied values and every override."""

    index: int
    run_id: str
    values: tuple[Any, ...]
    overrides: tuple[str, ...]  # the base overrides, then one per varied key (and seed key)
    references: tuple[FileReference, ...]
    point: int = 0  # index of the point in sweep order (its replicates share it)


def _string_values(node: Any, path: tuple[str, ...] = ()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _string_values(value, (*path, str(key)))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _string_values(value, (*path, str(index)))
    elif isinstance(node, str) and node:
        yield ".".join(path), node


def _map_image(yaml_file: Path) -> Path | None:
    """The `image:` a ROS map YAML names (the map loader reads it beside the YAML)."""
    try:
        lines = yaml_file.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    for line in lines:
        key, _, value = line.partition(":")
        if key.strip() == "image":
            image = yaml_file.parent / value.split("#")[0].strip().strip("'\"")
            return image.resolve() if image.is_file() else None
    return None


def _named_files(written: str, base_dir: Path) -> list[tuple[str | None, Path]]:
    """The existing file a string value names (and a map YAML's image): [] when it names none."""
    if "\n" in written or len(written) > 4096:
        return []
    path = Path(written) if Path(written).is_absolute() else base_dir / written
    try:
        if not path.is_file():
            return []
    except OSError:
        return []
    path = path.resolve()
    found: list[tuple[str | None, Path]] = [(written, path)]
    if path.suffix in (".yaml", ".yml"):
        image = _map_image(path)
        if image is not None:
            found.append((None, image))
    return found


def referenced_files(
    raw: dict[str, Any], base_dir: Path, known: dict[str, list] | None = None
) -> list[tuple[str | None, str, Path]]:
    """(key, name as written, resolved path) of every existing file the parsed scenario names.
    `known` remembers what each string names, for many runs of one sweep (one look per string)."""
    found: list[tuple[str | None, str, Path]] = []
    for key, written in _string_values(raw):
        named = known.get(written) if known is not None else None
        if named is None:
            named = _named_files(written, base_dir)
            if known is not None:
                known[written] = named
        for name, path in named:
            found.append((key, written, path) if name is not None else (None, str(path), path))
    return found


class BundleBuilder:
    """Collects the files of every run of a sweep into one bundle, reading each file once."""

    def __init__(self, scenario_path: Path) -> None:
        self.scenario_path = scenario_path.resolve()
        self.source = str(scenario_path)
        try:
            self.text = self.scenario_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            from cosim.errors import CosimError

            raise CosimError(f"{scenario_path}: no such scenario file") from None
        self._paths: dict[Path, str] = {}  # resolved path -> SHA-256 hex
        self._data: dict[Path, bytes] = {}
        self._add(self.scenario_path, self.text.encode())
        self._runs: list[tuple[int, tuple, tuple[str, ...], list[tuple[str | None, str, Path]], int]] = []
        self._parsed: dict[str, Any] | None = None
        self._named: dict[str, list] = {}

    def _add(self, path: Path, data: bytes | None = None) -> None:
        if path not in self._paths:
            data = path.read_bytes() if data is None else data
            self._data[path] = data
            self._paths[path] = hashlib.sha256(data).hexdigest()

    def add_run(
        self, index: int, values: tuple, overrides: tuple[str, ...], point: int | None = None
    ) -> None:
        # The scenario is parsed once; each run applies its overrides to a copy (a sweep of 100,000
        # points would otherwise spend minutes parsing the same text).
        if self._parsed is None:
            self._parsed = adapter.raw_toml(self.text, self.source, ())
        raw = adapter.with_overrides(copy.deepcopy(self._parsed), self.source, overrides)
        files = referenced_files(raw, self.scenario_path.parent, self._named)
        for _, _, path in files:
            self._add(path)
        self._runs.append((index, values, overrides, files, index if point is None else point))

    def finish(self) -> tuple[Bundle, list[Run]]:
        root = Path(os.path.commonpath([self.scenario_path.parent, *self._paths]))
        relative = {path: path.relative_to(root).as_posix() for path in self._paths}
        bundle = Bundle(str(root), relative[self.scenario_path])
        for path, name in relative.items():
            bundle.files[name] = self._data[path]
            bundle.digests[name] = self._paths[path]
        runs = []
        for index, values, overrides, files, point in self._runs:
            digest = hashlib.sha256()
            digest.update(b"navcosim sweep run\0" + self.text.encode() + b"\0")
            # Names as written, not bundle paths: the bundle root depends on the other runs. A file
            # no key names (a map YAML's image) by its content alone: its resolved path would make
            # the same sweep in another folder other runs (`--resume` there would redo them all).
            for key, written, path in sorted(files, key=lambda item: (item[0] or "", item[1])):
                digest.update(
                    f"{key or ''} {written if key is not None else ''} {self._paths[path]}\0".encode()
                )
            digest.update("\0".join(overrides).encode())
            references = tuple(FileReference(key, written, relative[path]) for key, written, path in files)
            run_id = digest.hexdigest()[:RUN_ID_LENGTH]
            runs.append(Run(index, run_id, values, overrides, references, point))
        return bundle, runs
