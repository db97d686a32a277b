"""One reader for every physical release curve the project writes or records.

Accepted sources (a file or a folder):

- ``sfr analyze``'s ``curve.csv`` (``t_s,...,released_g``; the water mass follows from
  ``released_g / conc_smooth_g_per_kg``, and a ``run.json`` beside it or one level up gives the weighed mass);
- ``sfr simulate --simcal``'s ``release_physical.csv`` (``t_s,released_g,conc_g_per_kg``);
- ``sfr design --simcal``'s ``curves_physical.csv`` (``t_s,target_released_g,design_released_g``; the
  design column unless ``column`` says otherwise);
- any CSV with ``t_s`` and ``released_g`` columns;
- a run folder recorded by the app (``frames.csv`` + ``run.json``): analysed with the given bench
  calibration, else its own ``calibration.json``; weighed and water mass come from ``run.json``;
- a folder holding exactly one of the CSVs above (an analysis, simulation or design folder).

Every value is checked: a NaN or infinite entry, or a time that does not increase, is an error naming the
file and its row (row 1 is the first data row after the header). A CSV whose times end before
:data:`MIN_SPAN_S` is refused as times in hours or minutes (but ``sfr analyze``'s ``curve.csv``, whose times
are its frames' own), and :func:`check_same_unit` refuses the one
of several curves whose times are a unit's factor (60, 3600) shorter than another's, naming it.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import AnalysisError, BenchCalibration, analyze_run
from labapp.errors import UsageError
from labapp.records.manifests import RUN_JSON, RecordReadError, read_record
from labapp.records.runrecord import RunRecord

CURVE_FILES = ("curve.csv", "release_physical.csv", "curves_physical.csv")
"""The physical curve files the project writes, looked for in that order inside a folder."""
_DEFAULT_COLUMN = {"curves_physical.csv": "design_released_g"}


MIN_SPAN_S = 60.0
"""The shortest release a curve of this bench spans, s: a printed object dissolves over minutes to hours and a
frame is taken every few seconds, so a curve that ends sooner has its times in hours or minutes (a 2.43 h
run written in hours ends at t_s = 2.43)."""
UNIT_FACTORS = {"minutes": 60.0, "hours": 3600.0}
"""The factors by which times in another unit fall short of seconds, with the unit's name."""
UNIT_FACTOR_TOLERANCE = 1.5
"""How far (as a factor either way) the ratio of two curves' spans may be from a unit factor to be read as one:
two runs of one product differ in length by far less than the factor itself."""


class CurveFileError(UsageError):
    """A curve file or run folder that cannot be read as a physical release curve."""


@dataclass(frozen=True, eq=False)
class PhysicalCurve:
    """A cumulative release curve in physical units.

    Attributes
    ----------
    t_s : (N,) ndarray of float, s since the drop, strictly increasing
    released_g : (N,) ndarray of float, g of released solid
    object_mass_g : float or None
        Weighed mass of the object, g, when the source records it.
    water_g : float or None
        Water in the beaker, g, when the source records it.
    source : str
        The file or folder read (with the column, when not ``released_g``).
    """

    t_s: np.ndarray
    released_g: np.ndarray
    object_mass_g: float | None
    water_g: float | None
    source: str


def _positive_or_none(value: object) -> float | None:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def _record(folder: Path) -> RunRecord | None:
    """The record in ``folder`` (None without a ``run.json``)."""
    path = folder / RUN_JSON
    if not path.is_file():
        return None
    try:
        return read_record(folder)
    except RecordReadError as exc:
        raise CurveFileError(f"{path}: not readable JSON ({exc.reason})") from exc


def check_curve(t_s: np.ndarray, released_g: np.ndarray, source: str) -> None:
    """Raise :class:`CurveFileError` naming ``source`` and the row of the first bad value.

    Parameters
    ----------
    t_s, released_g : (N,) ndarray of float
    source : str
        Named in the message.
    """
    if t_s.size < 2:
        raise CurveFileError(f"{source}: {t_s.size} data rows; a release curve needs at least 2")
    for name, values in (("t_s", t_s), ("released_g", released_g)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise CurveFileError(f"{source}: row {bad[0] + 1}: {name} = {float(values[bad[0]])} is not a finite number")
    if t_s[0] < 0:
        raise CurveFileError(f"{source}: row 1: t_s = {t_s[0]:g} s; times count from the drop (t = 0), never negative")
    steps = np.flatnonzero(np.diff(t_s) <= 0)
    if steps.size:
        i = steps[0] + 1
        raise CurveFileError(f"{source}: row {i + 1}: t_s = {t_s[i]:g} s does not increase "
                             f"(row {i} has {t_s[i - 1]:g} s); times must increase strictly")


def check_time_unit(t_s: np.ndarray, source: str) -> None:
    """Refuse times that end before :data:`MIN_SPAN_S`: hours or minutes written as ``t_s``.

    Raises
    ------
    CurveFileError
        Naming ``source``, the last time and what it would be in hours and in minutes.
    """
    end = float(t_s[-1])
    if end < MIN_SPAN_S:
        raise CurveFileError(f"{source}: t_s ends at {end:g}, a release over {end:g} s; a curve of this bench spans "
                             f"at least {MIN_SPAN_S:g} s, so its times look like hours ({end:g} h = {end * 3600:g} s) "
                             f"or minutes ({end * 60:g} s): t_s must be seconds since the drop")


def _unit_between(short_s: float, long_s: float) -> str | None:
    """The unit (``"hours"``, ``"minutes"``) whose factor the ratio of two spans is, within the tolerance."""
    if not short_s > 0:
        return None
    ratio = long_s / short_s
    return next((name for name, factor in UNIT_FACTORS.items()
                 if factor / UNIT_FACTOR_TOLERANCE <= ratio <= factor * UNIT_FACTOR_TOLERANCE), None)


def check_same_unit(spans: list[tuple[str, float]]) -> None:
    """Refuse curves whose times are not all in one unit: of ``(source, span s)`` pairs, the shortest against the
    longest; a span a unit's factor shorter (:data:`UNIT_FACTORS`) is that unit written as seconds.

    Raises
    ------
    CurveFileError
        Naming the curve at fault, the curve it was measured against and the unit its times look like.
    """
    if len(spans) < 2:
        return
    (short, short_s), (long, long_s) = min(spans, key=lambda p: p[1]), max(spans, key=lambda p: p[1])
    unit = _unit_between(short_s, long_s)
    if unit is not None:
        raise CurveFileError(f"{short}: t_s spans {short_s:g} s, {long_s / short_s:.0f} times less than {long} "
                             f"({long_s:g} s): its times look like {unit}, not seconds; convert t_s to seconds "
                             f"since the drop")


def read_header(path: str | Path) -> list[str]:
    """The column names of a curve CSV's first line (empty for an empty or unreadable file)."""
    try:
        with open(path, newline="") as fh:
            return [h.strip() for h in next(csv.reader(fh), [])]
    except (OSError, UnicodeDecodeError):
        return []


def _read_csv(path: Path, column: str | None) -> PhysicalCurve:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError) as exc:
        raise CurveFileError(f"{path}: cannot read ({exc})") from exc
    if not rows:
        raise CurveFileError(f"{path}: empty file; expected a header with t_s and released_g")
    header = [h.strip() for h in rows[0]]
    column = column or _DEFAULT_COLUMN.get(path.name, "released_g")
    missing = [c for c in ("t_s", column) if c not in header]
    if missing:
        raise CurveFileError(f"{path}: no column {', '.join(missing)}; the header has {', '.join(header)} "
                             f"(expected t_s and {column})")
    cols = {name: header.index(name) for name in header}

    def numbers(name: str) -> np.ndarray:
        out = np.empty(len(rows) - 1)
        for r, row in enumerate(rows[1:], start=1):
            try:
                out[r - 1] = float(row[cols[name]])
            except (IndexError, ValueError):
                cell = row[cols[name]] if cols[name] < len(row) else "<missing>"
                raise CurveFileError(f"{path}: row {r}: {name} = {cell!r} is not a number") from None
        return out

    t_s, released = numbers("t_s"), numbers(column)
    source = str(path) if column == "released_g" else f"{path} ({column})"
    check_curve(t_s, released, source)
    if "file" not in cols:      # sfr analyze's curve.csv names each frame: its times are the frames' own, in s
        check_time_unit(t_s, source)
    water = None
    conc_col = next((c for c in ("conc_smooth_g_per_kg", "conc_g_per_kg") if c in cols), None)
    if conc_col is not None and column == "released_g":
        conc = numbers(conc_col)
        ok = np.isfinite(conc) & (np.abs(conc) > 1e-9)
        if ok.any():
            water = _positive_or_none(float(np.median(released[ok] / conc[ok])) * 1000.0)
    record = _record(path.parent) or _record(path.parent.parent)
    mass = _positive_or_none(record.object_mass_g) if record is not None else None
    if water is None and record is not None:
        water = _positive_or_none(record.water_g)
    return PhysicalCurve(t_s, released, mass, None if water is None else round(water, 6), source)


def _read_run(folder: Path, calibration: BenchCalibration | None, cache_dir: Path | None) -> PhysicalCurve:
    record = _record(folder)
    if calibration is None:
        cal_path = folder / "calibration.json"
        if not cal_path.is_file():
            raise CurveFileError(f"{folder}: a run folder without calibration.json; give a bench calibration")
        try:
            calibration = BenchCalibration.load(cal_path)
        except (AnalysisError, OSError, ValueError) as exc:
            raise CurveFileError(f"{cal_path}: {exc}") from exc
    try:
        curve = analyze_run(folder, calibration, cache_dir=cache_dir)
    except AnalysisError as exc:
        raise CurveFileError(f"{folder}: {exc}") from exc
    check_curve(curve.t_s, curve.released_g, str(folder))
    mass = _positive_or_none(record.object_mass_g) if record is not None else None
    return PhysicalCurve(curve.t_s, curve.released_g, mass, curve.water_g, str(folder))


def read_physical_curve(path: str | Path, *, calibration=None, column: str | None = None,
                        cache_dir: str | Path | None = None) -> PhysicalCurve:
    """Read any physical release curve of the project (see the module docstring for the sources).

    Parameters
    ----------
    path : str or Path
        A curve CSV, a run folder, or a folder holding one curve CSV.
    calibration : analysis.BenchCalibration, optional
        For a run folder: the bench calibration to analyse it with (default: its ``calibration.json``).
    column : str, optional
        The released-grams column (default ``released_g``; ``design_released_g`` for ``curves_physical.csv``).
    cache_dir : str or Path, optional
        For a run folder: where the analysis keeps its per-frame cache (default: none).

    Returns
    -------
    PhysicalCurve

    Raises
    ------
    CurveFileError
        Missing file, missing column, a bad value (file and row named), or a run that cannot be analysed.
    """
    path = Path(path)
    if path.is_dir():
        if (path / "frames.csv").is_file():
            return _read_run(path, calibration, None if cache_dir is None else Path(cache_dir))
        found = [path / name for name in CURVE_FILES if (path / name).is_file()]
        if not found:
            raise CurveFileError(f"{path}: neither a run folder (frames.csv) nor a folder with one of "
                                 f"{', '.join(CURVE_FILES)}")
        if len(found) > 1:
            raise CurveFileError(f"{path}: holds {', '.join(p.name for p in found)}; name the file")
        path = found[0]
    elif not path.is_file():
        raise CurveFileError(f"{path}: no such file or folder")
    return _read_csv(path, column)
