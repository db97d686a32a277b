"""Sweep panel of the design launcher: a small grid of design settings on the local Dask cluster
(`labapp.scaleout.sweep.sweep_on_cluster`, the job behind `sfr sweep`), then its contact sheet and each design's
report."""
from __future__ import annotations

import csv
import threading
import time
from pathlib import Path
from typing import Callable

from PySide6.QtCore import Qt
from PySide6.QtGui import QPixmap
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QPushButton,
    QScrollArea,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from design.inverse.presets import PRESET_NAMES
from labapp.figures.contact_sheet import rank
from labapp.gui.bridge import BackgroundTask
from labapp.records.fileio import sanitize_name
from labapp.scaleout.cluster import local_worker_count
from labapp.scaleout.sweep import Progress, SweepResult, sweep_on_cluster
from labapp.scaleout.sweepspec import SweepSpec, parse_spec, spec_text

SHEET_ITEM = "contact sheet (ranked)"


def parse_values(text: str, name: str) -> list[float]:
    """Comma-separated numbers of one grid field; raises ValueError naming the field."""
    try:
        values = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError as exc:
        raise ValueError(f"{name}: expected numbers separated by commas, got {text!r}") from exc
    if not values:
        raise ValueError(f"{name}: give at least one value")
    return values


class SweepPanel(QGroupBox):
    """Grid fields, Sweep / Stop / Open buttons, progress, and a browser of the sweep's contact sheet.

    Parameters
    ----------
    data_dir : Path
        Sweeps go to ``data_dir/sweeps/<time>_<target>``.
    base_settings : callable
        Returns the launcher's current target, fixed settings and simulation calibration (path or None):
        ``(target, {"space": ..., ...}, simcal)``.
    """

    def __init__(self, data_dir: Path, base_settings: Callable[[], tuple[str, dict, str | None]],
                 parent: QWidget | None = None) -> None:
        super().__init__("Sweep (local Dask cluster)", parent)
        self.data_dir, self.base_settings = Path(data_dir), base_settings
        self.w_binary, self.radius, self.beta = QLineEdit("10, 20"), QLineEdit("3, 4"), QLineEdit("3")
        self.preset = QComboBox()
        self.preset.addItems(["(none)", *PRESET_NAMES])
        self.preset.setToolTip("adds one combination with the paper's settings for this target")
        self.workers = QSpinBox()
        self.workers.setRange(1, 64)
        self.workers.setValue(local_worker_count(1.0))
        self.sweep_button, self.stop_button, self.open_button = (QPushButton("Sweep"), QPushButton("Stop sweep"),
                                                                 QPushButton("Open sweep..."))
        self.sweep_button.clicked.connect(self.start)
        self.stop_button.clicked.connect(self.stop)
        self.open_button.clicked.connect(self._pick_sweep)
        self.stop_button.setEnabled(False)
        self.status = QLabel("each combination is an ordinary design run folder; a rerun resumes")
        self.status.setWordWrap(True)
        self.designs = QListWidget()
        self.designs.currentTextChanged.connect(self._show)
        self.picture = QLabel()
        self.picture.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop)
        scroll = QScrollArea()
        scroll.setWidget(self.picture)
        scroll.setWidgetResizable(True)
        form = QFormLayout()
        form.addRow("w_binary values", self.w_binary)
        form.addRow("radius values (voxels)", self.radius)
        form.addRow("beta values", self.beta)
        form.addRow("plus paper preset", self.preset)
        form.addRow("workers", self.workers)
        buttons = QHBoxLayout()
        for b in (self.sweep_button, self.stop_button, self.open_button):
            buttons.addWidget(b)
        browse = QHBoxLayout()
        browse.addWidget(self.designs, 1)
        browse.addWidget(scroll, 4)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addLayout(buttons)
        layout.addWidget(self.status)
        layout.addLayout(browse, 1)
        self.task: BackgroundTask | None = None
        self.sweep_dir: Path | None = None
        self._folders: dict[str, str] = {}
        self._stop = threading.Event()

    @property
    def busy(self) -> bool:
        """True while a sweep runs."""
        return self.task is not None and self.task.running

    def spec(self) -> SweepSpec:
        """The sweep spec of the fields; raises ValueError naming a bad field."""
        target, fixed, simcal = self.base_settings()
        if not target:
            raise ValueError("choose a target first")
        grid = {"w_binary": parse_values(self.w_binary.text(), "w_binary"),
                "radius_vox": parse_values(self.radius.text(), "radius"),
                "beta": parse_values(self.beta.text(), "beta")}
        points = [{"preset": self.preset.currentText()}] if self.preset.currentIndex() > 0 else []
        return parse_spec(spec_text(target, fixed, grid, points, simcal), source="sweep")

    def start(self) -> None:
        """Run the sweep on a local cluster in the background."""
        try:
            spec = self.spec()
        except ValueError as exc:
            self.status.setText(f"cannot sweep: {exc}")
            return
        self.sweep_dir = self.data_dir / "sweeps" / f"{time.strftime('%Y%m%d-%H%M%S')}_" \
                                                    f"{sanitize_name(Path(spec.target).stem)}"
        sweep_dir, workers = self.sweep_dir, self.workers.value()
        self._stop.clear()

        def work(progress: Callable[[Progress], None]) -> SweepResult:
            return sweep_on_cluster(spec, sweep_dir, workers=workers, on_progress=progress, should_stop=self._stop.is_set)
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self._progress)
        self.task.finished.connect(self._finished)
        self.task.failed.connect(self._failed)
        self.task.start()
        self.sweep_button.setEnabled(False)
        self.stop_button.setEnabled(True)
        self.status.setText(f"starting {len(spec.combinations)} designs on {workers} workers into {sweep_dir} ...")

    def stop(self) -> None:
        """Running designs checkpoint and stop; queued ones do not start (Sweep again resumes the sweep)."""
        self._stop.set()
        if self.busy:
            self.status.setText("stopping: running designs stop at their next checkpoint, queued ones do not start")

    def _progress(self, p: Progress) -> None:
        eta = "-" if p.eta_s is None else f"{p.eta_s / 60:.1f} min"
        self.status.setText(f"{p.done} done ({p.failed} failed), {p.running} running, {p.left} left, ETA {eta}"
                            + (f"; dashboard {p.dashboard}" if p.dashboard else ""))

    def _finished(self, result: SweepResult) -> None:
        self.sweep_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        stopped = " (stopped: Sweep again resumes)" if result.stopped else ""
        self.status.setText(f"sweep{stopped}: {len(result.rows)} designs, {len(result.failed)} failed; "
                            f"{result.table}")
        self.browse(result.table.parent)

    def _failed(self, message: str) -> None:
        self.sweep_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        self.status.setText(f"sweep failed: {message}")

    def _pick_sweep(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "sweep folder", str(self.data_dir / "sweeps"))
        if path:
            self.browse(Path(path))

    def browse(self, sweep_dir: Path) -> None:
        """List a sweep's designs best first (the contact sheet's ranking) and show its contact sheet."""
        self.sweep_dir = Path(sweep_dir)
        try:
            with open(self.sweep_dir / "sweep.csv", newline="") as fh:
                rows = rank(list(csv.DictReader(fh)))
        except OSError as exc:
            self.status.setText(f"{sweep_dir} holds no sweep.csv: {exc.strerror or exc}")
            return
        self._folders = {f"#{i + 1} {r['name']}": r["folder"] for i, r in enumerate(rows)}
        self.designs.clear()
        self.designs.addItems([SHEET_ITEM, *self._folders])
        self.designs.setCurrentRow(0)

    def _show(self, item: str) -> None:
        if not item or self.sweep_dir is None:
            return
        path = self.sweep_dir / ("contact_sheet.png" if item == SHEET_ITEM else
                                 Path(self._folders[item]) / "report.png")
        pixmap = QPixmap(str(path))
        self.picture.setPixmap(pixmap)
        if pixmap.isNull():
            self.picture.setText(f"no picture: {path}")
