"""Requests to the process recording a run, from another process or thread (`sfr change`, the GUI).

A request is a JSON file in ``RUN/.sfr-requests/`` (a dot folder: ``verify`` and ``folder_kind`` ignore it, so
it never changes what the record is). The recording process claims a request by renaming it, carries it out
at its next safe point (the next frame) and writes the answer beside it; the asker reads the answer and
removes it. An asker that gives up withdraws its request, unless it has been claimed, so a request is carried
out at most once and never after its asker stopped waiting.
"""
from __future__ import annotations

import json
import os
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from labapp.records.fileio import atomic_write

__all__ = ["REQUESTS_DIR", "answer", "claim", "post", "wait_answer", "withdraw"]

REQUESTS_DIR = ".sfr-requests"
"""The folder of pending requests and their answers inside a run folder."""
_ASKED, _TAKEN, _ANSWER = ".json", ".taken", ".answer"


def post(folder: str | Path, body: dict[str, Any]) -> Path:
    """Leave the request ``body`` for the process recording ``folder``; the request's file."""
    box = Path(folder) / REQUESTS_DIR
    box.mkdir(exist_ok=True)
    path = box / f"{time.time_ns()}-{uuid.uuid4().hex[:8]}{_ASKED}"
    atomic_write(path, json.dumps(body).encode())
    return path


def claim(folder: str | Path) -> Iterator[tuple[Path, dict[str, Any] | None]]:
    """The pending requests of ``folder`` in the order they came, each claimed as it is yielded: (its file,
    its body, None for a file that is not a JSON object). Answer each with :func:`answer`."""
    box = Path(folder) / REQUESTS_DIR
    if not box.is_dir():
        return
    for path in sorted(box.glob(f"*{_ASKED}")):
        taken = path.with_suffix(_TAKEN)
        try:
            os.replace(path, taken)
        except FileNotFoundError:       # withdrawn meanwhile
            continue
        try:
            body = json.loads(taken.read_text())
        except (OSError, ValueError):
            body = None
        yield path, body if isinstance(body, dict) else None


def answer(request: Path, outcome: dict[str, Any]) -> None:
    """Answer the claimed ``request`` with ``outcome``."""
    atomic_write(request.with_suffix(_ANSWER), json.dumps(outcome).encode())
    request.with_suffix(_TAKEN).unlink(missing_ok=True)


def withdraw(request: Path) -> bool:
    """Take back a request not yet claimed; False when the recording process has claimed it already."""
    try:
        request.unlink()
        return True
    except FileNotFoundError:
        return False


def wait_answer(request: Path, timeout_s: float, should_stop: Callable[[], bool] = lambda: False,
                poll_s: float = 0.2) -> dict[str, Any] | None:
    """The answer to ``request`` (read and removed), or None when none came within ``timeout_s`` seconds or
    ``should_stop()``: the request is then withdrawn; one already claimed is waited for a further
    ``timeout_s`` (its answer says what was done)."""
    reply = request.with_suffix(_ANSWER)
    deadline, claimed_deadline = time.monotonic() + timeout_s, None
    while not reply.exists():
        now = time.monotonic()
        if claimed_deadline is None and (now > deadline or should_stop()):
            if withdraw(request):
                return None
            claimed_deadline = now + timeout_s
        elif claimed_deadline is not None and now > claimed_deadline:
            return None
        time.sleep(poll_s)
    outcome = json.loads(reply.read_text())
    reply.unlink(missing_ok=True)
    return outcome
