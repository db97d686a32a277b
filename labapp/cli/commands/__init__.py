"""Subcommands of `sfr`, one module each (discovered by `labapp.cli.main`)."""
