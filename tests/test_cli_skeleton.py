"""The CLI's frame: every sub-command is registered, user errors exit 2 with one line."""

import subprocess
import sys

import pytest

from cosim.cli import COMMANDS, build_parser, main
from cosim.errors import CosimError
from planner.errors import NavcosimError, PlannerError


def test_every_subcommand_is_registered():
    help_text = build_parser().format_help()
    for name in COMMANDS:
        assert name in help_text


def test_project_errors_share_one_base():
    assert issubclass(CosimError, NavcosimError)
    assert issubclass(PlannerError, NavcosimError)


def test_cli_runs_as_module_and_prints_help():
    result = subprocess.run([sys.executable, "-m", "cosim", "--help"], capture_output=True, text=True)
    assert result.returncode == 0
    assert "COMMAND" in result.stdout


def test_missing_command_is_a_usage_error():
    with pytest.raises(SystemExit) as exit_:
        main([])
    assert exit_.value.code == 2
