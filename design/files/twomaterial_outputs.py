"""The outputs of a two-material design: both solids, their meshes, the print's release and the pictures.

From the optimised fields: the printable pair (`design.fabrication.twomaterial_print`), ``design.stl`` (the
drug), ``barrier.stl``, ``design.3mf`` (both as separate objects, `design.files.threemf`), the print's
release on the design grid (both meshes re-voxelised at the voxel centres, the drug winning where they
overlap as in ``sfr simulate --barrier``, simulated at the true barrier speed by
`design.forward.twomaterial.simulate_two`), by the two-material reference evaluator when it is installed,
``release.csv``, ``materials.png`` (slices of both materials and the curves) and ``summary.json``.

Both meshes are marching-cubes contours of the two binary solids on one grid, so their shared faces
coincide: each edge between a drug and a barrier voxel gets its vertex at the same midpoint in both.
"""
from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from design.fabrication.extract import density_mesh, revoxelize
from design.fabrication.twomaterial_print import PrintablePair, printable_pair
from design.files.threemf import write_objects
from design.forward.twomaterial import TwoMaterialRelease, barrier_cover, simulate_two
from design.inverse.objective import rel_rmse
from design.inverse.twomaterial_objective import Fields
from design.inverse.twomaterial_problem import TwoMaterialProblem
from design.inverse.twomaterial_targets import MIN_BARRIER_MM

DRUG_COLOUR = "#E69F00"
BARRIER_COLOUR = "#0072B2"
REFERENCE_MODULE = "design.forward.twomaterial_reference"
"""Where the two-material reference evaluator lives (``two_material_reference_release``), when installed."""


def print_release(problem: TwoMaterialProblem, drug_mesh: trimesh.Trimesh, barrier_mesh: trimesh.Trimesh | None
                  ) -> tuple[TwoMaterialRelease, np.ndarray, np.ndarray]:
    """The meshes re-voxelised on the full design grid (the drug wins) and their release at the true speed."""
    space = problem.space
    shape = tuple(n * (2 if m else 1) for n, m in zip(space.grid_shape, space.mirror))
    drug = revoxelize(drug_mesh, space.dx_mm, problem.origin_mm, shape)
    barrier = (revoxelize(barrier_mesh, space.dx_mm, problem.origin_mm, shape) & ~drug if barrier_mesh is not None
               else np.zeros(shape, bool))
    release = simulate_two(drug.astype(float), barrier.astype(float), space.dx_mm, problem.settings.barrier_speed,
                           total_time_mm=problem.target.total_time_mm,
                           dtau_mm=float(problem.target.tau_mm[1] - problem.target.tau_mm[0]))
    return release, drug, barrier


def reference_curve(problem: TwoMaterialProblem, drug_mesh, envelope_mesh) -> tuple[np.ndarray | None, str]:
    """The print's release by the two-material reference evaluator on the target's tau grid, or None and why not.

    The evaluator gets the drug and the envelope of both materials as the barrier's solid (the drug wins where they
    overlap): the same print as the barrier's own solid, without faces that coincide with the drug's."""
    try:
        module = importlib.import_module(REFERENCE_MODULE)
    except ImportError:
        return None, f"{REFERENCE_MODULE} is not installed"
    if envelope_mesh is None:
        return None, "the print has no barrier"
    result = module.two_material_reference_release(drug_mesh, envelope_mesh, problem.settings.barrier_speed,
                                                   problem.target.tau_mm)
    return np.asarray(result.released_mm3, float), "two_material_reference_release"


def write_outputs(problem: TwoMaterialProblem, fields: Fields, out: Path, *, status: str, evaluations: int,
                  seconds: float, reference: bool = True) -> dict[str, Any]:
    """Write every output of a finished two-material design into ``out``; return the summary."""
    space, target = problem.space, problem.target
    phi, f = space.unfold(fields.phi), space.unfold(fields.f)
    pair = printable_pair(phi, f, space.dx_mm, MIN_BARRIER_MM)
    drug_mesh = density_mesh(pair.drug.astype(float), space.dx_mm, problem.origin_mm)
    barrier_mesh = (density_mesh(pair.barrier.astype(float), space.dx_mm, problem.origin_mm)
                    if pair.barrier.any() else None)
    drug_mesh.export(out / "design.stl")
    objects = {"drug": drug_mesh}
    if barrier_mesh is not None:
        barrier_mesh.export(out / "barrier.stl")
        objects["barrier"] = barrier_mesh
    write_objects(out / "design.3mf", objects)
    release, drug_v, barrier_v = print_release(problem, drug_mesh, barrier_mesh)
    envelope = (density_mesh((pair.drug | pair.barrier).astype(float), space.dx_mm, problem.origin_mm)
                if reference and barrier_mesh is not None else None)
    ref, ref_how = reference_curve(problem, drug_mesh, envelope) if reference else (None, "not asked")
    cover = barrier_cover(drug_v.astype(float), barrier_v.astype(float), space.dx_mm)
    columns = [target.tau_mm, target.released_mm3, fields.released_mm3, release.released_mm3]
    names = "tau_mm,target_mm3,density_mm3,print_grid_mm3"
    if ref is not None:
        columns.append(ref)
        names += ",print_reference_mm3"
    np.savetxt(out / "release.csv", np.column_stack(columns), delimiter=",", header=names, comments="", fmt="%.9g")
    np.savez_compressed(out / "fields.npz", phi=phi, f=f, drug=pair.drug, barrier=pair.barrier, dx_mm=space.dx_mm,
                        origin_mm=problem.origin_mm)
    summary = _summary(problem, pair, release, cover, ref, ref_how, drug_mesh, barrier_mesh)
    summary.update(status=status, evaluations=evaluations, seconds=seconds,
                   density_fit=rel_rmse(fields.released_mm3, target.released_mm3))
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    draw(problem, pair, release, ref, out / "materials.png")
    return summary


def _summary(problem: TwoMaterialProblem, pair: PrintablePair, release: TwoMaterialRelease, cover: float,
             ref: np.ndarray | None, ref_how: str, drug_mesh, barrier_mesh) -> dict[str, Any]:
    target, s, settings = problem.target, problem.settings.barrier_speed, problem.settings
    dx = problem.space.dx_mm
    return {
        "target": settings.target, "target_source": target.source, "barrier_speed": s, "space": settings.space,
        "resolution": settings.resolution, "domain_mm": problem.domain_mm, "voxel_size_mm": dx,
        "total_time_mm": target.total_time_mm, "target_mm3": target.final_mm3,
        "design_slowness": problem.slowness, "cap_mm": problem.space.cap_vox * dx,
        "needs": list(problem.needs), "one_material_infeasible": list(problem.one_material),
        "phases": {"delay_mm": problem.phases.delay_mm, "end_mm": problem.phases.end_mm,
                   "pauses_mm": [list(p) for p in problem.phases.pauses]},
        "drug": {"volume_mm3": float(drug_mesh.volume), "pieces": pair.pieces["drug"], "mesh": "design.stl"},
        "barrier": {"volume_mm3": float(barrier_mesh.volume) if barrier_mesh is not None else 0.0,
                    "pieces": pair.pieces["barrier"], "mesh": "barrier.stl" if barrier_mesh is not None else None,
                    "min_wall_mm": pair.min_barrier_mm, "min_wall_required_mm": MIN_BARRIER_MM,
                    "thin_mm3": pair.thin_barrier_mm3,
                    "cover_mm": cover, "release_starts_mm": (cover / s if s > 0 else None) if cover > 0.01 * dx else 0.0},
        "print_pieces": pair.pieces["print"], "piece_notes": list(pair.piece_notes),
        "extraction_level": pair.level, "thickened_voxels": pair.thickened_voxels, "dropped_voxels": pair.dropped_voxels,
        "sealed_mm3": release.sealed_mm3, "three_mf": "design.3mf",
        "grid_fit": rel_rmse(release.released_mm3, target.released_mm3),
        "grid_fit_method": f"print re-voxelised on the {dx:.4g} mm design grid, simulate_two at s = {s:g}",
        "reference_fit": None if ref is None else rel_rmse(ref, target.released_mm3), "reference": ref_how,
    }


def draw(problem: TwoMaterialProblem, pair: PrintablePair, release: TwoMaterialRelease, ref: np.ndarray | None,
         path: Path) -> None:
    """Slices of both materials (drug orange, barrier blue, void white) through the centre, and the curves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    labels = pair.drug.astype(int) + 2 * pair.barrier.astype(int)
    cmap = ListedColormap(["white", DRUG_COLOUR, BARRIER_COLOUR])
    dx, origin, shape = problem.space.dx_mm, problem.origin_mm, labels.shape
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    for ax, cut, (a, b), title in ((axes[0], labels[:, :, shape[2] // 2].T, (0, 1), "horizontal slice (z = middle)"),
                                   (axes[1], labels[:, shape[1] // 2, :].T, (0, 2), "vertical slice (y = 0)")):
        extent = [origin[a], origin[a] + shape[a] * dx, origin[b], origin[b] + shape[b] * dx]
        ax.imshow(cut, origin="lower", cmap=cmap, vmin=0, vmax=2, extent=extent, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("xyz"[a] + " (mm)")
        ax.set_ylabel("xyz"[b] + " (mm)")
    axes[0].plot([], [], "s", color=DRUG_COLOUR, label="drug")
    axes[0].plot([], [], "s", color=BARRIER_COLOUR, label="barrier")
    axes[0].legend(fontsize=8, loc="upper right")
    t = problem.target
    axes[2].plot(t.tau_mm, t.released_mm3, "k", lw=2, label="target")
    axes[2].plot(release.tau_mm, release.released_mm3, "C3--", label="print (design grid)")
    if ref is not None:
        axes[2].plot(t.tau_mm, ref, "C2:", label="print (reference)")
    axes[2].set_xlabel("dissolution time $\\tau$ (mm of drug)")
    axes[2].set_ylabel("released drug (mm$^3$)")
    axes[2].legend(fontsize=8)
    axes[2].grid(alpha=0.3)
    fig.suptitle(f"{problem.settings.target}, barrier speed {problem.settings.barrier_speed:g} "
                 f"({problem.settings.space})", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
