"""Crash-safe file primitives of the records: atomic writes, checksums, safe names, free disk space.

A file written by :func:`atomic_write` goes to ``.<name>.part``, is flushed, fsync'ed and renamed over its
name, and the folder is fsync'ed: after a crash the name is either absent or complete, never partial.
:class:`StorageError` is the error of every record folder (run folders, :mod:`labapp.records.storage`).
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import time
from pathlib import Path

from labapp.errors import LabError

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


class StorageError(LabError):
    """A run folder could not be created, written or read; the message names the path."""


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


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that ``path`` is either absent or complete, never partial."""
    tmp = path.with_name(f".{path.name}.part")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


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

