"""Meshes that are not one clean body: overlapping bodies united, inverted or self-crossing ones refused,
mirror planes the shape lacks refused."""
import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.files.meshio import checked_mesh, load_mesh
from design.files.pipeline import mesh_grid
from design.geometry.voxelize import voxelize


def _overlapping_boxes() -> trimesh.Trimesh:
    a = trimesh.creation.box(extents=(10, 10, 10))
    b = trimesh.creation.box(extents=(10, 10, 10))
    b.apply_translation((5, 5, 5))
    return trimesh.util.concatenate([a, b])


def test_overlapping_bodies_in_one_file_are_united(tmp_path):
    path = tmp_path / "two bodies.stl"
    _overlapping_boxes().export(path)
    mesh = load_mesh(path)
    # two 1000 mm^3 cubes sharing a 5 mm cube: the union holds 1875 mm^3 (exact booleans: to round-off)
    assert mesh.volume == pytest.approx(1875.0, rel=1e-9)
    assert len(mesh.split(only_watertight=False)) == 1


def test_bodies_that_share_an_edge_are_united_and_the_note_is_in_mm(tmp_path, caplog):
    # an L of two boxes drawn in inches whose corner edges coincide: once the file's vertices are merged that edge
    # bounds four faces, which is closed bodies touching, not an open surface
    a = trimesh.creation.box(extents=(2.0, 0.25, 1.0))
    b = trimesh.creation.box(extents=(0.25, 1.5, 1.0))
    b.apply_translation((-0.875, 0.625, 0.0))
    path = tmp_path / "bracket.stl"
    trimesh.util.concatenate([a, b]).export(path)
    with caplog.at_level("WARNING"):
        mesh = load_mesh(path, 25.4)
    # 0.5 + 0.375 in^3 sharing 0.0625 in^3 (exact booleans on the STL's float32 coordinates in mm: to 1e-7)
    assert mesh.volume == pytest.approx(0.8125 * 25.4 ** 3, rel=1e-7)
    assert mesh.is_watertight and len(mesh.split(only_watertight=False)) == 1
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: 2 overlapping bodies united into one solid of 1.331e+04 mm^3 (they shared 1024 mm^3)"]


def test_an_open_surface_is_refused_with_its_open_edges(tmp_path):
    box = trimesh.creation.box(extents=(10, 10, 10))
    box.update_faces(np.arange(12) != 3)  # one triangle gone: its three edges bound one face each
    with pytest.raises(DesignError, match=r"open\.stl: is not watertight \(it has 3 open edges\)"):
        checked_mesh(box, "open.stl")


def test_overlap_is_inside_on_the_voxel_grid():
    """Winding numbers, not ray parity: the shared cube counts once, not as outside."""
    two = _overlapping_boxes()
    dx = 0.5  # the boxes' faces lie on voxel faces: the voxel count is exact
    inside = voxelize(two, dx)
    assert inside.sum() * dx ** 3 == pytest.approx(1875.0)


def test_hollow_shell_keeps_its_cavity():
    outer = trimesh.creation.icosphere(subdivisions=3, radius=5)
    inner = trimesh.creation.icosphere(subdivisions=3, radius=3)
    inner.invert()
    hollow = trimesh.util.concatenate([outer, inner])
    solid = checked_mesh(hollow, "hollow.stl")
    assert solid is hollow  # nothing overlaps: the mesh is used as it is
    rho, dx, _ = mesh_grid(hollow, resolution=64)
    # the cavity is empty on the grid too: within the voxelisation's error of the exact shell volume
    assert rho.sum() * dx ** 3 == pytest.approx(hollow.volume, rel=0.02)


def test_inside_out_mesh_is_refused_with_the_reason():
    sphere = trimesh.creation.icosphere()
    sphere.invert()
    with pytest.raises(DesignError, match=r"inv\.stl: is inside out .*flip its faces"):
        checked_mesh(sphere, "inv.stl")


def test_inverted_body_outside_any_solid_is_refused():
    solid = trimesh.creation.icosphere(radius=5)
    stray = trimesh.creation.icosphere(radius=2)
    stray.invert()
    stray.apply_translation((20, 0, 0))
    with pytest.raises(DesignError, match="faces inward with no solid around it"):
        checked_mesh(trimesh.util.concatenate([solid, stray]), "stray.stl")


@pytest.mark.parametrize("corner", [(-7, 4, 4), (5, 5, -9)])
def test_self_intersecting_surface_is_refused(corner):
    box = trimesh.creation.box(extents=(10, 10, 10))
    vertices = box.vertices.copy()
    vertices[np.argmax(vertices.sum(axis=1))] = corner  # pulled through the opposite faces
    crossed = trimesh.Trimesh(vertices, box.faces, process=False)
    assert crossed.is_watertight and crossed.volume > 0  # what trimesh alone would accept
    with pytest.raises(DesignError, match="passes through itself"):
        checked_mesh(crossed, "crossed.stl")


def test_symmetry_the_shape_lacks_is_refused_with_how_far_off():
    cone = trimesh.creation.cone(radius=5, height=10, sections=64)
    for axes in ("x", "xy"):
        mesh_grid(cone, resolution=32, symmetry=axes)  # a cone is symmetric about x and y
    with pytest.raises(DesignError, match=r"plane z = 5 mm \((7[0-9]\.[0-9])% of the volume"):
        mesh_grid(cone, resolution=32, symmetry="xz")
