"""Each mesh's simulated release corrected for the fast marching's shape-dependent bias
(labapp.jobs.printrelease.grid_bias, bias_corrected_release): with identity physics it is the reference
evaluator's exact release, so a calibration on runs whose truth is the exact release recovers its time scale, and
predicts an unseen curved shape, to within the reference's quadrature error instead of the grid's bias.

Truth: a sphere (the ball of the mesh's volume) and a box released by their closed forms
(tests/design/forward/test_reference.py), a density and a time scale, sampled every 30 s without noise, the
constant model (no bath effect: 5 kg of water). The unseen shape is a capsule lying along x (the pill's shape),
released as the capsule of its mesh's volume: the points deeper than t form a capsule of radius r - t.
"""
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from analysis.physics_grid import PHYSICS_IDENTITY
from design.files.pipeline import mesh_grid
from design.forward.simulator import simulate
from labapp.jobs import printrelease as pr
from labapp.jobs.bands import source_release_exact, source_simulator
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.physical import predict_mesh
from labapp.records import simcal as sc
from labapp.records.simcal import load_simcal
from tests.labapp.jobs.simcal_sets import write_run, write_set

DENSITY, SECONDS_PER_MM, RESOLUTION, WATER_G = 1.3e-3, 1200.0, 24, 5000.0


def _sphere():
    mesh = trimesh.creation.icosphere(4, radius=5.0)
    r = (mesh.volume / (4 / 3 * math.pi)) ** (1 / 3)
    return mesh, lambda t: mesh.volume - 4 / 3 * math.pi * np.clip(r - t, 0, None) ** 3


def _box():
    a, b, c = 12.0, 9.0, 4.5
    mesh = trimesh.creation.box((a, b, c))
    return mesh, lambda t: a * b * c - np.prod([np.clip(s - 2 * t, 0, None) for s in (a, b, c)], axis=0)


def _capsule():
    length, radius = 8.0, 2.5
    mesh = trimesh.creation.capsule(height=length, radius=radius, count=[48, 48])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))   # lying along x
    # the capsule of the mesh's volume: its cylinder's length, the radius that holds the faceted volume
    r = float(np.real(np.roots([4 / 3 * math.pi, math.pi * length, 0, -mesh.volume]).max()))
    return mesh, lambda t: mesh.volume - (math.pi * length + 4 / 3 * math.pi * np.clip(r - t, 0, None)) \
        * np.clip(r - t, 0, None) ** 2


def _set(folder):
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, make in (("sphere", _sphere), ("box", _box)):
        mesh, exact = make()
        mass = DENSITY * float(mesh.volume)
        end = 1.1 * SECONDS_PER_MM * max(mesh.extents) / 2
        t = np.arange(30.0, end, 30.0)
        grams = DENSITY * exact(t / SECONDS_PER_MM)
        rows.append(write_run(folder, name, mesh, t, grams, mass, WATER_G))
    return write_set(folder, rows)


def _calibrate(tmp_path, name):
    return calibrate_sim(_set(tmp_path / "set"), None, tmp_path / name, resolution=RESOLUTION, model="constant",
                         physics="none", max_offset_s=0.0)


def _unseen_error(tmp_path, simcal) -> float:
    """RMS error of the unseen capsule's prediction from its mesh, % of its mass."""
    mesh, exact = _capsule()
    mesh.export(tmp_path / "capsule.stl")
    t, grams = predict_mesh(tmp_path / "capsule.stl", simcal)
    truth = DENSITY * exact(t / SECONDS_PER_MM)
    return 100 * float(np.sqrt(np.mean((grams - truth) ** 2)) / (DENSITY * mesh.volume))


def test_identity_physics_release_is_the_reference_release():
    from design.forward.reference import design_lattice, reference_release

    mesh, _ = _sphere()
    tau, vol, _ = pr.mesh_release(mesh, "sphere.stl", RESOLUTION)
    depths = np.linspace(0.0, 0.5 * max(mesh.extents), pr.BIAS_SAMPLES)   # the depths the reference is made at
    ref = reference_release(mesh, depths, cells=design_lattice(RESOLUTION))
    np.testing.assert_allclose(np.interp(depths, tau, vol), ref.released_mm3, rtol=0, atol=1e-9 * mesh.volume)
    # with print physics: still monotone and ending at the print's volume, the evaluator's quadrature of the print:
    # Steiner's volume of the grown convex mesh within its stated error (measured 0.015%)
    physics = dict(PHYSICS_IDENTITY, anisotropy=1.3, offset_mm=0.1)
    tau, vol, _ = pr.mesh_release(mesh, "sphere.stl", RESOLUTION, physics)
    assert np.all(np.diff(vol) >= 0) and vol[0] == 0.0
    assert vol[-1] == pytest.approx(pr.print_volume_mm3(mesh, 0.1), rel=2e-3)


def test_bias_is_computed_once_per_mesh_resolution_and_anisotropy(monkeypatch):
    import design.forward.reference as reference

    calls = []
    real = reference.reference_release
    monkeypatch.setattr(reference, "reference_release", lambda *a, **k: calls.append(1) or real(*a, **k))
    mesh = trimesh.creation.box((7.0, 5.0, 3.0))
    grid = mesh_grid(mesh, resolution=RESOLUTION)
    first = pr.grid_bias(mesh, grid, RESOLUTION)
    for _ in range(2):
        for anisotropy in (0.8, 1.0, 1.25):   # each anisotropy its own bias, once
            pr.mesh_release(mesh, "box.stl", RESOLUTION, dict(PHYSICS_IDENTITY, anisotropy=anisotropy))
    assert pr.grid_bias(mesh, mesh_grid(mesh, resolution=RESOLUTION), RESOLUTION) is first
    assert len(calls) == 3
    pr.grid_bias(mesh, mesh_grid(mesh, resolution=RESOLUTION + 2), RESOLUTION + 2)   # another grid: its own bias
    assert len(calls) == 4


@pytest.mark.parametrize("anisotropy", [0.7, 1.5])
def test_anisotropic_release_is_corrected_at_its_own_anisotropy(anisotropy):
    """An ellipsoid with semi-axes (r, r, a r) eroding a times faster along z is a sphere of radius r in the metric
    with z scaled by 1 / a, so its released fraction is the sphere's closed form 1 - (1 - tau / r)^3 (the faceted
    mesh's r: the radius of the ball of its volume in that metric). The grid alone misses it by its first-order
    bias (measured at 24 voxels: 5.6 % of the volume at most at a = 0.7, 6.8 % at 1.5); corrected at the same
    anisotropy it is within the reference's quadrature error (bound 0.5 %; measured 0.02 % for both). Corrected by
    the isotropic bias instead it stays off (measured: 1.7 %, 1.8 %)."""

    mesh = trimesh.creation.icosphere(4, radius=4.0)
    mesh.apply_scale([1.0, 1.0, anisotropy])
    r = (mesh.volume / anisotropy / (4 / 3 * math.pi)) ** (1 / 3)
    physics = dict(PHYSICS_IDENTITY, anisotropy=anisotropy)
    tau, vol, _ = pr.mesh_release(mesh, "ellipsoid.stl", RESOLUTION, physics)
    exact = mesh.volume * (1 - np.clip(1 - tau / r, 0, None) ** 3)
    corrected = float(np.max(np.abs(vol - exact))) / mesh.volume
    grid = mesh_grid(mesh, resolution=RESOLUTION)
    plain = simulate(*grid[:2], mirror=grid[2], anisotropy=anisotropy)
    plain_vol = pr.exact_volume_release(plain.released_mm3, mesh)
    alone = float(np.max(np.abs(plain_vol - mesh.volume * (1 - np.clip(1 - plain.tau_mm / r, 0, None) ** 3))))
    iso_tau, iso_vol = pr.bias_corrected_release(plain.tau_mm, plain.released_mm3, mesh, 0.0,
                                                 pr.grid_bias(mesh, grid, RESOLUTION, 1.0))
    isotropic = float(np.max(np.abs(iso_vol - mesh.volume * (1 - np.clip(1 - iso_tau / r, 0, None) ** 3))))
    print(f"a={anisotropy}: corrected {100 * corrected:.2f}%, grid alone {100 * alone / mesh.volume:.2f}%, "
          f"isotropic bias {100 * isotropic / mesh.volume:.2f}%")
    assert corrected < 0.005
    assert alone / mesh.volume > 4 * corrected
    assert isotropic / mesh.volume > 3 * corrected


def test_calibration_recovers_time_scale_and_predicts_unseen_curved_shape(tmp_path, monkeypatch):
    run = _calibrate(tmp_path, "cal")
    assert run.doc["release_method"] == sc.RELEASE_METHOD
    simcal = load_simcal(run.path)
    assert simcal.release_method == sc.RELEASE_METHOD
    # the corrected release is the exact one to the reference's quadrature error (< 0.2 % of the volume at
    # 96 cells, docs/forward.md) and the truth is exact, so what remains is that error and the fit's tolerance:
    # the shared time scale within 0.5 %, the unseen capsule within 0.5 % of its mass (measured: 0.03 %, 0.02 %)
    assert run.doc["seconds_per_mm"] == pytest.approx(SECONDS_PER_MM, rel=5e-3)
    assert run.doc["g_per_mm3"] == pytest.approx(DENSITY, rel=1e-3)
    new_error = _unseen_error(tmp_path, simcal)
    assert new_error < 0.5

    # the grid alone (no bias): the sphere's front runs ahead of the box's, so neither the time scale nor the
    # capsule comes out right (measured: the time scale 6.8 % off, the capsule 3.2 % of its mass)
    def grid_alone(mesh, grid, resolution, physics, release=None, interpolated=False):
        plain = simulate(*grid[:2], mirror=grid[2], anisotropy=physics["anisotropy"])
        return plain.tau_mm, pr.exact_volume_release(plain.released_mm3, mesh, physics["offset_mm"])

    monkeypatch.setattr(pr, "print_release", grid_alone)
    old = _calibrate(tmp_path, "grid")
    assert abs(old.doc["seconds_per_mm"] / SECONDS_PER_MM - 1) > 5 * abs(run.doc["seconds_per_mm"] / SECONDS_PER_MM - 1)
    assert abs(old.doc["seconds_per_mm"] / SECONDS_PER_MM - 1) > 0.015
    assert _unseen_error(tmp_path, load_simcal(old.path)) > 3 * new_error


def test_older_file_reads_as_grid_method_and_predicts_with_it(tmp_path):
    run = _calibrate(tmp_path, "cal")
    doc = json.loads(run.path.read_text())
    del doc["release_method"]
    older = tmp_path / "older.json"
    older.write_text(json.dumps(doc))
    simcal = load_simcal(older)
    assert simcal.release_method == sc.OLD_RELEASE_METHOD
    mesh, _ = _sphere()
    mesh.export(tmp_path / "ball.stl")
    tau, vol = source_simulator(str(tmp_path / "ball.stl"), RESOLUTION, method=simcal.release_method)(simcal.physics)
    grid = mesh_grid(mesh, resolution=RESOLUTION)

    plain = simulate(*grid[:2], mirror=grid[2])
    np.testing.assert_allclose(vol, pr.exact_volume_release(plain.released_mm3, mesh))
    np.testing.assert_array_equal(tau, plain.tau_mm)
    doc["release_method"] = "magic"
    older.write_text(json.dumps(doc))
    with pytest.raises(sc.SimCalError, match="release_method 'magic'"):
        load_simcal(older)


def test_density_array_keeps_its_release(tmp_path):
    rho = np.zeros((10, 10, 10))
    rho[2:8, 2:8, 3:7] = 1.0
    np.save(tmp_path / "block.npy", rho)
    tau, released = np.linspace(0, 3, 7), np.linspace(0, 144, 7)
    release = SimpleNamespace(tau_mm=tau, released_mm3=released)
    out_tau, out = source_release_exact(str(tmp_path / "block.npy"), release, dict(PHYSICS_IDENTITY),
                                        resolution=RESOLUTION)
    np.testing.assert_array_equal(out_tau, tau)
    np.testing.assert_array_equal(out, released)


@pytest.mark.parametrize("offset", [0.3, -0.4])
def test_offset_print_is_the_grown_or_shrunk_solid(offset):
    """A sphere of radius r printed ``offset`` larger releases like the sphere of radius r + offset: every inner
    point is ``offset`` deeper and the added shell goes first (shrunk: the points deeper than -offset, each that much
    shallower). Corrected release against the closed form, within the reference's quadrature error and the faceted
    mesh's Steiner volume (bound 0.5 % of the volume; measured: 0.01 % for both). The grid alone at 24 voxels places
    a surface moved by under a voxel only to within its voxels (measured: 4.3 %, 4.9 %)."""
    mesh, _ = _sphere()
    r = (mesh.volume / (4 / 3 * math.pi)) ** (1 / 3) + offset
    physics = dict(PHYSICS_IDENTITY, offset_mm=offset)
    tau, vol, _ = pr.mesh_release(mesh, "sphere.stl", RESOLUTION, physics)
    total = pr.print_volume_mm3(mesh, offset)
    exact = total * (1 - np.clip(1 - tau / r, 0, None) ** 3)
    grid_tau, grid_vol, _ = pr.mesh_release(mesh, "sphere.stl", RESOLUTION, physics, method=sc.OLD_RELEASE_METHOD)
    grid_exact = total * (1 - np.clip(1 - grid_tau / r, 0, None) ** 3)
    corrected = float(np.max(np.abs(vol - exact))) / total
    alone = float(np.max(np.abs(grid_vol - grid_exact))) / total
    print(f"offset {offset}: corrected {100 * corrected:.2f}%, grid alone {100 * alone:.2f}%")
    assert corrected < 0.005 and alone > 4 * corrected


def test_offset_in_the_anisotropic_metric():
    """A face across the build direction moves offset / a in the metric of anisotropy a, a face along it the offset
    itself; a thin slab's mean is near the first, a tall column's near the second."""
    slab, column = trimesh.creation.box((40.0, 40.0, 1.0)), trimesh.creation.box((1.0, 1.0, 40.0))
    assert pr.metric_offset_mm(slab, 1.0, 0.1) == 0.1
    assert pr.metric_offset_mm(slab, 1.6, 0.1) == pytest.approx(0.1 / 1.6, rel=0.06)
    assert pr.metric_offset_mm(column, 1.6, 0.1) == pytest.approx(0.1, rel=0.03)
    assert pr.metric_offset_mm(slab, 0.6, -0.1) == pytest.approx(-0.1 / 0.6, rel=0.06)
