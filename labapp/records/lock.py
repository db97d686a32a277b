"""One writer per output folder: an advisory lock held while a command writes the folder.

:func:`folder_lock` takes an exclusive ``fcntl.flock`` on ``FOLDER/.sfr.lock`` and writes who holds it (process
id, host, command, since when) into that file. A second command that would write the same folder is refused
at once with :class:`FolderLocked` (exit code 2) naming the holder. The operating system releases the lock
when the holding process ends, however it ends; a lock file left behind by a killed process is harmless (the
next writer takes the lock on it). A clean release removes the file, and a folder the lock itself created is
removed again when nothing else was written into it. ``folder_kind`` and ``verify`` ignore dot files, so the
lock file never changes what a folder is.

The lock is re-entrant within one thread (a command and the job it calls may both take it); another thread
of the same process is refused like another process.
"""
from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
import socket
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from labapp.errors import UsageError

__all__ = ["LOCK_NAME", "FolderLocked", "folder_lock", "holder"]

LOCK_NAME = ".sfr.lock"
"""The lock file inside a locked folder."""

_held: dict[tuple[Path, int], int] = {}
"""(folder, thread id) -> nesting depth of the locks this process holds."""


class FolderLocked(UsageError):
    """The folder is being written by another command (the message names it)."""


def _describe(info: dict) -> str:
    if not info:
        return "a process that has not recorded itself yet"
    return (f"process {info.get('pid', '?')} on {info.get('host', '?')}, `{info.get('command', '?')}`, "
            f"since {info.get('since', '?')}")


def holder(folder: str | Path) -> dict | None:
    """Who holds the lock on ``folder`` (``pid``, ``host``, ``command``, ``since``), or None when nobody does."""
    path = Path(folder) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_info(fd)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _read_info(fd: int) -> dict:
    try:
        info = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def _make_dirs(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; the ones created, outermost first."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot create the folder {folder}: {exc.strerror or exc}") from exc
    return missing


def _remove_empty(created: list[Path]) -> None:
    for path in reversed(created):
        try:
            path.rmdir()
        except OSError:
            return


def _acquire(folder: Path, command: str) -> int:
    path = folder / LOCK_NAME
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise UsageError(f"cannot write in {folder} ({path}: {exc.strerror or exc}); choose a writable "
                             "folder") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            info = _read_info(fd)
            os.close(fd)
            raise FolderLocked(f"{folder} is being written by {_describe(info)}; wait until it ends or stop it, "
                               "or choose another folder") from None
        # the holder before us may have removed the file between our open and our lock: lock the file there now
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    info = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
            "since": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
    except OSError:
        pass    # a full disk: the lock holds all the same, only the holder's description is missing
    return fd


@contextmanager
def folder_lock(folder: str | Path, command: str | None = None) -> Iterator[Path]:
    """Hold the write lock on ``folder`` (created if missing) while the block runs; yields the resolved folder.

    Parameters
    ----------
    folder : str or Path
        The output folder a command is about to write.
    command : str, optional
        How the holder is described to a refused writer (default: this process's command line).

    Raises
    ------
    FolderLocked
        When another process (or thread) holds the lock; the message names the holder.
    UsageError
        When the folder cannot be created or written (read-only, no permission), naming it.
    """
    folder = Path(folder).expanduser().resolve()
    key = (folder, threading.get_ident())
    if key in _held:
        _held[key] += 1
        try:
            yield folder
        finally:
            _held[key] -= 1
        return
    created = _make_dirs(folder)
    try:
        fd = _acquire(folder, command or " ".join(["sfr", *sys.argv[1:]]))
    except BaseException:
        _remove_empty(created)
        raise
    _held[key] = 1
    try:
        yield folder
    finally:
        del _held[key]
        try:
            os.unlink(folder / LOCK_NAME)     # still locked: a writer that opened it now retries on a new file
        except OSError:
            pass
        os.close(fd)
        _remove_empty(created)
