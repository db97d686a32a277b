"""What the bench application remembers between sessions (``QSettings``): the last run's settings, in
``run.json``'s flat layout (``labapp.acquisition.settings.to_record`` / ``from_record``), and the last
simulation calibration. Method templates are ``labapp.acquisition.methods`` files, the ones ``sfr method``
and ``sfr run --method`` use.
"""
from __future__ import annotations

import json
import os
from typing import Any

from PySide6.QtCore import QSettings

from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import from_record, to_record
from labapp.errors import UsageError

ORGANISATION, APPLICATION = "shape-from-release", "sfr-lab"
SETTINGS_ENV = "SFR_LAB_SETTINGS"
"""An INI file to keep the GUI's settings in instead of the user's (tests, several benches on one account)."""
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
