"""The bench's settings, each declared once: name, unit, allowed range, default and help text.

From these declarations are made the `sfr run` / `sfr calibrate-bench` / `sfr lab` options
(:func:`labapp.cli.argtypes.add_setting`), the GUI's spin boxes (:class:`labapp.gui.fields.SettingBox`) and
the checks in the ``__post_init__`` of :class:`BathSettings`, :class:`labapp.acquisition.procedures.RunConfig`
and :class:`labapp.acquisition.calseries.SeriesConfig`. The hotplate's limits are the driver's: the
setpoint ranges of :data:`drivers.hotplate.protocol.HEIDOLPH_HEI_TEC` capped by the client-side limits of
:class:`drivers.hotplate.HotplateConfig` (what the bench's driver, built by
:func:`labapp.acquisition.devices.make_hotplate`, accepts), and the poll interval stays below the plate's
connection check. The decoding factors are the analysis' (:data:`analysis.decode.REDUCE_FACTORS`).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from analysis.calibration import WATER_RANGE_G
from analysis.decode import REDUCE_FACTORS
from drivers.hotplate import HEIDOLPH_HEI_TEC, HotplateConfig
from labapp.errors import UsageError

__all__ = ["ADDED_MASS", "BATH_SETTINGS", "BathSettings", "CHANGEABLE_DURING_RUN", "EXCURSION", "FRAME_BYTES", "GRID",
           "HEAT_TIMEOUT", "HOLD", "INSTANT_STABLE_STEP_S", "INTERVAL", "KEEPALIVE", "LOW_SPACE", "MAX_DURATION",
           "MIN_DURATION", "MIRROR_COL", "OBJECT_MASS", "REDUCE", "REFERENCE_ALARM_G_PER_KG", "ROOM_TEMPERATURE_C",
           "RUN_SETTINGS", "SERIES_REDUCE", "SERIES_SETTINGS", "SETPOINT", "SETTLE", "SIM_SPEED", "STABLE_STEP",
           "STIRRING", "Setting", "TOLERANCE", "WATER", "check_settings", "from_record", "parse_masses", "to_record"]

Number = float | int


@dataclass(frozen=True)
class Setting:
    """One setting: where it is stored, its unit, allowed range and default.

    Parameters
    ----------
    name : str
        Field name in the config dataclass and in ``run.json`` (carries the unit: ``setpoint_c``).
    label : str
        What it is, for help texts and GUI labels.
    unit : str
        Unit of the stored value ('' for a count or factor).
    default : float or int or None
        Default; None for an optional setting that is not given.
    low, high : float, optional
        Allowed range; None: unbounded on that side.
    low_open, high_open : bool
        The bound itself is excluded (``> low``, ``< high``).
    integer : bool
        Whole numbers only.
    optional : bool
        None is allowed (the quantity is unknown or not used).
    choices : tuple of int
        The only allowed values (instead of a range).
    decimals : int
        Decimals shown in the GUI.
    flag : str, optional
        Command-line option; None: not an option (a technical setting).
    scale : float
        Stored value / shown value: the command line and the GUI show ``value / scale`` in ``shown_unit``.
    shown_unit : str, optional
        Unit shown by the command line and the GUI (default ``unit``).
    note : str
        Further help text (what 0 or an omitted value means).
    """

    name: str
    label: str
    unit: str = ""
    default: Number | None = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    integer: bool = False
    optional: bool = False
    choices: tuple[int, ...] = ()
    decimals: int = 1
    flag: str | None = None
    scale: float = 1.0
    shown_unit: str | None = None
    note: str = ""

    def __post_init__(self) -> None:
        if self.default is not None and not self.allows(self.default):
            raise ValueError(f"setting {self.name}: default {self.default!r} is not {self.range_text()}")

    @property
    def display_unit(self) -> str:
        """The unit the command line and the GUI use."""
        return self.unit if self.shown_unit is None else self.shown_unit

    def allows(self, value: Any) -> bool:
        """Whether ``value`` (stored units) is allowed."""
        if value is None:
            return self.optional
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return False
        if self.integer and value != int(value):
            return False
        if self.choices:
            return value in self.choices
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return not (self.high is not None and (value >= self.high if self.high_open else value > self.high))

    def range_text(self, shown: bool = False) -> str:
        """The allowed values in words: ``in [0, 100] C``, ``> 0 s``, ``one of 1, 2, 4, 8``, ``any``.

        ``shown``: in the command line's and GUI's unit (``scale`` applied).
        """
        k, unit = (self.scale, self.display_unit) if shown else (1.0, self.unit)
        tail = f" {unit}" if unit else ""
        if self.choices:
            return "one of " + ", ".join(f"{c:g}" for c in self.choices)
        low = None if self.low is None else self.low / k
        high = None if self.high is None else self.high / k
        if low is not None and high is not None:
            return f"in {'(' if self.low_open else '['}{low:g}, {high:g}{')' if self.high_open else ']'}{tail}"
        if low is not None:
            return f"{'>' if self.low_open else '>='} {low:g}{tail}"
        if high is not None:
            return f"{'<' if self.high_open else '<='} {high:g}{tail}"
        return "finite"

    def check(self, value: Any, owner: str) -> None:
        """Raise UsageError naming ``owner.name``, the value and the allowed range unless ``value`` is allowed."""
        if not self.allows(value):
            kind = "a whole number " if self.integer and not self.choices else ""
            raise UsageError(f"{owner}.{self.name} must be {kind}{self.range_text()}, got {value!r}")

    def shown(self, value: Number) -> float:
        """A stored value in the shown unit."""
        return value / self.scale

    def stored(self, value: Number) -> Number:
        """A shown value in the stored unit."""
        return int(value) if self.integer else value * self.scale

    def help(self) -> str:
        """Help text with unit, default and range: ``bath temperature setpoint, C (default 70; in [0, 100] C)``."""
        unit = f", {self.display_unit}" if self.display_unit else ""
        parts = [] if self.default is None else [f"default {self.shown(self.default):g}"]
        parts += [] if self.range_text() == "finite" else [self.range_text(shown=True)]
        parts += [self.note] if self.note else []
        return f"{self.label}{unit} ({'; '.join(parts)})"


_PLATE = HotplateConfig()
_TEMP_C = _PLATE.setpoint_range("temperature")
_SPEED_RPM = _PLATE.setpoint_range("speed")

ROOM_TEMPERATURE_C = 25.0
"""The lowest bath setpoint, C: a hotplate only heats, and a bath starts at room temperature (about 20-25 C), so
a lower setpoint would never be reached and the procedure would wait out its heating timeout. For a bath
at room temperature choose no setpoint (no heating)."""

# -- the bath (shared by a release run and a calibration series) -----------------------------------------------
WATER = Setting("water_g", "water in the beaker", "g", 500.0, *WATER_RANGE_G, flag="--water-g",
                note="a beaker's bath, 500 g in paper section 4.2; outside the range a typing or unit error")
SETPOINT = Setting("setpoint_c", "bath temperature", "C", 70.0, max(_TEMP_C[0], ROOM_TEMPERATURE_C), _TEMP_C[1],
                   optional=True, flag="--setpoint",
                   note="from room temperature up to what the hotplate driver accepts (a hotplate only heats)")
STIRRING = Setting("speed_rpm", "stirring speed", "rpm", 150.0, *_SPEED_RPM, optional=True, decimals=0, flag="--rpm",
                   note="what the hotplate driver accepts")
TOLERANCE = Setting("tolerance_c", "stable-bath tolerance", "C", 0.5, low=0.0, low_open=True, decimals=2,
                    flag="--tolerance", note="the bath is stable once within setpoint +/- this for the hold time")
EXCURSION = Setting("excursion_c", "temperature alarm band during acquisition", "C", 2.0, low=0.0, low_open=True,
                    decimals=1, flag="--excursion",
                    note="an alarm is raised when the bath leaves setpoint +/- this after the drop")
HOLD = Setting("hold_s", "stable-bath hold time", "s", 120.0, low=0.0, low_open=True, decimals=0, flag="--hold")
HEAT_TIMEOUT = Setting("heat_timeout_s", "heating timeout", "s", 2 * 3600.0, low=0.0, low_open=True, decimals=0,
                       flag="--heat-timeout", note="a bath not stable by then fails the procedure")
STABLE_STEP = Setting("stable_step_s", "bath check interval while heating", "s", 5.0, low=0.0, low_open=True)
KEEPALIVE = Setting("keepalive_s", "hotplate poll interval", "s", 2.0, low=0.0, high=HEIDOLPH_HEI_TEC.watchdog_s,
                    low_open=True, high_open=True, decimals=2,
                    note="below the plate's connection check")
BATH_SETTINGS = (WATER, SETPOINT, STIRRING, TOLERANCE, EXCURSION, HOLD, HEAT_TIMEOUT, STABLE_STEP, KEEPALIVE)

INSTANT_STABLE_STEP_S = 60.0
"""Bath check interval on an instant clock (time moves only when a procedure sleeps), s."""

# -- a release run -------------------------------------------------------------------------------------------
INTERVAL = Setting("interval_s", "frame interval", "s", 11.0, low=0.0, low_open=True, flag="--interval",
                   note="paper section 4.2")
MAX_DURATION = Setting("max_duration_s", "maximum duration", "s", 4 * 3600.0, low=0.0, low_open=True, decimals=2,
                       flag="--max-hours", scale=3600.0, shown_unit="h")
MIN_DURATION = Setting("min_duration_s", "shortest run before a steady-state stop", "s", 1800.0, low=0.0, decimals=0,
                       flag="--min-minutes", scale=60.0, shown_unit="min")
OBJECT_MASS = Setting("object_mass_g", "object mass (weighed)", "g", None, low=0.0, low_open=True, optional=True,
                      decimals=4, flag="--object-mass", note="omitted: not recorded")
FRAME_BYTES = Setting("frame_bytes_estimate", "bytes of one frame for the disk-space check", "B", None, low=0.0,
                      low_open=True, integer=True, optional=True, decimals=0, note="not given: the bench's own")
LOW_SPACE = Setting("low_space_bytes", "free space below which a warning is logged", "B", 2_000_000_000, low=0.0,
                    integer=True, decimals=0)
RUN_SETTINGS = (INTERVAL, MAX_DURATION, MIN_DURATION, OBJECT_MASS, FRAME_BYTES, LOW_SPACE)
CHANGEABLE_DURING_RUN = (MAX_DURATION, MIN_DURATION)
"""The settings a recording run may change (with a reason, audited): the acquisition reads them at every frame;
every other setting is fixed at the start."""

REFERENCE_ALARM_G_PER_KG = 0.1
"""A run's reference frame (clear water) reading further than this from the calibration's zero level, g/kg, and
beyond the offline analysis' 3 sigma (``analysis.reference_offset``), raises an alarm before the drop; a
smaller significant offset is logged as a warning, as the offline analysis does."""

# -- a calibration series ------------------------------------------------------------------------------------
SETTLE = Setting("settle_s", "wait after each addition", "s", 600.0, low=0.0, decimals=0, flag="--settle",
                 note="the simulated bench's filament dissolves in it; a real bench waits 0 s (the operator "
                      "enters each mass once the piece has dissolved)")
GRID = Setting("grid", "cells per side of the crop", "", 10, low=1.0, integer=True, decimals=0, flag="--grid")
REDUCE = Setting("reduce", "decode the images downscaled by this factor", "", 1, choices=REDUCE_FACTORS,
                 integer=True, decimals=0, flag="--reduce")
SERIES_REDUCE = dataclasses.replace(REDUCE, default=2, note="a recorded series is fitted at half resolution; a run "
                                                            "decodes its frames at its calibration's factor")
MIRROR_COL = Setting("mirror_col", "column of the mirror axis", "px", None, optional=True, flag="--mirror-col",
                     note="not given: the image centre")
ADDED_MASS = Setting("added_mass_g", "cumulative added mass", "g", 0.0, low=0.0, decimals=4)
SERIES_SETTINGS = (SETTLE, GRID, SERIES_REDUCE, MIRROR_COL)

# -- the simulated bench -------------------------------------------------------------------------------------
SIM_SPEED = Setting("speed", "simulated time acceleration", "", 100.0, low=0.0, flag="--speed",
                    note="0 = as fast as frames render")


def check_settings(config: Any, settings: tuple[Setting, ...]) -> None:
    """Check the fields of ``config`` named by ``settings`` (UsageError naming class, field, value, range)."""
    for setting in settings:
        setting.check(getattr(config, setting.name), type(config).__name__)


def parse_masses(text: str) -> tuple[float, ...]:
    """``"0.25, 0.5, 1"`` -> (0.25, 0.5, 1.0): cumulative masses in g (``;`` separates too; empty: none).

    Raises
    ------
    UsageError
        For an entry that is not a number.
    """
    masses = []
    for item in text.replace(";", ",").split(","):
        if item.strip():
            try:
                masses.append(float(item))
            except ValueError:
                raise UsageError(f"masses {text!r}: {item.strip()!r} is not a number (cumulative mass, g)") from None
    return tuple(masses)


@dataclass(frozen=True)
class BathSettings:
    """The bath of a release run or a calibration series: water, temperature, stirring and when it is stable.

    Water in g, temperatures in C, speed in rpm, times in s (procedure clock); ranges in :data:`BATH_SETTINGS`.
    ``setpoint_c`` None: the plate is not heated and nothing waits for the bath; ``speed_rpm`` None: the
    speed setpoint is left as it is.
    """

    water_g: float = WATER.default
    setpoint_c: float | None = SETPOINT.default
    speed_rpm: float | None = STIRRING.default
    tolerance_c: float = TOLERANCE.default
    excursion_c: float = EXCURSION.default
    hold_s: float = HOLD.default
    heat_timeout_s: float = HEAT_TIMEOUT.default
    stable_step_s: float = STABLE_STEP.default
    keepalive_s: float = KEEPALIVE.default

    def __post_init__(self) -> None:
        check_settings(self, BATH_SETTINGS)

    def on_clock(self, speed: float) -> BathSettings:
        """These settings for a clock running ``speed`` times real time: on an instant clock (``inf``) the
        bath is checked every :data:`INSTANT_STABLE_STEP_S` s of procedure time."""
        return dataclasses.replace(self, stable_step_s=INSTANT_STABLE_STEP_S) if math.isinf(speed) else self


def to_record(config: Any) -> dict[str, Any]:
    """A config as stored in ``run.json``: its fields, with the bath's fields alongside them (one flat dict)."""
    data = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name != "bath"}
    if hasattr(config, "bath"):
        data.update(dataclasses.asdict(config.bath))
    return {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}


def from_record(cls: type, data: dict[str, Any]) -> Any:
    """Rebuild a config of ``cls`` from ``run.json``'s flat layout (:func:`to_record`); unknown keys are
    ignored, lists become tuples."""
    names = {f.name for f in dataclasses.fields(cls)}
    bath_names = {f.name for f in dataclasses.fields(BathSettings)}
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k in names and k != "bath"}
    if "bath" in names:
        kwargs["bath"] = BathSettings(**{k: v for k, v in data.items() if k in bath_names})
    return cls(**kwargs)
