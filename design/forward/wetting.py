"""Sealed voids of a closed solid and the times their fluid is wetted (the reference evaluator's offsets).

A shell enclosed by another (the wall of a sealed void, or a body inside such a void) is wetted only once the
erosion front reaches the fluid region it faces: :func:`wetting` finds the shells, their nesting and the fluid
region each faces, and the regions' wetting times by a shortest path over them (Dijkstra), w_R = min over wetted
regions Q of (w_Q + dist(shells of Q, shells of R)); see :mod:`design.forward.reference`.
"""
from __future__ import annotations

import heapq

import numpy as np
import trimesh

from design.forward.distance import Surface


def _winding(points: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Winding number of closed triangles `vx` (F, 3, 3) at each point (van Oosterom and Strackee)."""
    out = np.empty(len(points))
    for i, p in enumerate(points):
        a, b, c = (vx[:, k, :] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
               + np.einsum("ij,ij->i", c, a) * lb)
        out[i] = np.arctan2(det, den).sum() / (2.0 * np.pi)
    return out


def wetting(mesh: trimesh.Trimesh) -> tuple[np.ndarray, int]:
    """Per face, the time its fluid region is wetted (0 at the bath); the number of sealed voids."""
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    n_shells = int(labels.max()) + 1
    if n_shells == 1:
        return np.zeros(len(mesh.faces)), 0
    vx = mesh.vertices[mesh.faces]
    shells = [np.flatnonzero(labels == s) for s in range(n_shells)]
    # containment: the number of other shells around a vertex of each shell (its nesting depth)
    probe = np.array([mesh.vertices[mesh.faces[f[0], 0]] for f in shells])
    inside = np.zeros((n_shells, n_shells), dtype=bool)  # inside[s, r]: shell s lies within shell r
    for r in range(n_shells):
        wind = np.abs(_winding(probe, vx[shells[r]]))
        inside[:, r] = wind > 0.5
        inside[r, r] = False
    depth = inside.sum(axis=1)
    # fluid region of each shell: 0 the bath; an odd-depth shell bounds its own void; an even-depth
    # shell inside one faces the void of its innermost enclosing (odd-depth) shell
    region = np.zeros(n_shells, dtype=np.int64)
    voids = [s for s in range(n_shells) if depth[s] % 2 == 1]
    if not voids:  # separate bodies, every one facing the bath
        return np.zeros(len(mesh.faces)), 0
    for k, s in enumerate(voids):
        region[s] = k + 1
    for s in range(n_shells):
        if depth[s] > 0 and depth[s] % 2 == 0:
            parent = next(r for r in voids if inside[s, r] and depth[r] == depth[s] - 1)
            region[s] = region[parent]
    n_regions = len(voids) + 1
    # region-to-region distance: the closest approach of their shells, from vertices, edge midpoints
    # and face centroids of each shell to the exact surface of the other
    surfaces = {s: Surface(mesh.submesh([shells[s]], append=True)) for s in range(n_shells)}
    samples = {s: np.concatenate([vx[shells[s]].reshape(-1, 3), vx[shells[s]].mean(axis=1),
                                  0.5 * (vx[shells[s]] + np.roll(vx[shells[s]], 1, axis=1)).reshape(-1, 3)])
               for s in range(n_shells)}
    gap = np.full((n_regions, n_regions), np.inf)
    for s in range(n_shells):
        for r in range(n_shells):
            if region[s] != region[r]:
                d = float(surfaces[r].nearest(samples[s])[0].min())
                a, b = region[s], region[r]
                gap[a, b] = gap[b, a] = min(gap[a, b], d)
    wet = np.full(n_regions, np.inf)
    wet[0] = 0.0
    heap = [(0.0, 0)]
    while heap:
        t, a = heapq.heappop(heap)
        if t > wet[a]:
            continue
        for b in range(n_regions):
            if t + gap[a, b] < wet[b]:
                wet[b] = t + gap[a, b]
                heapq.heappush(heap, (wet[b], b))
    return wet[region[labels]], len(voids)

