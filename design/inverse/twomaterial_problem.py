"""Setting up a two-material design: settings, the design space with its barrier caps, the target, the start.

`prepare_two` turns `TwoMaterialSettings` into a `TwoMaterialProblem`: the domain (sized from the target
unless given), the space ("nfc": free 3D, octant symmetry; "extruded": a 2D layout of both materials
extruded along z between barrier caps that hold for the whole curve, quadrant symmetry), the target on
its tau grid with its phases and barrier needs (`design.inverse.twomaterial_targets`), and the start
layout built from those phases (`start_layout`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from design.errors import DesignError
from design.inverse.spaces import BUILD_AXIS, DesignSpace, SpaceRequest, extruded_space, nfc_space
from design.inverse.targets import Target, check_feasibility, curve_end_mm, target_from_curve
from design.inverse.twomaterial_objective import design_slowness
from design.inverse.twomaterial_targets import (
    MIN_BARRIER_MM,
    Phases,
    barrier_needs,
    check_two_material_target,
    family_end_mm,
    family_target,
    is_two_material_spec,
    parse_two_material,
)

TWO_MATERIAL_SPACES = ("nfc", "extruded")
"""Design spaces of a two-material design. ICO is refused: its incremental-compliance term (section 3.6)
models one material's stiffness, and a stiffness law for a drug/barrier pair is not calibrated."""
TIME_MARGIN = 1.25
"""The horizon T is this many times the target's end."""
DOMAIN_PER_END = 2.4
"""The default cubic domain's edge per mm of the target's end (the drug dissolves from both sides)."""
HEIGHT_FRACTION = 0.5
"""The default extrusion height as a fraction of the domain's edge."""
CONSTANT_RATE_RATIO = 1.33
"""A release phase whose second-half rate is within this factor of its first-half rate starts as a column."""


@dataclass(frozen=True)
class TwoMaterialSettings:
    """Everything a two-material design depends on (``config.json`` of its run folder).

    Parameters
    ----------
    target : str
        A two-material family spec (`design.inverse.twomaterial_targets`) or a ``tau_mm,released_mm3`` CSV path.
    barrier_speed : float
        s >= 0, the barrier's erosion speed over the drug's (0: insoluble).
    space : str
        One of `TWO_MATERIAL_SPACES`.
    resolution : int
        Voxels along the domain's edge (even, >= 16).
    domain_mm : float or None
        Edge of the square (nfc: cubic) domain, mm; None = `DOMAIN_PER_END` x the target's end.
    height_mm : float or None
        Extrusion height (extruded), mm, caps included; None = the caps and `_inner_height` between them.
    radius_mm : float
        Smoothing radius of both fields, mm: the minimum feature (default the thinnest barrier, two print lines).
    max_iter : int
        Objective evaluations.
    beta, beta_final : float
        Projection steepness at the first and last of `stages` stages.
    w_binary : float
        Weight of J_binary (`design.inverse.twomaterial_objective`).
    stages : int
        Stages of the beta continuation.
    samples : int
        Points of the tau grid.
    """

    target: str
    barrier_speed: float
    space: str = "nfc"
    resolution: int = 48
    domain_mm: float | None = None
    height_mm: float | None = None
    radius_mm: float = MIN_BARRIER_MM
    max_iter: int = 150
    beta: float = 4.0
    beta_final: float = 32.0
    w_binary: float = 0.5
    stages: int = 4
    samples: int = 501

    def __post_init__(self) -> None:
        checks = [("space", self.space in TWO_MATERIAL_SPACES,
                   f"one of {', '.join(TWO_MATERIAL_SPACES)} (ico: its stiffness model is one material's)"),
                  ("barrier_speed", math.isfinite(self.barrier_speed) and self.barrier_speed >= 0, "a number >= 0"),
                  ("resolution", self.resolution >= 16 and self.resolution % 2 == 0, "an even number >= 16"),
                  ("domain_mm", self.domain_mm is None or self.domain_mm > 0, "> 0 mm"),
                  ("height_mm", self.height_mm is None or self.height_mm > 0, "> 0 mm"),
                  ("radius_mm", self.radius_mm > 0, "> 0 mm"),
                  ("max_iter", self.max_iter >= 1, ">= 1"),
                  ("beta", 0 < self.beta <= self.beta_final <= 64, "0 < beta <= beta_final <= 64"),
                  ("w_binary", self.w_binary >= 0, ">= 0"), ("stages", self.stages >= 1, ">= 1"),
                  ("samples", self.samples >= 11, ">= 11")]
        for name, ok, expected in checks:
            if not ok:
                raise DesignError(f"two-material design: {name} = {getattr(self, name)!r}; expected {expected}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> TwoMaterialSettings:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise DesignError(f"unknown two-material design settings {unknown}")
        return cls(**values)


@dataclass(frozen=True)
class TwoMaterialSpace:
    """A design space (`design.inverse.spaces.DesignSpace`) whose extruded fields lie between barrier caps.

    ``cap_vox`` layers at the bottom and top of an extruded grid hold barrier wherever there is material
    (the drug share is 0 there); 0 for nfc.
    """

    base: DesignSpace
    cap_vox: int = 0

    @property
    def name(self) -> str:
        return self.base.name

    @property
    def var_shape(self) -> tuple[int, ...]:
        return self.base.var_shape

    @property
    def var_mirror(self) -> tuple[bool, ...]:
        return self.base.var_mirror

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        return self.base.grid_shape

    @property
    def mirror(self) -> tuple[bool, bool, bool]:
        return self.base.mirror

    @property
    def dx_mm(self) -> float:
        return self.base.dx_mm

    def to_grid(self, v: np.ndarray) -> np.ndarray:
        return self.base.to_grid(v)

    def to_grid_adjoint(self, g: np.ndarray) -> np.ndarray:
        return self.base.to_grid_adjoint(g)

    def drug_share(self, f_var: np.ndarray) -> np.ndarray:
        """The drug share on the simulation grid: the variables' extruded, 0 in the caps."""
        f = self.base.to_grid(f_var)
        if self.cap_vox:
            f = f.copy()
            f[..., :self.cap_vox] = 0.0
            f[..., -self.cap_vox:] = 0.0
        return f

    def drug_share_adjoint(self, g: np.ndarray) -> np.ndarray:
        """Adjoint of `drug_share`."""
        if self.cap_vox:
            g = g.copy()
            g[..., :self.cap_vox] = 0.0
            g[..., -self.cap_vox:] = 0.0
        return self.base.to_grid_adjoint(g)

    def unfold(self, grid: np.ndarray) -> np.ndarray:
        return self.base.unfold(grid)


@dataclass(frozen=True)
class TwoMaterialProblem:
    """A prepared two-material design problem.

    Attributes
    ----------
    settings : TwoMaterialSettings
    space : TwoMaterialSpace
    target : Target
    phases : Phases
    needs : tuple of str
        What the target needs of the barrier, in words.
    one_material : tuple of str
        Why a single material cannot release the target (the one-material feasibility check), empty if it can.
    slowness : float
        k_d, the barrier slowness the optimiser sees.
    radius_vox : float
    origin_mm : (3,) ndarray
        Corner of the full grid, mm (x, y centred on 0, z from 0).
    domain_mm : float
    """

    settings: TwoMaterialSettings
    space: TwoMaterialSpace
    target: Target
    phases: Phases
    needs: tuple[str, ...]
    one_material: tuple[str, ...]
    slowness: float
    radius_vox: float
    origin_mm: np.ndarray
    domain_mm: float


def _target_end(settings: TwoMaterialSettings, curve: tuple[np.ndarray, np.ndarray] | None) -> float:
    if is_two_material_spec(settings.target):
        return family_end_mm(*parse_two_material(settings.target))
    if curve is None:
        raise DesignError(f"target {settings.target!r} is neither a two-material family (delay-zero:, pulses:, "
                          "constant:) nor a tau_mm,released_mm3 CSV")
    return curve_end_mm(*curve)


def prepare_two(settings: TwoMaterialSettings, curve: tuple[np.ndarray, np.ndarray] | None = None) -> TwoMaterialProblem:
    """Build the domain, the space, the target and its phases; refuse a target the barrier cannot give.

    Parameters
    ----------
    settings : TwoMaterialSettings
    curve : (tau_mm, released_mm3), optional
        The columns of a CSV target.

    Raises
    ------
    DesignError
        For a target the domain or the barrier cannot give (`check_two_material_target`), or a space
        too small for its caps.
    """
    end = _target_end(settings, curve)
    t_total = TIME_MARGIN * end
    edge = settings.domain_mm or DOMAIN_PER_END * end
    dx = edge / settings.resolution
    full = [settings.resolution] * 3
    s = settings.barrier_speed
    target = (family_target(settings.target, t_total, settings.samples) if is_two_material_spec(settings.target)
              else target_from_curve(*curve, t_total, settings.samples, source=settings.target))
    phases = check_two_material_target(target, s, edge, dx_mm=dx)
    cap_vox = 0
    if settings.space == "extruded":
        cap_vox = max(1, math.ceil(max(MIN_BARRIER_MM, s * t_total) / dx - 1e-9))
        height = settings.height_mm or 2 * cap_vox * dx + _inner_height(phases, edge)
        full[BUILD_AXIS] = max(2 * cap_vox + 2, int(round(height / dx)))
        base = extruded_space(SpaceRequest(tuple(full), dx, full[BUILD_AXIS]))
    else:
        base = nfc_space(SpaceRequest(tuple(full), dx))
    space = TwoMaterialSpace(base, cap_vox)
    volume = float(np.prod(full)) * dx ** 3
    one = check_feasibility(target, volume, dx_mm=dx, domain_area_mm2=2 * (3 * edge * edge)).problems
    origin = np.array([-0.5 * full[0] * dx, -0.5 * full[1] * dx, 0.0])
    radius = max(1.0, settings.radius_mm / dx)
    return TwoMaterialProblem(settings, space, target, phases, tuple(barrier_needs(phases, s)), tuple(one),
                              design_slowness(s, t_total), radius, origin, edge)


def _inner_height(phases: Phases, edge_mm: float) -> float:
    """The default extrusion height between the caps, mm: a drug strip of the fastest phase's rate R, open at both
    ends, is then as wide as it is high (R = 2 ends x width x height), at most `HEIGHT_FRACTION` of the edge."""
    rate = max(v / (b - a) for a, b, v in phases.releases)
    return min(HEIGHT_FRACTION * edge_mm, math.sqrt(rate / 2.0))


def _centres(space: TwoMaterialSpace) -> list[np.ndarray]:
    """Centred coordinates of the simulation grid's voxel centres, mm, broadcastable: mirrored axes from their
    plane, the others from the middle."""
    dx = space.dx_mm
    out = []
    for ax, (n, m) in enumerate(zip(space.grid_shape, space.mirror)):
        c = (np.arange(n) + 0.5) * dx - (0.0 if m else 0.5 * n * dx)
        shape = [1, 1, 1]
        shape[ax] = n
        out.append(np.abs(c).reshape(shape))
    return out


def _phase_rates(target: Target, phases: Phases) -> list[float] | None:
    """The rate of each release phase, mm^3/mm, if every phase releases at a near-constant rate, else None."""
    rates = []
    for a, b, volume in phases.releases:
        at = np.interp([a, 0.5 * (a + b), b], target.tau_mm, target.released_mm3)
        first, second = at[1] - at[0], at[2] - at[1]
        if not (first > 0 and 1.0 / CONSTANT_RATE_RATIO <= second / first <= CONSTANT_RATE_RATIO):
            return None
        rates.append(volume / (b - a))
    return rates


def start_layout(problem: TwoMaterialProblem) -> np.ndarray:
    """Start variables (phi_hat, f_hat) built from the target's phases.

    When every release phase has a near-constant rate the start is a drug column open at both ends (zero
    order: the two end faces recede at unit speed), built from the middle out: the last phase's drug, a
    barrier plug (pause x s), the previous phase's drug, ..., and a barrier cap (delay x s); each drug
    segment is as long as its phase lasts and as wide as its rate asks, and the column's walls hold for the
    whole curve. Otherwise the start is nested layers from the outside in: barrier cover (delay x s), the
    first phase's drug, a barrier layer (pause x s), the next phase's drug (nfc: balls; extruded: cylinders
    between the caps). Drug 1, barrier 0 and void 0.5 in f_hat; material 1, void 0 in phi_hat.
    """
    space, phases, target = problem.space, problem.phases, problem.target
    s, dx = problem.settings.barrier_speed, space.dx_mm
    x, y, z = _centres(space)
    extruded = space.name == "extruded"
    h_in = (space.grid_shape[2] - 2 * space.cap_vox) * dx
    cover = max(phases.delay_mm * s, MIN_BARRIER_MM) if phases.delay_mm > dx else 0.0
    rates = _phase_rates(target, phases)
    drug = np.zeros(space.grid_shape, bool)
    pos = 0.0
    if rates is not None:
        along, across = (x + 0 * z, y + 0 * z) if extruded else (z + 0 * x, np.maximum(x, y))
        widest = 0.0
        for i, ((a, b, _), rate) in enumerate(zip(reversed(phases.releases), reversed(rates))):
            half = rate / (4.0 * h_in) if extruded else 0.5 * math.sqrt(rate / 2.0)
            widest = max(widest, half)
            drug |= (along >= pos) & (along <= pos + b - a) & (across <= half)
            pos += (b - a) + _barrier_after(phases, i, s, cover)
        material = (along <= pos) & (across <= widest + max(MIN_BARRIER_MM, 1.2 * s * phases.end_mm, 2 * dx))
    else:
        r_field = np.sqrt(x * x + y * y) + 0 * z if extruded else np.sqrt(x * x + y * y + z * z)
        for i, (_, _, volume) in enumerate(reversed(phases.releases)):
            r_out = (math.sqrt(pos * pos + volume / (math.pi * h_in)) if extruded
                     else (pos ** 3 + 3.0 * volume / (4.0 * math.pi)) ** (1.0 / 3.0))
            drug |= (r_field >= pos) & (r_field <= r_out)
            pos = r_out + _barrier_after(phases, i, s, cover)
        material = drug | (r_field <= pos)
    phi = np.broadcast_to(material, space.grid_shape).astype(float)
    f = np.where(drug, 1.0, np.where(phi > 0, 0.0, 0.5))
    if extruded:
        mid = space.grid_shape[2] // 2
        phi, f = phi[..., mid], f[..., mid]
    return np.stack([phi, f])


def _barrier_after(phases: Phases, i: int, s: float, cover: float) -> float:
    """Barrier outside the i-th phase from the last: the plug of the pause before it, or the cover, mm."""
    k = len(phases.pauses) - 1 - i
    if k >= 0:
        a, b = phases.pauses[k]
        return max(MIN_BARRIER_MM, (b - a) * s)
    return cover
