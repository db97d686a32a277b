"""Calibrate the bench: a calibration-series folder to its per-cell Beer-Lambert fit (`sfr calibrate-bench`)."""
from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis import CropGeometry, default_geometry
from labapp.acquisition.calseries import fit_series, image_shape, read_masses
from labapp.acquisition.settings import WATER
from labapp.errors import UsageError
from labapp.records import operators
from labapp.records.audit import AUDIT_FILE, Action
from labapp.records.audit import append as audit
from labapp.records.fileio import WriteError, disk_error
from labapp.records.manifests import MASSES_CSV, RUN_JSON, RecordReadError, read_record
from labapp.records.outpaths import OutPathError, check_out

log = logging.getLogger(__name__)

PLAUSIBLE_MAX_G_PER_KG = 100.0
"""The highest concentration a calibration level plausibly has, g/kg: 10 % w/w, i.e. 50 g of filament in the
500 g bath of paper section 4.2. A series covers what a release run reaches, and a run ends at a few g/kg
(a 1-2 g printed object in 500 g of water); levels a thousand times that are masses typed in mg."""


def implausible_levels(masses_g: np.ndarray, water_g: float, source: str = MASSES_CSV) -> list[str]:
    """Warnings for cumulative masses whose concentrations no calibration series plausibly has (mg typed as g).

    Parameters
    ----------
    masses_g : (L,) ndarray of float
        Cumulative added masses, g.
    water_g : float
        Water in the beaker, g.
    source : str
        The file the masses come from, for the message.
    """
    masses_g = np.asarray(masses_g, dtype=float)
    if masses_g.size == 0:
        return []
    top = float(masses_g.max())
    conc = top / water_g * 1000.0
    if conc <= PLAUSIBLE_MAX_G_PER_KG:
        return []
    return [f"{source}: the levels reach {conc:.4g} g/kg ({top:g} g added to {water_g:g} g of water), above the "
            f"0-{PLAUSIBLE_MAX_G_PER_KG:g} g/kg a dye solution on this bench plausibly has (a release run ends at a "
            f"few g/kg: a 1-2 g object in {water_g:g} g of water). Check the water, {water_g:g} g (--water-g), and "
            f"the masses: added_mass_g is the cumulative mass in grams, and masses typed in milligrams give "
            f"this (in grams the top level would be {conc / 1000.0:.4g} g/kg)"]


def calibrate_series(folder: str | Path, out: str | Path, *, water_g: float = WATER.default,
                     crop: tuple[int, int, int] | None = None, grid: int = 10, mirror_col: float | None = None,
                     mirror: bool = True, reduce: int = 1, camera: dict[str, str] | None = None,
                     progress: Callable[[int, int], None] | None = None,
                     on_warning: Callable[[str], None] | None = None):
    """Fit the bench calibration of a series folder (images + ``masses.csv``) and save it to ``out``.

    ``crop`` (x, y, size px) defaults to the series' recorded crop (``run.json``), else
    ``analysis.default_geometry``. Masses whose concentrations no series plausibly has
    (:func:`implausible_levels`) are reported through ``on_warning`` (default: the log) before the fit.
    ``progress(done, total)`` is called after each image and may raise ``KeyboardInterrupt`` to stop there
    (nothing is written). Returns the ``analysis.BenchCalibration``.

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
    audited = (folder / AUDIT_FILE).is_file()          # a series recorded with its audit trail: the fit is an entry
    operator = operators.require(f"calibrating from {folder}") if audited else None
    WATER.check(water_g, "calibrate_series")
    files, masses = read_masses(folder)
    for message in implausible_levels(masses, water_g, str(folder / MASSES_CSV)):
        (on_warning or log.warning)(message)
    crop = crop or _recorded_crop(folder)
    if crop:
        geometry = CropGeometry(*crop, grid, mirror_col, mirror)
    else:
        base = default_geometry(image_shape(files[0]) if files[0].is_file() else (0, 0), grid)
        geometry = CropGeometry(base.x, base.y, base.size, grid, mirror_col, mirror)
    cal = fit_series(files, masses, geometry, water_g, camera, reduce, progress=progress)
    out.parent.mkdir(parents=True, exist_ok=True)
    _save_new(cal, out)
    if audited:
        audit(folder, Action.CALIBRATE, f"bench calibration fitted from {len(files)} images: {out.resolve()} "
              f"(SHA-256 {hashlib.sha256(out.read_bytes()).hexdigest()})", operator=operator)
    return cal


def _save_new(cal, out: Path) -> None:
    """Save ``cal`` to ``out``, which must still not exist: written beside it, then linked into place, so two
    commands given the same ``--out`` never both write it (the second is refused, naming the file)."""
    tmp = out.with_name(f".{out.name}.{os.getpid()}.part")
    try:
        cal.save(tmp)
        try:
            os.link(tmp, out)
        except FileExistsError:
            raise OutPathError(f"--out {out} was written by another command meanwhile; it is never overwritten: "
                               "choose a new file name") from None
        except OSError as exc:      # a file system without hard links: the check, then a rename
            if disk_error(exc) is not None:
                raise
            if out.exists():
                raise OutPathError(f"--out {out} was written by another command meanwhile; it is never "
                                   "overwritten: choose a new file name") from None
            os.replace(tmp, out)
    except Exception as exc:        # analysis.AnalysisError from an OSError, when the calibration's save fails
        cause = disk_error(exc)
        if cause is None:
            raise
        raise WriteError(f"cannot write {out}: {cause.strerror}; nothing of it was left; free space or choose a "
                         "writable --out") from exc
    finally:
        tmp.unlink(missing_ok=True)


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
