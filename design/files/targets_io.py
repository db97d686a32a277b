"""Reading a design target's files: ``tau_mm,released_mm3`` curves and source meshes.

The numerics of a target (resampling, the horizon and feasibility checks) are `design.inverse.targets`;
`load_problem` reads what a target spec names and prepares the problem (`design.inverse.problem.prepare`).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from design.errors import DesignError
from design.files.meshio import load_mesh
from design.inverse.config import DesignConfig
from design.inverse.problem import Problem, prepare
from design.inverse.target_spec import target_file
from design.inverse.targets import TAU_SAMPLES, Target, target_from_curve


def read_curve_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The ``tau_mm`` and ``released_mm3`` columns of a target CSV, as written (no resampling).

    Raises
    ------
    DesignError
        If the file cannot be read, a row lacks a finite number in either column (the message names the
        row and column), or a time is listed twice.
    """
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise DesignError(f"cannot read a tau_mm,released_mm3 curve from {path}: {exc}") from exc
    values = []
    for line, row in enumerate(rows, start=2):
        pair = []
        for key in ("tau_mm", "released_mm3"):
            try:
                pair.append(float(row[key]))
            except (KeyError, TypeError, ValueError):
                raise DesignError(f"{path} row {line}, {key}: {row.get(key)!r} is not a number; expected a "
                                  "tau_mm,released_mm3 curve") from None
            if not np.isfinite(pair[-1]):
                raise DesignError(f"{path} row {line}, {key}: {row[key]!r}; expected a finite number")
        if values and pair[0] == values[-1][0]:
            raise DesignError(f"{path} row {line}: tau_mm {pair[0]:g} is listed twice (rows {line - 1} and {line}); "
                              "give each time once")
        values.append(pair)
    tau, c = (np.array(col, dtype=float) for col in zip(*values)) if values else (np.array([]), np.array([]))
    if tau.size < 2:
        raise DesignError(f"{path}: a target curve needs >= 2 rows, got {tau.size}")
    return tau, c


def target_from_csv(path: str | Path, total_time_mm: float, samples: int = TAU_SAMPLES) -> Target:
    """Read a ``tau_mm,released_mm3`` CSV and resample it onto the design grid
    (`design.inverse.targets.target_from_curve`).

    Raises
    ------
    DesignError
        If the curve is unreadable or not monotone, or if it still rises after the horizon T.
    """
    tau, c = read_curve_csv(path)
    return target_from_curve(tau, c, total_time_mm, samples, source=str(path))


def load_problem(config: DesignConfig, announce: bool = True) -> Problem:
    """`design.inverse.problem.prepare` with the target's file read: a mesh file's mesh, a CSV's curve (``announce``:
    as `prepare`).

    Raises
    ------
    DesignError
        When the target file is missing or unreadable, and as `prepare` does.
    """
    kind = target_file(config.target)
    if kind == "mesh":
        path = Path(config.target)
        if not path.exists():
            raise DesignError(f"target mesh {path} does not exist")
        return prepare(config, mesh=load_mesh(path), announce=announce)
    if kind == "csv":
        return prepare(config, curve=read_curve_csv(config.target), announce=announce)
    return prepare(config, announce=announce)
