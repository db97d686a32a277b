"""Method files: a release run's settings, calibration and acceptance criteria, saved once and cited by runs.

A method file is JSON (:data:`METHOD_FORMAT` in ``format``): ``name``, who made it and when, ``settings`` (the
bath and the run settings of :data:`METHOD_SETTINGS`, in their stored units, plus ``stop_on_steady``), an
optional ``calibration`` (the bench calibration file's path and SHA-256) and ``acceptance`` criteria
(:class:`Criterion`). ``sfr run --method M.json`` runs with exactly these settings (an option that would
change one is refused) and records the method's path and SHA-256 in ``run.json`` (``method``); the report
checks the criteria. Each value is checked against its declaration in :mod:`labapp.acquisition.settings`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labapp.acquisition.settings import (
    HEAT_TIMEOUT,
    HOLD,
    INTERVAL,
    MAX_DURATION,
    MIN_DURATION,
    SETPOINT,
    STIRRING,
    TOLERANCE,
    WATER,
    BathSettings,
    Setting,
)
from labapp.errors import UsageError
from labapp.records import operators
from labapp.records.fileio import atomic_write, sha256_file
from labapp.records.manifests import read_record

__all__ = ["METHOD_FORMAT", "METHOD_SETTINGS", "Criterion", "Method", "MethodError", "load_method", "make_method",
           "method_from_config", "method_from_run", "save_method"]

METHOD_FORMAT = 1
"""The layout of a method file this version writes."""
METHOD_KIND = "sfr-method"
METHOD_SETTINGS: tuple[Setting, ...] = (WATER, SETPOINT, STIRRING, TOLERANCE, HOLD, HEAT_TIMEOUT, INTERVAL,
                                        MAX_DURATION, MIN_DURATION)
"""The settings a method fixes (the bath and the run's timing); the object, its mass and the notes belong to
each run."""
_BATH = {f.name for f in dataclasses.fields(BathSettings)}


class MethodError(UsageError):
    """A method file that cannot be read, or a run that contradicts its method; the message names the field."""


@dataclass(frozen=True)
class Criterion:
    """One acceptance criterion. ``metric`` ``released_percent``: the release at ``at_h`` hours, % of the
    weighed mass, within [``low``, ``high``]; ``f2``: the similarity factor against the reference at least
    ``low``."""

    metric: str
    low: float | None = None
    high: float | None = None
    at_h: float | None = None

    def __post_init__(self) -> None:
        if self.metric not in ("released_percent", "f2"):
            raise MethodError(f"acceptance metric {self.metric!r}: expected released_percent or f2")
        if self.metric == "released_percent" and (self.at_h is None or self.at_h <= 0):
            raise MethodError("acceptance released_percent needs at_h > 0 (the time in hours)")
        if self.low is None and self.high is None:
            raise MethodError(f"acceptance {self.metric}: give low, high or both")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise MethodError(f"acceptance {self.metric}: low {self.low:g} is above high {self.high:g}; expected "
                              "low <= high")

    def text(self) -> str:
        """``released at 1 h in [20, 40] %`` or ``f2 >= 50``."""
        if self.metric == "f2":
            return f"f2 >= {self.low:g}"
        bounds = f"in [{self.low:g}, {self.high:g}]" if self.low is not None and self.high is not None else \
            (f">= {self.low:g}" if self.low is not None else f"<= {self.high:g}")
        return f"released at {self.at_h:g} h {bounds} % of the weighed mass"

    def holds(self, value: float) -> bool:
        """Whether ``value`` meets the criterion."""
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)


@dataclass(frozen=True)
class Method:
    """A method as read: its settings (stored units), calibration file and SHA-256, criteria, and the file's
    own path and SHA-256 (what a run records)."""

    name: str
    settings: Mapping[str, Any]
    stop_on_steady: bool
    calibration_file: str | None
    calibration_sha256: str | None
    acceptance: tuple[Criterion, ...]
    created_by: str | None
    created_utc: str | None
    path: Path | None = None
    sha256: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The method file's object."""
        return {"format": METHOD_FORMAT, "kind": METHOD_KIND, "name": self.name, "created_by": self.created_by,
                "created_utc": self.created_utc, "settings": dict(self.settings, stop_on_steady=self.stop_on_steady),
                "calibration": None if self.calibration_file is None else
                {"file": self.calibration_file, "sha256": self.calibration_sha256},
                "acceptance": [{k: v for k, v in dataclasses.asdict(c).items() if v is not None}
                               for c in self.acceptance]}

    def citation(self) -> dict[str, Any]:
        """What ``run.json`` records under ``method``: name, path and SHA-256 of the file."""
        return {"name": self.name, "path": str(self.path), "sha256": self.sha256}

    def apply(self, config: Any) -> Any:
        """``config`` (a :class:`labapp.acquisition.procedures.RunConfig`) with the method's settings. A
        setting ``config`` holds at a value other than its default and the method's was given on purpose:
        refused.

        Raises
        ------
        MethodError
            Naming the setting, the value given and the method's.
        """
        changes: dict[str, Any] = {}
        bath: dict[str, Any] = {}
        for setting in METHOD_SETTINGS:
            method_value = self.settings[setting.name]
            holder = config.bath if setting.name in _BATH else config
            given = getattr(holder, setting.name)
            if given != setting.default and given != method_value:
                raise MethodError(f"{setting.flag or setting.name} {_shown(setting, given)} contradicts method "
                                  f"{self.name!r} ({_shown(setting, method_value)}); a method's settings are fixed: "
                                  "save a new method to change them")
            (bath if setting.name in _BATH else changes)[setting.name] = method_value
        if not config.stop_on_steady and self.stop_on_steady:
            raise MethodError(f"--no-steady-stop contradicts method {self.name!r} (stops at steady state)")
        changes["stop_on_steady"] = self.stop_on_steady
        return dataclasses.replace(config, bath=dataclasses.replace(config.bath, **bath), **changes)

    def check_calibration(self, calibration: str | Path | None) -> Path | None:
        """The bench calibration to run with: ``calibration`` if given, else the method's; refused when its
        SHA-256 is not the method's."""
        if self.calibration_file is None:
            return Path(calibration) if calibration else None
        path = Path(calibration) if calibration else Path(self.calibration_file)
        if not path.is_file():
            raise MethodError(f"method {self.name!r}: calibration {path} does not exist")
        if sha256_file(path) != self.calibration_sha256:
            raise MethodError(f"calibration {path} is not the one method {self.name!r} names (SHA-256 "
                              f"{self.calibration_sha256[:16]}...); use that calibration or save a new method")
        return path


def _shown(setting: Setting, value: Any) -> str:
    if value is None:
        return "none"
    return f"{setting.shown(value):g} {setting.display_unit}".strip()


def _criteria(items: Any, where: str) -> tuple[Criterion, ...]:
    if not isinstance(items, list):
        raise MethodError(f"{where}: acceptance must be a list of criteria")
    out = []
    for k, item in enumerate(items, start=1):
        try:
            out.append(Criterion(**item))
        except TypeError as exc:
            raise MethodError(f"{where}: acceptance item {k}: {exc}") from None
        except MethodError as exc:
            raise MethodError(f"{where}: acceptance item {k}: {exc}") from None
    return tuple(out)


def make_method(name: str, settings: Mapping[str, Any], stop_on_steady: bool = True,
                calibration: str | Path | None = None, acceptance: tuple[Criterion, ...] = ()) -> Method:
    """A new method from settings in stored units (every setting of :data:`METHOD_SETTINGS`), made by the
    current operator; the calibration file's SHA-256 is taken now.

    Raises
    ------
    MethodError
        For a missing or out-of-range setting, or a calibration file that does not exist.
    """
    checked = {}
    for setting in METHOD_SETTINGS:
        if setting.name not in settings:
            raise MethodError(f"method {name!r}: setting {setting.name} is missing")
        setting.check(settings[setting.name], f"method {name!r}")
        checked[setting.name] = settings[setting.name]
    cal_file = cal_sha = None
    if calibration is not None:
        cal = Path(calibration)
        if not cal.is_file():
            raise MethodError(f"method {name!r}: calibration {cal} does not exist")
        cal_file, cal_sha = str(cal.resolve()), sha256_file(cal)
    return Method(name, checked, bool(stop_on_steady), cal_file, cal_sha, tuple(acceptance),
                  operators.require(f"saving method {name!r}"), operators.utc_now())


def method_from_run(run: str | Path, name: str, calibration: str | Path | None = None,
                    acceptance: tuple[Criterion, ...] = ()) -> Method:
    """A method with the settings a run was recorded with (``run.json``'s ``config``); its calibration is
    ``calibration``, else the run's copy of its calibration.

    Raises
    ------
    MethodError
        If the run records no settings.
    """
    from labapp.acquisition.procedures import RunConfig  # here: `sfr method --help` loads no engine

    run = Path(run)
    record = read_record(run)
    if not record.config:
        raise MethodError(f"{run}/run.json records no settings (config); it cannot make a method")
    if calibration is None and (run / "calibration.json").is_file():
        calibration = run / "calibration.json"
    return method_from_config(name, RunConfig.from_dict(dict(record.config)), calibration, acceptance)


def method_from_config(name: str, config: Any, calibration: str | Path | None = None,
                       acceptance: tuple[Criterion, ...] = ()) -> Method:
    """A method with the settings of a :class:`labapp.acquisition.procedures.RunConfig` (the GUI's run
    settings, a run's recorded ones), made by the current operator; see :func:`make_method`."""
    settings = {s.name: getattr(config.bath if s.name in _BATH else config, s.name) for s in METHOD_SETTINGS}
    return make_method(name, settings, config.stop_on_steady, calibration, acceptance)


def save_method(method: Method, path: str | Path) -> Path:
    """Write ``method`` to a new file ``path`` (never over an existing one).

    Raises
    ------
    MethodError
        If ``path`` exists.
    """
    path = Path(path)
    if path.exists():
        raise MethodError(f"{path} exists; a method file is never overwritten (save a new one)")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, (json.dumps(method.to_json(), indent=2) + "\n").encode())
    return path


def load_method(path: str | Path) -> Method:
    """Read and check a method file.

    Raises
    ------
    MethodError
        Naming the file and the field that is missing, of the wrong kind or out of range.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
        data = json.loads(raw)
    except (OSError, ValueError) as exc:
        raise MethodError(f"{path}: not a readable method file ({exc})") from None
    if not isinstance(data, dict) or data.get("kind") != METHOD_KIND:
        raise MethodError(f"{path}: not a method file (kind {METHOD_KIND!r} expected)")
    if data.get("format") != METHOD_FORMAT:
        raise MethodError(f"{path}: format {data.get('format')!r}; this version reads format {METHOD_FORMAT}")
    settings = data.get("settings")
    if not isinstance(settings, dict):
        raise MethodError(f"{path}: settings must be an object of setting: value")
    checked = {}
    for setting in METHOD_SETTINGS:
        if setting.name not in settings:
            raise MethodError(f"{path}: settings.{setting.name} is missing ({setting.label}, {setting.unit})")
        setting.check(settings[setting.name], f"{path}: settings")
        checked[setting.name] = settings[setting.name]
    cal = data.get("calibration")
    if cal is not None and not (isinstance(cal, dict) and isinstance(cal.get("file"), str)
                                and isinstance(cal.get("sha256"), str)):
        raise MethodError(f"{path}: calibration must be {{file, sha256}} or null")
    return Method(str(data.get("name") or path.stem), checked, bool(settings.get("stop_on_steady", True)),
                  cal["file"] if cal else None, cal["sha256"] if cal else None,
                  _criteria(data.get("acceptance", []), str(path)), data.get("created_by"), data.get("created_utc"),
                  path.resolve(), hashlib.sha256(raw).hexdigest())
