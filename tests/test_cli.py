"""The `sfr` entry point discovers its subcommands."""
import subprocess
import sys

from labapp.cli.main import build_parser


def test_every_command_module_is_complete():
    parser = build_parser()
    names = set(parser._subparsers._group_actions[0].choices)
    assert names, "no subcommands discovered"


def test_help_runs_as_a_process():
    out = subprocess.run([sys.executable, "-m", "labapp.cli.main", "--help"], capture_output=True, text=True, check=True)
    assert "COMMAND" in out.stdout
