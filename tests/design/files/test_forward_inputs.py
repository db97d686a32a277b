"""Sample shapes, mesh and density loading, and the one-call mesh simulation."""
from pathlib import Path

import numpy as np
import pytest
import trimesh

from design import SAMPLE_SHAPES, DesignError, load_density, load_mesh, sample_shape, simulate_mesh
from design.files.pipeline import input_grid, parse_symmetry
from design.geometry.shapes import VOLUME_MM3

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures" / "shapes"


@pytest.mark.parametrize("name", SAMPLE_SHAPES)
def test_sample_shapes_are_closed_and_weigh_one_print(name):
    mesh = sample_shape(name)
    assert mesh.is_watertight and mesh.volume == pytest.approx(VOLUME_MM3, rel=1e-9)
    assert np.allclose(mesh.bounds.mean(axis=0), 0.0, atol=1e-9)


def test_unknown_sample_shape():
    with pytest.raises(DesignError, match="unknown sample shape 'cone'"):
        sample_shape("cone")


def test_load_mesh_round_trip_and_errors(tmp_path):
    path = tmp_path / "pill.stl"
    sample_shape("pill").export(path)
    assert load_mesh(path).volume == pytest.approx(VOLUME_MM3, rel=1e-6)
    open_box = trimesh.creation.box()
    open_box.update_faces(np.arange(12) != 3)
    open_box.export(tmp_path / "open.stl")
    with pytest.raises(DesignError, match="open.stl: is not watertight"):
        load_mesh(tmp_path / "open.stl")
    with pytest.raises(DesignError, match="missing.obj: no such file"):
        load_mesh(tmp_path / "missing.obj")
    (tmp_path / "junk.ply").write_text("not a mesh")
    with pytest.raises(DesignError, match="junk.ply"):
        load_mesh(tmp_path / "junk.ply")
    with pytest.raises(DesignError, match="unsupported mesh format"):
        load_mesh(tmp_path / "x.step")


def test_load_density_formats_and_errors(tmp_path):
    rho = np.random.default_rng(0).random((4, 5, 6))
    np.savez(tmp_path / "d.npz", rho=rho, dx_mm=0.2)
    got, dx = load_density(tmp_path / "d.npz")
    np.testing.assert_array_equal(got, rho)
    assert dx == 0.2
    np.save(tmp_path / "d.npy", rho)
    with pytest.raises(DesignError, match="d.npy: a .npy array has no voxel size"):
        load_density(tmp_path / "d.npy")
    assert load_density(tmp_path / "d.npy", 0.3)[1] == 0.3
    cases = {"neg.npz": dict(rho=rho, dx_mm=0.0), "nan.npz": dict(rho=rho * np.nan, dx_mm=0.1),
             "big.npz": dict(rho=rho + 1, dx_mm=0.1), "empty.npz": dict(rho=np.zeros((0, 2)), dx_mm=0.1),
             "nokey.npz": dict(density=rho)}
    messages = {"neg.npz": "neg.npz must be finite and > 0", "nan.npz": "nan.npz has .* non-finite",
                "big.npz": r"big.npz must lie in \[0, 1\]", "empty.npz": "empty.npz is empty",
                "nokey.npz": r"nokey.npz: missing array\(s\)"}
    for name, arrays in cases.items():
        np.savez(tmp_path / name, **arrays)
        with pytest.raises(DesignError, match=messages[name]):
            load_density(tmp_path / name)
    with pytest.raises(DesignError, match="contradicts"):
        load_density(tmp_path / "d.npz", 0.5)


def test_simulate_mesh_symmetry_gives_the_full_object():
    mesh = sample_shape("sphere")
    full = simulate_mesh(mesh, resolution=32)
    octant = simulate_mesh(mesh, resolution=32, symmetry="xyz")
    assert octant.u_mm.size * 8 == full.u_mm.size
    # same voxel centres, mirror planes through the centre: same curve to round-off
    np.testing.assert_allclose(octant.released_mm3, full.released_mm3, rtol=1e-12, atol=1e-9)
    # the voxelised sphere is within 2 % of the mesh volume at 32 voxels across (observed 0.5 %)
    assert full.volume_mm3 == pytest.approx(VOLUME_MM3, rel=0.02)


def test_input_grid_and_symmetry_letters(tmp_path):
    assert parse_symmetry("zx") == (True, False, True)
    with pytest.raises(DesignError, match="unknown axes"):
        parse_symmetry("w")
    with pytest.raises(DesignError, match="either resolution or voxel_size_mm"):
        simulate_mesh(sample_shape("sphere"), resolution=8, voxel_size_mm=1.0)
    np.savez(tmp_path / "a.npz", rho=np.ones((3, 4)), dx_mm=0.5)
    rho, dx, mirror = input_grid(str(tmp_path / "a.npz"), symmetry="y")
    assert rho.shape == (3, 4) and dx == 0.5 and mirror == (False, True)
    rho, dx, _ = input_grid("sample:csg", voxel_size_mm=1.0)
    assert dx == 1.0 and rho.ndim == 3


@pytest.mark.parametrize("name", SAMPLE_SHAPES)
def test_shipped_fixture_is_the_sample_shape(name):
    # fixtures/shapes/*.stl come from fixtures/make_shape_fixtures.py; STL stores float32 vertices
    shipped = load_mesh(FIXTURES / f"{name}.stl")
    built = sample_shape(name)
    assert len(shipped.faces) == len(built.faces)
    assert shipped.volume == pytest.approx(built.volume, rel=1e-6)
