"""Reading a JSON file the application wrote under a named format (``simcal.json``, ``mc.json``)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from labapp.errors import UsageError


def read_format(path: Path, fmt: str, what: str, remedy: str, error: type[UsageError] = UsageError) -> dict[str, Any]:
    """The JSON object in ``path`` whose ``format`` is ``fmt``.

    Parameters
    ----------
    path : Path
    fmt : str
        The format the file must carry, e.g. ``"sfr-simcal/1"``.
    what : str
        What the file is, for messages ("a simulation calibration").
    remedy : str
        How to make a good one ("make one with sfr calibrate-sim").
    error : type
        The `UsageError` subclass raised.

    Raises
    ------
    UsageError
        (``error``) naming the file: unreadable, not JSON, or another format.
    """
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise error(f"{path}: cannot read {what} ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise error(f"{path}: format {found!r} is not {fmt!r}; {remedy}")
    return doc
