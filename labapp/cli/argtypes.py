"""Argument types for `sfr` numbers: every command-line number is finite and in its meaningful range.

``argparse`` accepts ``nan``, ``inf`` and ``-2`` for ``type=float``/``int``; these types refuse them with a
message naming what was expected (argparse prefixes the option name and exits with code 2). Use them as
``parser.add_argument("--water-g", type=positive_float)``.
"""
from __future__ import annotations

import argparse
import math

__all__ = ["finite_float", "nonnegative_float", "nonnegative_int", "positive_float", "positive_int"]


def finite_float(text: str) -> float:
    """A finite float (no ``nan``, ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number")
    return value


def positive_float(text: str) -> float:
    """A finite float > 0."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number > 0")
    return value


def nonnegative_float(text: str) -> float:
    """A finite float >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number >= 0")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def positive_int(text: str) -> int:
    """An integer >= 1."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 1")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 0")
    return value
