"""The base exception of the `design` package."""
from __future__ import annotations


class DesignError(Exception):
    """Invalid input or a broken invariant in the simulator or optimiser (`design` package)."""
