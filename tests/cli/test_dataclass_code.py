"""`cosim.cli.DataclassCode`: the `cosim` program keeps the code `dataclasses` compiles for each class
across processes. A class made with code from the cache has the functions of one made by
`dataclasses` alone (the same code, annotations and behaviour); an unreadable cache is an empty one;
a second process finds everything the first compiled."""

from __future__ import annotations

import dataclasses
import inspect
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import DataclassCode

REPO = Path(__file__).resolve().parents[2]
GENERATED = ("__init__", "__repr__", "__eq__", "__hash__", "__setattr__", "__delattr__")


def _make():
    """A new frozen dataclass (defaults, a factory, annotations) each call, as a module defines one."""

    @dataclasses.dataclass(frozen=True)
    class Pose:
        x: float
        y: float = 2.0
        tags: tuple[str, ...] = ()
        notes: dict = dataclasses.field(default_factory=dict, hash=False)

    return Pose


def _made_with(code: DataclassCode):
    code.install()
    try:
        return _make()
    finally:
        code.uninstall()


def _same_class(made, plain) -> None:
    for name in GENERATED:
        ours, theirs = inspect.unwrap(getattr(made, name)), inspect.unwrap(getattr(plain, name))
        assert ours.__code__ == theirs.__code__, name
        assert ours.__annotations__ == theirs.__annotations__, name
        assert ours.__qualname__.rsplit(".", 1)[-1] == theirs.__qualname__.rsplit(".", 1)[-1]
    a, b = made(1.5, tags=("a",)), plain(1.5, tags=("a",))
    assert repr(a).replace(made.__qualname__, "P") == repr(b).replace(plain.__qualname__, "P")
    assert a == made(1.5, 2.0, ("a",), {}) and hash(a) == hash(made(1.5, tags=("a",)))
    assert a.notes == {} and a.notes is not made(0.0).notes
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.x = 3.0  # type: ignore[misc]


def test_classes_made_with_kept_code_are_those_dataclasses_makes(tmp_path):
    plain = _make()
    path = tmp_path / "code.marshal"
    first = DataclassCode(path)
    made = _made_with(first)
    assert first.compiled == len(GENERATED)  # nothing kept yet: each function compiled
    first.save()
    assert path.is_file() and first.compiled == 0
    second = DataclassCode(path)
    again = _made_with(second)
    assert second.compiled == 0  # every function's code read from the file
    assert "exec" not in vars(dataclasses)  # uninstalled: the builtin again
    _same_class(made, plain)
    _same_class(again, plain)


def test_an_unreadable_cache_is_an_empty_one(tmp_path):
    path = tmp_path / "code.marshal"
    for garbage in (b"", b"\x00not marshal", b"\xfb\x00\x00"):
        path.write_bytes(garbage)
        code = DataclassCode(path)
        _same_class(_made_with(code), _make())
        assert code.compiled == len(GENERATED)
        code.save()
        assert DataclassCode(path).compiled == 0 and path.read_bytes() != garbage


def test_the_file_keeps_what_its_command_uses(tmp_path):
    """Entries this process did not use stay while they are at most as many as those it used; a
    file of more is cut to what was used (so it does not grow without end); a damaged entry is
    compiled again."""
    import marshal

    path = tmp_path / "code.marshal"
    unused = {f"x = {k}": marshal.dumps(compile(f"x = {k}", "<string>", "exec")) for k in range(4)}
    path.write_bytes(marshal.dumps(unused))
    code = DataclassCode(path)
    _made_with(code)
    code.save()
    assert set(unused) < set(marshal.loads(path.read_bytes()))  # 4 unused beside 6 used: kept
    many = {f"y = {k}": marshal.dumps(compile(f"y = {k}", "<string>", "exec")) for k in range(20)}
    path.write_bytes(marshal.dumps(many))
    code = DataclassCode(path)
    _made_with(code)
    code.save()
    kept = marshal.loads(path.read_bytes())
    assert len(kept) == len(GENERATED) and not set(many) & set(kept)
    damaged = {text: data[:5] for text, data in kept.items()}
    path.write_bytes(marshal.dumps(damaged))
    code = DataclassCode(path)
    _same_class(_made_with(code), _make())
    assert code.compiled == len(GENERATED)


@pytest.mark.slow
def test_the_program_keeps_the_code_for_its_next_process(tmp_path):
    """Two `cosim log info` processes: the first writes the cache in the kernels' folder
    ($NAVCOSIM_NATIVE_CACHE), the second compiles nothing new (the file is left as it was) and
    prints the same."""
    sys.path.insert(0, str(REPO / "tests"))
    try:
        from log_synthetic import write_log
    finally:
        sys.path.pop(0)
    log = tmp_path / "run.mcap"
    write_log(log, steps=20)
    env = {**os.environ, "PYTHONPATH": str(REPO), "NAVCOSIM_NATIVE_CACHE": str(tmp_path / "cache")}
    command = [sys.executable, "-m", "cosim", "log", "info", str(log)]
    first = subprocess.run(command, capture_output=True, text=True, env=env, cwd=REPO)
    assert first.returncode == 0, first.stderr
    (kept,) = (tmp_path / "cache").glob("dataclass-code-log-*.marshal")
    written = kept.stat().st_mtime_ns
    second = subprocess.run(command, capture_output=True, text=True, env=env, cwd=REPO)
    assert second.returncode == 0, second.stderr
    assert second.stdout == first.stdout
    assert kept.stat().st_mtime_ns == written
