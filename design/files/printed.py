"""The print of a design and its release: what every headline figure of a design run is of.

Every headline figure is the print's: ``design.stl`` released by the reference evaluator
(`design.forward.reference`, exact surface distances, independent of the design grid) against the
target's physical release (a source shape's by the same evaluator), and its volume and mass are the
mesh's own. The design grid's figures stay as diagnostics: the density's release and the binary solid's
(the printed mesh re-voxelised on the design grid, as the paper plots it, Fig. 6), both first-order fast
marching with a shape-dependent O(dx) error.

Print physics (`DesignConfig` ``anisotropy``, ``print_offset_mm``, ``swelling_mm``, from a simulation
calibration): the optimised density is the solid that must come out of the printer. A print comes out
``print_offset_mm`` larger than its mesh, so ``design.stl`` is that solid shrunk by the offset (the file to
print), and the print is ``design.stl`` grown by it again; every print figure (fit, volume, mass, channels,
pieces) is the grown solid's. The print's release is ``design.stl`` grown by the offset released by the reference
evaluator itself (`design.forward.offset_lattice`: the print {signed distance to design.stl > -offset}, at the
print's anisotropy, exact distances with z scaled by 1/a), not the extracted grown mesh's. With swelling that shuts
a channel the print keeps (on the design grid, `design.forward.swelling.shut_channels`) the print's release is the
forward model's with the print physics on voxels half the design grid's (the reference evaluator does not shut
channels); swelling that shuts none changes nothing, and the reference evaluator releases the print.
Channels narrower than ``swelling_mm`` are filled before extraction (`close_narrow_channels`), the minimum
open channel width the print must keep, and ``summary.json`` says whether the print meets it and how many voxels
the fill added (``channel_fill_voxels``: 0 when the objective's channel-width term, weight ``w_channel``, kept the
optimised design's channels open by itself).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from design.fabrication.extract import revoxelize
from design.forward.reference import ReferenceRelease, design_lattice
from design.forward.simulator import simulate
from design.forward.swelling import shut_channels
from design.inverse.objective import rel_rmse
from design.inverse.release_cache import cached_reference_release


def solid_release(solid: np.ndarray, dx_mm: float, mirror: tuple[bool, ...], total_time_mm: float,
                  dtau_mm: float, anisotropy: float = 1.0, swelling_mm: float = 0.0) -> np.ndarray:
    """Released volume of a full (unfolded) binary solid, simulated on its reduced grid (with the print physics
    ``anisotropy`` and ``swelling_mm`` of `design.forward.simulator.simulate`), mm^3 per tau sample."""
    half = tuple(slice(n // 2 if m else 0, None) for n, m in zip(solid.shape, mirror))
    return simulate(solid[half].astype(float), dx_mm, mirror=tuple(mirror), total_time_mm=total_time_mm,
                    dtau_mm=dtau_mm, anisotropy=anisotropy, swelling_mm=swelling_mm).released_mm3


def fine_release(mesh, dx_mm: float, origin_mm: np.ndarray, full_shape: tuple[int, int, int],
                 mirror: tuple[bool, ...], total_time_mm: float, dtau_mm: float, factor: int,
                 anisotropy: float = 1.0, swelling_mm: float = 0.0) -> np.ndarray:
    """Released volume of a printed mesh re-voxelised on voxels `factor` times smaller than the design
    grid's (same domain: `dx_mm`, `origin_mm`, `full_shape`, `mirror`), mm^3 per tau sample; zeros
    for ``mesh`` None (no solid extracted). ``anisotropy`` and ``swelling_mm``: the print physics."""
    shape = tuple(factor * n for n in full_shape)
    fine_dx = dx_mm / factor
    solid = (revoxelize(mesh, fine_dx, origin_mm, shape) if mesh is not None else np.zeros(shape, dtype=bool))
    return solid_release(solid, fine_dx, mirror, total_time_mm, dtau_mm, anisotropy, swelling_mm)


PRINT_PHYSICS_FACTOR = 2
"""With swelling, the print's release is the forward model's on voxels this many times smaller
than the design grid's."""


def close_narrow_channels(rho_full: np.ndarray, dx_mm: float, width_mm: float, level: float
                          ) -> tuple[np.ndarray, int]:
    """The minimum open channel width as a correction stage: every channel of the solid ``rho >= level`` narrower
    than ``width_mm`` filled with material (`design.forward.swelling.shut_channels` on the full grid).

    Returns
    -------
    rho_full : ndarray of float
        The density with the filled voxels at 1.
    filled : int
        Voxels filled.
    """
    plug = shut_channels((np.asarray(rho_full) >= level).astype(float), dx_mm, width_mm)
    return np.where(plug, 1.0, rho_full), int(np.count_nonzero(plug))


def channel_constraint(solid: np.ndarray, dx_mm: float, width_mm: float, filled: int,
                       min_channel_mm: float | None) -> dict:
    """Whether the print keeps every open channel at least ``width_mm`` wide.

    ``met`` when its narrowest open channel (`design.fabrication.printability.narrowest_channel_mm`, measured to
    within dx/2) is none or at least ``width_mm - dx/2``, and no void voxel of it lies in a channel narrower than
    ``width_mm`` by the forward model's own test (`design.forward.swelling.shut_channels`; ``narrow_left_mm3``).
    ``filled_mm3`` is what the correction stage filled.
    """
    left = int(np.count_nonzero(shut_channels(solid.astype(float), dx_mm, width_mm)))
    measured = min_channel_mm is None or min_channel_mm >= width_mm - 0.5 * dx_mm
    return {"width_mm": width_mm, "met": measured and left == 0, "min_channel_mm": min_channel_mm,
            "filled_mm3": filled * dx_mm ** 3, "narrow_left_mm3": left * dx_mm ** 3}


def _exact_print(mesh: trimesh.Trimesh, stl: trimesh.Trimesh | None, config, tau_mm: np.ndarray) -> ReferenceRelease:
    """The print released by the reference evaluator: ``stl`` grown by the print offset
    (`design.forward.offset_lattice`), or ``mesh`` (the extracted print; the one the last correction round judged)
    without an offset, without ``stl``, or for a file with sealed voids (their wetting with an offset is not
    modelled)."""
    from design.errors import DesignError

    cells, offset = design_lattice(config.resolution), float(config.print_offset_mm)
    if stl is not None and offset != 0.0:
        try:
            return cached_reference_release(stl, tau_mm, cells=cells, anisotropy=config.anisotropy, offset_mm=offset)
        except DesignError:
            pass
    return cached_reference_release(mesh, tau_mm, cells=cells, anisotropy=config.anisotropy)


@dataclass(frozen=True)
class PrintRelease:
    """The release of a design's print and its fit to the target.

    Attributes
    ----------
    released_mm3 : (K,) ndarray of float, mm^3
        The print's release per tau sample: by the reference evaluator, or with swelling by the forward model
        on voxels `PRINT_PHYSICS_FACTOR` times smaller than the design grid's; zeros without a print.
    binary_mm3 : (K,) ndarray of float, mm^3
        The print's re-voxelised solid's release on the design grid.
    reference : ReferenceRelease or None
        The reference evaluator's release of the print (None with swelling that shuts a channel, or without a print).
    volume_mm3 : float
        The print's volume, the mesh's own or the reference evaluator's (0 without a print), mm^3.
    rel_rmse : float
        rel. RMSE of ``released_mm3`` against the target's release.
    rel_rmse_error : float
        Bound on the error of ``rel_rmse`` from the two curves' stated errors.
    """

    released_mm3: np.ndarray
    binary_mm3: np.ndarray
    reference: ReferenceRelease | None
    volume_mm3: float
    rel_rmse: float
    rel_rmse_error: float


def print_release(problem, config, mesh: trimesh.Trimesh | None, solid: np.ndarray, judged: bool = True,
                  stl: trimesh.Trimesh | None = None) -> PrintRelease:
    """The release of a design's print and of its re-voxelised solid, and its fit to the target.

    Parameters
    ----------
    problem : design.inverse.problem.Problem
    config : design.inverse.config.DesignConfig
        Its print physics ``anisotropy`` and ``swelling_mm``, and its ``resolution``.
    mesh : trimesh.Trimesh or None
        The print (``design.stl`` grown by the print offset), mm; None when no solid was extracted.
    solid : ndarray of bool, ``problem.full_shape``
        The print re-voxelised on the full design grid.
    judged : bool
        Release the print (False: only its re-voxelised solid; the print's curve and fit NaN, its volume the
        mesh's). A coarse start of a multi-start, which its J alone ranks, is not judged.
    stl : trimesh.Trimesh, optional
        ``design.stl``, the file to print: with a print offset the reference evaluator releases it grown by the
        offset exactly (None: ``mesh`` itself is released).
    """
    space, target = problem.space, problem.target
    physics = {"anisotropy": config.anisotropy, "swelling_mm": config.swelling_mm}
    dtau_mm = target.total_time_mm / (target.tau_mm.size - 1)
    binary_curve = solid_release(solid, space.dx_mm, space.mirror, target.total_time_mm, dtau_mm, **physics)
    # the print: design.stl (grown by the offset) released by exact surface distances at the print's anisotropy;
    # with swelling that shuts a channel, by the forward model with the print physics on a finer grid
    if not judged:
        nan = np.full_like(binary_curve, np.nan)
        return PrintRelease(nan, binary_curve, None, float(mesh.volume) if mesh is not None else 0.0, np.nan, np.nan)
    modelled = config.swelling_mm > 0 and bool(shut_channels(solid.astype(float), space.dx_mm, config.swelling_mm).any())
    printed = _exact_print(mesh, stl, config, target.tau_mm) if mesh is not None and not modelled else None
    if modelled:
        print_curve = fine_release(mesh, space.dx_mm, problem.origin_mm, problem.full_shape, space.mirror,
                                   target.total_time_mm, dtau_mm, PRINT_PHYSICS_FACTOR, **physics)
        volume = float(mesh.volume) if mesh is not None else 0.0
    else:
        print_curve = printed.released_mm3 if printed is not None else np.zeros_like(binary_curve)
        volume = printed.volume_mm3 if printed is not None else 0.0
    # |rmse(a) - rmse(b)| <= max |a - b|: the two curves' stated errors bound the fit's
    fit_error = ((printed.error_mm3 if printed is not None else 0.0) + (problem.target_error_mm3 or 0.0)) \
        / target.final_mm3
    return PrintRelease(print_curve, binary_curve, printed, volume, rel_rmse(print_curve, target.released_mm3),
                        fit_error)
