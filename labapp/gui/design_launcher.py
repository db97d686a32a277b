"""Design launcher: a target (a measured run or curve through the active simulation calibration, a
``tau_mm,released_mm3`` CSV, a mesh, a sample shape or an analytic curve, as ``sfr design --target`` takes)
-> its curve and feasibility report -> inverse design in the background (iteration i of N, fit, mid-slices)
-> target vs achieved, in grams over time when calibrated, the printed solid in three slices, save the STL;
stopped designs resume from their checkpoint."""
from __future__ import annotations

import csv
import dataclasses
import shutil
import tempfile
import threading
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSplitter,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from design.files.meshio import MESH_SUFFIXES
from design.files.records import load_config
from design.files.summary_text import summary_lines
from design.files.targets_io import load_problem
from design.geometry.shapes import SAMPLE_SHAPES
from design.inverse.config import DesignConfig
from design.inverse.settings import ALLOW_INFEASIBLE, MAX_ITER, RESOLUTION, SPACE
from design.inverse.status import DesignStatus
from labapp.gui.bridge import BackgroundTask
from labapp.gui.fields import problems, setting_field
from labapp.gui.plots import hmm, time_plot
from labapp.gui.sweep_panel import SweepPanel
from labapp.jobs.bands import quantile_columns
from labapp.jobs.design import design as design_job
from labapp.jobs.design import design_folder
from labapp.jobs.physical import adjustment_line, is_physical, write_target_csv
from labapp.records.simcal import SimCalFile, curve_of, load_simcal

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


ANALYTIC_TARGETS = ("zero-order", "accel:q=2", "accel:q=0.5")
"""Analytic targets offered (``sfr design --target``: zero-order[:final=F,duration=D], accel:q=Q[,...])."""
MESH_FILTER = "meshes (" + " ".join(f"*{s}" for s in MESH_SUFFIXES) + ")"


@dataclasses.dataclass(frozen=True)
class TargetPreview:
    """What a target becomes before a design: its curve in simulation units, the feasibility report and,
    for a measured target, the measured curve (s, g) and what making it feasible changed
    (:func:`labapp.jobs.physical.adjustment_line`)."""

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    report: str
    feasible: bool
    measured: tuple[np.ndarray, np.ndarray] | None
    warnings: tuple[str, ...]
    adjustment: str = ""


def preview_target(target: str, space: str, resolution: int, simcal: SimCalFile | None) -> TargetPreview:
    """The target curve on the design grid and its feasibility report, without designing (slow for a mesh:
    it is simulated; call it off the GUI thread). A measured target goes through ``simcal`` as ``sfr design``
    converts it (``labapp.jobs.physical.write_target_csv``)."""
    measured, adjustment = None, ""
    with tempfile.TemporaryDirectory() as tmp:
        if is_physical(target):
            if simcal is None:
                raise ValueError(NO_SIMCAL)
            curve = curve_of(target)
            measured = (np.asarray(curve.t_s, float), np.asarray(curve.released_g, float))
            written = write_target_csv(curve, simcal, Path(tmp) / "target.csv")
            target, adjustment = str(written.csv), adjustment_line(written)
        problem = load_problem(DesignConfig(target=target, space=space, resolution=resolution))
    return TargetPreview(np.asarray(problem.target.tau_mm), np.asarray(problem.target.released_mm3),
                         problem.feasibility.text(), problem.feasibility.feasible, measured, tuple(problem.warnings),
                         adjustment)


class SolidView(QWidget):
    """Three orthogonal mid-slices of a voxel solid (top, front, side) with a scale bar in mm; during a design
    the first view shows the mid-slice of the design variables."""

    TITLES = ("top (x-y)", "front (x-z)", "side (y-z)")

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.graphics = pg.GraphicsLayoutWidget()
        self.views, self.images, self.bars = [], [], []
        for i, title in enumerate(self.TITLES):
            row, col = divmod(i, 2)
            self.graphics.addLabel(title, row=2 * row, col=col)
            view = self.graphics.addViewBox(row=2 * row + 1, col=col, lockAspect=True, invertY=True)
            image = pg.ImageItem(axisOrder="row-major")
            view.addItem(image)
            self.views.append(view)
            self.images.append(image)
        self.caption = QLabel("the printed solid appears here when a design ends")
        self.caption.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics, 1)
        layout.addWidget(self.caption)

    def show_variables(self, image: np.ndarray) -> None:
        """The mid-slice of the design variables (0..1), during a design."""
        self.images[0].setImage(np.asarray(image, float), levels=(0.0, 1.0))
        self.images[0].setRect(0, 0, image.shape[1], image.shape[0])
        self.views[0].autoRange(padding=0.02)

    def show_solid(self, solid: np.ndarray, dx_mm: float) -> None:
        """Mid-slices of a (X, Y, Z) voxel solid of edge ``dx_mm``, each with a scale bar."""
        solid = np.asarray(solid, float)
        nx, ny, nz = solid.shape
        slices = (solid[:, :, nz // 2], solid[:, ny // 2, :].T, solid[nx // 2, :, :].T)
        for bar in self.bars:
            if bar.scene() is not None:
                bar.scene().removeItem(bar)
        self.bars.clear()
        extent_mm = max(solid.shape) * dx_mm
        bar_mm = _nice_length(extent_mm / 4.0)
        for view, image, sl in zip(self.views, self.images, slices):
            image.setImage(sl, levels=(0.0, 1.0))
            image.setRect(0.0, 0.0, sl.shape[1] * dx_mm, sl.shape[0] * dx_mm)
            view.autoRange(padding=0.05)
            bar = pg.ScaleBar(size=bar_mm, suffix="m", brush=pg.mkBrush(255, 200, 0), pen=pg.mkPen(None))
            bar.text.setText(f"{bar_mm:g} mm")
            bar.setParentItem(view)
            bar.anchor((1, 1), (1, 1), offset=(-12, -12))
            self.bars.append(bar)
        self.caption.setText(f"printed solid: {nx} x {ny} x {nz} voxels of {dx_mm:.3g} mm "
                             f"({nx * dx_mm:.1f} x {ny * dx_mm:.1f} x {nz * dx_mm:.1f} mm), mid-slices")


def _nice_length(mm: float) -> float:
    """1, 2 or 5 times a power of ten, at most ``mm``."""
    power = 10.0 ** np.floor(np.log10(max(mm, 1e-6)))
    return float(max(v for v in (1.0, 2.0, 5.0) if v * power <= mm) * power) if mm >= power else float(power)


class DesignLauncher(QWidget):
    """Pick a target, check it, run ``labapp.jobs.design.design`` off the GUI thread with progress, show the
    target vs achieved curves beside the printed solid, save the STL; resume a stopped design.

    Emits ``simcal_requested(path)`` when the operator loads a ``simcal.json`` here (the main window makes it
    the active simulation calibration everywhere).
    """

    simcal_requested = Signal(str)

    def __init__(self, data_dir: Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.data_dir = Path(data_dir)
        self.simcal: SimCalFile | None = None
        self.task: BackgroundTask | None = None
        self.check_task: BackgroundTask | None = None
        self._stop = threading.Event()
        self.out_dir: Path | None = None
        self._max_iter = 0
        self.source = QLineEdit("")
        self.source.setPlaceholderText("run folder, curve CSV, mesh, sample name, zero-order or accel:q=Q")
        self.source.setToolTip("what sfr design --target takes: a measured run or t_s,released_g CSV (through the "
                               "active simulation calibration), a tau_mm,released_mm3 CSV, a mesh "
                               f"({', '.join(MESH_SUFFIXES)}), a sample shape ({', '.join(SAMPLE_SHAPES)}), "
                               "zero-order[:final=F,duration=D] or accel:q=Q[,final=F,duration=D]")
        self.space, self.resolution, self.max_iter, self.allow_infeasible = (
            setting_field(s) for s in (SPACE, RESOLUTION, MAX_ITER, ALLOW_INFEASIBLE))
        self.barrier_speed = QLineEdit("")
        self.barrier_speed.setPlaceholderText("one material")
        self.barrier_speed.setToolTip("a second material, a placebo barrier eroding at S times the drug's rate (0: "
                                      "insoluble): sfr design --barrier-speed S, in the nfc or extruded space, for "
                                      "the targets one material cannot give (delay-zero:, pulses:, constant: or a "
                                      "CSV); empty: one material")
        self.allow_infeasible.setToolTip("the check's report is kept as feasibility.txt in the design folder; "
                                         "a measured target is optimised whatever its report says, since its "
                                         "noise alone can put short stretches under the isoperimetric bound")
        self.status = QLabel(NO_SIMCAL)
        self.status.setWordWrap(True)
        self.status.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        self.status.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.progress = QProgressBar()
        self.progress.setFormat("no design running")
        self.progress.setValue(0)
        self._make_buttons()
        self._make_plots()
        self.sweep = SweepPanel(self.data_dir, self.sweep_settings, self)
        self.pages = QTabWidget()
        self.pages.addTab(self._result_view(), "design")
        self.pages.addTab(self.sweep, "sweep")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(self._top_row())
        layout.addWidget(self.pages, 1)

    def _make_buttons(self) -> None:
        """The target pickers and the action buttons, connected to their slots."""
        self.target_buttons = (QPushButton("Run..."), QPushButton("CSV..."), QPushButton("Mesh..."))
        for button, slot in zip(self.target_buttons, (self._pick_run, self._pick_csv, self._pick_mesh)):
            button.clicked.connect(slot)
        self.sample = QComboBox()
        self.sample.addItems(["sample shape...", *SAMPLE_SHAPES])
        self.sample.activated.connect(lambda i: i and self.use_target(self.sample.itemText(i)))
        self.analytic = QComboBox()
        self.analytic.addItems(["analytic...", *ANALYTIC_TARGETS])
        self.analytic.setToolTip("zero-order: constant rate; accel:q=Q: rate growing as t^(q-1); edit the text "
                                 "to add final=F (mm^3) or duration=D (mm)")
        self.analytic.activated.connect(lambda i: i and self.use_target(self.analytic.itemText(i)))
        self.check_button, self.start_button, self.stop_button = (QPushButton("Check target"), QPushButton("Design"),
                                                                  QPushButton("Stop"))
        self.resume_button, self.simcal_button = QPushButton("Resume..."), QPushButton("Load simcal...")
        self.save_button = QPushButton("Save STL...")
        self.resume_button.setToolTip("continue a stopped design from its checkpoint (sfr design --resume)")
        self.simcal_button.setToolTip("make a simcal.json (sfr calibrate-sim) the active simulation calibration")
        for button, slot in ((self.check_button, self.check), (self.start_button, self.start),
                             (self.stop_button, self.stop), (self.resume_button, self.resume),
                             (self.simcal_button, self._pick_simcal), (self.save_button, self._save)):
            button.clicked.connect(slot)
        self.stop_button.setEnabled(False)
        self.save_button.setEnabled(False)

    def _make_plots(self) -> None:
        """The release plots (simulation units; grams over time) and the printed solid's slices."""
        self.plot = pg.PlotWidget(title="release: target vs achieved (simulation units)")
        self.plot.setLabel("bottom", "tau (mm)")
        self.plot.setLabel("left", "released (mm\u00b3)")
        self.plot.addLegend()
        self.target_curve = self.plot.plot([], [], pen=pg.mkPen("g", width=2), name="target")
        self.achieved_curve = self.plot.plot([], [], pen=pg.mkPen("m", width=2, style=Qt.PenStyle.DashLine),
                                             name="achieved (the print)")
        self.solid = SolidView()
        self.slice_image = self.solid.images[0]
        self.physical_plot = time_plot("predicted release over the measured target")
        self.physical_plot.setLabel("left", "released (g)")
        self.physical_plot.addLegend()
        self.physical_target = self.physical_plot.plot([], [], pen=pg.mkPen("g", width=2), name="target")
        self.physical_design = self.physical_plot.plot(
            [], [], pen=pg.mkPen("m", width=2, style=Qt.PenStyle.DashLine), name="design (predicted)")
        self.physical_band = [self.physical_plot.plot([], [], pen=pg.mkPen(None)) for _ in range(2)]
        self.physical_plot.addItem(pg.FillBetweenItem(*self.physical_band, brush=pg.mkBrush(255, 0, 255, 50)))

    def _top_row(self) -> QHBoxLayout:
        """The form (target, settings, buttons, progress) beside the scrollable report."""
        form = QGridLayout()
        form.addWidget(QLabel("target"), 0, 0)
        form.addWidget(self.source, 0, 1, 1, 3)
        picks = QHBoxLayout()
        for w in (*self.target_buttons, self.sample, self.analytic):
            picks.addWidget(w)
        form.addLayout(picks, 1, 1, 1, 3)
        settings = QHBoxLayout()
        for setting, w in ((SPACE, self.space), (RESOLUTION, self.resolution), (MAX_ITER, self.max_iter)):
            settings.addWidget(QLabel(setting.label))
            settings.addWidget(w)
        settings.addWidget(QLabel("barrier speed"))
        settings.addWidget(self.barrier_speed)
        settings.addStretch(1)
        form.addLayout(settings, 2, 1, 1, 3)
        form.addWidget(self.allow_infeasible, 3, 1, 1, 3)
        buttons = QHBoxLayout()
        for b in (self.check_button, self.start_button, self.stop_button, self.resume_button, self.simcal_button,
                  self.save_button):
            buttons.addWidget(b)
        form.addLayout(buttons, 4, 0, 1, 4)
        form.addWidget(self.progress, 5, 0, 1, 4)
        report = QScrollArea()
        report.setWidget(self.status)
        report.setWidgetResizable(True)
        top = QHBoxLayout()
        top.addLayout(form, 3)
        top.addWidget(report, 2)
        return top

    def _result_view(self) -> QSplitter:
        """The release curves (two tabs) beside the printed solid."""
        self.curves = QTabWidget()
        self.curves.addTab(self.plot, "simulation units")
        self.curves.addTab(self.physical_plot, "grams over time")
        result = QSplitter()
        result.addWidget(self.curves)
        result.addWidget(self.solid)
        result.setStretchFactor(0, 3)
        result.setStretchFactor(1, 2)
        result.setChildrenCollapsible(False)
        return result

    def settings(self) -> dict:
        """The design settings of the form, as `DesignConfig` fields (not checked; see :func:`problems`)."""
        return {"space": self.space.currentText(), "resolution": self.resolution.stored(),
                "max_iter": self.max_iter.stored(), "allow_infeasible": self.allow_infeasible.isChecked()}

    @property
    def busy(self) -> bool:
        """True while a design runs."""
        return self.task is not None and self.task.running

    def busy_work(self) -> list[str]:
        """What closing now would cut short: the running design and sweep, each as a sentence."""
        work = []
        if self.busy:
            work.append(f"the design in {self.out_dir} (it stops at its next checkpoint; Design tab, "
                        "Resume... continues it)")
        if self.sweep.busy:
            work.append(f"the sweep in {self.sweep.sweep_dir} (running designs checkpoint, queued ones "
                        "do not start; Sweep again resumes it)")
        return work

    def stop_all(self) -> None:
        """Stop the running design and sweep at their next checkpoints."""
        self.stop()
        self.sweep.stop()

    def set_simcal(self, path: Path | None) -> None:
        """Make a ``simcal.json`` the active simulation calibration (None: none)."""
        self.simcal = None if path is None else load_simcal(path)
        self.status.setText(NO_SIMCAL if self.simcal is None else f"active simulation calibration: "
                            f"{self.simcal.describe()}")

    def use_target(self, target: str) -> None:
        """Take ``target`` (anything ``sfr design --target`` takes) and check it."""
        self.source.setText(str(target))
        self.check()

    def sweep_settings(self) -> tuple[str, dict, str | None]:
        """The target, fixed design settings and simulation calibration a sweep starts from: this form's."""
        return self.source.text().strip(), self.settings(), None if self.simcal is None else str(self.simcal.path)

    def _pick_run(self) -> None:
        path = QFileDialog.getExistingDirectory(self, "measured run", str(self.data_dir))
        if path:
            self.use_target(path)

    def _pick_csv(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "target curve", str(self.data_dir), "CSV (*.csv)")
        if path:
            self.use_target(path)

    def _pick_mesh(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "target mesh", str(self.data_dir), MESH_FILTER)
        if path:
            self.use_target(path)

    def _pick_simcal(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "simulation calibration", str(self.data_dir),
                                              "simulation calibration (simcal.json *.json)")
        if path:
            self.simcal_requested.emit(path)

    # -- checking the target ----------------------------------------------------------------------------
    def check(self) -> None:
        """Show the target's curve and feasibility report (computed in the background)."""
        target = self.source.text().strip()
        if not target or (self.check_task is not None and self.check_task.running):
            return
        space, resolution, simcal = self.space.currentText(), self.resolution.stored(), self.simcal
        self.check_task = BackgroundTask(lambda progress: preview_target(target, space, resolution, simcal), self)
        self.check_task.finished.connect(self._checked)
        self.check_task.failed.connect(self._check_failed)
        self.status.setText(f"checking {target} ...")
        self.check_task.start()

    def _checked(self, preview: TargetPreview) -> None:
        self.preview = preview
        self.target_curve.setData(preview.tau_mm, preview.released_mm3)
        self.achieved_curve.setData([], [])
        if preview.measured is not None:
            self.physical_target.setData(*preview.measured)
            self.physical_design.setData([], [])
            for curve in self.physical_band:
                curve.setData([], [])
        self.curves.setCurrentIndex(0)
        note = f"\n{preview.adjustment}" if preview.adjustment else ""
        warnings = "".join(f"\nWarning: {w}" for w in preview.warnings)
        self.status.setText(f"Target {self.source.text().strip()}: {preview.released_mm3[-1]:.4g} mm\u00b3 over "
                            f"tau {preview.tau_mm[-1]:.4g} mm.\n{preview.report[:1].upper()}{preview.report[1:]}"
                            f"{note}{warnings}")

    def _check_failed(self, message: str) -> None:
        self.status.setText(f"target not usable: {message}")

    # -- designing ----------------------------------------------------------------------------------------
    def start(self) -> None:
        """Run the design in the background (a measured target is converted through the simulation calibration)."""
        text = self.source.text().strip()
        source = Path(text)
        if self.barrier_speed.text().strip():
            self._start_barrier(text)
            return
        named = text in SAMPLE_SHAPES or text.startswith(("zero-order", "accel:"))
        if not text or (not named and not source.exists()):
            self.status.setText(f"{text or 'the target'} does not exist: choose a run, a CSV, a mesh, a sample "
                                "shape or an analytic target")
            return
        wrong = problems([self.resolution, self.max_iter])
        if wrong:
            self.status.setText("\n".join(wrong))
            return
        name = source.stem if source.exists() else text.replace(":", "_").replace("=", "").replace(",", "_")
        self.out_dir = design_folder(self.data_dir, name)
        config = DesignConfig(target=str(source) if source.exists() else text, **self.settings())
        self._run(config, self.out_dir, resume=False)

    def barrier_settings(self, target: str):
        """The two-material design settings of the form (``sfr design --barrier-speed``), checked.

        Raises
        ------
        design.DesignError
            For a barrier speed that is not a number >= 0, or a space, resolution or iteration count a
            two-material design does not take."""
        from design.forward.twomaterial import check_barrier_speed
        from design.inverse.twomaterial_problem import TwoMaterialSettings

        form = self.settings()
        return TwoMaterialSettings(target=target, barrier_speed=check_barrier_speed(self.barrier_speed.text().strip()),
                                   space=form["space"], resolution=int(form["resolution"]),
                                   max_iter=int(form["max_iter"]))

    def _start_barrier(self, target: str) -> None:
        """Run a two-material design (`labapp.jobs.design_barrier.design_barrier`, as ``sfr design --barrier-speed``)."""
        from design.errors import DesignError
        from design.inverse.twomaterial_targets import is_two_material_spec

        if not is_two_material_spec(target) and not Path(target).is_file():
            self.status.setText(f"{target or 'the target'}: a two-material design takes delay-zero:, pulses:, "
                                "constant: or a tau_mm,released_mm3 CSV")
            return
        wrong = problems([self.resolution, self.max_iter])
        try:
            settings = None if wrong else self.barrier_settings(target)
        except DesignError as exc:
            wrong = [f"barrier: {exc}"]
        if wrong:
            self.status.setText("\n".join(wrong))
            return
        self._run_barrier(settings, design_folder(self.data_dir, Path(target).stem if Path(target).exists()
                                                  else target.replace(":", "_").replace("=", "").replace(",", "_")))

    def _run_barrier(self, settings, out_dir: Path) -> None:
        """Start (``settings``) or resume (None) the two-material run in ``out_dir`` off the GUI thread, through the
        job function ``sfr design --barrier-speed`` and ``sfr design --resume`` call."""
        from design.errors import DesignError
        from design.files.twomaterial_run import load_settings
        from labapp.jobs.design_barrier import design_barrier

        if self.busy:
            self.status.setText("a design is running; stop it first")
            return
        resume = settings is None
        try:
            stored = load_settings(out_dir) if resume else settings
        except DesignError as exc:
            self.status.setText(f"design failed: {exc}")
            return
        self._stop.clear()
        self.out_dir, self._max_iter = out_dir, stored.max_iter

        def work(progress):
            return design_barrier(settings, out_dir, resume=resume,
                                  on_iteration=lambda k, terms: progress((k, terms, None)), should_stop=self._stop.is_set)
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self._progress)
        self.task.finished.connect(self._barrier_finished)
        self.task.failed.connect(self._failed)
        self.task.start()
        for button, enabled in ((self.start_button, False), (self.resume_button, False), (self.stop_button, True)):
            button.setEnabled(enabled)
        self.progress.setRange(0, max(1, self._max_iter))
        self.progress.setValue(0)
        self.progress.setFormat("starting ...")
        self.status.setText(f"{'resuming' if resume else 'designing'} drug and barrier (barrier speed {stored.barrier_speed:g}) "
                            f"{'in' if resume else 'into'} {out_dir} ...")

    def _barrier_finished(self, result) -> None:
        for button, enabled in ((self.start_button, True), (self.resume_button, True), (self.stop_button, False)):
            button.setEnabled(enabled)
        if result.summary is None:
            self.progress.setFormat("stopped: Resume... continues it")
            self.status.setText(f"two-material design stopped: the best design so far is in {result.out}; Resume... "
                                "continues it")
            return
        self.progress.setValue(self.progress.maximum())
        self.progress.setFormat(f"two-material design {result.status}")
        self.status.setText(f"two-material design {result.status}: design.stl (drug), barrier.stl and the two-object "
                            f"3MF in {result.out}")

    def resume(self, folder: str | Path | None = None) -> None:
        """Continue a stopped design, one-material or two-material (``sfr design --resume``): ``folder``, or one
        chosen in a dialog."""
        if not folder:
            folder = QFileDialog.getExistingDirectory(self, "design folder to resume", str(self.data_dir / "designs"))
            if not folder:
                return
        from design.files.twomaterial_run import is_two_material_run

        if is_two_material_run(folder):
            self._run_barrier(None, Path(folder))
            return
        self.out_dir = Path(folder)
        self._run(None, self.out_dir, resume=True)

    def _run(self, config: DesignConfig | None, out_dir: Path, resume: bool) -> None:
        if self.busy:
            self.status.setText("a design is running; stop it first")
            return
        self._stop.clear()
        simcal = self.simcal
        self._max_iter = config.max_iter if config is not None else _stored_max_iter(out_dir)

        def work(progress):  # a resume uses the calibration the run started with, kept in its folder
            return design_job(config, out_dir, resume=resume, simcal=None if resume else simcal,
                              on_iteration=lambda k, x, terms: progress((k, terms, mid_slice(x, k))),
                              should_stop=self._stop.is_set)
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self._progress)
        self.task.finished.connect(self._finished)
        self.task.failed.connect(self._failed)
        self.task.start()
        self.start_button.setEnabled(False)
        self.resume_button.setEnabled(False)
        self.stop_button.setEnabled(True)
        self.progress.setRange(0, max(1, self._max_iter))
        self.progress.setValue(0)
        self.progress.setFormat("starting ...")
        self.status.setText(f"{'resuming' if resume else 'designing into'} {out_dir} ...")

    def stop(self) -> None:
        """Ask the optimiser to stop at its next checkpoint (the best design so far is still written; Resume...
        continues it)."""
        self._stop.set()
        if self.busy:
            self.progress.setFormat("stopping at the next checkpoint ...")

    def _progress(self, update: tuple) -> None:
        k, terms, image = update
        phase = f"{terms['phase']}, " if "phase" in terms else ""
        eta = terms.get("eta_s")
        left = f", about {hmm(eta, seconds=True)} left" if eta is not None and np.isfinite(eta) else ""
        self.progress.setValue(min(k, self.progress.maximum()))
        self.progress.setFormat(f"{phase}iteration {k} of {self._max_iter}{left}")
        self.status.setText(f"{phase}iteration {k} of {self._max_iter}: J = {terms.get('J', float('nan')):.5g}, "
                            f"fit {terms.get('J_fit', float('nan')):.4g}{left}")
        if image is not None:
            self.solid.show_variables(image)

    def _finished(self, outcome) -> None:
        result, physical = outcome
        self.start_button.setEnabled(True)
        self.resume_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        stopped = not DesignStatus(result.status).finished
        self.progress.setFormat("stopped: Resume... continues it" if stopped else "done")
        self.progress.setValue(self.progress.maximum() if not stopped else self.progress.value())
        curves = read_curves(result.out_dir / "curves.csv")
        self.target_curve.setData(curves["tau_mm"], curves["target_mm3"])
        # the print's release (a design recorded before it was computed: the design grid's binary solid)
        self.achieved_curve.setData(curves["tau_mm"], curves["print_mm3" if "print_mm3" in curves else "binary_mm3"])
        self.save_button.setEnabled((result.out_dir / "design.stl").is_file())
        density = result.out_dir / "density.npz"
        if density.is_file():
            with np.load(density) as data:
                self.solid.show_solid(data["solid"], float(data["dx_mm"]))
        if physical is not None:
            rows = read_curves(result.out_dir / "curves_physical.csv")
            self.physical_target.setData(rows["t_s"], rows["target_released_g"])
            self.physical_design.setData(rows["t_s"], rows["design_released_g"])
            for curve, column in zip(self.physical_band, (f"design_released_g_{q}" for q in quantile_columns())):
                curve.setData(rows["t_s"] if column in rows else [], rows.get(column, []))   # the prediction's band
        # the lines sfr design prints, each shown as a sentence
        lines = summary_lines(physical or result.outputs.summary, result.out_dir)
        self.status.setText("\n".join(line[:1].upper() + line[1:] for line in [f"design {lines[0]}", *lines[1:]]))

    def _failed(self, message: str) -> None:
        self.start_button.setEnabled(True)
        self.resume_button.setEnabled(True)
        self.stop_button.setEnabled(False)
        self.progress.setFormat("failed")
        self.status.setText(f"design failed: {message}")

    def _save(self) -> None:
        if self.out_dir is None:
            return
        path, _ = QFileDialog.getSaveFileName(self, "save STL", "design.stl", "STL (*.stl)")
        if path:
            shutil.copyfile(self.out_dir / "design.stl", path)


def _stored_max_iter(out_dir: Path) -> int:
    """The iteration budget a design folder was started with (0 when unreadable: the job reports why)."""
    try:
        return int(load_config(Path(out_dir)).max_iter)
    except Exception:
        return 0
