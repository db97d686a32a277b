"""The sweep spec: a TOML file naming one target and the design settings to try (docs/scale.md).

```toml
target = "pill"              # anything `sfr design --target` takes; a relative path is the spec's folder's
space = "extruded"           # top-level design settings hold for every combination
resolution = 32
max_iter = 100

[grid]                       # every combination of these lists ...
w_binary = [10, 20, 40]
radius_vox = [3, 4]

[[points]]                   # ... plus these single combinations
preset = "paper:pill"
```

Setting names are `design.inverse.config.DesignConfig`'s fields. Each combination's settings are the top-level
ones overridden by its own; a preset (``preset = "paper:NAME"``, `design.inverse.presets`) fills the
hyperparameters neither gives, as `sfr design --preset` does.
``simcal`` (a simulation-to-bench calibration, as `sfr design --simcal` takes) is passed through with the
target. Every combination is checked here, so that a bad value stops the sweep before any work.
"""
from __future__ import annotations

import itertools
import json
import re
import tomllib
import types
import typing
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from design.errors import DesignError
from design.geometry.shapes import SAMPLE_SHAPES
from design.inverse.config import DesignConfig
from design.inverse.target_spec import parse_analytic
from labapp.errors import UsageError
from labapp.jobs.physical import is_physical
from labapp.records.simcal import SimCalError, load_simcal

PRESET_KEY = "preset"
SPEC_ONLY_KEYS = ("target", "simcal", "grid", "points")
DESIGN_KEYS = tuple(f.name for f in fields(DesignConfig) if f.name != "target")
SETTING_KEYS = (PRESET_KEY, *(k for k in DESIGN_KEYS if k != PRESET_KEY))
_HINTS = typing.get_type_hints(DesignConfig)


class SpecError(UsageError):
    """A sweep spec that cannot be read or holds an invalid setting."""


@dataclass(frozen=True)
class Combination:
    """One design of a sweep.

    Attributes
    ----------
    name : str
        Its run folder's name, from its own settings (stable when the spec's other entries change).
    settings : dict
        The settings the spec gives this combination itself (grid values, point entries, preset).
    config : DesignConfig
        The resolved configuration of its `sfr design` run.
    simcal : str or None
        Simulation-to-bench calibration passed to the design job with the target.
    """

    name: str
    settings: dict
    config: DesignConfig
    simcal: str | None = None


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep spec: its source text and its combinations, in spec order (grid, then points)."""

    text: str
    target: str
    simcal: str | None
    combinations: tuple[Combination, ...]

    @property
    def swept_keys(self) -> tuple[str, ...]:
        """Settings given per combination, in `SETTING_KEYS` order (the sweep table's columns)."""
        given = {k for c in self.combinations for k in c.settings}
        return tuple(k for k in SETTING_KEYS if k in given)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep spec file.

    Raises
    ------
    SpecError
        Naming the file, the key and what was expected.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SpecError(f"cannot read the sweep spec {path}: {exc.strerror or exc}") from exc
    return parse_spec(text, base_dir=path.parent, source=str(path))


def parse_spec(text: str, *, base_dir: str | Path = ".", source: str = "spec") -> SweepSpec:
    """Parse sweep-spec TOML; relative paths (target, simcal) are taken from `base_dir`."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{source}: not valid TOML: {exc}") from exc
    unknown = sorted(set(data) - set(SPEC_ONLY_KEYS) - set(SETTING_KEYS))
    if unknown:
        raise SpecError(f"{source}: unknown key {unknown[0]!r}; expected target, simcal, [grid], [[points]] or a "
                        f"design setting ({', '.join(SETTING_KEYS)})")
    target = data.get("target")
    if not isinstance(target, str) or not target.strip():
        raise SpecError(f"{source}: 'target' is required: a string naming what `sfr design --target` takes")
    simcal = data.get("simcal")
    if simcal is not None and not isinstance(simcal, str):
        raise SpecError(f"{source}: 'simcal' must be a path string, got {simcal!r}")
    target, simcal = _resolve(target, base_dir), _resolve(simcal, base_dir) if simcal else None
    _check_target(source, target, base_dir)
    _check_simcal(source, target, simcal)
    fixed = {k: v for k, v in data.items() if k in SETTING_KEYS}
    for key, value in fixed.items():
        _check_value(source, key, value)
    entries = _grid(source, data.get("grid", {})) + _points(source, data.get("points", []))
    if not entries:
        entries = [{}]
    combos, seen = [], {}
    for own in entries:
        name = combination_name(own)
        if name in seen:
            raise SpecError(f"{source}: the combination {name} appears twice")
        seen[name] = own
        combos.append(Combination(name, own, _config(source, name, target, fixed, own), simcal))
    return SweepSpec(text, target, simcal, tuple(combos))


def spec_text(target: str, fixed: dict, grid: dict[str, list], points: list[dict] = (),
              simcal: str | None = None) -> str:
    """Sweep-spec TOML for a target (with its simulation calibration), fixed settings, grid lists and single
    points (what a GUI builds)."""
    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return json.dumps(v) if isinstance(v, str) else repr(v)

    lines = [f"target = {value(target)}"] + ([f"simcal = {value(simcal)}"] if simcal else [])
    lines += [f"{k} = {value(v)}" for k, v in fixed.items()]
    if grid:
        lines += ["", "[grid]"] + [f"{k} = {value(list(v))}" for k, v in grid.items()]
    for point in points:
        lines += ["", "[[points]]"] + [f"{k} = {value(v)}" for k, v in point.items()]
    return "\n".join(lines) + "\n"


def _resolve(value: str, base_dir: str | Path) -> str:
    """An existing relative path made absolute (the workers' working folder is not the spec's)."""
    candidate = Path(base_dir) / value
    return str(candidate.resolve()) if not Path(value).is_absolute() and candidate.exists() else value


def _check_target(source: str, target: str, base_dir: str | Path) -> None:
    """A target that names a file or folder must exist (looked for in the spec's folder, then the working folder):
    refused here, before a cluster starts, not by each combination."""
    try:
        if target in SAMPLE_SHAPES or parse_analytic(target) is not None:
            return
    except DesignError as exc:
        raise SpecError(f"{source}: target: {exc}") from exc
    if not Path(target).exists():
        looked = Path(base_dir).resolve() / target
        raise SpecError(f"{source}: target {target!r} does not exist (looked for {looked}"
                        f"{'' if Path(target).is_absolute() else ' and in the working folder'}); expected a sample "
                        f"shape ({', '.join(SAMPLE_SHAPES)}), an analytic curve (zero-order, accel:q=Q), or an existing "
                        f"mesh, CSV curve or run folder")


def _check_simcal(source: str, target: str, simcal: str | None) -> None:
    """A measured (physical) target needs a readable simulation calibration."""
    if simcal is None:
        if is_physical(target):
            raise SpecError(f"{source}: target {target} is a measured curve: add simcal = \"simcal.json\" "
                            "(made by sfr calibrate-sim) to map it to simulation units")
        return
    try:
        load_simcal(simcal)
    except SimCalError as exc:
        raise SpecError(f"{source}: simcal: {exc}") from exc


def _grid(source: str, grid) -> list[dict]:
    if not isinstance(grid, dict):
        raise SpecError(f"{source}: [grid] must be a table of lists, e.g. w_binary = [10, 20]")
    axes = []
    for key, values in grid.items():
        if key not in SETTING_KEYS:
            raise SpecError(f"{source}: unknown key {key!r} in [grid]; expected one of {', '.join(SETTING_KEYS)}")
        if not isinstance(values, list) or not values:
            raise SpecError(f"{source}: grid.{key} must be a non-empty list of values, got {values!r}")
        for value in values:
            _check_value(source, f"grid.{key}", value, key)
        axes.append([(key, v) for v in values])
    return [dict(product) for product in itertools.product(*axes)] if axes else []


def _points(source: str, points) -> list[dict]:
    if not isinstance(points, list) or not all(isinstance(p, dict) for p in points):
        raise SpecError(f"{source}: [[points]] must be tables, e.g. [[points]] then preset = \"paper:pill\"")
    for i, point in enumerate(points):
        if not point:
            raise SpecError(f"{source}: points[{i}] is empty; give at least one setting")
        for key, value in point.items():
            if key not in SETTING_KEYS:
                raise SpecError(f"{source}: unknown key {key!r} in points[{i}]; expected one of "
                                f"{', '.join(SETTING_KEYS)}")
            _check_value(source, f"points[{i}].{key}", value, key)
    return [dict(p) for p in points]


def _check_value(source: str, where: str, value, key: str | None = None) -> None:
    """Check a TOML value's type against the DesignConfig field it sets."""
    key = key or where
    if key == PRESET_KEY:
        ok, expected = isinstance(value, str), "a preset name such as \"paper:pill\""
    else:
        hint = _HINTS[key]
        union = typing.get_origin(hint) in (typing.Union, types.UnionType)
        kind = next(t for t in typing.get_args(hint) if t is not type(None)) if union else hint
        if typing.get_origin(kind) is tuple:
            ok = isinstance(value, list) and all(isinstance(v, (int, float, str)) and not isinstance(v, bool)
                                                 for v in value)
            expected = "a list"
        elif kind is float:
            ok, expected = isinstance(value, (int, float)) and not isinstance(value, bool), "a number"
        elif kind is int:
            ok, expected = isinstance(value, int) and not isinstance(value, bool), "an integer"
        else:
            ok, expected = isinstance(value, kind), kind.__name__
    if not ok:
        raise SpecError(f"{source}: {where} must be {expected}, got {value!r}")


def _format(value) -> str:
    if isinstance(value, list):
        return "x".join(_format(v) for v in value)
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return re.sub(r"[^A-Za-z0-9._+-]", "-", str(value))


def combination_name(settings: dict) -> str:
    """Run folder name of a combination: its own settings, preset first, then alphabetically."""
    keys = sorted(settings, key=lambda k: (k != PRESET_KEY, k))
    return ",".join(f"{k}={_format(settings[k])}" for k in keys) or "default"


def _config(source: str, name: str, target: str, fixed: dict, own: dict) -> DesignConfig:
    merged = {**fixed, **own}
    merged = {k: tuple(v) if isinstance(v, list) else v for k, v in merged.items()}
    try:
        return DesignConfig(target=target, **merged)
    except DesignError as exc:
        raise SpecError(f"{source}: combination {name}: {exc}") from exc


def config_matches(config: DesignConfig, stored: dict) -> bool:
    """Whether a run folder's stored ``config.json`` holds this configuration (the target aside: a run
    optimises its own copy of a file target, `labapp.jobs.design.design`)."""
    mine = json.loads(json.dumps(asdict(config)))
    return {k: v for k, v in mine.items() if k != "target"} == {k: v for k, v in stored.items() if k not in ("target", "format")}
