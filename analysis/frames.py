"""Which frames a folder holds and when they were taken (formats in docs/formats.md).

Two kinds of folder are read:

- a run folder: ``frames.csv`` (``file,t_s`` at least; ``file`` relative to the folder) and optionally
  ``run.json`` (water mass, crop, reference frame, ...);
- a plain folder of images off a camera card: times from EXIF, else ``interval_s`` per frame in file
  name order.
"""
from __future__ import annotations

import csv
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.capture_time import capture_time
from analysis.decode import IMAGE_SUFFIXES
from analysis.errors import AnalysisError

log = logging.getLogger(__name__)

FRAMES_CSV = "frames.csv"
RUN_JSON = "run.json"


@dataclass(frozen=True, eq=False)
class FrameList:
    """The frames of one run, in time order.

    Attributes
    ----------
    folder : Path
    files : list of Path
        Absolute paths of the frames (the reference frame excluded).
    t_s : (N,) ndarray of float, s
        Strictly increasing frame times.
    source : str
        Where the times came from: "frames.csv", "exif" or "interval".
    run : dict
        Contents of run.json ({} when absent).
    reference : Path or None
        The clear-water reference frame: run.json ``reference_file``, else ``reference.<image suffix>``
        in a run folder (as ``labapp.records.storage`` writes it), else None.
    warnings : list of str
    """

    folder: Path
    files: list[Path]
    t_s: np.ndarray
    source: str
    run: dict = field(default_factory=dict)
    reference: Path | None = None
    warnings: list[str] = field(default_factory=list)


def _read_run_json(folder: Path) -> dict:
    path = folder / RUN_JSON
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise AnalysisError(f"cannot read {path}: {exc}") from exc
    if not isinstance(data, dict):
        raise AnalysisError(f"{path} must hold a JSON object, got {type(data).__name__}")
    return data


def _from_manifest(folder: Path, warnings: list[str]) -> tuple[list[Path], np.ndarray]:
    path = folder / FRAMES_CSV
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, csv.Error, UnicodeDecodeError) as exc:
        raise AnalysisError(f"cannot read {path}: {exc}") from exc
    if rows and not {"file", "t_s"} <= set(rows[0]):
        raise AnalysisError(f"{path} needs the columns file,t_s; it has {','.join(rows[0])}")
    files, times = [], []
    listed: dict[str, int] = {}
    for line, row in enumerate(rows, start=2):
        try:
            t = float(row["t_s"])
        except (TypeError, ValueError):
            raise AnalysisError(f"{path} line {line}: t_s={row.get('t_s')!r} is not a number") from None
        if not np.isfinite(t):
            raise AnalysisError(f"{path} line {line}: t_s={row['t_s']!r}; expected a finite time in s")
        if row["file"] in listed:
            raise AnalysisError(f"{path} line {line}: {row['file']} is listed again (first on line "
                                f"{listed[row['file']]}); list each frame once")
        listed[row["file"]] = line
        if times and t <= times[-1]:
            raise AnalysisError(f"{path} line {line}: times are not increasing ({row['file']} at t_s={t:g} s "
                                f"follows {files[-1].name} at t_s={times[-1]:g} s)")
        frame = folder / row["file"]
        if not frame.is_file():
            warnings.append(f"{row['file']} is listed in {FRAMES_CSV} but missing; skipped")
            continue
        files.append(frame)
        times.append(t)
    return files, np.asarray(times, dtype=float)


def _from_images(folder: Path, interval_s: float | None, warnings: list[str]) -> tuple[list[Path], np.ndarray, str]:
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                   and not p.name.startswith("."))
    if not files:
        return [], np.empty(0), "interval" if interval_s else "exif"
    if interval_s is not None:
        return files, np.arange(len(files)) * float(interval_s), "interval"
    stamps = [capture_time(p) for p in files]
    missing = [p.name for p, s in zip(files, stamps) if s is None]
    if missing:
        raise AnalysisError(f"{len(missing)} images in {folder} have no EXIF capture time (first: {missing[0]}); "
                            "give the frame interval (--interval seconds)")
    t = np.array([(s - stamps[0]).total_seconds() for s in stamps])
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(len(t))):
        warnings.append("EXIF capture times are not in file-name order; frames sorted by capture time")
    files, t = [files[i] for i in order], t[order] - t[order].min()
    dup = np.flatnonzero(np.diff(t) <= 0)
    if dup.size:
        raise AnalysisError(f"{files[dup[0] + 1].name} has the same EXIF capture time as {files[dup[0]].name}; "
                            "give the frame interval (--interval seconds)")
    return files, t, "exif"


def read_frame_list(folder: str | Path, *, interval_s: float | None = None) -> FrameList:
    """List a run folder's or plain image folder's frames with their times.

    Parameters
    ----------
    folder : str or Path
    interval_s : float, optional
        Frame interval, s; for a plain folder it overrides EXIF times (ignored when frames.csv exists).

    Returns
    -------
    FrameList

    Raises
    ------
    AnalysisError
        Missing or empty folder, malformed manifest, non-increasing times, no usable times.
    """
    folder = Path(folder)
    if not folder.exists():
        raise AnalysisError(f"{folder} does not exist; give a run folder or a folder of images")
    if not folder.is_dir():
        raise AnalysisError(f"{folder} is not a folder; give a run folder or a folder of images")
    if interval_s is not None and not interval_s > 0:
        raise AnalysisError(f"interval_s={interval_s!r} s must be positive")
    warnings: list[str] = []
    run = _read_run_json(folder)
    if (folder / FRAMES_CSV).exists():
        files, t_s = _from_manifest(folder, warnings)
        source = FRAMES_CSV
    else:
        files, t_s, source = _from_images(folder, interval_s, warnings)
    reference = None
    if source == FRAMES_CSV and not run.get("reference_file"):
        found = sorted(p for p in folder.glob("reference.*") if p.suffix.lower() in IMAGE_SUFFIXES)
        reference = found[0] if found else None
    if run.get("reference_file"):
        reference = folder / str(run["reference_file"])
        if not reference.is_file():
            warnings.append(f"reference frame {run['reference_file']} named in {RUN_JSON} is missing")
            reference = None
        else:
            keep = [i for i, p in enumerate(files) if p != reference]
            files, t_s = [files[i] for i in keep], t_s[keep]
    if not files:
        raise AnalysisError(f"no frames in {folder} (looked for {FRAMES_CSV} or images: "
                            f"{', '.join(sorted(IMAGE_SUFFIXES))})")
    for message in warnings:
        log.warning("%s: %s", folder, message)
    return FrameList(folder, files, t_s, source, run, reference, warnings)
