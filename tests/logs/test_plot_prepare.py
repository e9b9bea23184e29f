"""What the plot process imports ahead (`cosim.logs.plot.prepare_drawing`): a module put in place by
`runs_when_used` runs its code only when a name of it is first looked up, and then holds what an
import would have given it; `fontTools.agl` (read by matplotlib only for usetex text) so."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cosim.logs import plot

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A package `lazy_pkg` with a module `counted` that counts its runs in `lazy_pkg.RUNS`."""
    root = tmp_path / "lazy_pkg"
    root.mkdir()
    (root / "__init__.py").write_text("RUNS = []\n")
    counted = "import lazy_pkg\nlazy_pkg.RUNS.append(1)\nVALUE = 42\n\n\ndef twice(x):\n    return 2 * x\n"
    (root / "counted.py").write_text(counted)
    (root / "broken.py").write_text("raise RuntimeError('broken on purpose')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "lazy_pkg"
    for name in [name for name in sys.modules if name.split(".")[0] == "lazy_pkg"]:
        del sys.modules[name]


def test_a_module_put_in_place_runs_when_first_used(package):
    import importlib

    module = plot.runs_when_used("lazy_pkg.counted")
    import lazy_pkg  # noqa: I001 (after it is put in place)
    import lazy_pkg.counted
    from lazy_pkg import counted

    assert counted is module is lazy_pkg.counted is sys.modules["lazy_pkg.counted"]
    assert counted.__name__ == "lazy_pkg.counted" and lazy_pkg.RUNS == []  # importing it ran nothing
    assert counted.VALUE == 42 and counted.twice(4) == 8 and lazy_pkg.RUNS == [1]
    assert type(counted) is type(lazy_pkg) and importlib.import_module("lazy_pkg.counted") is counted
    assert lazy_pkg.RUNS == [1]  # once
    assert plot.runs_when_used("lazy_pkg.counted") is None  # imported already: nothing done
    assert plot.runs_when_used("lazy_pkg.missing") is None and "lazy_pkg.missing" not in sys.modules


def test_a_module_that_fails_when_used_fails_as_its_import_would(package):
    plot.runs_when_used("lazy_pkg.broken")
    from lazy_pkg import broken

    with pytest.raises(RuntimeError, match="broken on purpose"):
        broken.anything  # noqa: B018
    assert "lazy_pkg.broken" not in sys.modules
    with pytest.raises(RuntimeError, match="broken on purpose"):
        import lazy_pkg.broken  # noqa: F401 (imported anew, failing again)


@pytest.mark.slow  # a fresh interpreter
def test_prepare_drawing_leaves_the_glyph_names_to_their_first_use():
    code = textwrap.dedent(
        """
        import sys
        from cosim.logs.plot import prepare_drawing

        prepare_drawing()
        agl = sys.modules["fontTools.agl"]
        print("AGL2UV" in vars(agl))
        from matplotlib import dviread

        print(dviread.fontTools.agl.toUnicode("Aacute") == "\\u00c1", "AGL2UV" in vars(agl))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert done.stdout.split() == ["False", "True", "True"]
