"""Channels shut by swelling in the forward model: a slot narrower than the swelling width against the slab's
analytic release less the plug's share, the exact identity with the filled slab, and the gradient."""
import numpy as np
import pytest
import trimesh

from design.files.pipeline import mesh_grid
from design.forward.release import ramp_release
from design.forward.simulator import release_gradient, simulate
from design.forward.swelling import shut_channels

RESOLUTION = 60  # 0.2 mm voxels over the 12 mm slab: the 0.4 mm slot is two voxels wide
SLOT_MM = 0.4


def _slab(slot=True):
    slab = trimesh.creation.box(extents=(12.0, 12.0, 4.0))
    if not slot:
        return slab
    cut = trimesh.creation.box(extents=(SLOT_MM, 8.0, 6.0))  # through the slab's thickness
    return trimesh.boolean.difference([slab, cut], engine="manifold")


def _plugged(tau):
    """The slab eroding as if the slot were filled, less the plug's share (it holds no drug), mm^3."""
    depth = np.clip(tau, 0, 2)
    return 576.0 - (12 - 2 * depth) ** 2 * (4 - 2 * depth) - SLOT_MM * 8 * 2 * depth


def test_a_slot_narrower_than_the_swelling_width_releases_as_the_plugged_slab():
    rho, dx, mirror = mesh_grid(_slab(), resolution=RESOLUTION)
    full, _, _ = mesh_grid(_slab(slot=False), resolution=RESOLUTION)
    assert rho.shape == full.shape and dx == pytest.approx(0.2)
    shut = simulate(rho, dx, swelling_mm=0.8, total_time_mm=2.2)
    filled = simulate(full, dx, total_time_mm=2.2)
    # the plug is the slot, voxel for voxel, and the front crosses it as it crosses solid
    assert np.array_equal(shut.plug, (full > 0.5) & (rho < 0.5))
    assert np.array_equal(shut.u_mm, filled.u_mm)
    # the curve is the filled slab's less the plug voxels' own ramps (eq. 7 with their weight)
    plug_share = ramp_release(filled.u_mm[shut.plug], np.full(int(shut.plug.sum()), dx),
                              np.full(int(shut.plug.sum()), dx ** 3), shut.dtau_mm, shut.tau_mm.size)
    np.testing.assert_allclose(shut.released_mm3, filled.released_mm3 - plug_share, rtol=0, atol=1e-9)
    # and against the closed form, within the first-order model's error on a grid-aligned box (1%)
    error = np.max(np.abs(shut.released_mm3 - _plugged(shut.tau_mm))) / _plugged(2.2)
    assert error < 0.01, error


def test_a_slot_wider_than_the_swelling_width_stays_open():
    rho, dx, _ = mesh_grid(_slab(), resolution=RESOLUTION)
    open_slot = simulate(rho, dx, swelling_mm=0.3, total_time_mm=2.2)
    shut = simulate(rho, dx, swelling_mm=0.8, total_time_mm=2.2)
    assert open_slot.plug is None
    np.testing.assert_array_equal(open_slot.released_mm3, simulate(rho, dx, total_time_mm=2.2).released_mm3)
    k = np.searchsorted(shut.tau_mm, 0.5)
    assert open_slot.released_mm3[k] > 1.1 * shut.released_mm3[k]  # the slot's walls dissolve from the start


def test_a_channel_continues_into_its_mirror_image_and_faces_are_left_alone():
    rho = np.zeros((16, 10, 10))
    rho[:, 1:9, 1:9] = 1.0
    rho[0, 2:8, :] = 0.0  # half of a 0.4 mm slot, 1.2 mm wide, on the mirror plane x = 0
    half = shut_channels(rho, 0.2, 0.8, (True, False, False))
    assert half[0, 2:8, 1:9].all() and half.sum() == 6 * 8
    # without the mirror it is a shallow groove 1.2 mm wide, open, concave corners and all
    assert not shut_channels(rho, 0.2, 0.8).any()
    box = np.zeros((12, 12, 12))
    box[3:9, 3:9, 3:9] = 1.0
    assert not shut_channels(box, 0.2, 2.0).any()
    ball = (np.linalg.norm(np.indices((20, 20, 20)) - 9.5, axis=0) < 8).astype(float)  # a voxel staircase
    assert not shut_channels(ball, 0.2, 2.0).any()
    chamber = np.ones((20, 20, 20))
    chamber[5:15, 5:15, 5:15] = 0.0  # concave corners, 2 mm wide: nothing narrower than 1.5 mm
    assert not shut_channels(chamber, 0.2, 1.5).any()


def test_the_gradient_holds_the_plug_fixed_and_matches_central_differences():
    rng = np.random.default_rng(3)
    rho = np.clip(rng.uniform(0.6, 1.0, (10, 9, 8)), 0, 1)
    rho[4:6, 1:, 1:7] = rng.uniform(0.0, 0.2, (2, 8, 6))  # a slot two voxels wide, grey
    tau_end = 3.0
    base = simulate(rho, 0.25, swelling_mm=0.8, total_time_mm=tau_end, anisotropy=1.3)
    assert base.plug is not None and base.plug.sum() > 20
    weights = rng.uniform(0.0, 1.0, base.tau_mm.size)
    grad = release_gradient(base, weights)
    h = 1e-6
    for idx in [(4, 5, 3), (5, 2, 2), (2, 3, 4), (7, 6, 1)]:
        plus, minus = rho.copy(), rho.copy()
        plus[idx] += h
        minus[idx] -= h
        fd = (weights @ simulate(plus, 0.25, swelling_mm=0.8, total_time_mm=tau_end, anisotropy=1.3).released_mm3
              - weights @ simulate(minus, 0.25, swelling_mm=0.8, total_time_mm=tau_end, anisotropy=1.3).released_mm3) / (2 * h)
        assert grad[idx] == pytest.approx(fd, rel=1e-5, abs=1e-6 * np.abs(grad).max())
