"""Design launcher: a measured run (through the active simulation calibration) or a target CSV -> inverse design
in the background (iteration, fit, mid-slices) -> target vs achieved, in grams over hours when calibrated, save
the STL."""
from __future__ import annotations

import csv
import shutil
import threading
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from design.files.outputs import summary_lines
from design.inverse.problem import DesignConfig
from labapp.gui.bridge import BackgroundTask
from labapp.gui.sweep_panel import SweepPanel
from labapp.jobs.calibrate_sim import SimCalFile, load_simcal
from labapp.jobs.design import DESIGN_DEFAULTS, design_folder
from labapp.jobs.design import design as design_job

NO_SIMCAL = ("no active simulation calibration: a measured run cannot become a target until one is made "
             "(calibration wizard, simulation step) and made active")


def read_curves(path: Path) -> dict[str, list[float]]:
    """Columns of a design's ``curves.csv`` (`design.files.outputs.CURVE_COLUMNS`)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {key: [float(r[key]) for r in rows] for key in (rows[0] if rows else {})}


def mid_slice(x, k: int, every: int = 5):
    """Every ``every`` iterations, the middle slice of the design variables, else None.

    ``x`` comes in the design space's variable shape: a 3D field (nfc, ico) shows its slice through the
    middle of the last axis, a 2D one (an extruded cross-section) itself.
    """
    if k % every:
        return None
    x = np.asarray(x, dtype=float)
    return np.array(x[..., x.shape[-1] // 2] if x.ndim == 3 else x)


class DesignLauncher(QWidget):
    """Pick a run folder or a ``tau_mm,released_mm3`` CSV, run ``design.files.rundir.run_design`` off the GUI
    thread with progress, show target vs achieved curves and save the STL."""

    def __init__(self, data_dir: Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.data_dir = Path(data_dir)
        self.source = QLineEdit("")
        self.source.setPlaceholderText("run folder or tau_mm,released_mm3 CSV")
        run_button, csv_button = QPushButton("Run folder..."), QPushButton("CSV...")
        run_button.clicked.connect(self._pick_run)
        csv_button.clicked.connect(self._pick_csv)
        self.space = QComboBox()
        self.space.addItems(["extruded", "nfc", "ico"])
        self.space.setCurrentText(DESIGN_DEFAULTS["space"])
        self.space.setToolTip("ico: free 3D design printable without supports along +z (incremental compliance)")
        self.resolution = QSpinBox()
        self.resolution.setRange(8, 256)
        self.resolution.setSingleStep(2)
        self.resolution.setValue(DESIGN_DEFAULTS["resolution"])
        self.max_iter = QSpinBox()
        self.max_iter.setRange(1, 5000)
        self.max_iter.setValue(DESIGN_DEFAULTS["max_iter"])
        self.allow_infeasible = QCheckBox("optimise even if the feasibility check fails")
        self.allow_infeasible.setToolTip("measured curves are noisy near the end of a run; the check's report "
                                         "is kept as feasibility.txt in the design folder")
        self.allow_infeasible.setChecked(DESIGN_DEFAULTS["allow_infeasible"])
        self.start_button, self.stop_button = QPushButton("Design"), QPushButton("Stop")
        self.save_button = QPushButton("Save STL...")
        self.start_button.clicked.connect(self.start)
        self.stop_button.clicked.connect(self.stop)
        self.save_button.clicked.connect(self._save)
        self.simcal: SimCalFile | None = None
        self.status = QLabel(NO_SIMCAL)
        self.status.setWordWrap(True)
        self.plot = pg.PlotWidget(title="release: target vs achieved (simulation units)")
        self.plot.setLabel("bottom", "tau (mm)")
        self.plot.setLabel("left", "released (mm^3)")
        self.plot.addLegend()
        self.target_curve = self.plot.plot([], [], pen=pg.mkPen("g", width=2), name="target")
        self.achieved_curve = self.plot.plot([], [], pen=pg.mkPen("m", width=2, style=pg.QtCore.Qt.PenStyle.DashLine),
                                             name="achieved (binary design)")
        self.slice_plot = pg.PlotWidget(title="mid-slice of the design variables")
        self.slice_plot.setAspectLocked(True)
        self.slice_image = pg.ImageItem()
        self.slice_plot.addItem(self.slice_image)
        self.physical_plot = pg.PlotWidget(title="predicted release over the measured target (g over h)")
        self.physical_plot.setLabel("bottom", "time since drop (h)")
        self.physical_plot.setLabel("left", "released (g)")
        self.physical_plot.addLegend()
        self.physical_target = self.physical_plot.plot([], [], pen=pg.mkPen("g", width=2), name="target")
        self.physical_design = self.physical_plot.plot(
            [], [], pen=pg.mkPen("m", width=2, style=pg.QtCore.Qt.PenStyle.DashLine), name="design (predicted)")
        form = QFormLayout()
        src = QHBoxLayout()
        src.addWidget(self.source, 1)
        src.addWidget(run_button)
        src.addWidget(csv_button)
        form.addRow("target", src)
        form.addRow("design space", self.space)
        form.addRow("resolution (voxels)", self.resolution)
        form.addRow("max iterations", self.max_iter)
        form.addRow("", self.allow_infeasible)
        buttons = QHBoxLayout()
        for b in (self.start_button, self.stop_button, self.save_button):
            buttons.addWidget(b)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addLayout(buttons)
        layout.addWidget(self.status)
        plots = QHBoxLayout()
        plots.addWidget(self.plot, 2)
        plots.addWidget(self.slice_plot, 1)
        plots.addWidget(self.physical_plot, 2)
        layout.addLayout(plots, 1)
        self.sweep = SweepPanel(self.data_dir, self.sweep_settings, self)
        layout.addWidget(self.sweep, 1)
        self.task: BackgroundTask | None = None
        self._stop = threading.Event()
        self.out_dir: Path | None = None
        self.stop_button.setEnabled(False)
        self.save_button.setEnabled(False)

    def set_simcal(self, path: Path | None) -> None:
        """Make a ``simcal.json`` the active simulation calibration (None: none)."""
        self.simcal = None if path is None else load_simcal(path)
        self.status.setText(NO_SIMCAL if self.simcal is None else f"active simulation calibration: "
                            f"{self.simcal.describe()}")

    def sweep_settings(self) -> tuple[str, dict, str | None]:
        """The target, fixed design settings and simulation calibration a sweep starts from: this form's."""
        fixed = {"space": self.space.currentText(), "resolution": self.resolution.value(),
                 "max_iter": self.max_iter.value(), "allow_infeasible": self.allow_infeasible.isChecked()}
        return self.source.text().strip(), fixed, None if self.simcal is None else str(self.simcal.path)

    def _pick_run(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "measured run", str(self.data_dir))
        if path:
            self.source.setText(path)

    def _pick_csv(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "target curve", str(self.data_dir), "CSV (*.csv)")
        if path:
            self.source.setText(path)

    def start(self) -> None:
        """Convert the source if it is a run, then run the design in the background."""
        source = Path(self.source.text().strip())
        if not source.exists():
            self.status.setText(f"{source} does not exist")
            return
        self.out_dir = design_folder(self.data_dir, source.stem)
        space, resolution, max_iter = self.space.currentText(), self.resolution.value(), self.max_iter.value()
        allow = self.allow_infeasible.isChecked()
        self._stop.clear()
        out_dir = self.out_dir

        simcal = self.simcal

        def work(progress):
            config = DesignConfig(target=str(source), space=space, resolution=resolution, max_iter=max_iter,
                                  allow_infeasible=allow)
            return design_job(config, out_dir, simcal=simcal,
                              on_iteration=lambda k, x, terms: progress((k, terms, mid_slice(x, k))),
                              should_stop=self._stop.is_set)
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self._progress)
        self.task.finished.connect(self._finished)
        self.task.failed.connect(self._failed)
        self.task.start()
        self.start_button.setEnabled(False)
        self.stop_button.setEnabled(True)
        self.status.setText(f"designing into {out_dir} ...")

    def stop(self) -> None:
        """Ask the optimiser to stop (the best design so far is still written)."""
        self._stop.set()

    def _progress(self, update: tuple) -> None:
        k, terms, image = update
        phase = f"{terms['phase']}, " if "phase" in terms else ""
        self.status.setText(f"{phase}iteration {k}: J = {terms.get('J', float('nan')):.5g}, "
                            f"fit {terms.get('J_fit', float('nan')):.4g}")
        if image is not None:
            self.slice_image.setImage(image, levels=(0.0, 1.0))

    def _finished(self, outcome) -> None:
        result, physical = outcome
        self.start_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        curves = read_curves(result.out_dir / "curves.csv")
        self.target_curve.setData(curves["tau_mm"], curves["target_mm3"])
        self.achieved_curve.setData(curves["tau_mm"], curves["binary_mm3"])
        self.save_button.setEnabled((result.out_dir / "design.stl").is_file())
        if physical is not None:
            rows = read_curves(result.out_dir / "curves_physical.csv")
            hours = [t / 3600.0 for t in rows["t_s"]]
            self.physical_target.setData(hours, rows["target_released_g"])
            self.physical_design.setData(hours, rows["design_released_g"])
        # the lines sfr design prints, each shown as a sentence
        lines = summary_lines(physical or result.outputs.summary, result.out_dir)
        self.status.setText("\n".join(line[:1].upper() + line[1:] for line in [f"design {lines[0]}", *lines[1:]]))

    def _failed(self, message: str) -> None:
        self.start_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        self.status.setText(f"design failed: {message}")

    def _save(self) -> None:
        if self.out_dir is None:
            return
        path, _ = QFileDialog.getSaveFileName(self, "save STL", "design.stl", "STL (*.stl)")
        if path:
            shutil.copyfile(self.out_dir / "design.stl", path)
