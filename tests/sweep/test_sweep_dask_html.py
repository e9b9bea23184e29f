"""Dask imported without its HTML templates' engine (`cosim.sweep.warm.import_dask(html=False)`, as
the `cosim` program imports it): jinja2 is not imported with Dask, Dask's own fallback for a
missing jinja2 is what renders HTML then (an ImportError), and jinja2 stays importable. Truth: Dask's
behaviour with jinja2 present, in the same fresh interpreter's terms."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("jinja2")
REPO = Path(__file__).resolve().parents[2]

CODE = """
import sys
from cosim.sweep.warm import import_dask
import_dask(html={html})
import dask.widgets
from distributed import Client, LocalCluster
print("jinja2" in sys.modules)
try:
    print(type(dask.widgets.get_template("client.html.j2")).__name__)
except ImportError:
    print("ImportError")
import jinja2
print(jinja2.Environment.__name__)
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    "html, expected",
    [(True, ["True", "Template", "Environment"]), (False, ["False", "ImportError", "Environment"])],
)
def test_dask_without_html_leaves_jinja2_out_but_importable(html, expected):
    result = subprocess.run(
        [sys.executable, "-c", CODE.format(html=html)], capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == expected
