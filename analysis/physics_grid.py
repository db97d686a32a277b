"""Print physics: parameters of the forward model itself (design.forward: anisotropy, surface offset, swelling)
that the calibration fits with its scales, their search grids, and the grid search over them.

The analysis never simulates: the caller gives ``shapes_at(values)``, the calibration shapes simulated with
those parameter values (the job caches them per mesh and values); the fit is :mod:`analysis.physics_fit`.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

PHYSICS_PARAMETERS = ("anisotropy", "offset_mm", "swelling_mm")
"""Print physics the calibration can fit: z / in-plane erosion rate, printed surface outside the mesh's (mm), the
width below which channels are shut by the swollen material until their walls dissolve (mm)."""
PHYSICS_IDENTITY = {"anisotropy": 1.0, "offset_mm": 0.0, "swelling_mm": 0.0}
"""Values that switch each effect off (the paper's isotropic model of the mesh as designed)."""
PHYSICS_GRIDS = {"anisotropy": tuple(float(x) for x in np.exp(np.linspace(math.log(0.5), math.log(2.0), 13))),
                 "offset_mm": tuple(float(x) for x in np.round(np.linspace(-0.2, 0.3, 11), 6)),
                 "swelling_mm": tuple(float(x) for x in np.round(np.linspace(0.0, 1.2, 13), 6))}
"""Search grid of each parameter (anisotropy log-spaced by a factor 1.12, offset in 0.05 mm steps, swelling width
in 0.1 mm steps from none to 1.2 mm); the minimum is refined by a parabola through the best grid point and its
neighbours (the swelling width changes the release in voxel steps, so its loss is often flat over several grid
points: the middle of that flat minimum is taken, `_flat_run`)."""
LAG = "wetting_lag_s"
"""The wetting lag (``SimCal.lag_s``, s) as a fitted parameter: not a parameter of the forward model (nothing is
simulated again for it) but of its clock, fitted with the time scale inside every loss evaluation
(:func:`analysis.simcal_fit._fit_time`), searched on `analysis.simcal_fit.LAG_BOUNDS_S`."""
FIT_PARAMETERS = PHYSICS_PARAMETERS + (LAG,)
"""Every parameter ``--physics`` can fit: the forward model's print physics and the wetting lag."""
FIT_IDENTITY = {**PHYSICS_IDENTITY, LAG: 0.0}
"""Values that switch each fitted effect off."""
_SIMULATED_SETS = {"none": (), "anisotropy": ("anisotropy",), "offset": ("offset_mm",), "swelling": ("swelling_mm",),
                   "anisotropy+offset": ("anisotropy", "offset_mm"), "anisotropy+swelling": ("anisotropy", "swelling_mm"),
                   "offset+swelling": ("offset_mm", "swelling_mm"), "anisotropy+offset+swelling": PHYSICS_PARAMETERS}
PHYSICS_SETS = {**{k: v for k, v in _SIMULATED_SETS.items() if k != "anisotropy+offset+swelling"},
                **{("lag" if k == "none" else f"{k}+lag"): v + (LAG,) for k, v in _SIMULATED_SETS.items()
                   if k != "anisotropy+offset+swelling"},
                "anisotropy+offset+swelling": PHYSICS_PARAMETERS, "all": FIT_PARAMETERS}
"""The parameter sets ``auto`` fits (every subset of `FIT_PARAMETERS`); a named ``--physics`` fits its own set and
``none``. ``all`` fits every parameter, the wetting lag included."""
PHYSICS_CHOICES = tuple(PHYSICS_SETS) + ("auto",)
"""``--physics`` values: a set of `PHYSICS_SETS` to fit; ``auto`` fits every subset and keeps the one leave-one-out
prefers."""
DEFAULT_PHYSICS = "auto"
"""What a calibration fits by default: the print physics leave-one-out shows earn their place (``none``, the
isotropic model of the mesh as designed, when none does)."""
_PHYSICS_ROUNDS = 2
_LOO_WINDOW = 3


def grid_coord(name: str, x: float) -> float:
    """The coordinate a parameter is searched in: log for anisotropy, the value itself for the others."""
    return math.log(x) if name == "anisotropy" else x


def _from_coord(name: str, c: float) -> float:
    return math.exp(c) if name == "anisotropy" else c


def _flat_run(losses: Sequence[float], i: int) -> tuple[int, int]:
    """The grid points either side of i whose loss equals the minimum (the same simulations: a voxel-step
    parameter such as the swelling width changes nothing between them)."""
    tol = 1e-12 * max(abs(losses[i]), 1e-300)
    a = b = i
    while a > 0 and abs(losses[a - 1] - losses[i]) <= tol:
        a -= 1
    while b < len(losses) - 1 and abs(losses[b + 1] - losses[i]) <= tol:
        b += 1
    return a, b


def _refine(name: str, grid: Sequence[float], i: int, losses: Sequence[float]) -> float:
    """Vertex of the parabola through grid point i and its neighbours (in log for anisotropy), kept between them;
    the middle of a flat minimum (`_flat_run`) when several grid points share it."""
    a, b = _flat_run(losses, i)
    if b > a:
        return float(_from_coord(name, 0.5 * (grid_coord(name, grid[a]) + grid_coord(name, grid[b]))))
    if i == 0 or i == len(grid) - 1:
        return float(grid[i])
    c = [grid_coord(name, grid[j]) for j in (i - 1, i, i + 1)]
    f = [losses[j] for j in (i - 1, i, i + 1)]
    den = (c[0] - c[1]) * (c[0] - c[2]) * (c[1] - c[2])
    a = (c[2] * (f[1] - f[0]) + c[1] * (f[0] - f[2]) + c[0] * (f[2] - f[1])) / den
    b = (c[2] ** 2 * (f[0] - f[1]) + c[1] ** 2 * (f[2] - f[0]) + c[0] ** 2 * (f[1] - f[2])) / den
    if not a > 0:
        return float(grid[i])
    return float(_from_coord(name, min(max(-b / (2 * a), c[0]), c[2])))


def _nearest(p: str, value: float) -> int:
    return int(np.argmin([abs(grid_coord(p, g) - grid_coord(p, value)) for g in PHYSICS_GRIDS[p]]))


def _descend(loss_of: Callable[[int], float], start: int, lo: int, hi: int) -> tuple[int, int, int]:
    """Walk from grid index ``start`` to a local minimum of ``loss_of`` within ``lo..hi - 1`` (one step at a time
    to the lower neighbour), then across the flat run of equal losses there. Returns ``(best, a, b)``: the minimum
    and the first and last index of the evaluated stretch around it (the minimum's neighbours included)."""
    i = start
    while True:
        here = loss_of(i)
        left = loss_of(i - 1) if i > lo else math.inf
        right = loss_of(i + 1) if i < hi - 1 else math.inf
        if min(left, right) >= here:
            break
        i = i - 1 if left < right else i + 1
    tol = 1e-12 * max(abs(here), 1e-300)
    a = b = i
    while a > lo and abs(loss_of(a - 1) - here) <= tol:
        a -= 1
    while b < hi - 1 and abs(loss_of(b + 1) - here) <= tol:
        b += 1
    return i, max(a - 1, lo), min(b + 1, hi - 1)


def physics_search(loss_at: Callable[[dict], float], fitted: Sequence[str], near: dict | None = None,
                   flat: dict | None = None) -> dict:
    """Coordinate search over the grids of the ``fitted`` parameters (values on grid points), then a parabola
    refinement of each from its grid neighbours. Returns every parameter's value.

    Coarse to fine: without ``near`` each parameter's grid is scanned at every other point (both ends included)
    and the search walks from the best of those to a neighbouring grid minimum (`_descend`); with ``near``
    (values: leave-one-out refits) it walks from there, within `_LOO_WINDOW` grid points either side. Losses are
    asked once per point. ``flat``, when given, receives per parameter the half-width of its flat minimum
    (`_flat_run`, in its grid coordinate; 0 for a single best point)."""
    start = near or PHYSICS_IDENTITY
    index = {p: _nearest(p, start[p]) for p in fitted}
    span = {p: (0, len(PHYSICS_GRIDS[p])) if near is None else
            (max(index[p] - _LOO_WINDOW, 0), min(index[p] + _LOO_WINDOW + 1, len(PHYSICS_GRIDS[p]))) for p in fitted}
    seen: dict[tuple, float] = {}

    def point(overrides: dict) -> dict:
        values = dict(PHYSICS_IDENTITY)
        values.update({p: PHYSICS_GRIDS[p][k] for p, k in index.items()})
        values.update(overrides)
        return values

    def loss_of(p: str) -> Callable[[int], float]:
        def at(k: int) -> float:
            key = tuple(sorted({**index, p: k}.items()))
            if key not in seen:
                seen[key] = loss_at(point({p: PHYSICS_GRIDS[p][k]}))
            return seen[key]
        return at

    stretch: dict[str, tuple[int, int]] = {}
    for round_ in range(_PHYSICS_ROUNDS if len(fitted) > 1 else 1):
        for p in fitted:
            lo, hi = span[p]
            at = loss_of(p)
            begin = index[p]
            if near is None and round_ == 0:     # coarse: every other grid point, then walk from the best
                coarse = sorted(set(range(lo, hi, 2)) | {hi - 1})
                begin = min(coarse, key=at)
            best, a, b = _descend(at, begin, lo, hi)
            index[p], stretch[p] = best, (a, b)
    values = point({})
    for p in fitted:
        a, b = stretch[p]
        at = loss_of(p)
        profile = [at(k) for k in range(a, b + 1)]
        grid = PHYSICS_GRIDS[p][a:b + 1]
        values[p] = _refine(p, grid, index[p] - a, profile)
        if flat is not None:
            f0, f1 = _flat_run(profile, index[p] - a)
            flat[p] = 0.5 * abs(grid_coord(p, grid[f1]) - grid_coord(p, grid[f0]))
    return values
