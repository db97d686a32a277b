"""A print larger or smaller than its mesh: the offset solid of design.files.pipeline against exact spheres."""
import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.files.pipeline import mesh_grid, simulate_mesh


@pytest.mark.parametrize("offset", [0.3, -0.25])
@pytest.mark.parametrize("symmetry", ["", "xz"])
def test_offset_sphere_is_the_sphere_of_radius_r_plus_offset(offset, symmetry):
    radius = 3.0
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    rho, dx, mirror = mesh_grid(mesh, resolution=40, symmetry=symmetry, offset_mm=offset)
    # the voxel size follows the mesh, the grid widens to hold the grown solid
    assert dx == pytest.approx(float(mesh.extents.max()) / 40)
    copies = 2 ** sum(mirror)
    centres = [(np.arange(n) + 0.5) * dx for n in rho.shape]
    origin = [(-c.size * dx / 2 if not m else 0.0) for c, m in zip(centres, mirror)]
    x, y, z = np.meshgrid(*[c + o for c, o in zip(centres, origin)], indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    # every voxel centre clearly inside/outside the offset sphere (of the polyhedral mesh: its faces lie
    # within 0.01 mm of the sphere at this subdivision) is classified so
    far = np.abs(r - (radius + offset)) > 0.02
    assert np.array_equal(rho[far] > 0, r[far] < radius + offset)
    volume = rho.sum() * dx ** 3 * copies
    assert volume == pytest.approx(4 / 3 * np.pi * (radius + offset) ** 3, rel=0.01)
    # without the offset the solid is the mesh's own
    base, _, _ = mesh_grid(mesh, resolution=40, symmetry=symmetry)
    assert (rho.sum() > base.sum()) == (offset > 0)


def test_offset_release_is_the_offset_sphere_s():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=3.0)
    r = simulate_mesh(mesh, resolution=32, offset_mm=0.2)
    assert r.volume_mm3 == pytest.approx(4 / 3 * np.pi * 3.2 ** 3, rel=0.015)
    assert r.total_time_mm == pytest.approx(3.2 + 0.5 * r.dx_mm, abs=r.dx_mm)  # the grid reaches the grown surface


def test_offset_guard():
    with pytest.raises(DesignError, match="offset_mm"):
        mesh_grid(trimesh.creation.box((2, 2, 1)), resolution=8, offset_mm=-0.6)
