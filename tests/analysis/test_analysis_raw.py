"""The camera-raw path (rawpy decode, exifread capture time) on a synthesised DNG with known truth.

tests/analysis/raw_fixture.py writes the DNG: left half = RATIO (0.4) x right half in every CFA channel,
black 512 DN, white 16383 DN, a colour matrix that makes LibRaw's camera-to-sRGB matrix the identity,
and a far-from-neutral AsShotNeutral that a correct (unit white balance) decode must ignore.

Tolerances. The decode is 16-bit: the smallest developed value here, the left-half blue at 0.0504, is
3303 codes, so rounding to a whole code moves one value by <= 0.5 / 3303 = 1.5e-4 and a ratio of two by
<= 3e-4; the colour matrix stored as x/10000 rationals is the identity to 1e-4 (off-diagonals mix the
other channels, up to 2.5 x brighter, into a channel by <= 2.5e-4 of it). Hence 1e-3 relative.
Measured: ratios 0.39997..0.39998, absolute values within 2.3e-4 of the truth, doubling 2.0000..2.0003.
Any mistake this path guards against is far outside it: camera white balance would scale R by 2 and B by
1.43, an sRGB or LibRaw's default BT.709 output curve would turn 0.126 into 0.39 or 0.33, and LibRaw's
auto-brightening (measured) scales everything by 3.17.
Demosaicing touches only the column either side of the region edge (measured: columns 47 and 48 of 96),
so region means use a margin of 4 px; the crops of read_cells stay >= 8 px from the edge.
"""
from __future__ import annotations

import numpy as np
import pytest

from analysis import AnalysisError, CropGeometry, capture_time, decode_image, read_cells
from tests.analysis import raw_fixture as rf

REL = 1e-3  # see the module docstring
MARGIN = 4  # px kept clear of the region edge and the image border, full resolution
# Crop in the left half (columns 8..39), its mirror across the centre column in the right half (56..87).
GEOMETRY = CropGeometry(8, 16, 32, grid=4)


@pytest.fixture(scope="module")
def dngs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("raw")
    return {gain: rf.write_dng(folder / f"gain{gain}.dng", gain) for gain in (1, 2)}


def _region_means(image: np.ndarray, reduce: int) -> dict[str, np.ndarray]:
    """Per-channel means of the two flat halves, ``MARGIN`` px (full resolution) from edges; also checks flatness."""
    m, half = -(-MARGIN // reduce), image.shape[1] // 2
    regions = {"left": image[m:-m, m:half - m], "right": image[m:-m, half + m:-m]}
    for name, region in regions.items():
        pixels = region.reshape(-1, 3)
        spread = np.ptp(pixels, axis=0)
        assert (spread <= 1.5 / 65535 + 1e-7).all(), f"{name} half is not flat: {spread}"
    return {name: region.reshape(-1, 3).mean(axis=0) for name, region in regions.items()}


@pytest.mark.parametrize("reduce", [1, 2, 4])
def test_raw_decode_is_linear_with_unit_white_balance(dngs, reduce):
    image = decode_image(dngs[1], reduce=reduce)
    assert image.dtype == np.float32 and image.shape == (rf.HEIGHT // reduce, rf.WIDTH // reduce, 3)
    means, truth = _region_means(image, reduce), rf.expected_linear()
    # (a) demosaicing (full size) / 2x2 binning (half size) and the colour matrix keep the ratio per channel
    assert means["left"] / means["right"] == pytest.approx(np.full(3, rf.RATIO), rel=REL)
    # absolute level: (raw - black) / (white - black), so gamma 1, unit (not as-shot) white balance
    for name in ("left", "right"):
        assert means[name] == pytest.approx(truth[name], rel=REL)
    # through read_cells: mirror-normalised cells are the known transmittance, raw cells the known light
    cells = read_cells(dngs[1], GEOMETRY, reduce=reduce, expect_shape=(rf.HEIGHT, rf.WIDTH))
    assert cells.shape == (4, 4) and np.allclose(cells, rf.RATIO, rtol=REL, atol=0)
    light = read_cells(dngs[1], CropGeometry(8, 16, 32, grid=4, mirror_normalise=False), reduce=reduce)
    assert np.allclose(light, np.exp(np.log(truth["left"]).mean()), rtol=REL, atol=0)


@pytest.mark.parametrize("reduce", [1, 2])
def test_raw_decode_is_not_auto_brightened(dngs, reduce):
    # (b) twice the light above black gives twice the output: a fixed gain, no histogram stretch
    once, twice = decode_image(dngs[1], reduce=reduce), decode_image(dngs[2], reduce=reduce)
    m1, m2 = _region_means(once, reduce), _region_means(twice, reduce)
    for name in ("left", "right"):
        assert m2[name] / m1[name] == pytest.approx(np.full(3, 2.0), rel=REL)
    assert m2["right"] == pytest.approx(rf.expected_linear(2.0)["right"], rel=REL)  # brightest: G 0.63, unclipped
    raw_cells = CropGeometry(8, 16, 32, grid=4, mirror_normalise=False)
    assert np.allclose(read_cells(dngs[2], raw_cells, reduce=reduce) / read_cells(dngs[1], raw_cells, reduce=reduce),
                       2.0, rtol=REL, atol=0)
    # the mirror-normalised transmittance does not depend on the exposure
    assert np.allclose(read_cells(dngs[2], GEOMETRY, reduce=reduce), rf.RATIO, rtol=REL, atol=0)


def test_raw_capture_time_from_exif(dngs, tmp_path):
    # (c) EXIF DateTimeOriginal 2024:03:05 14:07:09 + SubSecTimeOriginal "25", read with exifread
    assert capture_time(dngs[1]) == rf.CAPTURE_TIME
    assert capture_time(rf.write_dng(tmp_path / "untimed.dng", capture_time=None)) is None
    # the EXIF IFD is the last thing in the file: cut inside it, the time is lost or falls back to the
    # IFD0 DateTime (whole seconds), but is never a wrong time and never an exception
    data = rf.dng_bytes()
    allowed = {None, rf.CAPTURE_TIME, rf.CAPTURE_TIME.replace(microsecond=0)}
    for cut in list(range(len(data) - 70, len(data))) + [240, 242, 244, 436, 600]:
        path = tmp_path / "cut.dng"
        path.write_bytes(data[:cut])
        assert capture_time(path) in allowed, cut


def test_truncated_raw_is_a_clear_error(dngs, tmp_path):
    # (d) cut inside the pixel data, inside the IFD, and just after the header
    data = dngs[1].read_bytes()
    for cut in (len(data) // 2, 400, 16):
        path = tmp_path / f"cut{cut}.dng"
        path.write_bytes(data[:cut])
        with pytest.raises(AnalysisError, match=rf"cannot decode camera raw .*cut{cut}\.dng: .*truncated or corrupt"):
            decode_image(path)
        with pytest.raises(AnalysisError, match=rf"cut{cut}\.dng"):
            read_cells(path, GEOMETRY)
    # the same bytes without a file name: neither OpenCV (it refuses CFA TIFFs) nor LibRaw reads them
    with pytest.raises(AnalysisError, match="neither JPEG/PNG/TIFF nor camera raw"):
        decode_image(data[: len(data) // 2])
    # and the whole file as bytes is recognised as raw by content
    assert decode_image(data)[32, 4] == pytest.approx(rf.expected_linear()["left"], rel=REL)
