"""A simulation calibration's set file (``run,mesh,object_mass_g``) and what identifies a measured run.

:func:`read_set` reads the set ``sfr calibrate-sim`` and the GUI's calibration wizard calibrate on, refusing a
missing column, run or mesh, a mass that is not a positive number, fewer than two runs and a run listed twice
(by path, or as two copies with the same :func:`run_identity`).
"""
from __future__ import annotations

import csv
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

from labapp.records.fileio import sha256_file
from labapp.records.manifests import FRAMES_CSV
from labapp.records.simcal import SimCalError

SET_COLUMNS = ("run", "mesh", "object_mass_g")
"""The columns a set file must have (``water_g`` and ``barrier_mesh`` are optional)."""


@dataclass(frozen=True)
class SetRow:
    """One line of a calibration set file (row 1 = first data row)."""

    row: int
    run: Path
    mesh: Path
    object_mass_g: float | None
    water_g: float | None = None
    barrier_mesh: Path | None = None
    """A clear barrier printed around the drug ``mesh`` (a coated print, :mod:`labapp.jobs.calibrate_barrier`)."""


def read_set(path: str | Path) -> list[SetRow]:
    """Read a calibration set file: columns ``run,mesh,object_mass_g`` (and optionally ``water_g`` and
    ``barrier_mesh``, a coated print's barrier), paths relative to the file.

    Raises
    ------
    SimCalError
        Missing columns, a missing run or mesh (file and row named), a mass that is not a positive number.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            header = [h.strip() for h in reader.fieldnames or []]
            rows = list(reader)
    except OSError as exc:
        raise SimCalError(f"{path}: cannot read the set file ({exc.strerror or exc})") from exc
    missing = [c for c in SET_COLUMNS if c not in header]
    if missing:
        raise SimCalError(f"{path}: no column {', '.join(missing)}; expected {','.join(SET_COLUMNS)}")
    out = []
    for i, row in enumerate(rows, start=1):
        row = {k.strip(): (v or "").strip() for k, v in row.items() if k is not None}
        run, mesh = path.parent / row["run"], path.parent / row["mesh"]
        for what, p in (("run", run), ("mesh", mesh)):
            if not row[what] or not p.exists():
                raise SimCalError(f"{path}: row {i}: {what} {row[what]!r} does not exist (looked for {p})")
        barrier = path.parent / row["barrier_mesh"] if row.get("barrier_mesh") else None
        if barrier is not None and not barrier.is_file():
            raise SimCalError(f"{path}: row {i}: barrier_mesh {row['barrier_mesh']!r} does not exist (looked for "
                              f"{barrier})")
        grams = {}
        for column in ("object_mass_g", "water_g"):
            text = row.get(column, "")
            if not text:
                continue
            try:
                grams[column] = float(text)
            except ValueError:
                grams[column] = math.nan
            if not (math.isfinite(grams[column]) and grams[column] > 0):
                raise SimCalError(f"{path}: row {i}: {column} {text!r} is not a positive number of grams")
        out.append(SetRow(i, run, mesh, grams.get("object_mass_g"), grams.get("water_g"), barrier))
    if len(out) < 2:
        raise SimCalError(f"{path}: {len(out)} runs; a calibration needs at least 2 (4 or more recommended)")
    _refuse_repeated_runs(path, out)
    return out


def row_inputs(row: SetRow) -> list[Path]:
    """The files a row's calibration reads: its mesh, its barrier mesh if any, and its run (a curve file, or a run
    folder's ``frames.csv``, ``run.json`` and ``calibration.json`` where present)."""
    files = [row.mesh] + ([row.barrier_mesh] if row.barrier_mesh is not None else [])
    if not row.run.is_dir():
        return files + [row.run]
    return files + [p for p in (row.run / FRAMES_CSV, row.run / "run.json", row.run / "calibration.json") if p.is_file()]


def run_identity(run: Path) -> str:
    """SHA-256 of what identifies a run's measurement: a run folder's manifest (``frames.csv``, which lists every
    frame with its own SHA-256), for a folder without one all its files, for a curve file its bytes. Two copies
    of one run have the same identity wherever they lie."""
    if run.is_file():
        return sha256_file(run)
    if (run / FRAMES_CSV).is_file():
        return sha256_file(run / FRAMES_CSV)
    digest = hashlib.sha256()
    for p in sorted(q for q in run.rglob("*") if q.is_file() and not q.name.startswith(".")):
        digest.update(f"{p.relative_to(run)}\0{sha256_file(p)}\n".encode())
    return digest.hexdigest()


def _refuse_repeated_runs(path: Path, rows: list[SetRow]) -> None:
    """The same measured run twice (one path, or two copies with the same manifest) makes the leave-one-out
    meaningless: the left-out run is still in the fit."""
    by_path: dict[Path, SetRow] = {}
    by_content: dict[str, SetRow] = {}
    for row in rows:
        resolved = row.run.resolve()
        first = by_path.get(resolved)
        if first is not None:
            raise SimCalError(f"{path}: rows {first.row} and {row.row} list the same run {resolved}; each run may "
                              "be listed once (its leave-one-out would otherwise keep it in the fit)")
        by_path[resolved] = row
        try:
            identity = run_identity(row.run)
        except OSError as exc:
            raise SimCalError(f"{path}: row {row.row}: cannot read run {row.run} ({exc.strerror or exc})") from exc
        first = by_content.get(identity)
        if first is not None:
            what = "manifest (frames.csv)" if (row.run / FRAMES_CSV).is_file() else "content"
            raise SimCalError(f"{path}: rows {first.row} and {row.row} list the same run twice: {first.run} and "
                              f"{row.run} have an identical {what} (SHA-256 {identity[:12]}...); each run may be "
                              "listed once (its leave-one-out would otherwise keep it in the fit)")
        by_content[identity] = row
