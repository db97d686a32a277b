"""An independent check of the print's fit that design folders report (``rel_rmse_print`` of ``summary.json``).

`design.forward.reference` releases a mesh by a lattice quadrature over exact distances from a bounding-volume
hierarchy, its inside test by the pseudo-normals of the nearest feature. This script recomputes the same figure
with none of that code, for the source mesh (the run's target) and for ``design.stl`` separately:

- ``2**points_log2`` scrambled Sobol points (`scipy.stats.qmc.Sobol`) fill the mesh's bounding box;
- a point is inside when a ray from it crosses the surface an odd number of times (`inside`: the ray runs along
  a fixed direction, `RAY`, in whose plane no edge of a grid-aligned mesh lies; triangles are bucketed by their
  projection on a 2D grid);
- its distance to the surface is exact (`surface_distance`: the closest point on a triangle by its Voronoi
  regions, Ericson's construction, on every triangle of each group of triangles whose bounding box is no
  farther than the least distance found so far, which starts at the distance to the nearest centroid);
- the released volume at tau is the box's volume times the fraction of points that are inside and closer than
  tau to the surface: where every surface faces the bath, a point's dissolution time is its distance.

That last step holds for a void-free solid only (a sealed void is wetted only when the front reaches it). The
script counts each mesh's shells and those enclosed by another (`enclosed_shells`) and says so in the row; a
design with an enclosed shell is reported but left out of the comparison. The fit is the rel. RMSE over the run's
tau grid (``curves.csv``) divided by the target's final release, as `design.inverse.objective.rel_rmse` defines it.

    python -m studies.exact_check FOLDER [FOLDER ...] [--points-log2 18] [--csv OUT]
    python -m studies.exact_check --table CSV

A line per folder: the reported fit, the independent one and their difference in points; each curve's largest
deviation from ``curves.csv`` (``target_mm3``, ``print_mm3``) in % of the target's final release; the Monte Carlo
volume of the print against its mesh's exact volume; shells; seconds. Last line:
``largest difference: <points> over <n> designs``. ``--table`` prints a CSV of rows as the Markdown table of
docs/results.md.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from numba import njit
from scipy.spatial import cKDTree
from scipy.stats import qmc

from studies import physical_default

POINTS_LOG2 = 18
"""Sobol points per mesh, as a power of two (2^18 = 262,144)."""
SEED = 31
"""Scrambling seed of the Sobol points."""
RAY = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
"""The inside test's ray direction: no face or edge of a grid-aligned mesh is parallel to it."""
MAX_EDGE_FRACTION = 1.0 / 24.0
"""Triangles are split (the surface does not move) until no edge is longer than this fraction of the bounding
box's longest side, so that the distance search's certificate holds with few candidates."""
CLUSTER_EDGES = 2.0
"""Side of the distance search's groups of triangles, in the longest triangle edge."""


@njit(cache=False, nogil=True)
def _triangle_distance(px, py, pz, t):
    """Exact distance from (px, py, pz) to the triangle t (3, 3): the closest point by the triangle's Voronoi
    regions (C. Ericson, Real-Time Collision Detection, 2005, section 5.1.5), the first region that holds."""
    ax, ay, az = t[0, 0], t[0, 1], t[0, 2]
    abx, aby, abz = t[1, 0] - ax, t[1, 1] - ay, t[1, 2] - az
    acx, acy, acz = t[2, 0] - ax, t[2, 1] - ay, t[2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:  # vertex a
        return np.sqrt(apx * apx + apy * apy + apz * apz)
    bpx, bpy, bpz = px - t[1, 0], py - t[1, 1], pz - t[1, 2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:  # vertex b
        return np.sqrt(bpx * bpx + bpy * bpy + bpz * bpz)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:  # edge ab
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return np.sqrt(qx * qx + qy * qy + qz * qz)
    cpx, cpy, cpz = px - t[2, 0], py - t[2, 1], pz - t[2, 2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:  # vertex c
        return np.sqrt(cpx * cpx + cpy * cpy + cpz * cpz)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:  # edge ac
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return np.sqrt(qx * qx + qy * qy + qz * qz)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:  # edge bc
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        qx = bpx - w * (t[2, 0] - t[1, 0])
        qy = bpy - w * (t[2, 1] - t[1, 1])
        qz = bpz - w * (t[2, 2] - t[1, 2])
        return np.sqrt(qx * qx + qy * qy + qz * qz)
    denom = 1.0 / (va + vb + vc)  # the face's interior
    v, w = vb * denom, vc * denom
    qx, qy, qz = apx - v * abx - w * acx, apy - v * aby - w * acy, apz - v * abz - w * acz
    return np.sqrt(qx * qx + qy * qy + qz * qz)


@njit(cache=False, nogil=True)
def _pair_distances(points, tris):
    out = np.empty(len(points))
    for i in range(len(points)):
        out[i] = _triangle_distance(points[i, 0], points[i, 1], points[i, 2], tris[i])
    return out


def triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Exact distance (mm) from each point (n, 3) to the triangle of the same row (n, 3, 3)."""
    return _pair_distances(np.ascontiguousarray(points, dtype=np.float64),
                           np.ascontiguousarray(triangles, dtype=np.float64))


def prepared(mesh: trimesh.Trimesh) -> np.ndarray:
    """The mesh's triangles (m, 3, 3), split until no edge exceeds `MAX_EDGE_FRACTION` of the bounding box (the
    same surface), without those of zero area (they add no point to the surface)."""
    max_edge = MAX_EDGE_FRACTION * float(np.max(mesh.extents))
    vertices, faces = trimesh.remesh.subdivide_to_size(np.asarray(mesh.vertices, float), np.asarray(mesh.faces),
                                                       max_edge=max_edge, max_iter=30)
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return np.ascontiguousarray(tri[area > 1e-12 * max_edge ** 2])


def _ray_frame() -> np.ndarray:
    """Rows e1, e2, RAY: an orthonormal frame whose third axis is the ray."""
    e1 = np.cross(RAY, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return np.array([e1, np.cross(RAY, e1), RAY])


@njit(cache=False, nogil=True)
def _crossings(p, point_cell, tri, order, starts, ends):
    """Parity of the triangles (projected, (m, 3, 3) in the ray's frame) that the ray +z from each point crosses,
    testing only the triangles of the point's cell (order[starts[c]:ends[c]])."""
    out = np.zeros(len(p), dtype=np.bool_)
    for i in range(len(p)):
        c = point_cell[i]
        if c < 0:
            continue
        qx, qy, qz = p[i, 0], p[i, 1], p[i, 2]
        odd = False
        for k in range(starts[c], ends[c]):
            t = tri[order[k]]
            # edge functions: twice the signed area of (vertex j, vertex j + 1, q) in the plane across the ray
            w0 = (t[1, 0] - t[0, 0]) * (qy - t[0, 1]) - (t[1, 1] - t[0, 1]) * (qx - t[0, 0])
            w1 = (t[2, 0] - t[1, 0]) * (qy - t[1, 1]) - (t[2, 1] - t[1, 1]) * (qx - t[1, 0])
            w2 = (t[0, 0] - t[2, 0]) * (qy - t[2, 1]) - (t[0, 1] - t[2, 1]) * (qx - t[2, 0])
            if (w0 > 0.0 and w1 > 0.0 and w2 > 0.0) or (w0 < 0.0 and w1 < 0.0 and w2 < 0.0):
                # barycentric: vertex 0 faces edge (1, 2), whose function is w1, and so on
                z = (w1 * t[0, 2] + w2 * t[1, 2] + w0 * t[2, 2]) / (w0 + w1 + w2)
                if z > qz:
                    odd = not odd
        out[i] = odd
    return out


def inside(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Whether each point (n, 3) is inside the closed surface of ``triangles`` (m, 3, 3): the parity of the
    triangles that a ray from it along `RAY` crosses. The triangles are bucketed by the cells of a 2D grid across
    the ray that their projections' bounding boxes touch; a point is tested against the triangles of its cell."""
    frame = _ray_frame()
    tri = np.ascontiguousarray(triangles @ frame.T)
    p = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3) @ frame.T)
    lo, hi = tri[:, :, :2].min(axis=1), tri[:, :, :2].max(axis=1)
    cell = float((hi - lo).max())  # every triangle's box touches at most 2 x 2 cells
    origin = lo.min(axis=0)
    n_cells = np.floor((hi.max(axis=0) - origin) / cell).astype(np.int64) + 1
    first, last = np.floor((lo - origin) / cell).astype(np.int64), np.floor((hi - origin) / cell).astype(np.int64)
    tri_ids, cell_ids = [], []
    for di in (0, 1):
        for dj in (0, 1):
            keep = (first[:, 0] + di <= last[:, 0]) & (first[:, 1] + dj <= last[:, 1])
            tri_ids.append(np.flatnonzero(keep))
            cell_ids.append((first[keep, 0] + di) * n_cells[1] + first[keep, 1] + dj)
    tri_ids, cell_ids = np.concatenate(tri_ids), np.concatenate(cell_ids)
    order = np.argsort(cell_ids, kind="stable")
    tri_ids, cell_ids = tri_ids[order], cell_ids[order]
    cells = np.arange(int(np.prod(n_cells)))
    starts = np.searchsorted(cell_ids, cells, side="left")
    ends = np.searchsorted(cell_ids, cells, side="right")
    ij = np.floor((p[:, :2] - origin) / cell).astype(np.int64)
    outside = np.any((ij < 0) | (ij >= n_cells), axis=1)  # beyond every triangle: no crossing
    point_cell = np.where(outside, -1, ij[:, 0] * n_cells[1] + ij[:, 1])
    return _crossings(p, point_cell, tri, tri_ids, starts, ends)


@njit(cache=False, nogil=True)
def _nearest(points, upper, tri, cluster_start, cluster_lo, cluster_hi):
    """Least exact distance from each point to the triangles, visiting only the clusters whose box is no farther
    than the least distance so far (from ``upper``, a distance to a point of the surface)."""
    out = np.empty(len(points))
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = upper[i]
        for c in range(len(cluster_lo)):
            gx = max(cluster_lo[c, 0] - px, 0.0, px - cluster_hi[c, 0])
            gy = max(cluster_lo[c, 1] - py, 0.0, py - cluster_hi[c, 1])
            gz = max(cluster_lo[c, 2] - pz, 0.0, pz - cluster_hi[c, 2])
            if gx * gx + gy * gy + gz * gz > best * best:
                continue
            for k in range(cluster_start[c], cluster_start[c + 1]):
                d = _triangle_distance(px, py, pz, tri[k])
                if d < best:
                    best = d
        out[i] = best
    return out


def surface_distance(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact distance (mm) from each point (n, 3) to the surface of ``triangles`` (m, 3, 3).

    The triangles are grouped by the cell of a 3D grid (`CLUSTER_EDGES` longest edges a side) that holds their
    centroid, each group with its bounding box. The distance to the nearest centroid (a k-d tree) bounds each
    point's distance from above; a group whose box is farther than the least distance found so far cannot hold
    a nearer point, and every triangle of the other groups is measured exactly (`_triangle_distance`).
    """
    tri = np.asarray(triangles, float)
    centroids = tri.mean(axis=1)
    edge = float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max())
    ijk = np.floor((centroids - centroids.min(axis=0)) / (CLUSTER_EDGES * edge)).astype(np.int64)
    key = (ijk[:, 0] * (ijk[:, 1].max() + 1) + ijk[:, 1]) * (ijk[:, 2].max() + 1) + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    tri, key = np.ascontiguousarray(tri[order]), key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    lo = np.minimum.reduceat(tri.min(axis=1), start, axis=0)
    hi = np.maximum.reduceat(tri.max(axis=1), start, axis=0)
    points = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
    upper, _ = cKDTree(centroids).query(points, k=1)
    return _nearest(points, np.asarray(upper, float), tri, np.r_[start, len(tri)].astype(np.int64), lo, hi)


def enclosed_shells(mesh: trimesh.Trimesh) -> tuple[int, int]:
    """``(shells, enclosed)``: the mesh's connected surfaces and how many of them lie inside another (the wall of a
    sealed void, or a body inside one)."""
    bodies = mesh.split(only_watertight=False)
    enclosed = 0
    for i, body in enumerate(bodies):
        probe = np.asarray(body.vertices[:1], float)
        if any(inside(prepared(other), probe)[0] for j, other in enumerate(bodies) if j != i):
            enclosed += 1
    return len(bodies), enclosed


@dataclass(frozen=True)
class ExactRelease:
    """A closed mesh's release by Sobol points, parity inside tests and exact distances (`exact_release`).

    Attributes
    ----------
    released_mm3 : (K,) ndarray of float, mm^3
        The box's volume times the fraction of points inside and closer than tau to the surface.
    volume_mm3 : float
        The box's volume times the fraction of points inside.
    mesh_volume_mm3 : float
        The mesh's volume by signed tetrahedra (trimesh), to compare.
    shells, enclosed : int
        The mesh's connected surfaces, and those inside another (`enclosed_shells`): the release is the solid's
        only where none is enclosed.
    seconds : float
    """

    released_mm3: np.ndarray
    volume_mm3: float
    mesh_volume_mm3: float
    shells: int
    enclosed: int
    seconds: float


def exact_release(mesh: trimesh.Trimesh, tau_mm: np.ndarray, *, points_log2: int = POINTS_LOG2,
                  seed: int = SEED) -> ExactRelease:
    """The release of a closed mesh (mm) at each tau (mm) by the module's method."""
    began = time.perf_counter()
    triangles = prepared(mesh)
    lo, hi = np.asarray(mesh.bounds, float)
    points = lo + (hi - lo) * qmc.Sobol(d=3, scramble=True, seed=seed).random_base2(points_log2)
    solid = points[inside(triangles, points)]
    distance = np.sort(surface_distance(triangles, solid))
    per_point = float(np.prod(hi - lo)) / len(points)
    released = per_point * np.searchsorted(distance, np.asarray(tau_mm, float), side="left")
    shells, enclosed = enclosed_shells(mesh)
    return ExactRelease(released, per_point * len(solid), float(abs(mesh.volume)), shells, enclosed,
                        time.perf_counter() - began)


def _source_path(folder: Path, target: str) -> Path:
    path = Path(target)
    for candidate in (path, folder / path, folder.parent / path.name):
        if candidate.is_file():
            return candidate
    raise SystemExit(f"{folder / 'config.json'}: target {target!r} is not a mesh file found from here; "
                     "the check needs the source mesh")


def check_folder(folder: Path, points_log2: int = POINTS_LOG2) -> dict:
    """The row of one design folder (module doc)."""
    folder = Path(folder)
    for name in ("summary.json", "config.json", "curves.csv", "design.stl"):
        if not (folder / name).is_file():
            raise SystemExit(f"{folder}: no {name}; a finished design folder is expected")
    summary = json.loads((folder / "summary.json").read_text())
    config = json.loads((folder / "config.json").read_text())
    if "rel_rmse_print" not in summary:
        raise SystemExit(f"{folder / 'summary.json'}: no rel_rmse_print (a summary of format 2 is expected)")
    curves = np.genfromtxt(folder / "curves.csv", delimiter=",", names=True)
    tau = curves["tau_mm"]
    target = exact_release(trimesh.load_mesh(_source_path(folder, config["target"])), tau, points_log2=points_log2)
    printed = exact_release(trimesh.load_mesh(folder / "design.stl"), tau, points_log2=points_log2)
    final = target.released_mm3[-1]
    fit = float(np.sqrt(np.mean((printed.released_mm3 - target.released_mm3) ** 2)) / final)
    reported = float(summary["rel_rmse_print"])
    comparable = target.enclosed == 0 and printed.enclosed == 0
    return {"design": folder.name, "reported_pct": f"{100 * reported:.3f}", "exact_pct": f"{100 * fit:.3f}",
            "difference_points": f"{100 * (fit - reported):+.3f}" if comparable else "-",
            "target_dev_pct": f"{100 * np.abs(target.released_mm3 - curves['target_mm3']).max() / final:.3f}",
            "print_dev_pct": f"{100 * np.abs(printed.released_mm3 - curves['print_mm3']).max() / final:.3f}",
            "print_volume_mm3": f"{printed.volume_mm3:.2f}", "print_mesh_volume_mm3": f"{printed.mesh_volume_mm3:.2f}",
            "shells_target": target.shells, "shells_print": printed.shells,
            "enclosed": target.enclosed + printed.enclosed,
            "points": 1 << points_log2, "seconds": f"{target.seconds + printed.seconds:.0f}"}


def table(path: Path) -> str:
    """The rows of a CSV written with ``--csv`` as Markdown."""
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    lines = ["| design | reported (`rel_rmse_print`) | independent exact check | difference, points | "
             "target's curve, largest deviation | print's curve, largest deviation | print volume, points / mesh "
             "(mm^3) | shells (source, print), enclosed | seconds |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['design']} | {r['reported_pct']}% | {r['exact_pct']}% | {r['difference_points']} | "
                     f"{r['target_dev_pct']}% | {r['print_dev_pct']}% | {r['print_volume_mm3']} / "
                     f"{r['print_mesh_volume_mm3']} | {r['shells_target']}, {r['shells_print']}, {r['enclosed']} | "
                     f"{r['seconds']} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="*", type=Path)
    parser.add_argument("--points-log2", type=int, default=POINTS_LOG2)
    parser.add_argument("--csv", type=Path, help="append the rows to this CSV")
    parser.add_argument("--table", type=Path, metavar="CSV", help="print the rows of this CSV as a Markdown table")
    args = parser.parse_args()
    if args.table:
        print(table(args.table))
        return
    if not args.folders:
        parser.error("give at least one design folder (or --table CSV)")
    if not 8 <= args.points_log2 <= 24:
        raise SystemExit(f"--points-log2 must be between 8 and 24, got {args.points_log2}")
    differences = []
    for folder in args.folders:
        row = check_folder(folder, args.points_log2)
        print(", ".join(f"{k} {v}" for k, v in row.items()), flush=True)
        if row["difference_points"] != "-":
            differences.append(abs(float(row["difference_points"])))
        if args.csv:
            physical_default.append_row(args.csv, row)
    if not differences:
        print("largest difference: - over 0 designs (every design has an enclosed shell)")
        sys.exit(1)
    print(f"largest difference: {max(differences):.3f} points over {len(differences)} designs")


if __name__ == "__main__":
    main()
