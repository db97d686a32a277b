"""Mass from exact volumes: a mesh's simulated release is its voxel fraction released times the print's exact
volume (labapp.jobs.printrelease.exact_volume_release), in calibration and in every physical prediction alike.

The synthetic runs are the forward model's own release at 64 voxels, scaled to the mesh's exact volume and a
known density, so the calibration at 40 voxels must recover that density whatever its voxels hold: a 22 x 6 x 6 mm
bar voxelises to 0.84 of its volume at 40 voxels, and a 12 x 9 x 4.5 mm box (its 4.5 mm side is 15 voxels of
0.3 mm) to 1.067.
"""
import math

import numpy as np
import pytest
import trimesh

from design.files.pipeline import mesh_grid
from design.forward.simulator import simulate
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.physical import predict_mesh
from labapp.jobs.printrelease import exact_volume_release, print_volume_mm3
from labapp.records.simcal import load_simcal
from tests.labapp.jobs.simcal_sets import write_run, write_set

DENSITY, SECONDS_PER_MM, RESOLUTION = 1.3e-3, 1200.0, 40
MESHES = {"bar": lambda: trimesh.creation.box((22, 6, 6)),
          "sphere": lambda: trimesh.creation.icosphere(4, radius=5.0),
          "slab": lambda: trimesh.creation.box((14, 14, 3))}


def _voxel_volume(mesh, offset_mm=0.0):
    rho, dx, mirror = mesh_grid(mesh, resolution=RESOLUTION, offset_mm=offset_mm)
    return float(rho.sum()) * dx ** 3 * 2 ** sum(mirror)


def test_print_volume_is_steiners_formula():
    box = trimesh.creation.box((10, 6, 4))
    for o in (-0.2, 0.0, 0.15):
        # a box's parallel body: the box, its faces pushed out, quarter cylinders on the edges, eighth spheres
        exact = (10 + 2 * o) * (6 + 2 * o) * (4 + 2 * o) if o <= 0 else \
            10 * 6 * 4 + 2 * (60 + 40 + 24) * o + math.pi * o ** 2 * (10 + 6 + 4) + 4 / 3 * math.pi * o ** 3
        assert print_volume_mm3(box, o) == pytest.approx(exact, rel=1e-9 if o >= 0 else 5e-3)
    sphere = trimesh.creation.icosphere(5, radius=5.0)
    assert print_volume_mm3(sphere, 0.2) == pytest.approx(4 / 3 * math.pi * 5.2 ** 3, rel=2e-3)


def test_odd_voxel_box_gets_its_volume_at_full_release():
    box = trimesh.creation.box((12, 9, 4.5))
    assert _voxel_volume(box) / box.volume == pytest.approx(16 / 15)   # the voxels hold 6.7 % too much
    rho, dx, mirror = mesh_grid(box, resolution=RESOLUTION)
    release = simulate(rho, dx, mirror=mirror)
    scaled = exact_volume_release(release.released_mm3, box)
    assert scaled[-1] == pytest.approx(box.volume, rel=1e-9)
    np.testing.assert_allclose(scaled / scaled[-1], release.released_mm3 / release.released_mm3[-1])
    assert exact_volume_release(release.released_mm3, None) is not None   # a density array: as simulated
    np.testing.assert_array_equal(exact_volume_release(release.released_mm3, None), release.released_mm3)


def _synthetic_set(folder):
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, make in MESHES.items():
        mesh = make()
        rho, dx, mirror = mesh_grid(mesh, resolution=64)
        release = simulate(rho, dx, mirror=mirror)
        fraction = release.released_mm3 / release.released_mm3[-1]
        mass = DENSITY * float(mesh.volume)
        t = np.arange(30.0, 1.1 * SECONDS_PER_MM * release.tau_mm[-1], 30.0)
        grams = mass * np.interp(t / SECONDS_PER_MM, release.tau_mm, fraction)
        rows.append(write_run(folder, name, mesh, t, grams, mass, fmt="%.8f"))
    return write_set(folder, rows)


@pytest.mark.slow
def test_pooled_density_and_predicted_grams_follow_the_exact_volume(tmp_path):
    bar = MESHES["bar"]()
    assert _voxel_volume(bar) / bar.volume == pytest.approx(0.84, abs=0.01)
    run = calibrate_sim(_synthetic_set(tmp_path / "set"), None, tmp_path / "cal", resolution=RESOLUTION,
                        model="constant", physics="none")
    # pooled and per shape: the weighed grams over the exact volume, whatever the voxels hold
    assert run.doc["g_per_mm3"] == pytest.approx(DENSITY, rel=5e-3)
    for shape in run.doc["shapes"]:
        assert shape["g_per_mm3"] == pytest.approx(DENSITY, rel=5e-3)
    simcal = load_simcal(run.path)
    box = trimesh.creation.box((12, 9, 4.5))
    box.export(tmp_path / "box.stl")
    t, grams = predict_mesh(tmp_path / "box.stl", simcal)
    assert grams[-1] == pytest.approx(DENSITY * box.volume, rel=5e-3)
    assert np.all(np.diff(grams) >= 0) and t[0] >= 0
