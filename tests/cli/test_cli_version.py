"""`cosim --version` prints the installed distribution's version, as pip sees it."""

from importlib.metadata import version

import pytest

from cosim.cli import main


def test_version_prints_installed_distribution(capsys):
    with pytest.raises(SystemExit) as ended:
        main(["--version"])
    assert ended.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"navcosim {version('navcosim')} ")
    assert f"fmpy {version('fmpy')}" in out


def test_version_is_listed_in_help(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "--version" in capsys.readouterr().out
