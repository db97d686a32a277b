"""Argument types for `sfr` numbers: every command-line number is finite and in its meaningful range.

``argparse`` accepts ``nan``, ``inf`` and ``-2`` for ``type=float``/``int``; these types refuse them with a
message naming what was expected (argparse prefixes the option name and exits with code 2). A declared
setting (:mod:`labapp.acquisition.settings`) becomes its option with :func:`add_setting`; other numbers use
the types directly, as ``parser.add_argument("--window-s", type=positive_float)``. A declared design setting
(:mod:`design.inverse.settings`) becomes its ``sfr design`` option with :func:`add_design_option`.
"""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

from labapp.acquisition.settings import Setting

__all__ = ["add_design_option", "add_setting", "add_settings", "bounded", "finite_float", "nonnegative_float", "nonnegative_int",
           "positive_float", "positive_int", "setting_type", "setting_values"]


def setting_type(setting: Setting) -> Callable[[str], float | int]:
    """The argparse type of a declared setting: a number in the setting's shown unit, checked against its
    range and returned in its stored unit (``--max-hours 2`` -> 7200.0 s)."""
    def parse(text: str) -> float | int:
        value = _int(text) if setting.integer else finite_float(text)
        stored = setting.stored(value)
        if not setting.allows(stored):
            what = "" if setting.choices else "a whole number " if setting.integer else "a number "
            raise argparse.ArgumentTypeError(f"{text!r}: expected {what}{setting.range_text(shown=True)}")
        return stored
    parse.__name__ = setting.name
    return parse


def add_setting(parser: argparse.ArgumentParser | argparse._ArgumentGroup, setting: Setting) -> argparse.Action:
    """Add the option of a declared setting: its flag, a type with the range check, its default and a help
    text with unit, default and range; the value lands in ``args.<setting.name>``, in the stored unit."""
    return parser.add_argument(setting.flag, dest=setting.name, type=setting_type(setting), default=setting.default,
                               metavar=(setting.display_unit or "N").upper(), help=setting.help())


def add_settings(parser: argparse.ArgumentParser, settings: tuple[Setting, ...], title: str,
                 skip: tuple[Setting, ...] = ()) -> None:
    """The options of the ``settings`` that have a flag (not those in ``skip``), as a group named ``title``."""
    group = parser.add_argument_group(title)
    for setting in settings:
        if setting.flag and setting not in skip:
            add_setting(group, setting)


def setting_values(args: argparse.Namespace, settings: tuple[Setting, ...]) -> dict[str, float | int | None]:
    """``{name: value}`` of the ``settings`` the parsed ``args`` hold (keyword arguments of a config)."""
    return {s.name: getattr(args, s.name) for s in settings if hasattr(args, s.name)}


def add_design_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, setting: Any) -> argparse.Action:
    """Add the ``sfr design`` option of a declared design setting (:class:`design.inverse.settings.DesignSetting`).

    The option has no default (a setting left out takes the design configuration's, resolved from the others);
    the command line checks a number's declared range (each number of a tuple's) and the choices it is told to,
    the configuration the conditions between settings. The value lands in ``args.<setting.name>``.
    """
    kwargs: dict[str, Any] = {"dest": setting.name, "help": setting.help()}
    if setting.kind == "switch":
        return parser.add_argument(setting.flag, action="store_true", **kwargs)
    if setting.choices_checked:
        kwargs["choices"] = setting.choices
    else:
        kwargs["metavar"] = setting.metavar or setting.flag[2:].upper().replace("-", "_")
    if setting.kind == "number":
        kwargs["type"] = _range_type(setting)
    if setting.count is not None:
        kwargs["nargs"] = setting.count
    elif setting.many:
        kwargs.update(nargs="*", default=[])
    return parser.add_argument(setting.flag, **kwargs)


def _range_type(setting: Any) -> Callable[[str], float | int]:
    """The argparse type of a declared design number: a whole or finite number in the setting's range, the range
    stated in the refusal (``--resolution 9``: "expected a whole number >= 8 voxels (even)")."""
    def parse(text: str) -> float | int:
        value = _int(text) if setting.integer else finite_float(text)
        if not setting.allows_item(value):
            what = "a whole number " if setting.integer else "a number "
            raise argparse.ArgumentTypeError(f"{text!r}: expected {what}{setting.range_text()}")
        return value
    parse.__name__ = setting.name
    return parse


def bounded(low: float, high: float, *, integer: bool = False, low_open: bool = False,
            unit: str = "") -> Callable[[str], float | int]:
    """The argparse type of a number in ``[low, high]`` (``(low, high]`` with ``low_open``), the range stated in the
    refusal: the one limit of an option whose command checks a range narrower than a sign
    (``sfr calibrate-sim --resolution 2``: "expected a whole number in [8, 512] voxels")."""
    def parse(text: str) -> float | int:
        value = _int(text) if integer else finite_float(text)
        if not ((value > low if low_open else value >= low) and value <= high):
            what = "a whole number" if integer else "a number"
            where = f"{'(' if low_open else '['}{low:g}, {high:g}]" + (f" {unit}" if unit else "")
            raise argparse.ArgumentTypeError(f"{text!r}: expected {what} in {where}")
        return value
    return parse


def finite_float(text: str) -> float:
    """A finite float (no ``nan``, ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number")
    return value


def positive_float(text: str) -> float:
    """A finite float > 0."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number > 0")
    return value


def nonnegative_float(text: str) -> float:
    """A finite float >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number >= 0")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def positive_int(text: str) -> int:
    """An integer >= 1."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 1")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 0")
    return value
