"""Huygens minima over triangles wetted at linearly varying times (design.forward.linear_sources)."""
import numpy as np
import trimesh

from design.forward.linear_sources import LinearSources


def test_one_triangle_against_dense_samples():
    # min over the triangle of w(p) + |x - p| by 80 000 barycentric samples: the exact minimum is never above it and
    # within the samples' spacing (1/400 of an edge, times the slope and distance terms: < 1e-3) below it
    rng = np.random.default_rng(1)
    a, b = np.meshgrid(np.linspace(0, 1, 400), np.linspace(0, 1, 400))
    keep = a + b <= 1
    a, b = a[keep], b[keep]
    for scale in (0.3, 1.0, 3.0):              # slopes below and above 1
        v, w = rng.normal(size=(3, 3)), rng.normal(size=3) * scale
        points = v[0] + a[:, None] * (v[1] - v[0]) + b[:, None] * (v[2] - v[0])
        times = w[0] + a * (w[1] - w[0]) + b * (w[2] - w[0])
        x = rng.normal(size=(20, 3)) * 2
        T, tri, foot = LinearSources(trimesh.Trimesh(v, [[0, 1, 2]], process=False), w).arrival(x)
        brute = np.array([(times + np.linalg.norm(points - p, axis=1)).min() for p in x])
        assert np.all(T <= brute + 1e-12) and np.all(brute - T < 1e-3) and np.all(tri == 0)
        # the minimiser p* lies on the triangle and gives T
        s, r = np.linalg.lstsq(np.column_stack([v[1] - v[0], v[2] - v[0]]), (foot - v[0]).T, rcond=None)[0]
        assert np.all(s >= -1e-9) and np.all(r >= -1e-9) and np.all(s + r <= 1 + 1e-9)
        assert np.allclose(w[0] + s * (w[1] - w[0]) + r * (w[2] - w[0]) + np.linalg.norm(x - foot, axis=1), T)


def test_pruned_search_equals_the_full_one():
    # the hierarchy's bounds (least time, plane under the times) never prune the minimum: equal to a search with none
    rng = np.random.default_rng(2)
    mesh = trimesh.creation.icosphere(2, 1.0)
    x = rng.normal(size=(500, 3)) * 0.8
    for slope in (0.2, 1.0, 3.0):
        sources = LinearSources(mesh, mesh.vertices[:, 2] * slope + rng.uniform(0, 0.1, len(mesh.vertices)))
        T = sources.arrival(x)[0]
        sources.plane[:, 0] = -np.inf
        sources.floor[:] = -np.inf
        assert np.array_equal(T, sources.arrival(x)[0])


def test_a_time_linear_along_a_face_is_a_plane_front():
    # a square wetted at w = 0.6 y (slope 0.6 < 1): below its middle, T = w(x0) + z sqrt(1 - 0.36) exactly
    square = trimesh.Trimesh([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    sources = LinearSources(square, 0.6 * square.vertices[:, 1] + 3.0)
    x = np.array([[0.0, 0.0, -1.0], [1.0, -0.5, -2.0]])
    assert np.allclose(sources.arrival(x)[0], 3.0 + 0.6 * x[:, 1] + 0.8 * np.abs(x[:, 2]), atol=1e-12)
