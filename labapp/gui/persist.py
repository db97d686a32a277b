"""What the bench application remembers: the last run's settings and the last simulation calibration
(``QSettings``), and method templates (JSON files of a run's settings and its calibration).

A method stores the run settings in ``run.json``'s flat layout (``labapp.acquisition.settings.to_record``) and
reads them back through ``from_record``, so a template and a run folder describe a run the same way.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from PySide6.QtCore import QSettings

from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import from_record, to_record
from labapp.errors import UsageError
from labapp.records.jsonfile import read_format

ORGANISATION, APPLICATION = "shape-from-release", "sfr-lab"
SETTINGS_ENV = "SFR_LAB_SETTINGS"
"""An INI file to keep the GUI's settings in instead of the user's (tests, several benches on one account)."""
METHOD_FORMAT = "sfr-method/1"
METHOD_SUFFIX = ".method.json"
LAST_RUN, LAST_CALIBRATION, LAST_SIMCAL = "run/last", "run/calibration", "design/simcal"
NOT_REMEMBERED = ("object_mass_g", "object_name", "notes")
"""Run settings that belong to one object: never carried over to the next run or into a template."""


def app_settings() -> QSettings:
    """The application's settings store: the INI file named by ``$SFR_LAB_SETTINGS``, else the user's."""
    path = os.environ.get(SETTINGS_ENV)
    if path:
        return QSettings(path, QSettings.Format.IniFormat)
    return QSettings(ORGANISATION, APPLICATION)


def run_record(config: RunConfig) -> dict[str, Any]:
    """The settings of ``config`` worth keeping for the next run (flat ``run.json`` layout)."""
    return {k: v for k, v in to_record(config).items() if k not in NOT_REMEMBERED}


def remember_run(settings: QSettings, config: RunConfig, calibration: str | None) -> None:
    """Keep a started run's settings (and its calibration file) for the next session."""
    settings.setValue(LAST_RUN, json.dumps(run_record(config)))
    settings.setValue(LAST_CALIBRATION, calibration or "")
    settings.sync()


def last_run(settings: QSettings) -> tuple[RunConfig, str] | None:
    """The last run's settings and calibration path (None if none are kept or they no longer load)."""
    text = settings.value(LAST_RUN, "")
    if not text:
        return None
    try:
        return from_record(RunConfig, json.loads(str(text))), str(settings.value(LAST_CALIBRATION, "") or "")
    except (ValueError, TypeError, UsageError):
        return None


def write_method(path: Path, config: RunConfig, calibration: str | None) -> Path:
    """Save a method template: the run and bath settings and the bench calibration."""
    path = Path(path)
    if not path.name.endswith(METHOD_SUFFIX):
        path = path.with_name(path.name.removesuffix(".json") + METHOD_SUFFIX)
    doc = {"format": METHOD_FORMAT, "run": run_record(config), "calibration": calibration or None}
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path


def read_method(path: Path) -> tuple[RunConfig, str]:
    """A method template's run settings and calibration path (UsageError naming the file when unusable)."""
    doc = read_format(Path(path), METHOD_FORMAT, "a method template", "save one with File > Save method...")
    try:
        return from_record(RunConfig, dict(doc.get("run") or {})), str(doc.get("calibration") or "")
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{path}: run settings: {exc}") from exc
