"""From a two-material design's densities to a printable drug/barrier pair of voxel solids.

`printable_pair` cuts both fields (material where phi reaches its mass-preserving level, drug where the drug
share f reaches the level that keeps the drug's mass), drops floating specks and fills enclosed voids with
barrier (they trap air), thickens every barrier wall in front of covered drug to at least
``min_barrier_mm`` (two print lines), then reports the pieces of each material, the thinnest such wall
and the barrier thinner than the minimum anywhere.

Covered drug is drug behind barrier on every path from the bath (`covered_drug`); drug reached through an
opening releases from there whatever the wall beside it. `wall_thickness` is the Euclidean distance from
a voxel's centre to the nearest void voxel's centre: at a barrier voxel in front of drug, the wall's
thickness there (a wall k voxels thick measures k dx; a slanted wall its normal thickness, to within a
voxel's staircase). A covered drug voxel with a barrier neighbour thinner than the minimum sits behind a
thin wall; it becomes barrier, which thickens the wall inwards by a voxel, until none is left (each pass
adds a voxel, so ``min_barrier_mm / dx + 2`` passes suffice). Growing the wall outwards instead would close
the openings beside it. The optimiser avoids skins thinner than the minimum over drug
(`design.inverse.twomaterial_objective`'s J_skin), so this pass changes little; the release's own measure
of the barrier, the least barrier on any path from the bath to the drug, is the forward model's
`design.forward.twomaterial.barrier_cover`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from design.fabrication.extract import LEVEL_RANGE, count_pieces, mass_preserving_level
from design.forward.fmm import march
from design.forward.simulator import N_MIN

OPEN_COVER_VOXELS = 0.01
"""Drug with less barrier cover than this many voxels is reached through an opening (void costs n_min dx per voxel)."""
SPECK_FRACTION = 0.01
"""Composite pieces below this share of the largest are floating specks and are dropped."""
SPECK_VOXELS = 8
"""Pieces of one material smaller than this many voxels take the other material's place (or void)."""
_FACES = ndimage.generate_binary_structure(3, 1)


@dataclass(frozen=True)
class PrintablePair:
    """The printed drug and barrier solids and their printability facts.

    Attributes
    ----------
    drug, barrier : ndarray of bool
        The full (unfolded) solids on the design grid, disjoint.
    level : float
        The cut of phi (mass-preserving, `design.fabrication.extract.mass_preserving_level`).
    pieces : dict
        Face-connected pieces: ``print`` (both materials), ``drug``, ``barrier``.
    piece_notes : tuple of str
        Why a material is more than one piece, or a warning that the print is.
    min_barrier_mm : float or None
        The thinnest barrier wall in front of covered drug, mm (`wall_thickness`); None without covered drug.
    thickened_voxels : int
        Drug voxels made barrier to thicken walls thinner than the minimum.
    thin_barrier_mm3 : float
        Barrier thinner than the minimum anywhere (`thin_barrier`), mm^3: rims beside openings and fins.
    dropped_voxels : int
        Voxels of floating specks removed.
    """

    drug: np.ndarray
    barrier: np.ndarray
    level: float
    pieces: dict
    piece_notes: tuple[str, ...]
    min_barrier_mm: float | None
    thickened_voxels: int
    dropped_voxels: int
    thin_barrier_mm3: float


def wall_thickness(drug: np.ndarray, barrier: np.ndarray, dx_mm: float) -> np.ndarray:
    """Distance from each voxel's centre to the nearest void voxel's centre (the grid's border is void), mm:
    at a barrier voxel next to drug, the thickness of the wall in front of that drug (a wall k voxels thick: k dx)."""
    void = np.pad(~(drug | barrier), 1, constant_values=True)
    return ndimage.distance_transform_edt(~void, sampling=dx_mm)[1:-1, 1:-1, 1:-1]


def _neighbours(mask: np.ndarray) -> np.ndarray:
    return ndimage.binary_dilation(mask, _FACES) & ~mask


def covered_drug(drug: np.ndarray, barrier: np.ndarray, dx_mm: float) -> np.ndarray:
    """Drug behind barrier on every path from the bath: its barrier cover (eq. 5 on the slowness of the barrier
    alone, `design.forward.twomaterial.barrier_cover`'s field) exceeds `OPEN_COVER_VOXELS` voxels. Drug reached
    through an opening (through drug and void alone) is not covered, whatever the wall beside it."""
    n = np.where(barrier, 1.0, N_MIN)
    marching = march(n, dx_mm, (False,) * drug.ndim)
    return drug & (np.asarray(marching.interior(marching.u_pad)) > OPEN_COVER_VOXELS * dx_mm)


def thin_barrier(barrier: np.ndarray, dx_mm: float, min_mm: float) -> np.ndarray:
    """Barrier voxels in no cube of ``min_mm`` (rounded up to whole voxels) that fits in the barrier: thinner
    than a print holds (the morphological opening's removed part)."""
    k = max(1, int(math.ceil(min_mm / dx_mm - 1e-9)))
    return barrier & ~ndimage.binary_opening(barrier, np.ones((k,) * barrier.ndim, bool))


def thinnest_wall_mm(drug: np.ndarray, barrier: np.ndarray, dx_mm: float) -> float | None:
    """The thinnest barrier wall in front of covered drug, mm; None when no drug is covered."""
    covered = covered_drug(drug, barrier, dx_mm)
    front = _neighbours(covered) & barrier
    if not front.any():
        return None
    return float(wall_thickness(drug, barrier, dx_mm)[front].min())


def thicken_walls(drug: np.ndarray, barrier: np.ndarray, dx_mm: float, min_mm: float
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    """Make covered drug behind walls thinner than ``min_mm`` barrier, pass by pass (module doc); returns the new
    solids and the voxels changed."""
    drug, barrier = drug.copy(), barrier.copy()
    changed = 0
    for _ in range(int(math.ceil(min_mm / dx_mm)) + 2):
        t = wall_thickness(drug, barrier, dx_mm)
        thin = barrier & (t < min_mm - 1e-6 * dx_mm)
        behind = covered_drug(drug, barrier, dx_mm) & ndimage.binary_dilation(thin, _FACES)
        if not behind.any():
            break
        drug &= ~behind
        barrier |= behind
        changed += int(behind.sum())
    return drug, barrier, changed


def enclosed_void(drug: np.ndarray, barrier: np.ndarray) -> np.ndarray:
    """Void voxels the bath cannot reach through void (face-connected; the grid's border is bath)."""
    void = np.pad(~(drug | barrier), 1, constant_values=True)
    labels, _ = ndimage.label(void, _FACES)
    return (labels != labels[0, 0, 0])[1:-1, 1:-1, 1:-1] & ~(drug | barrier)


def _drop_specks(drug: np.ndarray, barrier: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    labels, count = ndimage.label(drug | barrier)
    if count < 2:
        return drug, barrier, 0
    sizes = ndimage.sum_labels(np.ones_like(labels), labels, np.arange(1, count + 1))
    speck = np.isin(labels, 1 + np.flatnonzero(sizes < SPECK_FRACTION * sizes.max()))
    drug, barrier = drug & ~speck, barrier & ~speck
    for mine, other in ((drug, barrier), (barrier, drug)):
        lab, k = ndimage.label(mine)
        if k > 1:
            small = np.isin(lab, 1 + np.flatnonzero(ndimage.sum_labels(mine, lab, np.arange(1, k + 1)) < SPECK_VOXELS))
            touching = small & ndimage.binary_dilation(other, _FACES, iterations=SPECK_VOXELS)
            mine &= ~small
            other |= touching
    return drug, barrier, int(speck.sum())


def _piece_notes(drug: np.ndarray, barrier: np.ndarray, pieces: dict) -> tuple[str, ...]:
    notes = []
    if pieces["print"] > 1:
        notes.append(f"the print is {pieces['print']} separate pieces (both materials together)")
    for name, mine, other in (("drug", drug, barrier), ("barrier", barrier, drug)):
        if pieces[name] > 1:
            lab, k = ndimage.label(mine)
            held = len(set(np.unique(lab[_neighbours(other) & mine])) - {0})
            notes.append(f"the {name} is {k} pieces: {held} of them bonded to the {'barrier' if name == 'drug' else 'drug'}"
                         + (" (each prints as part of the one composite)" if held == k and pieces["print"] == 1 else ""))
    return tuple(notes)


def drug_share_level(phi: np.ndarray, f: np.ndarray, material: np.ndarray) -> float:
    """The cut of the drug share that keeps the drug's mass (sum phi f) in the material, within `LEVEL_RANGE`."""
    share = f[material]
    k = int(round(float(np.sum(phi * f))))
    lo, hi = LEVEL_RANGE
    if k <= 0 or share.size == 0:
        return hi
    if k >= share.size:
        return lo
    kth, next_ = -np.partition(-share, (k - 1, k))[[k - 1, k]]
    return float(np.clip(0.5 * (kth + next_), lo, hi))


def printable_pair(phi_full: np.ndarray, f_full: np.ndarray, dx_mm: float, min_barrier_mm: float) -> PrintablePair:
    """Cut (phi at its mass-preserving level, f at `drug_share_level`), clean and thicken a two-material design
    (module doc).

    Parameters
    ----------
    phi_full, f_full : (X, Y, Z) ndarray of float in [0, 1]
        Material and drug share on the full (unfolded) design grid.
    dx_mm : float
    min_barrier_mm : float
        The thinnest wall a print holds, mm (two print lines).
    """
    level = mass_preserving_level(phi_full)
    material = phi_full >= level
    drug = material & (f_full >= drug_share_level(phi_full, f_full, material))
    barrier = material & ~drug
    drug, barrier, dropped = _drop_specks(drug, barrier)
    barrier |= enclosed_void(drug, barrier)
    drug, barrier, thickened = thicken_walls(drug, barrier, dx_mm, min_barrier_mm)
    pieces = {"print": count_pieces(drug | barrier), "drug": count_pieces(drug), "barrier": count_pieces(barrier)}
    return PrintablePair(drug, barrier, level, pieces, _piece_notes(drug, barrier, pieces),
                         thinnest_wall_mm(drug, barrier, dx_mm), thickened, dropped,
                         float(thin_barrier(barrier, dx_mm, min_barrier_mm).sum()) * dx_mm ** 3)
