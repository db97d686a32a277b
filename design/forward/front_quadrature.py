"""Release of a closed body wetted at a different time at each point of its surface: the two-material reference's
quadrature.

The body's surface is wetted at w(p) (0 where it faces the bath, later where a barrier covers it; linear over each
triangle of a subdivided copy of the surface, :class:`design.forward.linear_sources.LinearSources`), and the front
reaches a point x of the body at T(x) = min_p (w(p) + |x - p|) (exact minima over the triangles' hierarchy). As in
the one-material quadrature (:mod:`design.forward.quadrature`), each cell of a cubic lattice of spacing h spreads its
solid volume over an interval of arrival times around T at its centre, with unit slope per h^2 of cross-section:

* a cell inside the body by more than h/2: [T - h/2, T + h/2];
* a cell cut by the surface (|f| < h/2, f its signed distance), solid thickness L = f + h/2, w the arrival time
  at its closest point of the surface: where that point's front arrives first (T = w + |f|), [max(w + f - h/2, w),
  w + f + h/2], the one-material cut cell started at the wall's own wetting time; where a front from elsewhere
  arrives first (a covered face reached from the body's inside, or a front tilted along the face), an interval of
  length L centred on T at the solid part's centre, T + (h - L)/2 (grad T . n), n the outward normal;
* a cell whose gradient of T turns by more than `RIDGE_ANGLE_DEG` against a face neighbour (two fronts meet, or
  the medial axis) is split into `SPLIT`^3 sub-cells treated the same way (without the shift); one inside the body
  where a front from the opposite side meets the first (a plate's mid-plane) is two ramps ending where they meet.

T is evaluated exactly at every point used (the global minimum over all faces, so a front from a distant open face
is never missed), so the curve is second order in h where T is smooth, like the one-material one.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from design.forward.distance import Surface
from design.forward.linear_sources import LinearSources
from design.forward.quadrature import BAND, BLOCK, OPPOSITE_COS, SPLIT, Lattice, Ramps, ridge_cells, solid_blocks
from design.threads import thread_count

FIRST_SLACK = 1e-9
"""A cell's closest face's front arrives first when T >= w + |f| (1 - `FIRST_TILT`) - this x h (round-off)."""
FIRST_TILT = 0.02
"""A front tilted against the face by its wetting time's slope g arrives at w + |f| sqrt(1 - g^2): up to g = 0.2 it
is the face's own front, and the cell's solid part starts at the face's time."""


def _front_direction(points: np.ndarray, foot: np.ndarray, f: np.ndarray, n_in: np.ndarray) -> np.ndarray:
    """Unit grad T at each point: from its minimiser p* on the surface towards the point (outside the body, where only
    a cut cell's solid part arrives, its continuation: towards p*); the inward normal at p* itself."""
    d = (points - foot) * np.where(f < 0.0, -1.0, 1.0)[:, None]
    norm = np.linalg.norm(d, axis=1)
    return np.where(norm[:, None] > 0.0, d / np.where(norm > 0.0, norm, 1.0)[:, None], n_in)


def _cut_ramps(f, T, w, g, n_in, h, shift):
    """(start, end) of cells (or sub-cells) of spacing h at signed distance f, arrival T (exact, at the centre) and
    closest-face wetting time w. Where that face's front is the first (T = w + |f|), the cell's solid part arrives
    from that face: T is taken as w + f, also for a centre outside. Otherwise grad T ``g`` and the inward normal
    ``n_in`` shift the interval to the solid part's centre when ``shift``."""
    first = T >= w + np.abs(f) * (1.0 - FIRST_TILT) - FIRST_SLACK * h
    T = np.where(first, w + f, T)
    inside = f >= 0.5 * h
    solid = np.clip(f + 0.5 * h, 0.0, h)
    start = np.where(inside, T - 0.5 * h, np.maximum(T - 0.5 * h, w))
    end = T + 0.5 * h
    other = ~inside & ~first
    if other.any():
        centre = T[other] - (0.5 * (h - solid[other]) * np.einsum("ij,ij->i", g[other], n_in[other]) if shift else 0.0)
        start[other] = centre - 0.5 * solid[other]
        end[other] = centre + 0.5 * solid[other]
    return start, end


def _wall_time(source: LinearSources, points: np.ndarray, f: np.ndarray, n_in: np.ndarray) -> np.ndarray:
    """The arrival time at each point's closest point of the surface (the point moved by f along the outward
    normal)."""
    return source.arrival(points - f[:, None] * n_in)[0]


def _block_ramps(surface: Surface, source: LinearSources, lattice: Lattice, block: np.ndarray, ramps: Ramps) -> None:
    """Add one block's cells' ramps (the block with a halo of one cell, for the ridge test)."""
    h = lattice.h
    lo = np.maximum(block - 1, 0)
    hi = np.minimum(block + BLOCK + 1, lattice.n)
    shape = tuple(int(v) for v in hi - lo)
    centres = lattice.centres(lo, hi)
    f, n_in, _ = surface.lattice_distance(centres, shape, BAND * h)
    near = f > -h
    T = np.full(f.shape, np.inf)
    g = np.zeros((f.size, 3))
    if near.any():
        T[near], _, foot = source.arrival(centres[near])
        g[near] = _front_direction(centres[near], foot, f[near], n_in[near])
    ridge = ridge_cells(g.reshape(shape + (3,)), near.reshape(shape))
    own = np.zeros(shape, dtype=bool)
    own[tuple(slice(int(block[a] - lo[a]), int(min(block[a] + BLOCK, lattice.n[a]) - lo[a])) for a in range(3))] = True
    own = own.ravel() & near
    ridge = own & ridge.ravel()
    plain = own & ~ridge & (f > -0.5 * h)
    if plain.any():
        w = _wall_time(source, centres[plain], f[plain], n_in[plain])
        start, end = _cut_ramps(f[plain], T[plain], w, g[plain], n_in[plain], h, True)
        ramps.add(start, end, h * h)
    if ridge.any():
        _split_ramps(surface, source, centres[ridge], h, ramps)


def _split_ramps(surface: Surface, source: LinearSources, centres: np.ndarray, h: float, ramps: Ramps) -> None:
    """Ramps of the `SPLIT`^3 sub-cells of each cell centred at ``centres``."""
    hs = h / SPLIT
    axis = (np.arange(SPLIT) + 0.5) * hs - 0.5 * h
    sub = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    points = np.ascontiguousarray((centres[:, None, :] + sub[None, :, :]).reshape(-1, 3))
    f, n_in, _ = surface.signed_distance(points)
    keep = f > -0.5 * hs
    points, f, n_in = points[keep], f[keep], n_in[keep]
    if not len(points):
        return
    T, _, foot = source.arrival(points)
    zero = np.zeros((len(points), 3))
    start, end = _cut_ramps(f, T, _wall_time(source, points, f, n_in), zero, zero, hs, False)
    inside = np.flatnonzero(f >= 0.5 * hs)
    other = _opposite_arrival(source, points[inside], T[inside], foot[inside], hs)
    fold = np.isfinite(other)
    if fold.any():
        first, second, inside = T[inside][fold], other[fold], inside[fold]
        meet = np.minimum(0.5 * (second - first), 0.5 * hs)
        start[inside], end[inside] = first - 0.5 * hs, first + meet
        ramps.add(second - 0.5 * hs, second - meet, hs * hs)
    ramps.add(start, end, hs * hs)


def _opposite_arrival(source: LinearSources, points: np.ndarray, T: np.ndarray, foot: np.ndarray, hs: float
                      ) -> np.ndarray:
    """Per sub-cell of side hs inside the body (centre ``points``, arrival ``T`` from ``foot``): the arrival time at
    its centre of a front from the opposite side (within `RIDGE_ANGLE_DEG`) that meets the first inside it, as at a
    plate's mid-plane, else inf. Probed one side's length along the first front's direction: there the other front
    is first if they meet before, and its time is carried back to the centre along its own direction. Such a
    sub-cell is two ramps ending where the fronts meet (`design.forward.quadrature.folded_ramps`)."""
    ahead = points - foot
    ahead /= np.maximum(np.linalg.norm(ahead, axis=1), 1e-300)[:, None]
    probe = points + hs * ahead
    T_probe, _, foot_probe = source.arrival(probe)
    back = probe - foot_probe
    back /= np.maximum(np.linalg.norm(back, axis=1), 1e-300)[:, None]
    facing = np.einsum("ij,ij->i", ahead, back)
    second = T_probe - hs * facing
    return np.where((facing < -OPPOSITE_COS) & (second < T + hs), second, np.inf)


def front_curve(surface: Surface, source: LinearSources, bounds: np.ndarray, h: float, tau: np.ndarray, *,
                workers: int | None = None) -> tuple[np.ndarray, float, float]:
    """Quadrature on a lattice of spacing h: (unnormalised curve at tau, its volume, the largest arrival).

    ``surface`` is the body (its signed distances); ``source`` the same surface subdivided with its wetting times:
    T(x) = min_p (w(p) + |x - p|). Only the blocks that meet the body are evaluated, ``workers`` threads at a
    time; their ramps are summed in block order (deterministic).
    """
    lattice = Lattice.over(bounds, h)
    blocks = solid_blocks(surface, lattice)
    tau = np.asarray(tau, dtype=np.float64)

    def one(block: np.ndarray) -> Ramps:
        ramps = Ramps.empty(tau)
        _block_ramps(surface, source, lattice, block, ramps)
        return ramps

    total = Ramps.empty(tau)
    workers = workers or min(len(blocks), thread_count()) or 1
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for ramps in (pool.map(one, blocks) if workers > 1 else map(one, blocks)):
            total.merge(ramps)
    return total.curve(), total.volume, total.end
