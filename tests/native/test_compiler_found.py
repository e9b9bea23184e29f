"""`native.load.compiler_found`: whether `$CC` (its first word: CC may carry a wrapper or flags) or a
cc/gcc/clang on PATH names a program that exists. Truth: the files made in the test."""

from __future__ import annotations

import os
import stat

from native import load as native


def test_compiler_found_follows_cc_and_path(tmp_path, monkeypatch):
    program = tmp_path / "mycc"
    program.write_text("#!/bin/sh\nexit 0\n")
    program.chmod(program.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("CC", f"{program} -O2")
    assert native.compiler_found()
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    assert not native.compiler_found()
    monkeypatch.delenv("CC")
    monkeypatch.setenv("PATH", str(tmp_path))  # no cc, gcc nor clang there
    assert not native.compiler_found()
    (tmp_path / "gcc").symlink_to(program)
    assert native.compiler_found() and os.path.samefile(native.compiler(), program)
