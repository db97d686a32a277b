"""Crash-safe file primitives of the records: atomic writes, checksums, safe names, free disk space.

A file written by :func:`atomic_write` (or through :func:`atomic_file`) goes to ``.<name>.part``, is flushed,
fsync'ed and renamed over its name, and the folder is fsync'ed: after a crash the name is either absent or
complete, never partial; after an error (a full disk) the part file is removed as well, and a full,
read-only or forbidden disk is a :class:`WriteError` naming the file.
:class:`StorageError` is the error of every record folder (run folders, :mod:`labapp.records.storage`).
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from labapp.errors import EXIT_USAGE, LabError

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


OUT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM})
"""Errors of the file system that an output on a full, read-only or forbidden disk raises."""


class StorageError(LabError):
    """A run folder could not be created, written or read; the message names the path."""


class WriteError(StorageError):
    """An output could not be written: its disk is full, read-only or forbidden (exit code 2, the output is
    at fault, as for an ``--out`` that cannot be used); the message names the file, and nothing partial is
    left of it."""

    exit_code = EXIT_USAGE


def disk_error(exc: BaseException) -> OSError | None:
    """The full, read-only or forbidden disk behind ``exc``: itself or an error it was raised while handling
    (a compressor that fails on close after its write failed), else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, OSError) and exc.errno in OUT_ERRNOS:
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def sanitize_name(text: str, max_len: int = 64) -> str:
    """A file-system-safe single path component made from user text.

    Keeps letters, digits, ``.``, ``_`` and ``-``; everything else becomes ``_``; leading dots are removed
    so the result is never hidden, ``.`` or ``..``.

    Raises
    ------
    StorageError
        If nothing usable is left of ``text``.
    """
    name = _SAFE.sub("_", text.strip()).lstrip("._")[:max_len].rstrip("._")
    if not name:
        raise StorageError(f"name {text!r} has no usable characters (allowed: letters, digits, . _ -)")
    return name


def timestamp_name(name: str | None = None) -> str:
    """The name of a new folder: ``<YYYYmmdd-HHMMSS>_<sanitised name>`` in local time now (the stamp alone
    without ``name``); run folders, series, designs, sweeps and demos are named so."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return stamp if name is None else f"{stamp}_{sanitize_name(name)}"


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_file(path: str | Path, mode: int = 0o666) -> Iterator[IO[bytes]]:
    """A binary file handle whose contents appear at ``path`` only when the ``with`` block ends without error.

    Written to ``.<name>.part`` beside ``path`` (created with permissions ``mode``, less the umask), flushed,
    fsync'ed, renamed over ``path``; on any error the part file is removed and ``path`` is left as it was.

    Raises
    ------
    WriteError
        When the disk is full, read-only or forbidden (:data:`OUT_ERRNOS`), also behind another error.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.part")
    try:
        with open(tmp, "wb", opener=lambda name, flags: os.open(name, flags, mode)) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException as exc:
        _discard(tmp, path, exc)
        raise


def _discard(tmp: Path, path: Path, exc: BaseException) -> None:
    """Remove the part file ``tmp`` of ``path`` after ``exc``; a full, read-only or forbidden disk raises
    `WriteError` naming ``path`` (any other error is the caller's to re-raise)."""
    tmp.unlink(missing_ok=True)
    cause = disk_error(exc)
    if cause is not None:
        raise WriteError(f"cannot write {path}: {cause.strerror or os.strerror(cause.errno)}; nothing of it was "
                         "left; free space or choose a writable place") from exc


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path for a writer that takes a file name (a CSV writer, ``savefig``): what is written there
    replaces ``path`` (fsync'ed, renamed) when the ``with`` block ends without error; on any error it is
    removed and ``path`` is left as it was. Raises as :func:`atomic_file`."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.part{path.suffix}")      # the suffix kept: writers that choose by it
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException as exc:
        _discard(tmp, path, exc)
        raise


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that ``path`` is either absent or complete, never partial (see
    :func:`atomic_file`, whose errors it raises)."""
    with atomic_file(path) as fh:
        fh.write(data)


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def free_bytes(folder: Path) -> int:
    """Free space, in bytes, on the file system holding ``folder``."""
    return shutil.disk_usage(folder).free


def check_disk_space(folder: Path, frame_bytes: int, n_frames: int, margin: float = 1.5) -> int:
    """Refuse a run that would not fit: returns the free bytes when ``frame_bytes * n_frames * margin`` fit.

    Raises
    ------
    StorageError
        When the estimate exceeds the free space on ``folder``'s file system.
    """
    need = int(frame_bytes * n_frames * margin)
    have = free_bytes(folder)
    if need > have:
        raise StorageError(f"not enough disk space in {folder}: a run of {n_frames} frames of ~{frame_bytes} bytes "
                           f"needs ~{need / 1e9:.2f} GB (x{margin} margin), {have / 1e9:.2f} GB free")
    return have

