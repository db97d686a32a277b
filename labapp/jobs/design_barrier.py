"""Start or resume a two-material (drug and barrier) design run (`sfr design --barrier-speed S`)."""
from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from design.errors import DesignError
from design.files.twomaterial_run import TwoMaterialResult, load_settings, problem_for, run_two_material, save_settings
from design.inverse.twomaterial_problem import TwoMaterialSettings
from design.inverse.twomaterial_targets import is_two_material_spec
from labapp.errors import UsageError
from labapp.records.lock import folder_lock
from labapp.records.outpaths import FolderKind, check_out

TARGET_COPY = "target_input.csv"
"""The run's own copy of a CSV target, which the run and its resumes read."""


def _check_resume_options(out: Path, stored: TwoMaterialSettings, options: dict[str, Any]) -> TwoMaterialSettings:
    """The stored settings, with a raised ``max_iter``; any other option given must equal the stored one."""
    kept = stored.to_dict()
    raised = stored
    for name, value in options.items():
        if name == "target":
            continue
        if name == "max_iter" and value >= kept[name]:
            raised = dataclasses.replace(stored, max_iter=value)
            continue
        if value != kept[name]:
            raise UsageError(f"{name} = {value!r} differs from the run's stored {kept[name]!r} in {out / 'config.json'}; "
                             "drop it to resume")
    return raised


def design_barrier(settings: TwoMaterialSettings | None, out: str | Path, *, resume: bool = False,
                   options: dict[str, Any] | None = None, reference: bool = True,
                   on_iteration: Callable[[int, dict], None] | None = None,
                   should_stop: Callable[[], bool] | None = None) -> TwoMaterialResult:
    """Start (``settings``) or resume (``resume=True``) a two-material design in ``out``.

    A new run checks ``out`` and the target, and refuses a target the barrier or the domain cannot give
    (`design.inverse.twomaterial_targets.check_two_material_target`), before it writes anything; a CSV
    target is copied into the run (`TARGET_COPY`). A resume continues from the run's checkpoint
    (``options`` given with it must equal the stored settings; ``max_iter`` may be raised); a finished run
    is left as it is.

    Raises
    ------
    UsageError
        For an ``out`` that is an input or another command's folder, or a resume of a folder without a
        two-material run.
    design.DesignError
        For an unreadable or infeasible target, or invalid settings.
    """
    if resume:
        out = Path(out)
        if not (out / "config.json").is_file():
            raise UsageError(f"{out} holds no design run to resume (no config.json); start one with --target")
        stored = _check_resume_options(out, load_settings(out), dict(options or {}))
        with folder_lock(out):
            if stored.max_iter != load_settings(out).max_iter:
                save_settings(out, stored)
            return run_two_material(None, out, resume=True, reference=reference, on_iteration=on_iteration,
                                    should_stop=should_stop)
    csv = not is_two_material_spec(settings.target)
    out = check_out(out, FolderKind.DESIGN, [settings.target] if csv else [])
    if csv and not Path(settings.target).is_file():
        raise UsageError(f"--target {settings.target}: no such file (a tau_mm,released_mm3 CSV or a two-material family "
                         "delay-zero:, pulses:, constant:)")
    problem_for(settings)          # refuses an unreadable or infeasible target before anything is written
    existed = out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        with folder_lock(out):
            if csv:
                shutil.copyfile(settings.target, out / TARGET_COPY)
                settings = dataclasses.replace(settings, target=str((out / TARGET_COPY).resolve()))
            return run_two_material(settings, out, reference=reference, on_iteration=on_iteration,
                                    should_stop=should_stop)
    except DesignError:
        if not (out / "checkpoint.npz").exists() and not existed:
            shutil.rmtree(out, ignore_errors=True)
        raise
