"""Work the test session does once, however many xdist workers need it.

A module-scoped fixture runs once per worker that runs one of its module's tests: three workers can each spend the
same quarter-minute computing it. `once_per_session` runs it once, under a lock, in a folder of the session's own
temporary root (shared by its workers, never by another session), and the other workers load what it left.
"""
from __future__ import annotations

import fcntl
import os
import pickle
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

T = TypeVar("T")


def once_per_session(factory: pytest.TempPathFactory, name: str, make: Callable[[Path], T]) -> tuple[Path, T]:
    """``make(folder)`` run once in this test session in its folder ``name`` (created empty for it); returns the
    folder and what ``make`` returned (pickled for the other workers). Tests must only read the folder."""
    root = factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent            # the workers' basetemps are folders of the session's root
    folder, done = root / f"once-{name}", root / f"once-{name}.pickle"
    with open(root / f"once-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)     # what a worker that failed left
            folder.mkdir()
            value = make(folder)
            partial = done.with_suffix(".partial")
            partial.write_bytes(pickle.dumps(value))
            partial.rename(done)
        return folder, pickle.loads(done.read_bytes())
