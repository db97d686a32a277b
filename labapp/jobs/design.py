"""Start or resume a design run with its target recorded and copied (`sfr design`)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from design.files.meshio import MESH_SUFFIXES
from design.files.records import load_config, stored_form
from design.inverse.settings import option_flag
from labapp.errors import UsageError
from labapp.jobs.meshunits import design_memory_bytes, load_mesh_mm, require_memory, size_warnings
from labapp.jobs.physical import TARGET_CSV, design_from_target, is_physical
from labapp.records.fileio import timestamp_name
from labapp.records.lock import folder_lock
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.simcal import load_simcal

log = logging.getLogger(__name__)


TARGET_SOURCE = "target_source.json"
SIMCAL_COPY = "simcal_input.json"
"""The run's copy of the simulation calibration it started with (``--simcal``), which a resume uses."""
SIMCAL_SOURCE = "simcal_source.json"
"""Where that copy came from: ``source`` (absolute path), ``sha256`` (of the copy, as of the source then)."""

def design_folder(data_dir: str | Path, name: str) -> Path:
    """The folder of a new design run started from the GUI: ``DATA/designs/<YYYYmmdd-HHMMSS>_<name>``."""
    return Path(data_dir) / "designs" / timestamp_name(name)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _copy_target(target: str, out: Path, units: str) -> str:
    """Record a file or folder target in ``target_source.json`` (path and SHA-256); copy a simulation-unit
    target (CSV, mesh scaled from ``units`` to mm) into the run folder and return the copy's path, which the
    run then optimises. A measured (physical) target is turned into its CSV in the run folder by
    ``labapp.jobs.physical.design_from_target``; here only its source is recorded."""
    source = Path(target)
    if not source.exists():
        return target
    record: dict[str, Any] = {"source": str(source.resolve()), "units": units,
                              "sha256": _sha256(source) if source.is_file() else None, "copy": None}
    if source.is_file() and not is_physical(source):
        suffix = source.suffix.lower()
        copy = out / f"target_input{suffix}"
        if suffix in MESH_SUFFIXES:
            mesh = load_mesh_mm(source, units)
            for w in size_warnings(mesh.extents, float(mesh.volume), source=str(source)):
                log.warning("%s", w)
            if units != "mm":
                copy = out / "target_input.stl"
                mesh.export(copy)
            else:
                shutil.copyfile(source, copy)
        else:
            shutil.copyfile(source, copy)
        record.update(copy=copy.name, copy_sha256=_sha256(copy))
        target = str(copy.resolve())
    elif units != "mm":
        raise UsageError("--units applies to a mesh target")
    (out / TARGET_SOURCE).write_text(json.dumps(record, indent=2) + "\n")
    return target


def _check_target_unchanged(out: Path) -> list[str]:
    """On resume: warnings when the original target changed since the run started; refuses a run whose own
    copy of the target is missing or altered."""
    try:
        record = json.loads((out / TARGET_SOURCE).read_text())
    except FileNotFoundError:
        return []
    except (OSError, ValueError) as exc:
        raise UsageError(f"{out / TARGET_SOURCE} cannot be read: {exc}") from exc
    if record.get("copy"):
        copy = out / record["copy"]
        if not copy.is_file() or _sha256(copy) != record["copy_sha256"]:
            raise UsageError(f"{copy}: the run's copy of its target is missing or altered (SHA-256 differs from "
                             f"{TARGET_SOURCE}); the run cannot be resumed on the target it started with")
    source = Path(record["source"])
    if record.get("sha256") and (not source.is_file() or _sha256(source) != record["sha256"]):
        used = f"the copy taken at the start ({record['copy']})" if record.get("copy") else \
            "the target curve written at the start"
        return [f"the target {source} has changed (or is gone) since this run started; resuming with {used}"]
    return []


def _text(value: Any) -> str:
    if isinstance(value, (list, tuple)):
        return " ".join(_text(v) for v in value)
    return str(value)


def _same_target(out: Path, given: str, stored: str) -> tuple[bool, str]:
    """Whether a ``--target`` given to a resume names the target the run started with, and that target as
    the run records it."""
    try:
        record = json.loads((out / TARGET_SOURCE).read_text())
    except (OSError, ValueError):
        return given == stored, stored
    path = Path(given)
    if path.exists():
        if str(path.resolve()) == record.get("source"):
            return True, record["source"]
        if path.is_file() and record.get("sha256") and _sha256(path) == record["sha256"]:
            return True, record["source"]
    return False, record.get("source", stored)


def _resume_config(out: Path, options: dict[str, Any], units: str | None):
    """The configuration a resume runs with: None (the stored one), or the stored one with a raised
    evaluation limit. Options given with the resume must be the stored ones (``max_iter`` may be higher).

    Raises
    ------
    UsageError
        Naming the first option that differs, its stored value and the file that holds it.
    """
    stored = load_config(out)
    kept = stored_form(stored)
    where = out / "config.json"
    raised = None
    for name, value in options.items():
        if name == "target":
            same, shown = _same_target(out, str(value), stored.target)
            if not same:
                held = out / TARGET_SOURCE if (out / TARGET_SOURCE).is_file() else where
                raise UsageError(f"--target {value} differs from the run's stored {shown} in {held}; drop it to resume")
            continue
        if name not in kept:
            raise UsageError(f"{option_flag(name)} is not a design setting that {where} records")
        given = json.loads(json.dumps(value))
        if name == "max_iter" and given >= kept[name]:
            raised = given if given > kept[name] else raised  # a resume may raise the evaluation limit
            continue
        if given != kept[name]:
            more = "; a resume may only raise it" if name == "max_iter" else ""
            raise UsageError(f"{option_flag(name)} {_text(value)} differs from the run's stored {_text(kept[name])} in "
                             f"{where}; drop it to resume{more}")
    if units is not None:
        try:
            recorded = json.loads((out / TARGET_SOURCE).read_text()).get("units", "mm")
        except (OSError, ValueError):
            recorded = "mm"
        if units != recorded:
            raise UsageError(f"--units {units} differs from the run's stored {recorded} in {out / TARGET_SOURCE}; drop "
                             "it to resume")
    return None if raised is None else dataclasses.replace(stored, max_iter=raised)


def _copy_simcal(simcal, out: Path) -> None:
    """Copy the calibration a run starts with into it (`SIMCAL_COPY`) and record its source and SHA-256."""
    shutil.copyfile(simcal.path, out / SIMCAL_COPY)
    record = {"source": str(Path(simcal.path).resolve()), "sha256": _sha256(out / SIMCAL_COPY), "copy": SIMCAL_COPY}
    (out / SIMCAL_SOURCE).write_text(json.dumps(record, indent=2) + "\n")


def _stored_simcal(out: Path, given):
    """The calibration a resume uses: the run's own copy (its SHA-256 checked), which a ``--simcal`` given
    with the resume must equal; a run started without one takes none.

    Raises
    ------
    UsageError
        An altered copy, a different ``--simcal``, or one given to a run started without it.
    """
    try:
        record = json.loads((out / SIMCAL_SOURCE).read_text())
    except FileNotFoundError:
        record = None
    except (OSError, ValueError) as exc:
        raise UsageError(f"{out / SIMCAL_SOURCE} cannot be read: {exc}") from exc
    if record is None:
        if given is not None:
            raise UsageError(f"--simcal {given.path}: the run in {out} started without a simulation calibration "
                             f"(no {SIMCAL_SOURCE}); drop it to resume")
        return None
    copy = out / record["copy"]
    if not copy.is_file() or _sha256(copy) != record["sha256"]:
        raise UsageError(f"{copy}: the run's copy of its simulation calibration is missing or altered (SHA-256 "
                         f"differs from {SIMCAL_SOURCE}); the run cannot be resumed with the calibration it started with")
    if given is not None and _sha256(Path(given.path)) != record["sha256"]:
        raise UsageError(f"--simcal {given.path} differs from the run's stored calibration {copy} (SHA-256 "
                         f"{record['sha256'][:12]}..., from {record['source']}); drop it to resume")
    return load_simcal(copy)


def failed_design(summary: Mapping[str, Any]) -> str | None:
    """Why a design run that finished is a failed job (no printable solid came out of it), else None."""
    if summary.get("pieces", 1) == 0:
        return ("the design produced no solid: no density reached the extraction level, so design.stl was not "
                "written; run the design again with a higher --max-iter, or check the target and its feasibility.txt")
    return None


def design(config, out: str | Path, *, resume: bool = False, units: str | None = None, simcal=None,
           bench_calibration=None, on_iteration: Callable | None = None,
           should_stop: Callable[[], bool] | None = None, on_warning: Callable[[str], None] | None = None,
           options: dict[str, Any] | None = None):
    """Start (``config``: a ``design.inverse.config.DesignConfig``) or resume (``resume=True``) a design run in ``out``.

    A new run records a file target's path and SHA-256 in ``target_source.json`` and optimises a copy in
    the run folder (a mesh scaled from ``units`` to mm), so ``--resume`` uses the target the run started
    with; a changed original is reported through ``on_warning`` (default: the log). A simulation calibration
    (``simcal``) is copied into the run folder with its SHA-256 (`SIMCAL_COPY`, `SIMCAL_SOURCE`), and a
    resume uses that copy. A start that is rejected
    (invalid or infeasible target, bad settings, not enough memory) removes what it wrote, so a corrected
    rerun into the same ``out`` is not blocked. The optimisation itself, with a measured target and the
    physical prediction through ``simcal``, is ``labapp.jobs.physical.design_from_target``.

    A resume keeps everything the run started with: ``options`` (`DesignConfig` fields, and ``target``, as
    given with the resume) must equal the stored ones, except ``max_iter``, which may be raised; ``units``
    and ``simcal``, when given, must be the stored ones; a ``bench_calibration`` is refused (a measured
    target was converted when the run started). A run that finished with its outputs written is left as
    it is (``result.unchanged``).

    Returns
    -------
    result : design.files.rundir.DesignResult
    physical : dict or None
        The summary with the physical prediction (None without ``simcal``).

    Raises
    ------
    UsageError
        For an ``out`` that is another command's folder (or a design run, without ``resume``), or a grid
        that would not fit in memory.
    design.DesignError
        For an invalid configuration or target, an infeasible target, or a resume mismatch.
    """
    warn = on_warning or (lambda message: log.warning("%s", message))
    out = Path(out)
    run = dict(simcal=simcal, bench_calibration=bench_calibration, on_iteration=on_iteration,
               should_stop=should_stop)
    if resume:
        if not (out / "config.json").is_file():
            raise UsageError(f"{out} holds no design run to resume (no config.json); start one with --target")
        if bench_calibration is not None:
            raise UsageError(f"--calibration is used when a run starts, to convert a measured target (kept in {out}); "
                             "drop it to resume")
        resumed = _resume_config(out, dict(options or {}), units)
        run["simcal"] = _stored_simcal(out, simcal)
        for w in _check_target_unchanged(out):
            warn(w)
        with folder_lock(out):      # one writer: a second resume (sfr design, the GUI's launcher) is refused
            return design_from_target(resumed, out, resume=True, **run)
    units = units or "mm"
    out = check_out(out, FolderKind.DESIGN, [config.target])
    existed = out.exists()
    before = set(out.iterdir()) if existed else set()
    source = target = config.target
    try:
        n = config.resolution
        require_memory(design_memory_bytes(n, config.space), f"designing at resolution {n} ({config.space})")
        out.mkdir(parents=True, exist_ok=True)
        target = _copy_target(source, out, units)
        if simcal is not None:  # the run's own copy, as a resume uses it
            _copy_simcal(simcal, out)
            run["simcal"] = load_simcal(out / SIMCAL_COPY)
        return design_from_target(dataclasses.replace(config, target=target), out, **run)
    except Exception as exc:
        if (out / "checkpoint.npz").exists():
            raise
        for path in (set(out.iterdir()) - before) if out.exists() else ():   # rejected: leave no trace
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        if not existed and out.exists() and not any(out.iterdir()):
            out.rmdir()
        text = str(exc)
        for written in {target, str(out / TARGET_CSV), str((out / TARGET_CSV).resolve())} - {source}:
            text = text.replace(written, source if written == target else f"{source} (through --simcal)")
        if text != str(exc) and type(exc).__init__ is Exception.__init__:
            raise type(exc)(text) from exc      # name the operator's file, not the copy or the conversion
        raise
