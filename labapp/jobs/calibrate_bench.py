"""Calibrate the bench: a calibration-series folder to its per-cell Beer-Lambert fit (`sfr calibrate-bench`)."""
from __future__ import annotations

import hashlib
from pathlib import Path

from analysis import CropGeometry, default_geometry
from labapp.acquisition.calseries import fit_series, image_shape, read_masses
from labapp.acquisition.settings import WATER
from labapp.errors import UsageError
from labapp.records import operators
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.outpaths import check_out
from labapp.records.storage import MASSES_CSV, RUN_JSON, RecordReadError, read_record


def calibrate_series(folder: str | Path, out: str | Path, *, water_g: float = WATER.default,
                     crop: tuple[int, int, int] | None = None, grid: int = 10, mirror_col: float | None = None,
                     mirror: bool = True, reduce: int = 1, camera: dict[str, str] | None = None):
    """Fit the bench calibration of a series folder (images + ``masses.csv``) and save it to ``out``.

    ``crop`` (x, y, size px) defaults to the series' recorded crop (``run.json``), else
    ``analysis.default_geometry``. Returns the ``analysis.BenchCalibration``.

    Raises
    ------
    UsageError
        For an ``out`` that exists, is an input or lies inside a record, a malformed ``masses.csv``
        (named row and field), or a recorded crop that cannot be read.
    analysis.AnalysisError
        For unreadable images or a fit that is not possible.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise UsageError(f"{folder} is not a folder; give the calibration-series folder holding {MASSES_CSV}")
    out = check_out(out, "calibration", [folder / MASSES_CSV], file=True)
    operator = operators.require(f"calibrating from {folder}") if (folder / RUN_JSON).is_file() else None
    WATER.check(water_g, "calibrate_series")
    files, masses = read_masses(folder)
    crop = crop or _recorded_crop(folder)
    if crop:
        geometry = CropGeometry(*crop, grid, mirror_col, mirror)
    else:
        base = default_geometry(image_shape(files[0]) if files[0].is_file() else (0, 0), grid)
        geometry = CropGeometry(base.x, base.y, base.size, grid, mirror_col, mirror)
    cal = fit_series(files, masses, geometry, water_g, camera, reduce)
    out.parent.mkdir(parents=True, exist_ok=True)
    cal.save(out)
    if (folder / RUN_JSON).is_file():
        audit(folder, Action.CALIBRATE, f"bench calibration fitted from {len(files)} images: {out.resolve()} "
              f"(SHA-256 {hashlib.sha256(out.read_bytes()).hexdigest()})", operator=operator)
    return cal


def _recorded_crop(folder: Path) -> tuple[int, int, int] | None:
    """The crop a series recorded by `sfr lab`/`sfr run` stored in its run.json (x, y, size px), if any."""
    if not (folder / RUN_JSON).exists():
        return None
    try:
        crop = read_record(folder).crop
    except RecordReadError as exc:
        raise UsageError(f"{folder / RUN_JSON} cannot be read: {exc.reason}") from exc
    if crop is None:
        return None
    try:
        return int(crop["x"]), int(crop["y"]), int(crop["size"])
    except (KeyError, TypeError, ValueError) as exc:
        raise UsageError(f"{folder / RUN_JSON}: crop is not {{x, y, size}} in px: {exc}") from exc
