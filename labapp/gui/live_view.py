"""The latest frame with the crop square, its grid and its mirrored square (paper Fig. 4b).

The operator drags and resizes the crop (a square ROI); the grid and the mirrored square follow. Image
coordinates: x = column, y = row (pyqtgraph row-major), pixels.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget


def grid_segments(x: float, y: float, size: float, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """Line segments (x, y arrays, consecutive pairs) of a ``grid`` x ``grid`` subdivision of a square, px."""
    ticks = np.linspace(0.0, size, grid + 1)
    xs, ys = [], []
    for t in ticks:
        xs += [x + t, x + t, x, x + size]
        ys += [y, y + size, y + t, y + t]
    return np.array(xs), np.array(ys)


def decode_image(data: bytes | None = None, path: str | None = None) -> np.ndarray | None:
    """An RGB (H, W, 3) uint8 image from JPEG bytes or a file (None if undecodable)."""
    if path is not None:
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    else:
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return None if bgr is None else np.ascontiguousarray(bgr[..., ::-1])


def mirrored_x(x: float, size: float, mirror_col: float) -> float:
    """Left column of the square mirrored across the vertical axis at ``mirror_col`` (px)."""
    return 2.0 * mirror_col - x - size


class LiveView(QWidget):
    """Shows frames (``set_frame``) with the crop overlay; emits ``crop_changed(x, y, size)`` in px."""

    crop_changed = Signal(int, int, int)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.grid = 10
        self.mirror_col: float | None = None
        self._shape: tuple[int, int] | None = None
        self.graphics = pg.GraphicsLayoutWidget()
        self.view = self.graphics.addViewBox(lockAspect=True, invertY=True)
        self.image = pg.ImageItem(axisOrder="row-major")
        self.view.addItem(self.image)
        self.roi = pg.ROI([0, 0], [100, 100], pen=pg.mkPen("y", width=2), maxBounds=None)
        self.roi.addScaleHandle([1, 1], [0, 0], lockAspect=True)
        self.roi.addScaleHandle([0, 0], [1, 1], lockAspect=True)
        self.roi.sigRegionChanged.connect(self._update_overlay)
        self.roi.sigRegionChangeFinished.connect(self._emit_crop)
        self.view.addItem(self.roi)
        self.grid_item = pg.PlotCurveItem(pen=pg.mkPen((255, 255, 0, 140)), connect="pairs")
        self.mirror_item = pg.PlotCurveItem(pen=pg.mkPen("c", width=2, style=pg.QtCore.Qt.PenStyle.DashLine))
        self.axis_item = pg.InfiniteLine(angle=90, pen=pg.mkPen((0, 255, 255, 90)))
        for item in (self.grid_item, self.mirror_item, self.axis_item):
            self.view.addItem(item)
        self.caption = QLabel("no frame yet")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics, 1)
        layout.addWidget(self.caption)
        self.graphics.ci.layout.setContentsMargins(0, 0, 0, 0)
        self.view.sigResized.connect(self.fit)

    def set_frame(self, rgb: np.ndarray, caption: str = "") -> None:
        """Show an (H, W, 3) uint8 RGB frame."""
        new_shape = self._shape != rgb.shape[:2]
        self._shape = rgb.shape[:2]
        self.image.setImage(rgb, autoLevels=False, levels=(0, 255))
        if new_shape:
            self.fit()
        self.caption.setText(caption)
        self._update_overlay()

    def show_file(self, path: str, caption: str | None = None) -> None:
        """Show the image file ``path`` captioned with ``caption`` (default its name; nothing if it does not
        decode)."""
        rgb = decode_image(path=path)
        if rgb is not None:
            self.set_frame(rgb, Path(path).name if caption is None else caption)

    def clear(self, caption: str = "no frame yet") -> None:
        """Show no frame (a new run before its reference), with ``caption``; the crop stays where it is."""
        self.image.clear()
        self.caption.setText(caption)

    def show_jpeg(self, data: bytes, caption: str) -> None:
        """Show a JPEG given as bytes (nothing if it does not decode)."""
        rgb = decode_image(data=data)
        if rgb is not None:
            self.set_frame(rgb, caption)

    def fit(self) -> None:
        """Show the whole frame as large as the view allows (aspect kept): the range follows the image alone,
        not the crop square or its mirror, which may reach past it. Called again whenever the view is resized."""
        if self._shape is not None:
            self.view.autoRange(padding=0.0, items=[self.image])

    def set_geometry(self, x: int, y: int, size: int, grid: int = 10, mirror_col: float | None = None) -> None:
        """Place the crop square (px) and set the grid size and mirror axis (None: the image centre)."""
        self.grid, self.mirror_col = grid, mirror_col
        self.roi.setPos((x, y), update=False, finish=False)
        self.roi.setSize((size, size), update=False, finish=False)
        self.roi.stateChanged(finish=False)
        self._update_overlay()

    def geometry_px(self) -> tuple[int, int, int]:
        """The crop as (x, y, size), px."""
        pos, size = self.roi.pos(), self.roi.size()
        return int(round(pos.x())), int(round(pos.y())), int(round(min(size.x(), size.y())))

    def axis_col(self) -> float:
        """The mirror axis column (px): the configured one, else the image centre."""
        if self.mirror_col is not None:
            return self.mirror_col
        return self._shape[1] / 2.0 if self._shape else 0.0

    def _update_overlay(self) -> None:
        x, y, size = self.geometry_px()
        xs, ys = grid_segments(x, y, size, self.grid)
        self.grid_item.setData(xs, ys)
        mx = mirrored_x(x, size, self.axis_col())
        self.mirror_item.setData([mx, mx + size, mx + size, mx, mx], [y, y, y + size, y + size, y])
        self.axis_item.setPos(self.axis_col())

    def _emit_crop(self) -> None:
        self.crop_changed.emit(*self.geometry_px())
