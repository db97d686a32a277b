"""Decoding, crop/grid/mirror geometry and cell transmittances on hand-made images."""
import cv2
import numpy as np
import pytest

from analysis import AnalysisError, CropGeometry, cell_transmittance, decode_image, default_geometry, read_cells
from analysis.decode import srgb_to_linear_lut


def _image(h=40, w=80, left=0.25, right=0.5):
    """Left half ``left``, right half ``right`` (linear), all channels."""
    image = np.full((h, w, 3), right, np.float32)
    image[:, : w // 2] = left
    return image


def test_crop_divided_by_its_mirror_cell_by_cell():
    image = _image()
    image[10:15, 10:15] *= np.array([0.5, 0.25, 1.0], np.float32)     # one cell darker per channel
    cells = cell_transmittance(image, CropGeometry(5, 5, 25, grid=5))
    expected = np.full((5, 5), 0.5)
    expected[1, 1] = 0.5 * (0.5 * 0.25 * 1.0) ** (1 / 3)                # geometric mean over channels
    assert np.allclose(cells, expected, rtol=1e-6)


def test_mirror_column_and_switch_off():
    image = _image()
    image[:, 60:70] = 1.0                   # mirror of columns 10..19 across the centre (39.5)
    assert np.allclose(cell_transmittance(image, CropGeometry(10, 0, 10, grid=2)), 0.25)
    assert np.allclose(cell_transmittance(image, CropGeometry(10, 0, 10, grid=2, mirror_col=44.5)), 0.5)
    assert np.allclose(cell_transmittance(image, CropGeometry(10, 0, 10, grid=2, mirror_normalise=False)), 0.25)


@pytest.mark.parametrize("geometry, match", [
    (CropGeometry(70, 0, 20, grid=2), "reaches past the image"),
    (CropGeometry(30, 0, 20, grid=2), "overlaps its own mirror"),
    (CropGeometry(10, 0, 10, grid=2, mirror_col=70.0), "outside the image width"),
    (CropGeometry(0, 30, 20, grid=2), "reaches past the image"),
])
def test_geometry_that_does_not_fit_is_an_error(geometry, match):
    with pytest.raises(AnalysisError, match=match):
        cell_transmittance(_image(), geometry)


@pytest.mark.parametrize("kwargs, match", [
    ({"x": -1, "y": 0, "size": 20}, "negative"),
    ({"x": 0, "y": 0, "size": 5}, "smaller than grid"),
    ({"x": 0, "y": 0, "size": 20, "grid": 0}, "grid"),
])
def test_bad_geometry_is_refused(kwargs, match):
    with pytest.raises(AnalysisError, match=match):
        CropGeometry(**kwargs)


def test_srgb_lut_matches_the_standard_curve():
    lut = srgb_to_linear_lut(8)
    assert lut[0] == 0.0 and lut[255] == pytest.approx(1.0)
    assert lut[10] == pytest.approx(10 / 255 / 12.92)
    assert lut[128] == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4)


def _png(rgb):
    return cv2.imencode(".png", rgb[..., ::-1])[1].tobytes()


def test_decode_linearises_and_reads_cells_from_files(tmp_path):
    codes = np.zeros((40, 80, 3), np.uint8)
    codes[:, :40], codes[:, 40:] = 128, 255
    path = tmp_path / "a.png"
    path.write_bytes(_png(codes))
    linear = decode_image(path)
    assert linear.dtype == np.float32 and linear.shape == (40, 80, 3)
    assert linear[0, 0, 0] == pytest.approx(srgb_to_linear_lut(8)[128])
    cells = read_cells(path, CropGeometry(0, 0, 20, grid=4), expect_shape=(40, 80))
    assert np.allclose(cells, srgb_to_linear_lut(8)[128])
    assert np.allclose(read_cells(path, CropGeometry(0, 0, 20, grid=4), reduce=2), cells, rtol=1e-6)


def test_reduced_jpeg_decoding_keeps_cell_means():
    rng = np.random.default_rng(0)
    codes = np.clip(120 + 2 * rng.standard_normal((400, 800, 3)), 0, 255).astype(np.uint8)
    jpeg = cv2.imencode(".jpg", codes, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
    geometry = CropGeometry(80, 100, 200)
    full = read_cells(jpeg, geometry)
    for reduce in (2, 4, 8):
        assert decode_image(jpeg, reduce=reduce).shape == (400 // reduce, 800 // reduce, 3)
        # A downscaled decode rounds each block mean to a whole code: up to half a code (1 % of linear
        # light at code 120, on crop and mirror alike) per cell, unbiased over the 100 cells (< 0.1 %).
        reduced = read_cells(jpeg, geometry, reduce=reduce)
        assert np.allclose(reduced, full, rtol=0.015)
        assert reduced.mean() == pytest.approx(full.mean(), rel=1e-3)


def test_corrupt_truncated_empty_and_wrong_size_images(tmp_path):
    jpeg = cv2.imencode(".jpg", np.full((40, 80, 3), 100, np.uint8))[1].tobytes()
    (tmp_path / "cut.jpg").write_bytes(jpeg[: len(jpeg) // 2])
    (tmp_path / "junk.jpg").write_bytes(b"not an image at all" * 10)
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(AnalysisError, match="truncated"):
        decode_image(tmp_path / "cut.jpg")
    with pytest.raises(AnalysisError, match="cannot decode"):
        decode_image(tmp_path / "junk.jpg")
    with pytest.raises(AnalysisError, match="empty"):
        decode_image(tmp_path / "empty.png")
    with pytest.raises(AnalysisError, match="cannot read"):
        decode_image(tmp_path / "missing.jpg")
    with pytest.raises(AnalysisError, match="expected 100x40 px"):
        read_cells(jpeg, CropGeometry(0, 0, 20, grid=2), expect_shape=(40, 100))
    with pytest.raises(AnalysisError, match="reduce"):
        decode_image(jpeg, reduce=3)
    (tmp_path / "fake.nef").write_bytes(b"not raw" * 100)
    with pytest.raises(AnalysisError, match="cannot decode camera raw"):
        decode_image(tmp_path / "fake.nef")
    with pytest.raises(AnalysisError, match="neither JPEG/PNG/TIFF nor camera raw"):
        decode_image(b"not an image" * 10)


def test_default_geometry_sits_left_of_centre():
    geometry = default_geometry((536, 800))
    assert geometry.size % 40 == 0 and geometry.x + geometry.size < 400
    assert cell_transmittance(np.ones((536, 800, 3), np.float32), geometry).shape == (10, 10)
