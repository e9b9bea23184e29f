"""The log's navcosim version read straight from an installed `navcosim-*.dist-info` equals
importlib.metadata's answer (the truth), for the real environment and for made-up `sys.path`s."""

import importlib.metadata
import sys

import pytest

from cosim.record.logfile import dist_info_version, navcosim_version


def _truth() -> str:
    try:
        return importlib.metadata.version("navcosim")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def _dist(folder, name, version):
    info = folder / name
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: navcosim\nVersion: {version}\n\nbody\n")


def test_the_installed_version_is_importlib_metadatas():
    assert navcosim_version() == _truth()


@pytest.mark.parametrize(
    "layout",
    [
        [("a", "navcosim-9.8.7.dist-info", "9.8.7")],
        [("a", "NavCosim-1.2.dist-info", "1.2"), ("b", "navcosim-3.4.dist-info", "3.4")],
        [("a", "other-1.0.dist-info", "1.0"), ("b", "navcosim-5.0rc1.dist-info", "5.0rc1")],
        [("a", "navcosim_extra-1.0.dist-info", "1.0"), ("b", "navcosim-2.0.dist-info", "2.0")],
        [("a", "navcosim-0.3.egg-info", "0.3"), ("b", "navcosim-2.0.dist-info", "2.0")],
        [("a", "navcosim.egg-info", "0.1.0"), ("b", "navcosim-2.0.dist-info", "2.0")],
        [("a", "other-1.0.dist-info", "1.0")],
    ],
)
def test_a_made_up_path_gives_importlib_metadatas_version(tmp_path, monkeypatch, layout):
    for folder, name, version in layout:
        _dist(tmp_path / folder, name, version)
    if layout[0][1].endswith(".egg-info"):  # an egg-info's metadata file is PKG-INFO
        info = tmp_path / layout[0][0] / layout[0][1]
        (info / "METADATA").rename(info / "PKG-INFO")
    folders = sorted({str(tmp_path / folder) for folder, _, _ in layout})
    monkeypatch.setattr(sys, "path", [str(tmp_path / "missing"), *folders])
    fast = dist_info_version("navcosim")
    assert navcosim_version() == _truth()
    if fast is not None:
        assert fast == _truth()


def test_an_editable_checkouts_egg_info_is_read_without_importlib_metadata(tmp_path, monkeypatch):
    """`pip install -e .` leaves `navcosim.egg-info/PKG-INFO` in the checkout, first on `sys.path`
    under `python -m cosim`: its version is read directly, and it is importlib.metadata's."""
    _dist(tmp_path / "a", "navcosim.egg-info", "0.1.0")
    info = tmp_path / "a" / "navcosim.egg-info"
    (info / "METADATA").rename(info / "PKG-INFO")
    monkeypatch.setattr(sys, "path", [str(tmp_path / "a")])
    assert dist_info_version("navcosim") == "0.1.0" == _truth()
