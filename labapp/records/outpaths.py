"""Checking an ``--out`` before any work starts: never over an input, a record or another command's folder.

Two calls, both made before the first byte is computed or written:

``check_out(path, writes, inputs=(), file=False)``
    for a command's output folder (``writes`` names the kind it writes, e.g. ``"simulation"``) or, with
    ``file=True``, for a single output file.
``check_data_dir(path)``
    for a data directory in which a new run folder will be created (``sfr run --out``, ``sfr lab --data``).

Both raise :class:`OutPathError` (a :class:`labapp.errors.UsageError`, exit code 2) with a message that says
what the path is and what to do instead. The rules:

- an output file must not exist yet (it is never overwritten) and must not lie inside a record;
- an output folder must be new or empty: a folder holding results of the same kind written earlier is
  refused too (its results are never overwritten), unless the command resumes or redoes its own work there
  (``replace=True``: a sweep or a batch completes the combinations or runs not done yet, an analysis reuses
  its cell cache; a design run resumes with ``--resume``, which checks its own folder);
- nothing is written into a record (a run or calibration-series folder: it would appear there as an
  unlisted file), except the ``analysis`` subfolder ``sfr analyze`` keeps beside a run;
- an output never lies inside, nor contains, an input folder and is never an input file.

A folder's kind (:class:`FolderKind`) is recognised by the files a command writes (:data:`KINDS`); a
command with a new kind of output adds a member and one line there. A record's kind
(:class:`labapp.records.runrecord.RecordKind`) is what its ``run.json`` says.
"""
from __future__ import annotations

import enum
from collections.abc import Iterable
from pathlib import Path

from analysis.decode import IMAGE_SUFFIXES
from labapp.errors import UsageError
from labapp.records.fileio import StorageError
from labapp.records.manifests import RUN_JSON, read_record
from labapp.records.runrecord import RecordKind

__all__ = ["KINDS", "FolderKind", "OutPathError", "check_data_dir", "check_out", "folder_kind"]


class FolderKind(enum.StrEnum):
    """The kinds of folder the commands write or read, recognised by their files (:data:`KINDS`)."""

    DESIGN = "design"
    SIMULATION = "simulation"
    ANALYSIS = "analysis"
    IMAGES = "images"
    SWEEP = "sweep"
    BATCH_ANALYSIS = "batch-analysis"
    SIMCAL = "simcal"
    EVALUATION = "evaluation"
    OTHER = "other"
    """A non-empty folder of anything else."""


#: kind -> (what it is for the operator, marker files: the folder is of this kind if it holds all of one
#: group). Record kinds (``run``, ``calibration-series``) come from ``run.json``'s ``kind``.
KINDS: dict[FolderKind, tuple[str, tuple[tuple[str, ...], ...]]] = {
    FolderKind.DESIGN: ("a design run folder (sfr design)",
                        (("config.json", "feasibility.txt"), ("config.json", "checkpoint.npz"))),
    FolderKind.SIMULATION: ("a simulation folder (sfr simulate)", (("release.csv",),)),
    FolderKind.ANALYSIS: ("an analysis folder (sfr analyze)", (("curve.csv",), ("cells_cache.npz",))),
    FolderKind.IMAGES: ("an image or calibration-series folder (input data)", (("frames.csv",), ("masses.csv",))),
    FolderKind.SWEEP: ("a design sweep folder (sfr sweep)", (("spec.toml", "runs"),)),
    FolderKind.BATCH_ANALYSIS: ("a batch analysis folder (sfr analyze RUN... --out)", (("batch_summary.csv",),)),
    FolderKind.SIMCAL: ("a simulation calibration folder (sfr calibrate-sim)", (("simcal.json",),)),
    FolderKind.EVALUATION: ("a model evaluation folder (sfr evaluate)", (("evaluation.json",),)),
}
RECORD_KINDS = {RecordKind.RUN: "an acquisition run folder (a record)",
                RecordKind.CALIBRATION_SERIES: "a calibration-series folder (a record)"}
ANALYSIS_SUBFOLDER = "analysis"


class OutPathError(UsageError):
    """An output path that would overwrite an input, a record or another command's files."""


def folder_kind(path: Path) -> FolderKind | RecordKind | None:
    """The kind of folder ``path`` is: a record's kind (a folder with ``run.json``; ``run`` when its ``kind``
    is none this version knows), else a key of :data:`KINDS`, :attr:`FolderKind.OTHER` for a non-empty folder
    of anything else, None for an absent or empty folder."""
    path = Path(path)
    if not path.is_dir():
        return None
    if (path / RUN_JSON).exists():
        try:
            kind = read_record(path).kind
        except StorageError:
            kind = RecordKind.RUN
        return kind if kind in RECORD_KINDS else RecordKind.RUN
    for kind, (_, groups) in KINDS.items():
        if any(all((path / name).exists() for name in group) for group in groups):
            return kind
    entries = [p for p in path.iterdir() if not p.name.startswith(".")]
    if any(p.suffix.lower() in IMAGE_SUFFIXES for p in entries):
        return FolderKind.IMAGES
    return FolderKind.OTHER if entries else None


def _describe(kind: str) -> str:
    if kind in RECORD_KINDS:
        return RECORD_KINDS[kind]
    return KINDS[kind][0] if kind in KINDS else "a folder with other files"


def _record_above(path: Path) -> Path | None:
    """The nearest folder at or above ``path`` that is a record (has ``run.json``)."""
    for folder in (path, *path.parents):
        if (folder / RUN_JSON).is_file():
            return folder
    return None


def _check_inputs(path: Path, inputs: Iterable[str | Path], option: str) -> None:
    for item in inputs:
        if item is None or str(item).startswith("sample:"):
            continue
        src = Path(item).resolve()
        if path == src:
            raise OutPathError(f"{option} {path} is an input of this command; choose another {option}")
        if src.is_dir() and src in path.parents:
            raise OutPathError(f"{option} {path} lies inside the input folder {src}; choose a folder outside it")
        if path in src.parents:
            raise OutPathError(f"{option} {path} contains the input {src}; choose a new folder that holds no input")


def check_out(path: str | Path, writes: FolderKind | str, inputs: Iterable[str | Path] = (), *, file: bool = False,
              replace: bool = False, option: str = "--out", analysed: str | Path | None = None) -> Path:
    """Check an output path before any work; returns it (resolved). Creates nothing.

    Parameters
    ----------
    path : str or Path
        The output folder (or file, with ``file=True``).
    writes : FolderKind or str
        The kind of folder the command writes (:attr:`FolderKind.SIMULATION`, ``ANALYSIS``, ``DESIGN``, ...).
        With ``file=True`` only a name for the file's kind (not checked).
    inputs : iterable of path
        The command's input files and folders (``sample:NAME`` and None are skipped).
    file : bool
        ``path`` is one output file: it must not exist yet.
    replace : bool
        Accept an existing folder of kind ``writes``, in which the command resumes or redoes its own work
        (a sweep, a batch, an analysis); default False: a folder holding results is refused.
    option : str
        The option's name in messages.
    analysed : path, optional
        The record an analysis reads: the only record whose ``analysis`` subfolder it may write.

    Raises
    ------
    OutPathError
        Naming the path, what it is, and what to do instead.
    """
    path = Path(path).expanduser().resolve()
    _check_inputs(path, inputs, option)
    if file:
        if path.is_dir():
            raise OutPathError(f"{option} {path} is a folder; give a file name")
        if path.exists():
            raise OutPathError(f"{option} {path} exists; it is never overwritten: choose a new file name "
                               "or move the old file away first")
        record = _record_above(path.parent)
        if record is not None:
            raise OutPathError(f"{option} {path} lies inside {record}, {_describe(folder_kind(record))}, which no "
                               f"command adds files to; write it outside, e.g. {record.parent / path.name}")
        return path
    if path.exists() and not path.is_dir():
        raise OutPathError(f"{option} {path} is a file; give a folder")
    record = _record_above(path)
    own = analysed is not None and record == Path(analysed).expanduser().resolve()
    if record is not None and not (writes == FolderKind.ANALYSIS and path == record / ANALYSIS_SUBFOLDER and own):
        if writes == FolderKind.ANALYSIS and path == record / ANALYSIS_SUBFOLDER:
            mine = f"; {Path(analysed).resolve() / ANALYSIS_SUBFOLDER} is its own" if analysed is not None else ""
            raise OutPathError(f"{option} {path} is the analysis folder of {record}, another record: a record's "
                               f"analysis goes only into its own folder{mine}")
        hint = f"; its analysis goes to {record / ANALYSIS_SUBFOLDER}" if writes == FolderKind.ANALYSIS else ""
        raise OutPathError(f"{option} {path} is or lies inside {record}, {_describe(folder_kind(record))}, which "
                           f"no command adds files to; choose a folder outside it{hint}")
    kind = folder_kind(path)
    if kind is None or (kind == writes and replace):
        return path
    if kind == writes:
        resume = " or resume it with --resume" if writes == FolderKind.DESIGN else ""
        raise OutPathError(f"{option} {path} already holds {_describe(kind)}; its results are never overwritten: "
                           f"choose a new folder, e.g. {_new_name(path)}{resume}")
    raise OutPathError(f"{option} {path} is {_describe(kind)}, not a {writes} folder; its files are not "
                       f"overwritten: choose a new or empty folder")


def _new_name(path: Path) -> Path:
    """The first of ``path-2``, ``path-3``, ... that does not exist."""
    n = 2
    while path.with_name(f"{path.name}-{n}").exists():
        n += 1
    return path.with_name(f"{path.name}-{n}")


def check_data_dir(path: str | Path, option: str = "--out") -> Path:
    """Check a data directory (where a new run folder is created) before a run starts; returns it resolved.

    Raises
    ------
    OutPathError
        If ``path`` is a file, or is or lies inside a record, a design, simulation or analysis folder.
    """
    path = Path(path).expanduser().resolve()
    if path.exists() and not path.is_dir():
        raise OutPathError(f"{option} {path} is a file; give the data directory that holds the run folders")
    record = _record_above(path)
    if record is not None:
        raise OutPathError(f"{option} {path} is or lies inside {record}, {_describe(folder_kind(record))}; give "
                           f"the data directory that holds run folders, e.g. {record.parent}")
    kind = folder_kind(path)
    if kind in KINDS and kind != FolderKind.IMAGES:
        raise OutPathError(f"{option} {path} is {_describe(kind)}; give a data directory for run folders")
    return path
