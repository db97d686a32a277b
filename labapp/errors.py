"""The exceptions of :mod:`labapp` and the exit code each maps to.

Every error the bench application raises on purpose derives from :class:`LabError`. Two kinds matter to
the operator and to scripts calling ``sfr``:

- :class:`UsageError` (exit code 2): the input or the request is wrong (a bad number, a file that does
  not exist, an ``--out`` that would overwrite something); nothing was done, fix the input and rerun.
- :class:`JobFailed` and every other :class:`LabError` (exit code 1): the input was fine but the job
  could not be completed (a device failed, a run ended ``failed``).

The mapping of these and the other packages' errors to exit codes is in :func:`labapp.cli.main.exit_code`.
"""
from __future__ import annotations

__all__ = ["EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "JobFailed", "LabError", "UsageError"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
"""Ctrl-C or SIGTERM stopped the command (at a safe point: what it wrote is consistent)."""


class LabError(Exception):
    """Base of every deliberate :mod:`labapp` error; the message names the file, field or device and why."""

    exit_code = EXIT_FAILED


class UsageError(LabError, ValueError):
    """Bad input or a request that cannot be honoured as given; nothing has been written."""

    exit_code = EXIT_USAGE


class JobFailed(LabError):
    """A job started on valid input but did not complete (its record, if any, says how far it got)."""

    exit_code = EXIT_FAILED
