"""J_chan, the channel-width term: its gradient, its value on slots narrower and wider than the width, the
mirror faces, and its place in the design objective and configuration."""
import json
from dataclasses import replace

import numpy as np
import pytest

from design.errors import DesignError
from design.fabrication.channels import NarrowVoids, narrow_voids, segment_voxels
from design.forward.simulator import simulate, total_time
from design.forward.swelling import shut_channels
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective
from design.inverse.settings import W_CHANNEL
from design.inverse.spaces import SpaceRequest, build_space
from tests.design.gradcheck import assert_gradient_matches_fd

DX = 0.1
WIDTH = 1.0  # 10 voxels: runs of void of at most 9 voxels are narrower


def _slotted(width_vox, shape=(40, 24, 24), start=None):
    """A solid block with a through-slot of ``width_vox`` voxels across axis 0 (open to the bath on axis 1)."""
    rho = np.ones(shape)
    lo = (shape[0] - width_vox) // 2 if start is None else start
    rho[lo:lo + width_vox, :, 4:20] = 0.0
    return rho


@pytest.mark.parametrize("mirror, shape, width_mm", [
    (None, (7, 6, 5), 0.45),
    ((True, False, True), (7, 6, 5), 0.45),
    ((True, True, True), (3, 6, 5), 0.85),  # the mirror image is shorter than the padding
    ((False, True), (9, 7), 0.6),
])
def test_gradient_matches_central_differences(mirror, shape, width_mm):
    rng = np.random.default_rng(11)
    rho = rng.uniform(0.0, 1.0, shape)
    term = NarrowVoids(shape, DX, width_mm, mirror)
    value, grad = term(rho)
    assert value > 0
    h = 1e-6
    for _ in range(12):
        idx = tuple(int(rng.integers(0, n)) for n in shape)
        up, down = rho.copy(), rho.copy()
        up[idx] += h
        down[idx] -= h
        fd = (term(up)[0] - term(down)[0]) / (2 * h)
        assert abs(fd - grad[idx]) <= 1e-5 * np.abs(grad).max(), (idx, fd, grad[idx])
    # a random direction: the directional derivative to 1e-5 of itself
    step = rng.normal(size=shape)
    fd = (term(rho + h * step)[0] - term(rho - h * step)[0]) / (2 * h)
    assert fd == pytest.approx(float(np.sum(grad * step)), rel=1e-5)


def test_a_slot_narrower_than_the_width_costs_about_its_volume_and_a_wider_one_next_to_nothing():
    slot_mm3 = lambda w: w * DX * 24 * 16 * DX ** 2  # noqa: E731
    narrow, _ = narrow_voids(_slotted(4), DX, WIDTH)   # 0.4 mm
    edge, _ = narrow_voids(_slotted(9), DX, WIDTH)     # 0.9 mm: still narrower
    wide, _ = narrow_voids(_slotted(11), DX, WIDTH)    # 1.1 mm
    wider, _ = narrow_voids(_slotted(16), DX, WIDTH)   # 1.6 mm
    assert narrow == pytest.approx(slot_mm3(4), rel=0.15)
    assert edge > 0.5 * slot_mm3(9)
    # the residue at the faces of a slot the closing leaves open: under 2% of a narrow slot's cost per volume
    assert wide < 0.02 * slot_mm3(11) and wider < 0.02 * slot_mm3(16)
    # the same cut as the forward model's swelling test (runs of void shorter than the width)
    assert shut_channels(_slotted(9), DX, WIDTH).any() and not shut_channels(_slotted(11), DX, WIDTH).any()


def _face_residue_mm3_per_mm2(segment=10, sharpness=30.0):
    """The closing's residue along one face, per face area: ``C - rho`` at most ``log(L / d) / b`` at d voxels from
    the face (module docstring of `design.fabrication.channels`), squared and summed over a segment."""
    return DX * sum(np.log(segment / d) ** 2 for d in range(1, segment)) / sharpness ** 2


def test_a_solid_block_a_wide_chamber_and_a_uniform_grey_cost_only_the_face_residue():
    block = np.zeros((30, 30, 30))
    block[5:25, 5:25, 5:25] = 1.0   # 2 mm cube: 24 mm^2 of faces
    chamber = np.ones((40, 40, 40))
    chamber[5:35, 5:35, 5:] = 0.0   # 3 x 3 x 3.5 mm, open at the top, sharp concave corners: 51 mm^2 of faces
    narrow, _ = narrow_voids(_slotted(4), DX, WIDTH)
    residue = _face_residue_mm3_per_mm2()
    assert 0 < narrow_voids(block, DX, WIDTH)[0] <= 1.1 * 24.0 * residue
    assert 0 < narrow_voids(chamber, DX, WIDTH)[0] <= 1.1 * 51.0 * residue
    assert 24.0 * residue < 0.03 * narrow  # a 2 mm cube's faces cost under 3% of a 0.4 mm slot through 2.4 x 1.6 mm
    grey = np.full((20, 20, 20), 0.4)
    assert narrow_voids(grey, DX, WIDTH)[0] == 0.0
    assert narrow_voids(grey, DX, WIDTH, (True, True, True))[0] == 0.0


def test_a_slot_against_a_mirror_face_counts_by_its_full_mirrored_width():
    # 3 voxels at the mirror plane are 6 in the whole object: narrower than 10 voxels; 6 are 12: wider
    half_narrow = _slotted(3, start=0)
    half_wide = _slotted(6, start=0)
    mirror = (True, False, False)
    assert narrow_voids(half_narrow, DX, WIDTH, mirror)[0] > 0.5 * 3 * DX * 24 * 16 * DX ** 2
    assert narrow_voids(half_wide, DX, WIDTH, mirror)[0] < 0.02 * 6 * DX * 24 * 16 * DX ** 2
    # without the mirror, the 6-voxel slot on the low face opens to the bath: no channel
    assert narrow_voids(half_wide, DX, WIDTH)[0] < 0.02 * 6 * DX * 24 * 16 * DX ** 2
    # the half grid's value is exactly the unfolded grid's half, gradient included
    rng = np.random.default_rng(2)
    rho = rng.uniform(0.0, 1.0, (6, 7, 5))
    full = np.concatenate([np.flip(rho, 0), rho], axis=0)
    value, grad = narrow_voids(rho, DX, 0.45, mirror)
    value_full, grad_full = narrow_voids(full, DX, 0.45)
    assert value == pytest.approx(0.5 * value_full, rel=1e-12)
    np.testing.assert_allclose(grad, 0.5 * (grad_full[6:] + np.flip(grad_full[:6], 0)),
                               rtol=1e-10, atol=1e-14 * np.abs(grad).max())


def test_segment_and_guards():
    assert segment_voxels(1.0, 0.1) == 10 and segment_voxels(1.05, 0.1) == 11 and segment_voxels(0.05, 0.1) == 1
    # no channel is narrower than a voxel: the term is zero
    assert narrow_voids(_slotted(1), DX, 0.1)[0] == 0.0
    with pytest.raises(DesignError, match="minimum channel width"):
        NarrowVoids((4, 4, 4), DX, 0.0)
    with pytest.raises(DesignError, match="shape"):
        NarrowVoids((4, 4, 4), DX, 0.3)(np.zeros((4, 4, 5)))


def _objective(name, request, w_channel, channel_mm=0.6):
    space = build_space(name, request)
    big_t = total_time(space.grid_shape, space.dx_mm, space.mirror)
    target = simulate(np.full(space.grid_shape, 0.4), space.dx_mm, mirror=space.mirror,
                      total_time_mm=big_t).released_mm3
    return DesignObjective(space, target, big_t, radius_vox=2.0, beta=3.0, w_binary=20.0,
                           w_channel=w_channel, channel_mm=channel_mm)


@pytest.mark.parametrize("name, request_", [
    ("nfc", SpaceRequest((12, 12, 12), 0.25)),
    ("extruded", SpaceRequest((12, 10, 8), 0.25, 5)),
])
def test_objective_gradient_with_the_channel_term_matches_central_differences(name, request_):
    objective = _objective(name, request_, w_channel=50.0)
    rng = np.random.default_rng(4)
    x = rng.uniform(0.05, 0.95, objective.space.var_shape)
    ev = objective.evaluate(x)
    assert ev.terms["J_chan"] > 0
    # the term's gradient is a visible part of the total
    plain = _objective(name, request_, w_channel=0.0).evaluate(x)
    assert np.abs(ev.grad - plain.grad).max() > 1e-3 * np.abs(ev.grad).max()
    assert ev.value == pytest.approx(plain.value + 50.0 * ev.terms["J_chan"], rel=1e-12)
    assert plain.terms["J_chan"] == 0.0
    assert_gradient_matches_fd(objective, x, ev.grad, rng, entries=5)


def test_objective_and_config_guards():
    with pytest.raises(DesignError, match="w_channel must be"):
        _objective("nfc", SpaceRequest((8, 8, 8), 0.5), w_channel=-1.0)
    with pytest.raises(DesignError, match="minimum channel width > 0"):
        _objective("nfc", SpaceRequest((8, 8, 8), 0.5), w_channel=1.0, channel_mm=None)
    assert DesignConfig(target="sphere", swelling_mm=0.6).w_channel == W_CHANNEL
    assert DesignConfig(target="sphere", swelling_mm=0.6, w_channel=0.0).w_channel == 0.0
    assert DesignConfig(target="sphere").w_channel is None
    # a configuration given print physics later (`sfr design --simcal`) gets the default, an explicit 0 stays
    later = DesignConfig(target="sphere", physical_correction="none")
    assert replace(later, swelling_mm=0.6).w_channel == W_CHANNEL
    assert replace(later, w_channel=0.0, swelling_mm=0.6).w_channel == 0.0
    for bad in (-1.0, float("nan"), float("inf"), "5"):
        with pytest.raises(DesignError, match="w_channel must be a finite number >= 0"):
            DesignConfig(target="sphere", swelling_mm=0.6, w_channel=bad)
    with pytest.raises(DesignError, match="needs swelling_mm > 0"):
        DesignConfig(target="sphere", w_channel=5.0)


def test_summary_records_the_weight_and_the_voxels_the_fill_added(tmp_path_factory):
    from tests.design.files.test_print_physics_design import chamber_summaries

    # the source itself as the design: its 1 mm channel's two 3 mm arms are narrower than 1.5 mm
    outputs = chamber_summaries(tmp_path_factory)
    held, free, voxel_mm3 = outputs["held"], outputs["free"], outputs["dx_mm"] ** 3
    assert held["w_channel"] == W_CHANNEL
    assert held["channel_fill_voxels"] * voxel_mm3 == pytest.approx(2 * 3.0 * 1.0 * 1.0)
    assert held["channel_fill_voxels"] * voxel_mm3 == held["min_channel_constraint"]["filled_mm3"]
    assert free["w_channel"] == 0.0 and free["channel_fill_voxels"] is None


def test_config_json_written_before_the_term_resumes_without_it(tmp_path):
    from dataclasses import asdict

    from design.files.records import load_config, save_config, stored_form

    for swelling, expected in ((0.6, 0.0), (0.0, None)):
        config = DesignConfig(target="sphere", swelling_mm=swelling)
        save_config(tmp_path, config)
        older = {k: v for k, v in json.loads((tmp_path / "config.json").read_text()).items() if k != "w_channel"}
        (tmp_path / "config.json").write_text(json.dumps(older))
        assert load_config(tmp_path).w_channel == expected
        # a run stored now keeps its weight
        save_config(tmp_path, config)
        assert load_config(tmp_path) == config and stored_form(config)["w_channel"] == asdict(config)["w_channel"]
