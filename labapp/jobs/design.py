"""Start or resume a design run with its target recorded and copied (`sfr design`)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from design.files.meshio import MESH_SUFFIXES
from design.inverse.problem import DesignConfig
from labapp.errors import UsageError
from labapp.jobs.meshunits import design_memory_bytes, load_mesh_mm, require_memory, size_warnings
from labapp.jobs.physical import design_from_target, is_physical
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.storage import timestamp_name

log = logging.getLogger(__name__)


def _design_defaults() -> dict[str, Any]:
    return {f.name: f.default for f in dataclasses.fields(DesignConfig) if f.default is not dataclasses.MISSING}


#: The design settings every face starts from (``design.inverse.problem.DesignConfig``'s own defaults).
DESIGN_DEFAULTS: dict[str, Any] = _design_defaults()
TARGET_SOURCE = "target_source.json"


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


def design(config, out: str | Path, *, resume: bool = False, units: str = "mm", simcal=None,
           bench_calibration=None, on_iteration: Callable | None = None,
           should_stop: Callable[[], bool] | None = None, on_warning: Callable[[str], None] | None = None):
    """Start (``config``: a ``design.inverse.problem.DesignConfig``) or resume (``resume=True``) a design run in ``out``.

    A new run records a file target's path and SHA-256 in ``target_source.json`` and optimises a copy in
    the run folder (a mesh scaled from ``units`` to mm), so ``--resume`` uses the target the run started
    with; a changed original is reported through ``on_warning`` (default: the log). A start that is rejected
    (invalid or infeasible target, bad settings, not enough memory) removes what it wrote, so a corrected
    rerun into the same ``out`` is not blocked. The optimisation itself, with a measured target and the
    physical prediction through ``simcal``, is ``labapp.jobs.physical.design_from_target``.

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
        for w in _check_target_unchanged(out):
            warn(w)
        return design_from_target(None, out, resume=True, **run)
    out = check_out(out, FolderKind.DESIGN, [config.target], replace=False)
    existed = out.exists()
    before = set(out.iterdir()) if existed else set()
    source = target = config.target
    try:
        n = config.resolution
        require_memory(design_memory_bytes(n, config.space), f"designing at resolution {n} ({config.space})")
        out.mkdir(parents=True, exist_ok=True)
        target = _copy_target(source, out, units)
        return design_from_target(dataclasses.replace(config, target=target), out, **run)
    except Exception as exc:
        if (out / "checkpoint.npz").exists():
            raise
        for path in (set(out.iterdir()) - before) if out.exists() else ():   # rejected: leave no trace
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        if not existed and out.exists() and not any(out.iterdir()):
            out.rmdir()
        if target != source and target in str(exc) and type(exc).__init__ is Exception.__init__:
            raise type(exc)(str(exc).replace(target, source)) from exc   # name the operator's file, not the copy
        raise
