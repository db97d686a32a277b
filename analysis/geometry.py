"""Crop, grid and mirror normalisation: one image to a grid of cell transmittances (paper section 4.2).

Every pixel of the square crop inside the beaker is divided, channel by channel, by the pixel at its
mirror position across a vertical axis (default: the image centre column), which sees the bare LED
panel. Symmetric panel light and its drift cancel. The crop is split into ``grid x grid`` cells; per
cell the normalised values are averaged per channel and the three channel means are combined by their
geometric mean, so that a Beer-Lambert law per channel stays an exact exponential for the cell.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.decode import check_reduce, decode_encoded, srgb_to_linear_lut
from analysis.errors import AnalysisError

_FLOOR = np.float32(1e-6)  # linear light floor; keeps a black pixel from dividing by zero


@dataclass(frozen=True)
class CropGeometry:
    """Where to measure, in full-resolution pixel coordinates.

    Parameters
    ----------
    x, y : int
        Left column and top row of the square crop, px.
    size : int
        Side of the crop, px (at least ``grid``).
    grid : int
        Cells per side (paper: 10).
    mirror_col : float or None
        Column of the vertical mirror axis, px; None is the image centre, ``(W - 1) / 2``.
    mirror_normalise : bool
        Divide by the mirror image (the paper's method). False keeps raw linear light, for comparison.
    """

    x: int
    y: int
    size: int
    grid: int = 10
    mirror_col: float | None = None
    mirror_normalise: bool = True

    def __post_init__(self) -> None:
        if not 1 <= self.grid <= 100:
            raise AnalysisError(f"grid={self.grid!r} is outside 1..100 cells per side")
        if self.x < 0 or self.y < 0:
            raise AnalysisError(f"crop corner (x={self.x}, y={self.y}) px must not be negative")
        if self.size < self.grid:
            raise AnalysisError(f"crop size={self.size} px is smaller than grid={self.grid} cells")
        if self.mirror_col is not None and self.mirror_col < 0:
            raise AnalysisError(f"mirror_col={self.mirror_col!r} px must not be negative")

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"x": self.x, "y": self.y, "size": self.size, "grid": self.grid, "mirror_col": self.mirror_col,
                "mirror_normalise": self.mirror_normalise}

    @classmethod
    def from_dict(cls, data: dict) -> CropGeometry:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(int(data["x"]), int(data["y"]), int(data["size"]), int(data.get("grid", 10)),
                       None if data.get("mirror_col") is None else float(data["mirror_col"]),
                       bool(data.get("mirror_normalise", True)))
        except (KeyError, TypeError, ValueError) as exc:
            raise AnalysisError(f"bad crop geometry {data!r}: {exc}") from exc


def default_geometry(image_shape: tuple[int, int], grid: int = 10) -> CropGeometry:
    """A crop for a beaker standing left of the image centre, as on the paper's bench.

    Centred on row ``H / 2`` and column ``W / 4``, side ``min(H, W) / 4`` rounded down to a multiple
    of ``4 * grid`` px (at least ``grid``); mirror axis through the image centre.
    """
    height, width = image_shape
    size = max(grid, min(height, width) // 4 // (4 * grid) * (4 * grid))
    return CropGeometry(max(0, width // 4 - size // 2), max(0, height // 2 - size // 2), size, grid)


@dataclass(frozen=True)
class _Layout:
    """The geometry resolved on one decoded image: cell edges and the mirror offset, decoded px."""

    rows: np.ndarray
    cols: np.ndarray
    mirror_sum: int | None  # mirror column of c is mirror_sum - c


def _layout(geometry: CropGeometry, shape: tuple[int, int], reduce: int) -> _Layout:
    height, width = shape
    scale = 1.0 / reduce
    rows = np.round((geometry.y + np.linspace(0, geometry.size, geometry.grid + 1)) * scale).astype(int)
    cols = np.round((geometry.x + np.linspace(0, geometry.size, geometry.grid + 1)) * scale).astype(int)
    where = f"crop x={geometry.x}, y={geometry.y}, size={geometry.size} px"
    if np.any(np.diff(rows) < 1):
        raise AnalysisError(f"{where} is too small for a {geometry.grid}x{geometry.grid} grid at reduce={reduce}")
    if rows[-1] > height or cols[-1] > width:
        raise AnalysisError(f"{where} reaches past the image ({width * reduce}x{height * reduce} px)")
    if not geometry.mirror_normalise:
        return _Layout(rows, cols, None)
    axis = (width - 1) / 2 if geometry.mirror_col is None else (geometry.mirror_col + 0.5) * scale - 0.5
    mirror_sum = int(round(2 * axis))
    lo, hi = mirror_sum - (cols[-1] - 1), mirror_sum - cols[0]
    axis_px = (axis + 0.5) * reduce - 0.5
    if lo < 0 or hi >= width:
        raise AnalysisError(f"the mirror of {where} across column {axis_px:.1f} spans columns "
                            f"{lo * reduce}..{hi * reduce}, outside the image width {width * reduce} px")
    if lo < cols[-1] and cols[0] <= hi:
        raise AnalysisError(f"{where} overlaps its own mirror image across column {axis_px:.1f}; "
                            "move the crop off the mirror axis (it must lie inside the beaker, the mirror outside)")
    return _Layout(rows, cols, mirror_sum)


def _cell_means(values: np.ndarray, layout: _Layout) -> np.ndarray:
    """Per-cell, per-channel means of a (S, S, 3) array cut at the layout's edges; (g, g, 3)."""
    rows, cols = layout.rows - layout.rows[0], layout.cols - layout.cols[0]
    sums = np.add.reduceat(np.add.reduceat(values, rows[:-1], axis=0), cols[:-1], axis=1)
    counts = np.diff(rows)[:, None] * np.diff(cols)[None, :]
    return sums / counts[..., None]


def _combine(channel_means: np.ndarray) -> np.ndarray:
    """Geometric mean over channels: (g, g, 3) -> (g, g) float64."""
    return np.exp(np.log(np.maximum(channel_means.astype(np.float64), _FLOOR)).mean(axis=-1))


def _cells_from_regions(crop: np.ndarray, mirror: np.ndarray | None, layout: _Layout) -> np.ndarray:
    if mirror is not None:
        crop = crop / np.maximum(mirror, _FLOOR)
    return _combine(_cell_means(crop, layout))


def _regions(image: np.ndarray, layout: _Layout) -> tuple[np.ndarray, np.ndarray | None]:
    r0, r1, c0, c1 = layout.rows[0], layout.rows[-1], layout.cols[0], layout.cols[-1]
    crop = image[r0:r1, c0:c1]
    if layout.mirror_sum is None:
        return crop, None
    s = layout.mirror_sum
    return crop, image[r0:r1, s - c1 + 1:s - c0 + 1][:, ::-1]


def cell_transmittance(image_linear: np.ndarray, geometry: CropGeometry) -> np.ndarray:
    """Mirror-normalised cell transmittances of one decoded linear image.

    Parameters
    ----------
    image_linear : (H, W, 3) ndarray of float, linear light
        At the geometry's (full) resolution.
    geometry : CropGeometry

    Returns
    -------
    (grid, grid) ndarray of float64
        Geometric mean over channels of the per-cell mean normalised value (dimensionless; raw linear
        light when ``geometry.mirror_normalise`` is False).

    Raises
    ------
    AnalysisError
        Bad image shape; crop or mirror outside the image; crop overlapping its mirror.
    """
    if image_linear.ndim != 3 or image_linear.shape[2] != 3:
        raise AnalysisError(f"expected an (H, W, 3) image, got shape {image_linear.shape}")
    layout = _layout(geometry, image_linear.shape[:2], 1)
    crop, mirror = _regions(image_linear.astype(np.float32, copy=False), layout)
    return _cells_from_regions(crop, mirror, layout)


def cells_from_codes(codes: np.ndarray, geometry: CropGeometry, *, reduce: int = 1,
                     linear: bool = False) -> np.ndarray:
    """:func:`cell_transmittance` of integer codes, linearising only the crop and its mirror.

    ``codes`` is an (H, W, 3) uint8/uint16 RGB image decoded with downscaling ``reduce``; sRGB-encoded
    unless ``linear``.
    """
    layout = _layout(geometry, codes.shape[:2], check_reduce(reduce))
    crop, mirror = _regions(codes, layout)
    bits = 8 if codes.dtype == np.uint8 else 16
    if linear:
        lin = (lambda a: a.astype(np.float32) / np.float32(2 ** bits - 1))
    else:
        lut = srgb_to_linear_lut(bits)
        lin = (lambda a: lut[a])
    return _cells_from_regions(lin(crop), None if mirror is None else lin(mirror), layout)


def read_cells(path: str | Path | bytes, geometry: CropGeometry, *, reduce: int = 1,
               expect_shape: tuple[int, int] | None = None) -> np.ndarray:
    """Decode one image file and return its (grid, grid) cell transmittances.

    Parameters
    ----------
    path : path or bytes
        The image (any format of :func:`analysis.decode_image`).
    geometry : CropGeometry
        In full-resolution px.
    reduce : {1, 2, 4, 8}
        Decode downscaled (see :mod:`analysis.decode`).
    expect_shape : (H, W) or None
        Full-resolution size the geometry was chosen for; a different image size is an error.

    Returns
    -------
    (grid, grid) ndarray of float64

    Raises
    ------
    AnalysisError
        Unreadable image, wrong size, or geometry that does not fit it.
    """
    codes, linear = decode_encoded(path, reduce=reduce)
    if expect_shape is not None:
        want = tuple(-(-int(n) // reduce) for n in expect_shape)
        if codes.shape[:2] != want:
            name = "<bytes>" if isinstance(path, (bytes, bytearray, memoryview)) else str(path)
            raise AnalysisError(f"image {name} is {codes.shape[1] * reduce}x{codes.shape[0] * reduce} px, "
                                f"expected {expect_shape[1]}x{expect_shape[0]} px (the calibration's size)")
    return cells_from_codes(codes, geometry, reduce=reduce, linear=linear)
