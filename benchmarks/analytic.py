"""Solids with closed-form releases: voxel cases for the forward model, meshes for the reference evaluator.

The cases that the tests of ``tests/design/forward`` (``test_forward_analytic.py``, ``test_reference.py``) check
and that the scripts printing their tables and drawing their figures (`benchmarks.forward_evidence`,
`studies.reference_evidence`) run. Lengths in mm, volumes in mm^3.
"""
from __future__ import annotations

import numpy as np
import trimesh

from design.forward.simulator import simulate

__all__ = ["MESHES", "SHAPES", "box", "centres", "cylinder", "hollow", "nested", "release_error", "sphere", "torus"]


def centres(n: int, half_width: float) -> tuple[float, list[np.ndarray]]:
    """Voxel size, mm, and the (n, n, n) coordinates of the voxel centres of the cube [-half_width, half_width]^3."""
    dx = 2 * half_width / n
    c = (np.arange(n) + 0.5) * dx - half_width
    return dx, np.meshgrid(c, c, c, indexing="ij")


def _shell(tau, r):
    return 4 / 3 * np.pi * (r ** 3 - np.clip(r - tau, 0, None) ** 3)


SHAPES = {
    "sphere": (lambda x, y, z: x * x + y * y + z * z < 1.0, lambda t: _shell(t, 1.0), 1.0, 1.1),
    # cylinder of radius 1, height 2 (z in [-1, 1]): what remains at depth t is radius 1 - t, height 2 - 2t
    "cylinder": (lambda x, y, z: (x * x + y * y < 1.0) & (np.abs(z) < 1.0),
                 lambda t: np.pi * (2.0 - np.clip(1 - t, 0, None) ** 2 * np.clip(2 - 2 * t, 0, None)), 1.0, 1.1),
    # the cube fills its box, so its faces lie on voxel faces at every resolution
    "cube": (lambda x, y, z: np.ones(x.shape, dtype=bool),
             lambda t: 1.6 ** 3 - np.clip(1.6 - 2 * t, 0, None) ** 3, 0.8, 0.9),
    # Fig. 2: a ball of radius 0.4 inside a shell 0.6 < r < 1 with void between; the void dissolves at
    # once when the front reaches it at tau = 0.4, then the ball dissolves
    "nested": (lambda x, y, z: (np.sqrt(x * x + y * y + z * z) < 0.4)
               | ((x * x + y * y + z * z > 0.36) & (x * x + y * y + z * z < 1.0)),
               lambda t: _shell(np.minimum(t, 0.4), 1.0) + _shell(np.clip(t - 0.4, 0, None), 0.4), 1.0, 0.9),
}
"""Voxel cases: name -> (inside test on voxel centres, analytic C(tau), half width of the box, T simulated)."""


def release_error(name: str, n: int) -> float:
    """Largest |C - C*| over tau in [0, T] of `SHAPES` ``name``, relative to the analytic volume, at n voxels across."""
    inside, exact, half_width, t_end = SHAPES[name]
    dx, (x, y, z) = centres(n, half_width)
    r = simulate(inside(x, y, z).astype(float), dx, total_time_mm=t_end)
    truth = exact(r.tau_mm)
    return np.abs(r.released_mm3 - truth).max() / truth[-1]


def _ball(r):
    return 4 / 3 * np.pi * np.clip(r, 0, None) ** 3


def _lens(a, b, d):
    """Volume of the intersection of balls of radii a and b whose centres are d apart."""
    a = np.asarray(a, float)
    b = np.broadcast_to(np.asarray(b, float), a.shape)
    out = np.zeros(a.shape)
    inner = d <= np.abs(a - b)
    out[inner] = _ball(np.minimum(a, b)[inner])
    cut = ~inner & (d < a + b)
    aa, bb = a[cut], b[cut]
    out[cut] = np.pi * (aa + bb - d) ** 2 * (d * d + 2 * d * (aa + bb) - 3 * (aa - bb) ** 2) / (12 * d)
    return out


def _radius_of(volume, per_r3):
    return (volume / per_r3) ** (1 / 3)


# Each mesh case returns (mesh, depth at which it is dissolved, mm, analytic released mm^3 of tau). The mesh is a
# faceted stand-in: the analytic curve is that of the faceted solid (the cylinder's 128-gon, the box) or of the
# solid with the mesh's volume (the sphere's and torus' radii).

def sphere():
    """A sphere of radius 10 mm, off the origin."""
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    mesh.apply_translation([0.123, 0.377, -0.2])
    r = _radius_of(mesh.volume, 4 / 3 * np.pi)
    return mesh, 10.0, lambda t: mesh.volume - _ball(r - t)


def cylinder():
    """A 128-gon prism of radius 6 mm and height 15 mm."""
    n, a, height = 128, 6.0, 15.0
    mesh = trimesh.creation.cylinder(radius=a, height=height, sections=n)
    mesh.apply_translation([0.31, -0.17, 0.29])
    apothem = a * np.cos(np.pi / n)  # the regular n-gon's inradius: its offset polygons keep the shape

    def exact(t):
        return mesh.volume - n * np.tan(np.pi / n) * np.clip(apothem - t, 0, None) ** 2 * np.clip(height - 2 * t, 0, None)
    return mesh, a, exact


def box():
    """A 7.3 x 11.1 x 4.9 mm box off the lattice's centring."""
    dims = np.array([7.3, 11.1, 4.9])
    mesh = trimesh.creation.box(dims)
    mesh.apply_translation([0.217, 0.093, -0.311])
    return mesh, dims.min() / 2, lambda t: mesh.volume - np.prod(np.clip(dims - 2 * t[:, None], 0, None), axis=1)


def torus():
    """A torus of radii 8 and 3 mm."""
    major = 8.0
    mesh = trimesh.creation.torus(major_radius=major, minor_radius=3.0, major_sections=128, minor_sections=64)
    r = np.sqrt(mesh.volume / (2 * np.pi ** 2 * major))
    return mesh, 3.0, lambda t: mesh.volume - 2 * np.pi ** 2 * major * np.clip(r - t, 0, None) ** 2


def hollow():
    """A ball of radius 10 with a sealed spherical void of radius 3 centred 4 off its centre.

    The void is wetted when the outer front reaches it, at tau = w = 10 - 4 - 3; from then on the void
    grows as a ball of radius 3 + (tau - w) around its centre. What remains at tau is the ball of
    radius 10 - tau minus its intersection with the void's ball of radius max(3, 3 + tau - w).
    """
    outer = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    void = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    void.invert()
    void.apply_translation([4.0, 0.0, 0.0])
    mesh = trimesh.util.concatenate([outer, void])
    big = _radius_of(outer.volume, 4 / 3 * np.pi)
    small = _radius_of(-void.volume, 4 / 3 * np.pi)
    wet = big - 4.0 - small

    def exact(t):
        rest = np.clip(big - t, 0, None)
        return mesh.volume - (_ball(rest) - _lens(rest, small + np.clip(t - wet, 0, None), 4.0))
    return mesh, 10.0, exact


def nested():
    """A shell 6 < r < 10 around a sealed void holding a ball of radius 4 (paper Fig. 2): the shell
    dissolves as a ball until the front reaches the void at tau = 4, the ball then dissolves from 4."""
    outer = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    void = trimesh.creation.icosphere(subdivisions=4, radius=6.0)
    void.invert()
    core = trimesh.creation.icosphere(subdivisions=4, radius=4.0)
    mesh = trimesh.util.concatenate([outer, void, core])
    big, mid, small = (_radius_of(abs(m.volume), 4 / 3 * np.pi) for m in (outer, void, core))
    wet = big - mid

    def exact(t):
        shell = _ball(big) - _ball(np.maximum(big - t, mid))
        return shell + _ball(small) - _ball(small - np.clip(t - wet, 0, None))
    return mesh, 10.0, exact


MESHES = (sphere, cylinder, box, torus, hollow, nested)
"""The mesh cases, in the order of docs/forward.md's table."""
