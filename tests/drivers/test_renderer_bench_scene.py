"""The synthetic bench renderer: symmetry, Beer-Lambert attenuation, encoding, validation."""
import dataclasses

import cv2
import numpy as np
import pytest

from drivers.sim.bench_scene import BenchScene, SceneError, render_frame, render_jpeg, render_linear, srgb_encode

QUIET = BenchScene(width=300, height=200, panel_asymmetry=0.0, panel_texture=0.0, shot_noise=0.0, read_noise=0.0,
                   intrusion_probability=0.0)


def test_mirror_pixel_sees_the_same_panel_light():
    image, _ = render_linear(QUIET, 0.0, 0.0, np.random.default_rng(0))
    x, y, size = QUIET.default_crop()
    rows, cols = slice(y, y + size), slice(x, x + size)
    mirror = image[:, ::-1][rows, cols]
    # Clear water, symmetric panel: crop / mirror is exactly the glass transmittance (blue 2 % less).
    ratio = image[rows, cols] / mirror
    assert np.allclose(ratio, QUIET.glass_transmittance * np.array([1.0, 1.0, 0.98]), rtol=1e-5)


def test_beer_lambert_per_channel_at_the_beaker_axis():
    rng = np.random.default_rng(0)
    clear, _ = render_linear(QUIET, 0.0, 0.0, rng)
    dark, _ = render_linear(QUIET, 2.0, 0.0, rng)
    x, y, size = QUIET.default_crop()
    row, col = y + size // 2, round(QUIET.beaker_x_w * QUIET.width)
    ratio = dark[row, col] / clear[row, col]
    # On the axis the chord is the full diameter: T = exp(-k * c) exactly (no noise in QUIET).
    assert np.allclose(ratio, np.exp(-2.0 * np.array(QUIET.absorption_per_g_per_kg)), rtol=1e-5)


def test_drift_scales_all_light_and_intrusions_appear():
    rng = np.random.default_rng(1)
    a, _ = render_linear(QUIET, 1.0, 0.0, rng)
    b, _ = render_linear(QUIET, 1.0, QUIET.drift_period_s / 4, rng)
    assert np.allclose(b[50, 250] / a[50, 250], QUIET.drift(QUIET.drift_period_s / 4) / QUIET.drift(0.0), rtol=1e-5)
    busy = dataclasses.replace(QUIET, intrusion_probability=1.0)
    _, intrusions = render_linear(busy, 1.0, 0.0, rng)
    assert intrusions and all(i.kind in ("object", "bubble") for i in intrusions)


def test_encoded_outputs_have_the_scene_size_and_are_reproducible():
    scene = BenchScene(width=240, height=160)
    frame = render_frame(scene, 1.0, 0.0, np.random.default_rng(3))
    assert frame.shape == (160, 240, 3) and frame.dtype == np.uint8
    jpeg = render_jpeg(scene, 1.0, 0.0, np.random.default_rng(3))
    assert jpeg == render_jpeg(scene, 1.0, 0.0, np.random.default_rng(3))
    assert cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR).shape == (160, 240, 3)
    assert srgb_encode(np.array([0.0, 0.0031308, 0.18, 1.0])).tolist() == [0, 10, 118, 255]


def test_default_crop_lies_in_the_water_and_scales_with_size():
    for scene in (BenchScene(), BenchScene(width=6016, height=4016), BenchScene(width=800, height=536)):
        x, y, size = scene.default_crop()
        radius = scene.beaker_radius_w * scene.width
        assert x > scene.beaker_x_w * scene.width - radius and x + size < scene.beaker_x_w * scene.width + radius
        assert y > scene.water_h * scene.height and y + size < scene.beaker_bottom_h * scene.height
        assert scene.width - x - size > scene.width / 2  # the mirror lies in the right half


@pytest.mark.parametrize("kwargs, match", [
    ({"beaker_x_w": 0.4}, "right half"),
    ({"water_h": 0.95}, "water_h"),
    ({"absorption_per_g_per_kg": (0.1, -1.0, 0.1)}, "absorption"),
    ({"width": 4}, "size"),
])
def test_bad_scenes_are_refused(kwargs, match):
    with pytest.raises(SceneError, match=match):
        BenchScene(**kwargs)


def test_bad_concentration_and_quality_are_refused():
    rng = np.random.default_rng(0)
    with pytest.raises(SceneError, match="conc_g_per_kg"):
        render_linear(QUIET, -1.0, 0.0, rng)
    with pytest.raises(SceneError, match="quality"):
        render_jpeg(QUIET, 1.0, 0.0, rng, quality=0)
