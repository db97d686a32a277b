"""Ctrl-C and SIGTERM as a request to stop at the next safe point, never as an exception inside compiled code.

Python runs a signal handler in the main thread between two bytecodes, and also whenever compiled code
(a numba kernel's dispatcher, OpenCV, rawpy, nlopt) calls back into the interpreter. A handler that raises
there leaves the compiled caller with an exception it does not expect: numba reports "returned a result
with an exception set", and an interpreter shutting down while decoding threads still run can abort.

So the handler installed by :func:`handling` only records the request (and says so on stderr). The long
jobs call back at safe points (the design loop after each evaluation, the analysis after each frame, the
bench calibration after each image, the simulation calibration after each run and fit, the sweep and
batch polls); the command's callback calls :func:`check` there, which raises :class:`Interrupted` (a
``KeyboardInterrupt``, the exception the design loop and the Dask drivers already treat as Ctrl-C:
checkpoint, write what a stopped run writes). ``sfr`` then prints one line, ``interrupted: ...`` with
what to do next (:func:`set_hint`), and exits with :data:`labapp.errors.EXIT_INTERRUPTED` (130).

A second Ctrl-C quits at once (exit code 130, no clean-up: work since the last checkpoint is lost) unless
the command installed its own second-signal action (the acquisition's abort, which switches the heating
off).
"""
from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from labapp.errors import EXIT_INTERRUPTED

__all__ = ["Interrupted", "check", "handling", "hint", "ignore_while_exiting", "install", "raise_now", "requested",
           "reset", "set_hint", "suspended"]

DEFAULT_HINT = "stopped before its outputs were written; rerun the same command to start again"
"""What an interrupted command says when it set no hint of its own."""

_requests: list[int] = []
_hint: list[str] = []
_actions: list[tuple[str, Callable[[], None] | None, Callable[[], None] | None]] = []


class Interrupted(KeyboardInterrupt):
    """Raised by :func:`check` at a safe point after Ctrl-C or SIGTERM."""


def requested() -> bool:
    """Whether Ctrl-C (or SIGTERM) arrived since :func:`handling` began."""
    return bool(_requests)


def check() -> None:
    """At a safe point: raise :class:`Interrupted` if a stop was requested, else return at once.

    It raises at every safe point after the request, so a job that goes on after one stop (a further stage or
    round) stops at its next; a callback that the job also makes while it stops cleanly (a last progress report)
    checks :func:`requested` itself.
    """
    if _requests:
        raise Interrupted


def raise_now() -> None:
    """An ``on_second`` action for a main thread that only waits in Python (the Dask drivers' polls): raise
    ``KeyboardInterrupt`` from the handler, as Python's own Ctrl-C does, so their ``except`` clauses leave at
    once and the cluster still shuts down."""
    raise KeyboardInterrupt


def set_hint(text: str) -> None:
    """What to do after an interruption of the running command (e.g. how to resume), for its last line."""
    _hint[:] = [text]


def hint() -> str:
    """The running command's hint (:data:`DEFAULT_HINT` if it set none)."""
    return _hint[0] if _hint else DEFAULT_HINT


def reset() -> None:
    """Forget requests and the hint (a new command in the same process, e.g. tests calling ``main``)."""
    _requests.clear()
    _hint.clear()


def _say(text: str) -> None:
    # os.write, not print: the handler may run while the main thread is inside sys.stderr.write
    try:
        os.write(2, text.encode())
    except OSError:
        pass


def _on_signal(signum: int, frame) -> None:
    """Record the request; never raise (see the module docstring)."""
    _requests.append(signum)
    message, first, second = _actions[-1] if _actions else ("", None, None)
    name = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
    if len(_requests) == 1:
        _say(f"\n{name}: {message or 'stopping at the next safe point; Ctrl-C again quits at once'}\n")
        if first is not None:
            first()
    elif second is not None:
        second()
    else:
        _say(f"\n{name} again: quitting at once (no clean-up; work since the last checkpoint is lost)\n")
        os._exit(EXIT_INTERRUPTED)


def install() -> None:
    """Record Ctrl-C and SIGTERM from now until the process exits (``sfr``'s own process: a signal that comes
    while it exits does not turn into a traceback)."""
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def ignore_while_exiting() -> None:
    """Ignore Ctrl-C once the command has returned: Python's shutdown puts the default action back in place of a
    Python handler, and a Ctrl-C then would kill the process during its exit instead of leaving the exit code
    the command gave."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def handling(message: str = "", on_first: Callable[[], None] | None = None,
             on_second: Callable[[], None] | None = None) -> Iterator[None]:
    """Record Ctrl-C and SIGTERM instead of raising, while the block runs (main thread only; elsewhere a no-op).

    Parameters
    ----------
    message : str
        What the first signal does and a second would, for the line on stderr (default "stopping at the next
        safe point; Ctrl-C again quits at once").
    on_first, on_second : callable, optional
        Called (in the signal handler: keep it short, thread-safe and non-raising) on the first signal and on
        every further one; without ``on_second`` a second signal ends the process at once with exit code 130.
        Nested blocks apply their own actions and restore the outer ones when they end.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _actions.append((message, on_first, on_second))
    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _actions.pop()


@contextmanager
def suspended() -> Iterator[None]:
    """Python's own Ctrl-C (``KeyboardInterrupt``) and the default SIGTERM while the block runs: for a command that
    handles signals itself (the GUI's event loop)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signal.SIGINT: signal.signal(signal.SIGINT, signal.default_int_handler),
                signal.SIGTERM: signal.signal(signal.SIGTERM, signal.SIG_DFL)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
