"""native.load: C kernels built on first use, cached by source hash, loaded with ctypes."""

from __future__ import annotations

import ctypes
import math

import pytest

from native import load as native


def _package(tmp_path, body: str, header: str | None = None):
    (tmp_path / "pkg" / "native").mkdir(parents=True)
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pyproject.toml").write_text("")
    if header is not None:
        (tmp_path / "pkg" / "native" / "k.h").write_text(header)
    source = tmp_path / "pkg" / "native" / "k.c"
    source.write_text(body)
    return source


HYPOT = "#include <math.h>\ndouble hyp(double a, double b) { return sqrt(a * a + b * b); }\n"


def test_builds_loads_and_computes(tmp_path, monkeypatch):
    monkeypatch.delenv("NAVCOSIM_NATIVE_CACHE", raising=False)
    monkeypatch.setattr(native, "_loaded", {})
    source = _package(tmp_path, HYPOT)
    library = native.load(source)
    library.hyp.argtypes = [ctypes.c_double, ctypes.c_double]
    library.hyp.restype = ctypes.c_double
    assert library.hyp(3.0, 4.0) == 5.0
    assert library.hyp(0.1, 0.2) == math.sqrt(0.1 * 0.1 + 0.2 * 0.2)  # IEEE, no FMA contraction
    built = list((tmp_path / "build" / "native").glob("k-*.so"))
    assert [p.name for p in built] == [native.library_name(source)]
    assert native.load(source) is library  # once per process


def test_edit_of_source_or_header_gives_new_library(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_loaded", {})
    source = _package(tmp_path, '#include "k.h"\ndouble f(void) { return K; }\n', "#define K 1.0\n")
    first = native.library_name(source)
    (source.parent / "k.h").write_text("#define K 2.0\n")
    second = native.library_name(source)
    assert first != second
    library = native.load(source)
    library.f.restype = ctypes.c_double
    assert library.f() == 2.0


def test_cache_override_and_prebuilt_copy_is_used(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_loaded", {})
    source = _package(tmp_path, HYPOT)
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    native.load(source)
    assert (tmp_path / "cache" / native.library_name(source)).is_file()
    assert not (tmp_path / "build").exists()


def test_compile_error_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    source = _package(tmp_path, "double f(void) { return undefined_name; }\n")
    with pytest.raises(native.NativeBuildError) as error:
        native.load(source)
    message = str(error.value)
    assert "\n" not in message and "k.c" in message and "undefined_name" in message
    assert list((tmp_path / "cache").iterdir()) == []  # no partial library left behind


def test_missing_compiler_says_what_to_do(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    source = _package(tmp_path, HYPOT)
    with pytest.raises(native.NativeBuildError, match="cannot run the C compiler"):
        native.load(source)
    monkeypatch.delenv("CC")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(native.NativeBuildError, match="no C compiler found"):
        native.compiler()


@pytest.mark.slow
def test_cli_without_a_compiler_says_so_in_one_line(tmp_path):
    """A fresh install on a machine without a C compiler: `cosim plan` exits 2 with one line, no
    traceback, and names what to do."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    environment = dict(os.environ, NAVCOSIM_NATIVE_CACHE=str(tmp_path / "cache"), CC=str(tmp_path / "no-cc"))
    command = [sys.executable, "-m", "cosim", "plan", str(repo / "scenarios/maps/warehouse.yaml")]
    command += ["--start", "6,6", "--goal", "84,53", "--repeat", "1"]
    done = subprocess.run(command, capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("cosim: error: cannot run the C compiler") and done.stderr.count("\n") == 1


def test_bind_types_the_functions_and_can_hold_the_gil(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    library = native.load(_package(tmp_path, HYPOT))
    typed = native.bind(library, {"hyp": (ctypes.c_double, [ctypes.c_double, ctypes.c_double])})
    assert typed is library and typed.hyp(3, 4) == 5.0  # ints converted: the argtypes are set
    held = native.bind(library, {"hyp": (ctypes.c_double, [ctypes.c_double, ctypes.c_double])}, hold_gil=True)
    assert isinstance(held, ctypes.PyDLL) and held._handle == library._handle and held.hyp(6, 8) == 10.0


def _second_package(tmp_path, body: str):
    """Another kernel in the package of `_package` (call that first)."""
    source = tmp_path / "pkg" / "native" / "other.c"
    source.write_text(body)
    return source


def test_started_builds_are_waited_for_by_load(tmp_path, monkeypatch):
    """`start_builds` compiles the missing kernels side by side; `load` takes each from its build,
    the compile errors included; a second call finds them built and starts nothing."""
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setattr(native, "_pending", {})
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    good = _package(tmp_path, HYPOT)
    broken = _second_package(tmp_path, "double g(void) { return undefined_name; }\n")
    with ThreadPoolExecutor(2) as pool:
        assert native.start_builds([good, broken], pool) == [good.resolve(), broken.resolve()]
        assert native.start_builds([good, broken], pool) == []  # under way: not started twice
        library = native.bind(native.load(good), {"hyp": (ctypes.c_double, [ctypes.c_double] * 2)})
        assert library.hyp(3.0, 4.0) == 5.0
        with pytest.raises(native.NativeBuildError, match="compiling other.c failed: .*undefined_name"):
            native.load(broken)
    assert native._pending == {}
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [native.library_name(good)]
    with ThreadPoolExecutor(2) as pool:
        assert native.start_builds([good], pool) == []  # built (and loaded)
        monkeypatch.setattr(native, "_loaded", {})
        assert native.start_builds([good], pool) == []  # built: found in the cache


def test_a_forked_child_loads_what_its_parent_is_still_building(tmp_path, monkeypatch):
    """A process forked while a build of its parent is pending (`cosim run`'s plot process, during a
    first run's builds) has no build thread: its `load` builds or finds the library itself instead
    of waiting for the parent's build forever."""
    import os
    import threading
    import time
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setattr(native, "_pending", {})
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "cache"))
    good = _package(tmp_path, HYPOT)
    hold = threading.Event()
    with ThreadPoolExecutor(1) as pool:
        pool.submit(hold.wait)  # the one build thread is busy: the build below waits in the queue
        assert native.start_builds([good], pool) == [good.resolve()]
        pid = os.fork()
        if pid == 0:  # the child: exit 0 when the kernel loaded and computes
            code = 1
            try:
                library = native.bind(native.load(good), {"hyp": (ctypes.c_double, [ctypes.c_double] * 2)})
                code = 0 if library.hyp(3.0, 4.0) == 5.0 else 2
            finally:
                os._exit(code)
        deadline = time.monotonic() + 120.0  # a guard against a hang, not a speed limit
        while (done := os.waitpid(pid, os.WNOHANG))[0] == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        if done[0] == 0:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
        hold.set()
        assert done[0] == pid, "the child waited for its parent's build"
        assert os.waitstatus_to_exitcode(done[1]) == 0
        assert native.load(good) is not None  # the parent's own build still completes


def test_run_compiler_is_subprocess_run():
    done = native.run_compiler(["sh", "-c", "echo out; echo err >&2; exit 3"])
    assert (done.returncode, done.stdout, done.stderr) == (3, "out\n", "err\n")
