"""The records of a design run folder: ``config.json``, ``summary.json`` and ``checkpoint.npz``.

Each record carries a ``format`` integer (`CONFIG_FORMAT`, `SUMMARY_FORMAT`, `CHECKPOINT_FORMAT`), written
on save. A record without it is layout 0: written before records carried their format. Each is read through
one loader (`load_config`, `load_summary`, `load_checkpoint`) whose ``migrate_*`` function turns any layout
this version knows into the current one, in memory (a file is never rewritten by reading it), and refuses a
newer layout. Field by field in ``docs/formats.md``.
"""
from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from design.errors import DesignError
from design.inverse.config import DesignConfig
from design.inverse.optimize import HISTORY_COLUMNS, Checkpoint
from design.inverse.status import DesignStatus

CONFIG = "config.json"
SUMMARY = "summary.json"
CHECKPOINT = "checkpoint.npz"

CONFIG_FORMAT = 2
"""The layout of ``config.json`` this version writes: the `DesignConfig` fields and ``format``."""
SUMMARY_FORMAT = 2
"""The layout of ``summary.json`` this version writes (`DesignSummary`)."""
CHECKPOINT_FORMAT = 2
"""The layout of ``checkpoint.npz`` this version writes: the `Checkpoint` arrays (the "lbfgs" optimiser's
state prefixed ``lbfgs_``, the fabrication term's ``fab_``), ``beta``, ``status`` ("" while the run goes on)
and ``format``."""


def _layout(stored: Mapping[str, Any], current: int, what: str) -> int:
    """The layout number of a stored record (0 without ``format``), checked against ``current``."""
    layout = stored.get("format", 0)
    if isinstance(layout, np.ndarray) and layout.ndim == 0 and np.issubdtype(layout.dtype, np.integer):
        layout = int(layout)
    if isinstance(layout, bool) or not isinstance(layout, int) or layout < 0:
        raise DesignError(f"{what}: format {layout!r} is not a layout number (0, 1, ...)")
    if layout > current:
        raise DesignError(f"{what}: format {layout} is newer than this version reads (up to {current}); "
                          "update sfr to read it")
    return layout


def _upgrade(stored: Mapping[str, Any], current: int, upgrades: dict, what: str) -> dict[str, Any]:
    """A copy of ``stored`` brought to layout ``current`` by the ``upgrades`` (layout -> next layout) in turn."""
    record = dict(stored)
    layout = _layout(record, current, what)
    while layout < current:
        record = upgrades[layout](record)
        layout = int(record["format"])
    return record


# ----------------------------------------------------------------------------------------------- config.json

def _config_0_to_1(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 0 lacks the options added after its run started: their absence means what the run did then."""
    record = dict(stored, format=1)
    record.setdefault("rate_span", (0.0, 1.0))  # J_rate compared the whole curve
    record.setdefault("optimizer", "LD_LBFGS")  # runs were optimised with nlopt's L-BFGS
    record.setdefault("allow_pieces", True)  # no connectivity term
    record.setdefault("connect_planes", False)  # the connectivity term measured the core only
    record.setdefault("connect_tail", 0.0)  # and had no tail
    record.setdefault("line_search", "strong-wolfe")  # the "lbfgs" optimiser's only rule
    return record


def _config_1_to_2(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 1 predates the physical correction: its runs aimed at the design grid's release alone."""
    record = dict(stored, format=2)
    record.setdefault("physical_correction", "none")
    return record


_CONFIG_UPGRADES = {0: _config_0_to_1, 1: _config_1_to_2}
"""``layout -> function`` making the next layout of ``config.json``; one entry per format change."""


def migrate_config(stored: Mapping[str, Any], what: str = CONFIG) -> dict[str, Any]:
    """A ``config.json`` object of any known layout in the current one (`CONFIG_FORMAT`); a new dict.

    Every layout stores the configuration resolved, where a ``beta_final`` of None always meant a fixed
    beta: it reads as ``beta``; and a record without ``w_channel`` was written before the channel-width term:
    with ``swelling_mm`` > 0 it reads as 0 (its run had no such term), else as None (no term, as written now).

    Raises
    ------
    DesignError
        If ``format`` is not a layout number or is newer than `CONFIG_FORMAT`.
    """
    record = _upgrade(stored, CONFIG_FORMAT, _CONFIG_UPGRADES, what)
    if record.get("beta_final") is None:
        record["beta_final"] = record.get("beta")
    record.setdefault("w_channel", 0.0 if (record.get("swelling_mm") or 0.0) > 0 else None)
    return record


def load_config(out_dir: Path) -> DesignConfig:
    """The `DesignConfig` of a run folder's ``config.json`` (`migrate_config`; keys it does not know are
    ignored).

    Raises
    ------
    DesignError
        When the file is missing or unreadable, or its format is unknown.
    """
    try:
        stored = json.loads((out_dir / CONFIG).read_text())
    except (OSError, ValueError) as exc:
        raise DesignError(f"cannot resume: no readable config.json in {out_dir}: {exc}") from exc
    record = migrate_config(stored, str(out_dir / CONFIG))
    names = {f.name for f in fields(DesignConfig)}
    return DesignConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in record.items() if k in names})


def stored_form(config: DesignConfig) -> dict[str, Any]:
    """The fields of ``config`` as ``config.json`` holds them and `load_config` reads them (JSON values,
    `migrate_config`): two configurations run alike when their stored forms are equal."""
    record = migrate_config(json.loads(json.dumps({"format": CONFIG_FORMAT, **asdict(config)})))
    del record["format"]
    return record


def save_config(out_dir: Path, config: DesignConfig) -> None:
    """Write ``config.json``: ``format`` and the configuration's fields."""
    (out_dir / CONFIG).write_text(json.dumps({"format": CONFIG_FORMAT, **asdict(config)}, indent=2))


# ----------------------------------------------------------------------------------------------- summary.json

class DesignSummary(TypedDict, total=False):
    """``summary.json`` of a finished (or stopped) design run (`design.files.outputs.write_outputs`).

    Fractions are of the target's final release (``rel_rmse_*``) or of its mean rate (``rate_dev_*``);
    None where a figure was not computed. The headline ``rel_rmse_print`` is the printed solid's
    (``design.stl``) release by the reference evaluator against the target's physical release;
    ``rel_rmse_density`` and ``rel_rmse_design_grid_binary`` are the design grid's diagnostics.
    ``labapp.jobs.physical`` adds the physical prediction (``rel_rmse_physical``, ``print_mass_basis``,
    ``simcal``, ``release_metrics``) to the same file.
    """

    format: int
    status: DesignStatus | str
    target: str
    space: str
    rel_rmse_print: float | None
    rel_rmse_print_error: float | None
    rel_rmse_density: float
    rel_rmse_design_grid_binary: float
    reference: dict[str, Any] | None
    rate_dev_mid80: dict[str, float | None] | None
    rate_dev_mid80_vs_target: dict[str, float | None] | None
    iterations: int
    seconds: float
    seconds_per_iteration: float | None
    session_seconds: float
    pieces: int
    extraction_level: float | None
    volume_mm3: float
    print_mass_g: float
    min_channel_mm: float | None
    enclosed_voids: int | None
    enclosed_void_mm3: float | None
    overhang_fraction: float | None
    max_overhang_run_mm: float | None
    preset: str | None
    ico: dict[str, Any] | None
    iou_with_source: float | None
    target_final_mm3: float
    total_time_mm: float
    dx_mm: float
    full_shape: list[int]
    reduced_shape: list[int]
    feasible: bool
    warnings: list[str]
    software: dict[str, str | None] | None
    config: dict[str, Any]
    rel_rmse_physical: float
    print_mass_basis: str
    simcal: dict[str, Any]
    release_metrics: dict[str, Any]


_SUMMARY_LATER_KEYS = ("rel_rmse_fine", "fine_factor", "rate_dev_mid80", "rate_dev_mid80_vs_target",
                       "extraction_level", "enclosed_voids", "enclosed_void_mm3", "overhang_fraction",
                       "max_overhang_run_mm", "preset", "ico", "software")
"""Summary keys added after the first layout-0 summaries: absent, they read as None (not recorded)."""


def _summary_0_to_1(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 0 may lack the facts recorded since its version (`_SUMMARY_LATER_KEYS`, the ``fine`` rate
    deviation): they read as None."""
    record = dict(stored, format=1)
    for key in _SUMMARY_LATER_KEYS:
        record.setdefault(key, None)
    for key in ("rate_dev_mid80", "rate_dev_mid80_vs_target"):
        if record[key] is not None:
            record[key] = {"fine": None, **record[key]}
    return record


def _summary_1_to_2(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 1 judged the design on voxel grids only: its ``rel_rmse_binary`` is the design grid's
    (``rel_rmse_design_grid_binary``), and the print's figures (``rel_rmse_print``, its error, the
    ``reference`` evaluation) read as None; its re-simulation on a finer grid (``rel_rmse_fine``,
    ``fine_factor``, the ``fine`` rate deviation) is no longer a summary figure. Its ``volume_mm3`` and
    ``print_mass_g`` stay as recorded (from the voxel count)."""
    record = dict(stored, format=2)
    record["rel_rmse_design_grid_binary"] = record.pop("rel_rmse_binary", None)
    record.pop("rel_rmse_fine", None)
    record.pop("fine_factor", None)
    for key in ("rel_rmse_print", "rel_rmse_print_error", "reference"):
        record.setdefault(key, None)
    for key in ("rate_dev_mid80", "rate_dev_mid80_vs_target"):
        rates = record.get(key)
        if rates is not None:
            record[key] = {"print": None, "density": rates.get("density"),
                           "design_grid_binary": rates.get("binary")}
    return record


_SUMMARY_UPGRADES = {0: _summary_0_to_1, 1: _summary_1_to_2}
"""``layout -> function`` making the next layout of ``summary.json``; one entry per format change."""


def migrate_summary(stored: Mapping[str, Any], what: str = SUMMARY) -> DesignSummary:
    """A ``summary.json`` object of any known layout in the current one (`SUMMARY_FORMAT`); a new dict whose
    ``status`` is a `DesignStatus` when this version knows the stored value.

    Raises
    ------
    DesignError
        If ``format`` is not a layout number or is newer than `SUMMARY_FORMAT`.
    """
    record = _upgrade(stored, SUMMARY_FORMAT, _SUMMARY_UPGRADES, what)
    try:
        record["status"] = DesignStatus(record["status"])
    except (KeyError, ValueError):  # none stored, or a value this version does not know: kept as stored
        pass
    return DesignSummary(**record)


def load_summary(out_dir: Path) -> DesignSummary:
    """The ``summary.json`` of a run folder (`migrate_summary`).

    Raises
    ------
    OSError, ValueError
        When the file is missing or not JSON.
    DesignError
        When its format is unknown.
    """
    path = out_dir / SUMMARY
    return migrate_summary(json.loads(path.read_text()), str(path))


# ----------------------------------------------------------------------------------------------- checkpoint.npz

def _checkpoint_0_to_1(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 0 histories may lack the ``fab_seconds`` column (zeros), and the oldest checkpoints the best J
    (the history's lowest) and the beta stage (0)."""
    record = dict(stored, format=np.array(1))
    history = record["history"]
    if history.shape[1] != len(HISTORY_COLUMNS):
        record["history"] = np.insert(history, HISTORY_COLUMNS.index("fab_seconds"), 0.0, axis=1)
    record.setdefault("best_value", np.array(min(record["history"][:, HISTORY_COLUMNS.index("J")], default=np.inf)))
    record.setdefault("stage", np.array(0))
    return record


def _checkpoint_1_to_2(stored: dict[str, Any]) -> dict[str, Any]:
    """Layout 1 did not record the objective's beta (NaN: the beta of its stage), how the optimisation ended
    ("": not known, judged from the evaluations) nor the fabrication term's state (none: its warm starts
    begin again)."""
    return dict(stored, format=np.array(2), beta=np.array(np.nan), status=np.array(""))


_CHECKPOINT_UPGRADES = {0: _checkpoint_0_to_1, 1: _checkpoint_1_to_2}
"""``layout -> function`` making the next layout of ``checkpoint.npz``; one entry per format change."""


def migrate_checkpoint(stored: Mapping[str, np.ndarray], what: str = CHECKPOINT) -> dict[str, np.ndarray]:
    """The arrays of a ``checkpoint.npz`` of any known layout in the current one (`CHECKPOINT_FORMAT`).

    Raises
    ------
    DesignError
        If ``format`` is not a layout number or is newer than `CHECKPOINT_FORMAT`.
    """
    record = _upgrade(stored, CHECKPOINT_FORMAT, _CHECKPOINT_UPGRADES, what)
    return record


_VARIABLES = ("x", "best_x")
_STATES = ("lbfgs_", "fab_")


def load_checkpoint(path: Path, *, variables: bool = True) -> Checkpoint:
    """The `Checkpoint` in a ``checkpoint.npz`` (`migrate_checkpoint`).

    With ``variables=False`` only the history, stage, beta and status are read (a large run's design
    variables and optimiser state stay on disk): ``x`` and ``best_x`` are empty, ``lbfgs`` and ``fab`` too.

    Raises
    ------
    DesignError
        When the file cannot be read as a checkpoint (empty, truncated, not an ``.npz``, an array missing or
        of the wrong kind), naming the file.
    """
    what = str(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = {name: data[name] for name in data.files
                      if variables or not (name in _VARIABLES or name.startswith(_STATES))}
        if not variables:
            stored.update(x=np.empty(0), best_x=np.empty(0))
        record = migrate_checkpoint(stored, what)
        status = str(record["status"])
        checkpoint = Checkpoint(
            x=np.asarray(record["x"], float).ravel(), best_x=np.asarray(record["best_x"], float).ravel(),
            best_value=float(record["best_value"]), stage=int(record["stage"]),
            history=np.asarray(record["history"], float).reshape(-1, len(HISTORY_COLUMNS)),
            lbfgs={k[len("lbfgs_"):]: v for k, v in record.items() if k.startswith("lbfgs_")},
            beta=float(record["beta"]), status=DesignStatus(status) if status else None,
            fab={k[len("fab_"):]: v for k, v in record.items() if k.startswith("fab_")})
    except DesignError:
        raise
    except (OSError, EOFError, ValueError, KeyError, TypeError, IndexError, zipfile.BadZipFile) as exc:
        # what np.load and the record's arrays raise on an empty, truncated or foreign file
        raise DesignError(f"{what}: not a readable design checkpoint ({type(exc).__name__}: "
                          f"{exc or 'empty or truncated'}); restore it or start a new run") from exc
    if checkpoint.x.shape != checkpoint.best_x.shape:
        raise DesignError(f"{what}: x and best_x differ in size ({checkpoint.x.size}, {checkpoint.best_x.size})")
    return checkpoint


def save_checkpoint(path: Path, checkpoint: Checkpoint) -> None:
    """Write a `Checkpoint` to ``path``: a temporary file, flushed to the disk, then renamed over ``path``,
    so a crash or a full disk leaves the previous checkpoint and no partial file.

    Uncompressed: compressing the two design-variable arrays (17 MB each at 128^3) would cost
    more time per evaluation than writing them plainly.

    Raises
    ------
    DesignError
        When the file cannot be written (a read-only folder, a full disk), naming it; the temporary file is
        removed.
    """
    path = Path(path)
    tmp = path.with_suffix(".tmp.npz")
    status = "" if checkpoint.status is None else str(checkpoint.status)
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, format=CHECKPOINT_FORMAT, x=checkpoint.x, best_x=checkpoint.best_x,
                     best_value=checkpoint.best_value, stage=checkpoint.stage, history=checkpoint.history,
                     beta=checkpoint.beta, status=status,
                     **{f"lbfgs_{k}": v for k, v in checkpoint.lbfgs.items()},
                     **{f"fab_{k}": v for k, v in checkpoint.fab.items()})
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if not isinstance(exc, OSError):
            raise
        raise DesignError(f"cannot write the checkpoint {path}: {exc.strerror or exc} (a read-only folder or a "
                          "full disk?); the previous checkpoint is kept") from exc
