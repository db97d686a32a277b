"""Targets of a two-material (drug and barrier) design: their specs, phases and what they need of a barrier.

A two-material target is a ``tau_mm,released_mm3`` CSV or one of three families a single dissolving
material cannot reach (paper sections 5.2 and 6), in simulation units (tau in mm of drug dissolved,
release in mm^3 of drug):

- ``delay-zero:delay=D,rate=R,volume=V``: nothing until tau = D, then R mm^3/mm until V is released;
- ``pulses:volume=V,width=W,gap=G``: V over W at a constant rate, nothing for G, then V again over W;
- ``constant:rate=R,volume=V``: R mm^3/mm from tau = 0 until V is released (a constant rate to the end).

The barrier's own thickness is what buys time (docs/materials.md): a delay D needs barrier at least
``D s`` thick between the outside and all of the drug, a pause G between two pulses a barrier layer
``G s`` thick between the two drug regions; an insoluble barrier (s = 0) gives neither (water reaches
the drug through openings at once, void being dissolved at once). `target_phases` reads these from any
target curve and `check_two_material_target` refuses what the domain and the barrier cannot give.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.inverse.targets import Target, curve_end_mm, tau_grid

FAMILIES: dict[str, tuple[str, ...]] = {"delay-zero": ("delay", "rate", "volume"),
                                        "pulses": ("volume", "width", "gap"),
                                        "constant": ("rate", "volume")}
"""The analytic two-material target families and their parameters (module doc), all required."""
PHASE_LEVEL = 0.002
"""A target's release has started once it exceeds this fraction of its final value (the delay)."""
PAUSE_LEVEL = 0.005
"""Within a pause the target rises by less than this fraction of its final value per `PAUSE_WINDOW`."""
PAUSE_WINDOW = 0.02
"""Window of the pause test, as a fraction of the target's release span (delay to end)."""
MIN_BARRIER_MM = 0.4
"""The thinnest barrier a print holds: two 0.2 mm print lines (section 4.1's extrusion width)."""


def is_two_material_spec(spec: str) -> bool:
    """Whether a target spec names one of the analytic two-material `FAMILIES`."""
    return spec.partition(":")[0] in FAMILIES


def parse_two_material(spec: str) -> tuple[str, dict[str, float]]:
    """``(family, parameters)`` of an analytic two-material target spec.

    Raises
    ------
    DesignError
        Naming the unknown family, the missing, unknown or non-positive parameter.
    """
    head, _, tail = spec.partition(":")
    if head not in FAMILIES:
        raise DesignError(f"target {spec!r}: unknown two-material family {head!r}; use "
                          + ", ".join(f"{k}:{','.join(p + '=..' for p in v)}" for k, v in FAMILIES.items()))
    params: dict[str, float] = {}
    for item in filter(None, tail.split(",")):
        key, _, value = item.partition("=")
        if key not in FAMILIES[head]:
            raise DesignError(f"target {spec!r}: unknown parameter {key!r}; {head} takes {', '.join(FAMILIES[head])}")
        try:
            params[key] = float(value)
        except ValueError as exc:
            raise DesignError(f"target {spec!r}: {key} = {value!r} is not a number") from exc
        if not np.isfinite(params[key]) or params[key] <= 0:
            raise DesignError(f"target {spec!r}: {key} = {value}; expected a number > 0 (mm, mm^3 or mm^3/mm)")
    missing = [p for p in FAMILIES[head] if p not in params]
    if missing:
        raise DesignError(f"target {spec!r}: {head} needs {', '.join(p + '=..' for p in missing)}")
    return head, params


def family_curve(family: str, p: dict[str, float], tau_mm: np.ndarray) -> np.ndarray:
    """The analytic family's cumulative release on ``tau_mm``, mm^3."""
    t = np.asarray(tau_mm, float)
    if family == "delay-zero":
        return np.clip(p["rate"] * (t - p["delay"]), 0.0, p["volume"])
    if family == "constant":
        return np.clip(p["rate"] * t, 0.0, p["volume"])
    first = np.clip(t / p["width"], 0.0, 1.0)
    second = np.clip((t - p["width"] - p["gap"]) / p["width"], 0.0, 1.0)
    return p["volume"] * (first + second)


def family_end_mm(family: str, p: dict[str, float]) -> float:
    """When the analytic family's release ends, mm."""
    if family == "delay-zero":
        return p["delay"] + p["volume"] / p["rate"]
    if family == "constant":
        return p["volume"] / p["rate"]
    return 2.0 * p["width"] + p["gap"]


def family_target(spec: str, total_time_mm: float, samples: int) -> Target:
    """The analytic two-material target on the design's tau grid up to ``total_time_mm``."""
    family, p = parse_two_material(spec)
    end = family_end_mm(family, p)
    if end > total_time_mm:
        raise DesignError(f"target {spec!r} releases until tau = {end:.4g} mm, past the domain's horizon T = "
                          f"{total_time_mm:.4g} mm; enlarge the domain (--domain-mm) to at least {2.0 * end:.4g} mm")
    grid = tau_grid(total_time_mm, samples)
    return Target(grid, family_curve(family, p, grid), f"two-material:{spec}")


@dataclass(frozen=True)
class Phases:
    """What a target asks of the composite, read from its curve.

    Attributes
    ----------
    delay_mm : float
        tau at which the release first exceeds `PHASE_LEVEL` of its final value.
    end_mm : float
        When the release ends.
    pauses : tuple of (float, float)
        (start, end) of the pauses between the release's start and end: no more than `PAUSE_LEVEL` of the
        final release per `PAUSE_WINDOW` of the span, mm.
    releases : tuple of (float, float, float)
        (start, end, volume mm^3) of the release phases around the pauses.
    """

    delay_mm: float
    end_mm: float
    pauses: tuple[tuple[float, float], ...]
    releases: tuple[tuple[float, float, float], ...]

    @property
    def longest_pause_mm(self) -> float:
        return max((b - a for a, b in self.pauses), default=0.0)


def target_phases(target: Target) -> Phases:
    """The delay, the pauses and the release phases of a target curve (`Phases`)."""
    tau, c = target.tau_mm, target.released_mm3
    final = target.final_mm3
    delay = float(tau[np.argmax(c > PHASE_LEVEL * final)])
    end = curve_end_mm(tau, c)
    dtau = float(tau[1] - tau[0])
    window = max(1, int(round(PAUSE_WINDOW * (end - delay) / dtau)))
    idx = np.flatnonzero((tau >= delay) & (tau <= end))
    rise = np.interp(tau[idx] + window * dtau, tau, c) - c[idx]
    flat = rise < PAUSE_LEVEL * final
    pauses = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flat.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):
        start, stop = float(tau[idx[a]]), float(tau[idx[b - 1]] + window * dtau)
        if stop - start > window * dtau and start > delay and stop < end:
            pauses.append((start, stop))
    delay = delay if delay > window * dtau else 0.0      # a release that starts within the window starts at once
    bounds = [delay] + [x for p in pauses for x in p] + [end]
    releases = tuple((a, b, float(np.interp(b, tau, c) - np.interp(a, tau, c))) for a, b in zip(bounds[::2], bounds[1::2]))
    return Phases(delay, end, tuple(pauses), releases)


def barrier_needs(phases: Phases, barrier_speed: float) -> list[str]:
    """What the target needs of the barrier, in words (the feasibility report)."""
    s = barrier_speed
    needs = []
    if phases.delay_mm > 0:
        needs.append(f"a delay of {phases.delay_mm:.4g} mm: barrier at least {phases.delay_mm * s:.4g} mm thick "
                     "(delay x s) between the outside and all of the drug")
    for a, b in phases.pauses:
        needs.append(f"a pause from {a:.4g} to {b:.4g} mm: a barrier layer at least {(b - a) * s:.4g} mm thick "
                     "(pause x s) between the drug of the two pulses")
    needs.append(f"barrier at least {MIN_BARRIER_MM:g} mm thick wherever it is printed (two print lines)")
    return needs


def check_two_material_target(target: Target, barrier_speed: float, domain_mm: float, *, dx_mm: float,
                              drug_fill: float = 0.5) -> Phases:
    """Refuse a target that the barrier and the domain cannot give, before any work; return its phases.

    Parameters
    ----------
    target : Target
    barrier_speed : float
        s >= 0.
    domain_mm : float
        The smallest edge of the design domain, mm.
    dx_mm : float
        Voxel edge, mm: delays and pauses shorter than a voxel's crossing are release-start error, not asked.
    drug_fill : float
        Largest share of the domain the drug may fill.

    Raises
    ------
    DesignError
        Naming the target's field (delay, gap/pause, volume) and what it would need.
    """
    phases = target_phases(target)
    s = barrier_speed
    src = target.source
    if not target.final_mm3 > 0:
        raise DesignError(f"target {src}: it releases nothing (final release {target.final_mm3:g} mm^3)")
    if s == 0.0 and phases.delay_mm > dx_mm:
        raise DesignError(f"target {src}: delay {phases.delay_mm:.4g} mm with an insoluble barrier (--barrier-speed 0): "
                          "water reaches the drug through the barrier's openings at once (void dissolves at once), so "
                          "the release starts at tau = 0; a delay D needs a soluble barrier (s > 0) at least D x s thick")
    if s == 0.0 and phases.longest_pause_mm > dx_mm:
        raise DesignError(f"target {src}: pause (gap) of {phases.longest_pause_mm:.4g} mm with an insoluble barrier "
                          "(--barrier-speed 0): nothing but a soluble barrier takes time to cross without releasing "
                          "drug; a pause G needs a barrier layer G x s thick (s > 0)")
    cover = max(phases.delay_mm * s, MIN_BARRIER_MM if phases.delay_mm > dx_mm else 0.0)
    layers = sum((b - a) * s for a, b in phases.pauses)
    core = (target.final_mm3 / drug_fill) ** (1.0 / 3.0) if drug_fill > 0 else np.inf
    need = 2.0 * (cover + layers) + core
    if need > domain_mm:
        raise DesignError(f"target {src}: a delay of {phases.delay_mm:.4g} mm and pauses of {layers / s if s else 0:.4g} mm "
                          f"at barrier speed {s:g} need {cover:.4g} mm of barrier cover and {layers:.4g} mm of barrier "
                          f"layers on each side of {target.final_mm3:.4g} mm^3 of drug: about {need:.4g} mm across, more "
                          f"than the domain's {domain_mm:.4g} mm; enlarge the domain (--domain-mm) or lower the delay")
    return phases
