"""The simulated bench's own physics against closed-form releases.

Tolerance: 0.6% of the volume at 96 voxels along the padded grid (the world's second-order travel times
and per-voxel fractions resolve the release to about half a voxel of depth over the surface: 0.2-0.4%
at its default 128 on these shapes)."""
import numpy as np
import pytest
import trimesh

from labapp.acquisition.printworld import PrintPhysics, world_release

TOLERANCE = 0.006
RESOLUTION = 96


def _max_error(release, analytic) -> float:
    exact = analytic(release.tau_mm)
    return float(np.max(np.abs(release.released_mm3 - exact)) / exact[-1])


@pytest.mark.parametrize("anisotropy", [1.0, 0.6, 1.6])
def test_anisotropic_erosion_of_a_box_off_the_grid(anisotropy):
    box = trimesh.creation.box(extents=(10.0, 8.0, 6.0))
    box.apply_translation((0.123, 0.071, 0.033))
    release = world_release(box, PrintPhysics(anisotropy=anisotropy), resolution=RESOLUTION)

    def analytic(tau):  # the z faces recede anisotropy times faster than the others
        return 480.0 - (np.clip(10 - 2 * tau, 0, None) * np.clip(8 - 2 * tau, 0, None)
                        * np.clip(6 - 2 * anisotropy * tau, 0, None))
    assert _max_error(release, analytic) < TOLERANCE
    assert release.released_mm3[0] == 0.0


@pytest.mark.parametrize("offset_mm", [0.15, -0.05])
def test_a_print_larger_or_smaller_than_its_mesh(offset_mm):
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=6.0)
    release = world_release(sphere, PrintPhysics(offset_mm=offset_mm), resolution=RESOLUTION)
    radius = 6.0 + offset_mm
    assert release.volume_mm3 == pytest.approx(4 / 3 * np.pi * radius ** 3, rel=TOLERANCE)
    assert _max_error(release, lambda tau: 4 / 3 * np.pi * (radius ** 3 - np.clip(radius - tau, 0, None) ** 3)) \
        < TOLERANCE


def test_a_channel_narrower_than_the_swelling_stays_shut_until_its_walls_dissolve():
    slab = trimesh.creation.box(extents=(12.0, 12.0, 4.0))
    slot = trimesh.creation.box(extents=(0.4, 8.0, 6.0))  # a 0.4 mm slot through the slab
    mesh = trimesh.boolean.difference([slab, slot], engine="manifold")
    # the default resolution: the plug is the closing of a 4-voxel slot, a voxel-level operation
    open_slot = world_release(mesh, PrintPhysics())
    shut_slot = world_release(mesh, PrintPhysics(swelling_mm=0.6))

    def plugged(tau):  # the slab eroding as if the slot were filled, less the plug's share (no drug)
        depth = np.clip(tau, 0, 2)
        return 576.0 - (12 - 2 * depth) ** 2 * (4 - 2 * depth) - 0.4 * 8 * 2 * depth
    assert _max_error(shut_slot, plugged) < TOLERANCE
    k = np.searchsorted(open_slot.tau_mm, 0.5)
    assert open_slot.released_mm3[k] > 1.1 * np.interp(open_slot.tau_mm[k], shut_slot.tau_mm, shut_slot.released_mm3)


def test_hidden_draws_are_seeded_and_effects_switch_off():
    a, b = PrintPhysics.draw(7), PrintPhysics.draw(7)
    assert a == b and a != PrintPhysics.draw(8)
    assert 0.6 <= a.anisotropy <= 1.6 and -0.05 <= a.offset_mm <= 0.15 and 0.3 <= a.swelling_mm <= 0.8
    assert a.without("anisotropy", "offset_mm", "swelling_mm", "wetting_lag_s") == PrintPhysics()
    assert a.without("offset_mm").anisotropy == a.anisotropy
