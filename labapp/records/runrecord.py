"""What ``run.json`` says: the typed record of a run folder or calibration series, its format and migration.

``run.json`` carries a ``format`` integer (:data:`FORMAT`). A file without it is layout 0: written before
records carried their format, or by hand (the bench fixtures). Reading never rewrites a record:
:func:`migrate` turns any layout this version knows into the current one in memory, and
:meth:`RunRecord.from_stored` makes the typed record the application reads. The file itself is read by
:func:`labapp.records.manifests.read_record` (no I/O here). Field by field in ``docs/formats.md``.
"""
from __future__ import annotations

import copy
import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from labapp.errors import LabError

__all__ = ["FORMAT", "Gap", "RecordFormatError", "RecordKind", "RecordStatus", "RunRecord", "migrate"]

FORMAT = 1
"""The layout of ``run.json`` this version writes (its ``format`` key)."""


class RecordStatus(enum.StrEnum):
    """``status`` in ``run.json``: where the run stands."""

    CREATED = "created"
    """What a ``run.json`` without a ``status`` reads as (never written by this version)."""
    RUNNING = "running"
    INTERRUPTED = "interrupted"
    """Never stored: a ``running`` record whose writer process is gone reads as interrupted."""
    COMPLETE = "complete"
    STOPPED = "stopped"
    ABORTED = "aborted"
    FAILED = "failed"


class RecordKind(enum.StrEnum):
    """``kind`` in ``run.json``: what the folder records."""

    RUN = "run"
    CALIBRATION_SERIES = "calibration-series"


class RecordFormatError(LabError):
    """A ``run.json`` object this version cannot read (a newer format, or a field of the wrong shape)."""


_OPTIONAL: dict[str, Any] = {"kind": RecordKind.RUN, "status": RecordStatus.CREATED, "files": {}, "gaps": [],
                             "resumed": 0, "simulated": False}
"""Keys a writer leaves out until they are needed (and a layout-0 file by hand may lack), with what their
absence means."""


def _layout_0_to_1(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 0 is layout 1 without the ``format`` key."""
    return dict(stored, format=1)


_UPGRADES = {0: _layout_0_to_1}
"""``layout -> function`` making the next layout from it; one entry per format change."""


def migrate(stored: Mapping[str, Any]) -> dict[str, Any]:
    """A ``run.json`` object of any layout this version knows, in the current layout (:data:`FORMAT`).

    Returns a new dict (``stored`` is not changed, nor is any file): the layout upgraded step by step
    and the keys a writer leaves out until they are needed given what their absence means (``kind``
    ``run``, ``status`` ``created``, no ``files``, no ``gaps``, ``resumed`` 0, not ``simulated``).

    Raises
    ------
    RecordFormatError
        If ``format`` is not an integer, or is newer than :data:`FORMAT`.
    """
    record = dict(stored)
    layout = record.get("format", 0)
    if isinstance(layout, bool) or not isinstance(layout, int) or layout < 0:
        raise RecordFormatError(f"format {layout!r} is not a layout number (0, 1, ...)")
    if layout > FORMAT:
        raise RecordFormatError(f"format {layout} is newer than this version of sfr reads (up to {FORMAT}); "
                                "update sfr to read it")
    while layout < FORMAT:
        record = _UPGRADES[layout](record)
        layout = record["format"]
    for key, absent in _OPTIONAL.items():
        record.setdefault(key, copy.copy(absent))
    return record


def _known(enum_type: type[enum.StrEnum], value: Any) -> Any:
    """``value`` as a member of ``enum_type`` when it is one's value; else as stored (a value written by a
    newer version or by hand is kept, so that it can be shown and refused where it matters)."""
    try:
        return enum_type(value)
    except ValueError:
        return value


@dataclass(frozen=True)
class Gap:
    """No frames between two times, s from the drop (e.g. across a crash); ``reason`` says why."""

    after_t_s: float
    before_t_s: float
    reason: str


@dataclass(frozen=True)
class RunRecord:
    """The typed ``run.json`` of a run folder or calibration series (current layout).

    Times are s since the epoch (``*_unix_s``), masses g, temperatures C. ``kind`` and ``status`` are
    enum members when this version knows the stored value, else the value as stored. Keys not typed
    here (and a value's absence) are in :attr:`stored`, the object exactly as read.
    """

    format: int
    kind: RecordKind | str
    status: RecordStatus | str
    name: str | None
    config: Mapping[str, Any] | None
    """The ``RunConfig`` or ``SeriesConfig`` the run was started with (None: not recorded)."""
    simulated: bool
    created_unix_s: float | None
    t0_unix_s: float | None
    """The drop (time zero of ``t_s``); None before it."""
    finished_unix_s: float | None
    writer_pid: int | None
    writer_started: float | None
    """Start time of the writing process (so that a reused pid is not taken for the writer)."""
    resumed: int
    files: Mapping[str, str]
    """Auxiliary files (reference frame, calibration copy, raw companions): name -> SHA-256 (hex)."""
    gaps: tuple[Gap, ...]
    water_g: float | None
    object_mass_g: float | None
    object_name: str | None
    notes: str | None
    interval_s: float | None
    bench: str | None
    crop: Mapping[str, int] | None
    """The square crop chosen at acquisition, px: ``{"x", "y", "size"}``."""
    grid: int | None
    mirror_col: float | None
    reduce: int | None
    reference_file: str | None
    reference_t_unix_s: float | None
    calibration_file: str | None
    operator: str | None
    """Who started the run (an operator of the users file, or the demo operator); None: not recorded. Every
    later action and its operator is in the folder's ``audit.jsonl``."""
    method: Mapping[str, Any] | None
    """The method file the run followed: ``{name, path, sha256}``; None: none."""
    stored: Mapping[str, Any]

    @classmethod
    def from_stored(cls, stored: Mapping[str, Any]) -> RunRecord:
        """The record of a ``run.json`` object as read (any known layout; see :func:`migrate`).

        Raises
        ------
        RecordFormatError
            For a format this version cannot read, or ``files`` / ``gaps`` of the wrong shape.
        """
        data = migrate(stored)
        try:
            files = {str(name): str(digest) for name, digest in dict(data["files"]).items()}
        except (TypeError, ValueError) as exc:
            raise RecordFormatError(f"files is not an object of name: SHA-256 ({exc})") from None
        try:
            gaps = tuple(Gap(float(g["after_t_s"]), float(g["before_t_s"]), str(g["reason"])) for g in data["gaps"])
        except (KeyError, TypeError, ValueError) as exc:
            raise RecordFormatError(f"gaps is not a list of {{after_t_s, before_t_s, reason}} ({exc})") from None
        try:
            resumed = int(data["resumed"])
        except (TypeError, ValueError):
            raise RecordFormatError(f"resumed {data['resumed']!r} is not a count") from None
        return cls(format=data["format"], kind=_known(RecordKind, data["kind"]),
                   status=_known(RecordStatus, data["status"]), name=data.get("name"), config=data.get("config"),
                   simulated=bool(data["simulated"]), created_unix_s=data.get("created_unix_s"),
                   t0_unix_s=data.get("t0_unix_s"), finished_unix_s=data.get("finished_unix_s"),
                   writer_pid=data.get("writer_pid"), writer_started=data.get("writer_started"),
                   resumed=resumed, files=files, gaps=gaps, water_g=data.get("water_g"),
                   object_mass_g=data.get("object_mass_g"), object_name=data.get("object_name"),
                   notes=data.get("notes"), interval_s=data.get("interval_s"), bench=data.get("bench"),
                   crop=data.get("crop"), grid=data.get("grid"), mirror_col=data.get("mirror_col"),
                   reduce=data.get("reduce"), reference_file=data.get("reference_file"),
                   reference_t_unix_s=data.get("reference_t_unix_s"), calibration_file=data.get("calibration_file"),
                   operator=data.get("operator"), method=data.get("method"), stored=dict(stored))
