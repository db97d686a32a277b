"""Offline analysis of a whole run: frames to cells (parallel, cached) to a smoothed release curve.

Decoding dominates the cost and OpenCV releases the GIL while it decodes, so frames are read on a
thread pool (one thread per core by default). A frame that cannot be read, or has the wrong size, is
skipped with a warning naming it. Per-frame cell values are cached in ``cache_dir`` keyed by file name,
size, modification time, geometry and ``reduce``, so a rerun with other smoothing is instant.
"""
from __future__ import annotations

import csv
import json
import logging
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.calibration import WATER_RANGE_G, BenchCalibration, estimate_concentration, reference_offset, water_range_text
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S, smooth_curve
from analysis.decode import check_reduce
from analysis.errors import AnalysisError
from analysis.frames import FrameList, read_frame_list
from analysis.geometry import read_cells

log = logging.getLogger(__name__)

CACHE_FILE = "cells_cache.npz"


@dataclass(frozen=True, eq=False)
class RunCurve:
    """The release curve of one run.

    Attributes
    ----------
    files : list of str
        Frame files relative to the run folder, one per curve point.
    t_s : (N,) ndarray of float, s
    conc_g_per_kg, uncertainty_g_per_kg, conc_smooth_g_per_kg : (N,) ndarray of float, g/kg
    released_g : (N,) ndarray of float, g
        Smoothed concentration times the water mass.
    cells : (N, g, g) ndarray of float
        Cell transmittances of every frame.
    n_rejected : (N,) ndarray of int
        Cells rejected per frame (object or bubble in the crop).
    water_g : float
    warnings : list of str
        Skipped frames, reference trouble, manifest notes.
    object_mass_g : float or None
        Weighed mass of the object (run.json ``object_mass_g``), g, when recorded.
    """

    files: list[str]
    t_s: np.ndarray
    conc_g_per_kg: np.ndarray
    uncertainty_g_per_kg: np.ndarray
    conc_smooth_g_per_kg: np.ndarray
    released_g: np.ndarray
    cells: np.ndarray
    n_rejected: np.ndarray
    water_g: float
    warnings: list[str] = field(default_factory=list)
    object_mass_g: float | None = None

    @property
    def released_raw_g(self) -> np.ndarray:
        """(N,) ndarray of float, g: the unsmoothed concentration times the water mass."""
        return self.conc_g_per_kg * self.water_g / 1000.0


def _cache_key(calibration: BenchCalibration, reduce: int) -> str:
    return json.dumps({"geometry": calibration.geometry.to_dict(), "reduce": reduce,
                       "image_shape": calibration.image_shape}, sort_keys=True)


def _file_id(path: Path) -> str:
    st = path.stat()
    return f"{path.name}|{st.st_size}|{st.st_mtime_ns}"


def _load_cache(cache_dir: Path | None, key: str) -> dict[str, np.ndarray]:
    if cache_dir is None or not (cache_dir / CACHE_FILE).exists():
        return {}
    try:
        with np.load(cache_dir / CACHE_FILE, allow_pickle=False) as data:
            if str(data["key"]) != key:
                return {}
            return dict(zip(data["ids"].tolist(), data["cells"]))
    except (OSError, ValueError, KeyError) as exc:
        log.warning("ignoring unreadable cell cache %s: %s", cache_dir / CACHE_FILE, exc)
        return {}


def _save_cache(cache_dir: Path, key: str, cache: dict[str, np.ndarray]) -> None:
    cache_dir.mkdir(parents=True, exist_ok=True)
    tmp = cache_dir / f".{CACHE_FILE}.part.npz"
    ids = sorted(cache)
    try:
        np.savez(tmp, key=np.array(key), ids=np.array(ids), cells=np.array([cache[i] for i in ids]))
        os.replace(tmp, cache_dir / CACHE_FILE)
    finally:
        tmp.unlink(missing_ok=True)     # after an error (a full disk): no partial cache left


def analyze_run(folder: str | Path, calibration: BenchCalibration, *, interval_s: float | None = None,
                workers: int | None = None, progress: Callable[[int, int], None] | None = None,
                reduce: int | None = None, cache_dir: str | Path | None = None, water_g: float | None = None,
                window_s: float = DEFAULT_WINDOW_S, order: int = DEFAULT_ORDER) -> RunCurve:
    """Analyse every frame of a run folder or plain image folder.

    Parameters
    ----------
    folder : str or Path
        Run folder (frames.csv [+ run.json]) or plain folder of images.
    calibration : BenchCalibration
        Its geometry is the crop that is measured.
    interval_s : float, optional
        Frame interval for a plain folder without EXIF times, s.
    workers : int, optional
        Decoding threads (default: all cores).
    progress : callable, optional
        ``progress(done, total)`` after every frame. It may raise ``KeyboardInterrupt`` to stop the analysis
        there: the frames analysed so far are kept in the cell cache (``cache_dir``) and the exception propagates.
    reduce : {1, 2, 4, 8}, optional
        Decode downscaling (default: the calibration's).
    cache_dir : str or Path, optional
        Where to keep the per-frame cell cache (default: no cache).
    water_g : float, optional
        Water mass, g (default: run.json ``water_g``, else the calibration's).
    window_s, order
        Savitzky-Golay settings (:func:`analysis.smooth_curve`).

    Returns
    -------
    RunCurve

    Raises
    ------
    AnalysisError
        Unreadable folder or manifest, or no frame that could be analysed.
    """
    frames = read_frame_list(folder, interval_s=interval_s)
    reduce = check_reduce(calibration.reduce if reduce is None else reduce)
    water, warnings = _water_and_warnings(frames, calibration, water_g)
    key = _cache_key(calibration, reduce)
    cache_path = None if cache_dir is None else Path(cache_dir)
    cache = _load_cache(cache_path, key)
    try:
        results = _decode_frames(frames, calibration, reduce, cache, workers, progress)
    except KeyboardInterrupt:
        if cache_path is not None and cache:
            _save_cache(cache_path, key, cache)
        raise
    keep = _kept_frames(frames, results, cache, warnings)
    if cache_path is not None:
        _save_cache(cache_path, key, cache)
    reference_cells = _reference_cells(frames, calibration, reduce, warnings)
    cells = np.array([results[i][1] for i in keep])
    estimates = [estimate_concentration(c, calibration, reference_cells=reference_cells) for c in cells]
    t_s = frames.t_s[keep]
    conc = np.array([e.conc_g_per_kg for e in estimates])
    smooth = smooth_curve(t_s, conc, window_s=window_s, order=order)
    return RunCurve([str(frames.files[i].relative_to(frames.folder)) for i in keep], t_s, conc,
                    np.array([e.uncertainty_g_per_kg for e in estimates]), smooth, smooth * water / 1000.0,
                    cells, np.array([len(e.rejected_cells) for e in estimates]), water, warnings,
                    _positive_or_none(frames.run.get("object_mass_g")))


def _water_and_warnings(frames: FrameList, calibration: BenchCalibration, water_g: float | None) -> tuple[float, list[str]]:
    """The run's water mass, g (``water_g``, else run.json's, else the calibration's), and the warnings so far: the
    manifest's, and a run.json crop that differs from the calibration's.

    Raises
    ------
    AnalysisError
        If the water mass is outside `analysis.calibration.WATER_RANGE_G`, naming where it comes from.
    """
    warnings = list(frames.warnings)
    source = "--water-g" if water_g else f"{frames.folder}/run.json water_g" if frames.run.get("water_g") else \
        "the calibration's water_g"
    water = float(water_g or frames.run.get("water_g") or calibration.water_g)
    if not WATER_RANGE_G[0] <= water <= WATER_RANGE_G[1]:
        raise AnalysisError(f"water mass {water:g} g ({source}): {water_range_text()}")
    crop = frames.run.get("crop")
    if isinstance(crop, dict) and any(crop.get(k) != v for k, v in calibration.geometry.to_dict().items()
                                      if k in ("x", "y", "size")):
        warnings.append(f"run.json crop {crop} differs from the calibration's; the calibration's is used")
    return water, warnings


_Decoded = tuple[str, np.ndarray | None, str | None]
"""A frame's cache id, its cells (None when it could not be read) and the reason it could not."""


def _decode_frames(frames: FrameList, calibration: BenchCalibration, reduce: int, cache: dict[str, np.ndarray],
                   workers: int | None, progress: Callable[[int, int], None] | None) -> list[_Decoded]:
    """Every frame's cells, from ``cache`` or decoded on a thread pool, in the order of ``frames.files``.

    A ``KeyboardInterrupt`` from ``progress`` lets the frames being decoded finish, starts no others, adds the
    ones done to ``cache`` and propagates.
    """
    def work(path: Path) -> _Decoded:
        ident = _file_id(path)
        if ident in cache:
            return ident, cache[ident], None
        try:
            return ident, read_cells(path, calibration.geometry, reduce=reduce,
                                     expect_shape=calibration.image_shape), None
        except AnalysisError as exc:
            return ident, None, str(exc)

    n = len(frames.files)
    results: list[_Decoded] = []
    with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        try:
            for done, result in enumerate(pool.map(work, frames.files), start=1):
                results.append(result)
                if progress is not None:
                    progress(done, n)   # a safe point: ``progress`` may raise KeyboardInterrupt to stop here
        except KeyboardInterrupt:
            # the frames being decoded finish, the others are not started; the ones done stay in the cache
            pool.shutdown(wait=True, cancel_futures=True)
            cache.update((ident, cells) for ident, cells, _ in results if cells is not None)
            raise
    return results


def _kept_frames(frames: FrameList, results: list[_Decoded], cache: dict[str, np.ndarray],
                 warnings: list[str]) -> list[int]:
    """Indices of the frames whose cells were read (added to ``cache``); a warning for each skipped one.

    Raises
    ------
    AnalysisError
        If no frame could be read.
    """
    keep = []
    for i, (ident, cells, error) in enumerate(results):
        if cells is None:
            warnings.append(f"skipped frame {frames.files[i].name}: {error}")
            log.warning("skipped frame %s: %s", frames.files[i], error)
        else:
            cache[ident] = cells
            keep.append(i)
    if not keep:
        raise AnalysisError(f"none of the {len(results)} frames in {frames.folder} could be analysed; first problem: "
                            f"{results[0][2]}")
    return keep


def _reference_cells(frames: FrameList, calibration: BenchCalibration, reduce: int,
                     warnings: list[str]) -> np.ndarray | None:
    """The cells of the run's clear-water reference frame, None when it has none or it is unusable (a warning)."""
    if frames.reference is None:
        return None
    try:
        reference_cells = read_cells(frames.reference, calibration.geometry, reduce=reduce,
                                     expect_shape=calibration.image_shape)
    except AnalysisError as exc:
        warnings.append(f"reference frame unusable, calibration zero level used: {exc}")
        return None
    _, message = reference_offset(reference_cells, calibration)
    if message:
        warnings.append(message)
        log.warning("%s", message)
    return reference_cells


def _positive_or_none(value: object) -> float | None:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) and v > 0 else None


def write_curve_csv(curve: RunCurve, path: str | Path) -> None:
    """``curve.csv``: ``t_s,conc_g_per_kg,conc_smooth_g_per_kg,released_g,uncertainty_g_per_kg,n_rejected_cells,
    file,released_raw_g`` and, when the object's mass is known, ``released_pct`` (smoothed release in percent
    of that mass)."""
    with_pct = curve.object_mass_g is not None
    raw = curve.released_raw_g
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["t_s", "conc_g_per_kg", "conc_smooth_g_per_kg", "released_g", "uncertainty_g_per_kg",
                      "n_rejected_cells", "file", "released_raw_g"] + (["released_pct"] if with_pct else []))
        for i, name in enumerate(curve.files):
            row = [f"{curve.t_s[i]:.3f}", f"{curve.conc_g_per_kg[i]:.6f}", f"{curve.conc_smooth_g_per_kg[i]:.6f}",
                   f"{curve.released_g[i]:.6f}", f"{curve.uncertainty_g_per_kg[i]:.6f}", int(curve.n_rejected[i]),
                   name, f"{raw[i]:.6f}"]
            if with_pct:
                row.append(f"{100.0 * curve.released_g[i] / curve.object_mass_g:.4f}")
            out.writerow(row)


def write_cells_csv(curve: RunCurve, path: str | Path) -> None:
    """``cells.csv``: one row per frame per cell, ``file,t_s,row,col,transmittance``."""
    g = curve.cells.shape[1]
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["file", "t_s", "row", "col", "transmittance"])
        for i, name in enumerate(curve.files):
            for r in range(g):
                for c in range(g):
                    out.writerow([name, f"{curve.t_s[i]:.3f}", r, c, f"{curve.cells[i, r, c]:.7f}"])
