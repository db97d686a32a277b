"""Loaders of the published dissolution data in tests/analysis/data (see its SOURCES.md)."""
import csv
from pathlib import Path

import numpy as np

from analysis.replicates import ReplicateSet

DATA = Path(__file__).parent / "data"


def shah1998(batch: str) -> ReplicateSet:
    """A batch of Shah et al. 1998 (``ref``, ``test1`` ... ``test5``): 12 units, minutes."""
    a = np.loadtxt(DATA / f"shah1998_{batch}.csv", delimiter=",", skiprows=1)
    return ReplicateSet(a[:, 0], a[:, 1:].T, "min", batch)


def dip(name: str, column: str, level: str, times: list[str]) -> ReplicateSet:
    """The rows of disprofas' ``name`` whose ``column`` is ``level``, at the columns ``times`` (``t.15``)."""
    with open(DATA / f"{name}.csv") as f:
        rows = [r for r in csv.DictReader(f) if r[column] == level]
    units = np.array([[float(r[c]) for c in times] for r in rows])
    return ReplicateSet([float(c.split(".")[1]) for c in times], units, "min", level)
