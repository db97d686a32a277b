"""The time left as the command line's progress lines show it."""
from __future__ import annotations


def eta_text(seconds: float | None) -> str:
    """``ETA 45 s`` below a minute, ``ETA 1.2 min`` from there, ``ETA -`` before a job has measured its pace (None)."""
    if seconds is None:
        return "ETA -"
    return f"ETA {seconds / 60:.1f} min" if seconds >= 60 else f"ETA {seconds:.0f} s"
