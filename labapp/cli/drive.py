"""Walk an acquisition procedure from the terminal: the engine in its thread, a live status line, Ctrl-C (or a
service manager's SIGTERM) as a clean stop and a second Ctrl-C as an abort (`sfr run`,
`sfr calibrate-bench --record`). The signals are recorded through :mod:`labapp.cli.interrupt`, so ``sfr``
exits with 130 after the clean stop."""
from __future__ import annotations

import math
import shutil
import sys
import time
from collections.abc import Callable

from labapp.acquisition.engine import Engine, Procedure
from labapp.acquisition.status import RunStatus
from labapp.cli import interrupt

_quiet: list[bool] = []


def write_line(text: str, end: str = "\n") -> None:
    """Write to stdout unless its reader has gone (``sfr run | head``): then stay quiet, the run goes on."""
    if _quiet:
        return
    try:
        sys.stdout.write(text + end)
        sys.stdout.flush()
    except (BrokenPipeError, ValueError):
        from labapp.cli.main import _quiet_stdout

        _quiet.append(True)
        _quiet_stdout()


LOG_EVERY_S = 60.0
"""Away from a terminal, the status line is printed at each step (a new phase or frame) and otherwise at least
this often, s."""


def _status_printer(status: RunStatus, tty: bool, now: Callable[[], float] = time.monotonic) -> Callable[[], None]:
    """On a terminal (``tty``) the status line rewritten in place at each call; written to a file or a pipe,
    a line at each step (a new phase or frame) and otherwise every :data:`LOG_EVERY_S`."""
    shown: dict[str, object] = {"step": None, "at": -math.inf}

    def show() -> None:
        if tty:
            width = shutil.get_terminal_size((120, 20)).columns - 1
            write_line("\r" + status.line(width).ljust(width), end="")
            return
        step, t = (status.phase, status.frames), now()
        if step != shown["step"] or t - shown["at"] >= LOG_EVERY_S:
            write_line(status.line())
            shown.update(step=step, at=t)
    return show


def drive(engine: Engine, procedure: Procedure, status: RunStatus,
          started: Callable[[], None] = lambda: None) -> str | None:
    """Walk ``procedure`` on ``engine`` (``status`` subscribed to it) and show the status line until it ends
    (rewritten in place on a terminal; a line per step or per minute in a file or a pipe).

    ``started`` is called once the engine's thread runs (e.g. to wait for the operator's Enter). Returns the
    outcome.
    """
    tty = sys.stdout.isatty()
    show = _status_printer(status, tty)
    with interrupt.handling("stopping cleanly (heating off, folder finalised); Ctrl-C again aborts",
                            on_first=engine.stop, on_second=engine.abort):
        interrupt.check()   # Ctrl-C while the bench was being set up: nothing started
        engine.start(procedure)
        started()
        while engine.join(0.25) is None:
            show()
        show()
    if tty:
        write_line("")
    return engine.outcome
