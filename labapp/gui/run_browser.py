"""Run browser: past runs (interrupted ones too), reanalysis with other settings, resume, finalise, verify, and
f2 between two runs or a run and its prediction."""
from __future__ import annotations

import csv
import logging
import math
import re
import time
from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QDoubleSpinBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QMessageBox,
    QPushButton,
    QSpinBox,
    QSplitter,
    QTabWidget,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from analysis import RunCurve
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
from labapp.errors import UsageError
from labapp.gui import dialogs
from labapp.gui.bridge import BackgroundTask
from labapp.gui.overlay import PhysicalOverlay, prediction_curve, run_curve
from labapp.gui.plots import PlotsPanel
from labapp.gui.signing import save_report, sign_record
from labapp.jobs.analyse import analyse_run, writes_into_record
from labapp.jobs.compare import Comparison, compare_curves
from labapp.jobs.run import finalise, resumable
from labapp.jobs.verify import verify as verify_folder
from labapp.records.fileio import StorageError
from labapp.records.manifests import RunSnapshot, read_run
from labapp.records.outpaths import ANALYSIS_SUBFOLDER, folder_kind
from labapp.records.runrecord import RecordKind, RecordStatus

log = logging.getLogger(__name__)
FRAMES_COLUMN = 3


def list_runs(data_dir: Path) -> list[RunSnapshot]:
    """Snapshots of every run folder directly under ``data_dir``, newest first (unreadable ones skipped)."""
    runs = []
    for path in sorted(Path(data_dir).glob("*/run.json"), reverse=True):
        try:
            runs.append(read_run(path.parent))
        except StorageError as exc:
            log.warning("skipping %s: %s", path.parent, exc)
    return runs


def interrupted_runs(data_dir: Path) -> list[RunSnapshot]:
    """The acquisition runs under ``data_dir`` that stopped without finishing and can be resumed, newest first."""
    return [snap for snap in list_runs(data_dir) if snap.status == RecordStatus.INTERRUPTED
            and snap.record.kind == RecordKind.RUN and not snap.live]


def resume_offer(parent: QWidget, data_dir: Path, runs: list[RunSnapshot]) -> QMessageBox:
    """A question (not yet shown) naming the interrupted ``runs`` in ``data_dir``, newest first, and offering to
    resume the newest: its buttons' roles are accept (resume the newest), action (show it in the Runs tab) and
    reject (not now)."""
    names = "\n".join(f"  {snap.path.name} ({len(snap.frames)} frames)" for snap in runs[:8])
    box = QMessageBox(QMessageBox.Icon.Question, "interrupted runs",
                      f"{len(runs)} run(s) in {data_dir} stopped without finishing:\n{names}\n\n"
                      f"Resume {runs[0].path.name} now? (Later: Runs tab, Resume acquisition.)", parent=parent)
    box.addButton("Resume newest", QMessageBox.ButtonRole.AcceptRole)
    box.addButton("Show in Runs", QMessageBox.ButtonRole.ActionRole)
    box.addButton("Not now", QMessageBox.ButtonRole.RejectRole)
    return box


def frame_files(folder: Path) -> list[str]:
    """The frames listed in a folder's ``frames.csv`` (any layout), else its JPEG files."""
    try:
        with open(folder / "frames.csv", newline="") as fh:
            return [row["file"] for row in csv.DictReader(fh) if row.get("file")]
    except (OSError, KeyError, csv.Error):
        return sorted(p.name for p in folder.glob("*.jp*g"))


class RunBrowser(QWidget):
    """Lists runs under the data directory; the selected one can be reanalysed, resumed or finalised, and
    compared (f2) with a second selected run or with a prediction file.

    Emits ``resume_requested(path)`` (the main window resumes acquisition into that folder).
    """

    resume_requested = Signal(str)
    design_requested = Signal(str)

    def __init__(self, data_dir: Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.data_dir = Path(data_dir)
        self.tree = QTreeWidget()
        self.tree.setHeaderLabels(["run", "kind", "status", "frames", "created"])
        self.tree.setSelectionMode(QTreeWidget.SelectionMode.ExtendedSelection)
        self.tree.itemSelectionChanged.connect(self._selected)
        self.tree.setTextElideMode(Qt.TextElideMode.ElideMiddle)      # 20261202-...-name keeps both ends
        self.tree.setUniformRowHeights(True)
        header = self.tree.header()
        header.setStretchLastSection(False)
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        for column in range(1, FRAMES_COLUMN + 2):
            header.setSectionResizeMode(column, QHeaderView.ResizeMode.ResizeToContents)
        self.opened: list[Path] = []
        """Folders opened from elsewhere (File > Open run...), listed after the data directory's runs."""
        self.window = QDoubleSpinBox()
        self.window.setRange(11.0, 7200.0)
        self.window.setValue(DEFAULT_WINDOW_S)
        self.window.setSuffix(" s")
        self.order = QSpinBox()
        self.order.setRange(0, 6)
        self.order.setValue(DEFAULT_ORDER)
        self.calibration = QLineEdit("")
        self.calibration.setPlaceholderText("calibration JSON (default: the run's own copy)")
        self.prediction = QLineEdit("")
        self.prediction.setPlaceholderText("prediction to compare the run with (release_physical.csv, "
                                           "curves_physical.csv or any t_s,released_g CSV)")
        self.info = QLabel("")
        self.info.setWordWrap(True)
        self.plots = PlotsPanel(orientation=Qt.Orientation.Horizontal)
        self.overlay = PhysicalOverlay()
        self.simcal = None                     # the active simulation calibration (set by the main window)
        self.mesh = QLineEdit("")
        self.mesh.setPlaceholderText("mesh or sample:NAME to overlay as predicted through the active simulation "
                                     "calibration")
        overlay_buttons = QHBoxLayout()
        for text, slot in (("Overlay selected runs", self.overlay_runs), ("Overlay prediction", self.overlay_prediction),
                           ("Clear overlay", self.overlay.clear), ("Design from run", self._design)):
            button = QPushButton(text)
            button.clicked.connect(slot)
            overlay_buttons.addWidget(button)
        overlay_buttons.addWidget(self.mesh, 1)
        buttons = QHBoxLayout()
        self.refresh_button = QPushButton("Refresh")
        self.analyse_button = QPushButton("Reanalyse")
        self.resume_button = QPushButton("Resume acquisition")
        self.finalise_button = QPushButton("Finalise")
        self.verify_button = QPushButton("Verify")
        self.sign_button = QPushButton("Sign...")
        self.report_button = QPushButton("Report...")
        self.compare_button = QPushButton("f2")
        self.compare_button.setToolTip("f2 (and f1, MDT, DE) of two selected runs, the first selected the "
                                       "reference, or of the selected run and the prediction")
        for b, slot in ((self.refresh_button, self.refresh), (self.analyse_button, self.reanalyse),
                        (self.resume_button, self._resume), (self.finalise_button, self._finalise),
                        (self.verify_button, self._verify), (self.compare_button, self.compare),
                        (self.sign_button, self._sign), (self.report_button, self._report)):
            b.clicked.connect(slot)
            buttons.addWidget(b)
        settings = QHBoxLayout()
        settings.addWidget(QLabel("Savitzky-Golay window"))
        settings.addWidget(self.window)
        settings.addWidget(QLabel("order"))
        settings.addWidget(self.order)
        settings.addWidget(self.calibration, 1)
        top = QWidget()
        top_layout = QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addWidget(self.tree, 1)
        top_layout.addLayout(buttons)
        top_layout.addLayout(settings)
        top_layout.addWidget(self.prediction)
        top_layout.addWidget(self.info)
        overlay_page = QWidget()
        overlay_layout = QVBoxLayout(overlay_page)
        overlay_layout.setContentsMargins(0, 0, 0, 0)
        overlay_layout.addWidget(self.overlay, 1)
        overlay_layout.addLayout(overlay_buttons)
        self.views = QTabWidget()
        self.views.addTab(self.plots, "release and bath")
        self.views.addTab(overlay_page, "overlay (g over h)")
        self.splitter = QSplitter(Qt.Orientation.Vertical)
        self.splitter.addWidget(top)
        self.splitter.addWidget(self.views)
        self.splitter.setStretchFactor(0, 1)
        self.splitter.setStretchFactor(1, 1)
        self.splitter.setChildrenCollapsible(False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(self.splitter)
        self.task: BackgroundTask | None = None
        self.overlay_task: BackgroundTask | None = None
        self.refresh()

    def refresh(self) -> None:
        """Re-read the data directory (the selection is kept)."""
        selected = self.selected_paths()
        self.tree.blockSignals(True)
        self.tree.clear()
        for snap in list_runs(self.data_dir):
            created = time.strftime("%Y-%m-%d %H:%M", time.localtime(snap.record.created_unix_s or 0))
            self._add_item(snap.path, [snap.path.name, snap.record.kind, snap.status, str(len(snap.frames)), created])
        for path in self.opened:
            try:
                snap = read_run(path)
                row = [path.name, snap.record.kind, snap.status, str(len(snap.frames)),
                       time.strftime("%Y-%m-%d %H:%M", time.localtime(snap.record.created_unix_s or 0))]
            except StorageError:
                row = [path.name, str(folder_kind(path) or "-"), "not a run record", str(len(frame_files(path))), ""]
            self._add_item(path, row)
        for i in range(self.tree.topLevelItemCount()):
            item = self.tree.topLevelItem(i)
            item.setSelected(Path(item.data(0, 256)) in selected)
        self.tree.blockSignals(False)
        self._selected()

    def show_frames(self, folder: str | Path, n_frames: int) -> None:
        """The live frame count of a run still recording (a slot fed by each stored frame), in its row and, when
        it is selected, in the info line."""
        folder = Path(folder)
        for i in range(self.tree.topLevelItemCount()):
            item = self.tree.topLevelItem(i)
            if Path(item.data(0, 256)) == folder:
                item.setText(FRAMES_COLUMN, str(n_frames))
                if item.isSelected() and len(self.tree.selectedItems()) == 1:
                    self.info.setText(re.sub(r", \d+ frames,", f", {n_frames} frames,", self.info.text(), count=1))

    def _add_item(self, path: Path, row: list[str]) -> None:
        item = QTreeWidgetItem([str(v) for v in row])
        item.setData(0, 256, str(path))
        item.setToolTip(0, str(path))
        self.tree.addTopLevelItem(item)

    def open_folder(self, path: Path) -> None:
        """List a run folder from anywhere (a run record, or a folder of frames the analysis reads) and select it.

        Raises
        ------
        UsageError
            When ``path`` is not a folder or holds no frames.
        """
        path = Path(path).resolve()
        if not path.is_dir():
            raise UsageError(f"{path} is not a folder")
        if not (path / "run.json").is_file() and not frame_files(path):
            raise UsageError(f"{path} holds no run.json and no frames: not a run folder")
        if path.parent.resolve() != self.data_dir.resolve() and path not in self.opened:
            self.opened.append(path)
        self.refresh()
        self.select(path)

    def selected_path(self) -> Path | None:
        """The selected run folder."""
        items = self.tree.selectedItems()
        return Path(items[0].data(0, 256)) if items else None

    def selected_paths(self) -> list[Path]:
        """The selected run folders, in the order they were selected."""
        return [Path(item.data(0, 256)) for item in self.tree.selectedItems()]

    def select(self, path: Path) -> None:
        """Select the run at ``path`` (after :meth:`refresh`)."""
        for i in range(self.tree.topLevelItemCount()):
            item = self.tree.topLevelItem(i)
            if Path(item.data(0, 256)) == Path(path):
                self.tree.setCurrentItem(item)

    def _selected(self) -> None:
        path = self.selected_path()
        has = path is not None
        try:
            snap = read_run(path) if has else None
        except StorageError as exc:
            snap = None
            if has:
                self.info.setText(f"{path}: not a run record of this application ({exc}); a folder of "
                                  f"{len(frame_files(path))} frames: Reanalyse reads it with a calibration JSON")
        for b in (self.analyse_button, self.verify_button):
            b.setEnabled(has)
        self.verify_button.setEnabled(snap is not None)
        interrupted = snap is not None and snap.status == RecordStatus.INTERRUPTED
        self.resume_button.setEnabled(interrupted and snap.record.kind == RecordKind.RUN)
        self.finalise_button.setEnabled(interrupted)
        if snap is None:
            if has:
                self.plots.clear()
                self._show_analysis(path)
            return
        self.info.setText(f"{snap.path}: {snap.status}, {len(snap.frames)} frames, {len(snap.record.gaps)} gaps"
                          + (f", torn last row of {snap.torn_bytes} bytes" if snap.torn_bytes else ""))
        self.plots.clear()
        for f in snap.frames:
            self.plots.add_reading(f.t_s, f.plate_c, f.probe_c, f.speed_rpm)
        config = snap.record.config or {}
        self.plots.set_setpoint_band(config.get("setpoint_c"), config.get("tolerance_c"))
        self.plots.set_object_mass(snap.record.object_mass_g)
        if snap.frames:
            self.plots.mark("drop", 0.0, "drop")
        for gap in snap.record.gaps:
            self.plots.mark("gap", gap.after_t_s, "gap", end_s=gap.before_t_s)
        self._show_analysis(path)

    def _show_analysis(self, path: Path) -> None:
        """The release curve of an analysed run (``RUN/analysis/curve.csv``), if it has one."""
        curve_csv = self.analysis_dir(path) / "curve.csv"
        if not curve_csv.is_file():
            self.plots.release.setTitle("release: not analysed yet (press Reanalyse)")
            self.info.setText(f"{self.info.text()}; no analysis yet: press Reanalyse to see its release curve")
            return
        self.plots.release.setTitle("release")
        try:
            with open(curve_csv, newline="") as fh:
                rows = list(csv.DictReader(fh))
            for row in rows:
                self.plots.add_frame(float(row["t_s"]), float(row["conc_g_per_kg"]))
        except (OSError, KeyError, ValueError) as exc:
            log.warning("%s: cannot show the curve: %s", curve_csv, exc)

    def analysis_dir(self, path: Path) -> Path:
        """Where a folder's analysis goes: ``RUN/analysis`` for the data directory's runs and opened run records;
        for an opened folder of another layout, ``DATA/analyses/<name>`` (the folder itself is not written)."""
        if path.parent.resolve() == self.data_dir.resolve() or _is_record(path):
            return path / ANALYSIS_SUBFOLDER
        return self.data_dir / "analyses" / path.name

    def reanalyse(self) -> None:
        """Analyse the selected run with the chosen calibration and smoothing (in the background), writing
        ``RUN/analysis/curve.csv``, ``cells.csv`` and ``curve.png`` as ``sfr analyze`` does."""
        path = self.selected_path()
        if path is None or (self.task is not None and self.task.running):
            return
        cal_text = self.calibration.text().strip()
        cal_path = Path(cal_text) if cal_text else path / "calibration.json"
        if not cal_path.is_file():
            self.info.setText(f"no calibration: {cal_path} does not exist; choose a calibration JSON")
            return
        window, order = self.window.value(), self.order.value()
        out = self.analysis_dir(path)
        reason = None
        if writes_into_record(path, out):      # audited as `sfr analyze --reason` is: ask why, optional as there
            question = dialogs.reanalyse_question(path.name, f"{path.name}/{out.relative_to(path)}", cal_path.name)
            reason = dialogs.ask_reason(self, question, required=False)
            if reason is None:
                return

        def work(progress):
            return analyse_run(path, cal_path, out, window_s=window, order=order, reason=reason or None,
                               progress=lambda done, total: progress((done, total))).curve
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self._progress)
        self.task.finished.connect(self.show_curve)
        self.task.failed.connect(self.info.setText)
        self.task.start()

    def compare(self) -> None:
        """f2 between the two selected runs (the first selected is the reference), or between the selected
        run (the reference) and the prediction file, through the job of ``sfr compare`` (in the background).
        A run is read from its analysis (``RUN/analysis/curve.csv``) when it has one."""
        paths = self.selected_paths()
        prediction = self.prediction.text().strip()
        if len(paths) == 2:
            a, b = paths
        elif len(paths) == 1 and prediction:
            a, b = paths[0], Path(prediction)
        else:
            self.info.setText("f2: select two runs, or one run and give a prediction file")
            return
        if self.task is not None and self.task.running:
            return
        sources = [p / ANALYSIS_SUBFOLDER if (p / ANALYSIS_SUBFOLDER / "curve.csv").is_file() else p for p in (a, b)]
        self.task = BackgroundTask(lambda progress: compare_curves(*sources), self)
        self.task.finished.connect(self.show_comparison)
        self.task.failed.connect(self._comparison_failed)
        self.task.start()

    def show_comparison(self, result: Comparison) -> None:
        """Slot: f1/f2, MDT and DE of a comparison in the info line."""
        s = result.similarity
        head = (f"f2 = {s.f2:.1f} ({'similar' if s.similar else 'not similar'}), f1 = {s.f1:.1f} on "
                f"{s.points_used} points" if s.f2 is not None else f"f2 not reported: {s.reason}")
        self.info.setText(f"{head}\nA {result.a.source}: MDT {result.a.mdt_s:.0f} s, DE {result.a.de_pct:.1f} %\n"
                          f"B {result.b.source}: MDT {result.b.mdt_s:.0f} s, DE {result.b.de_pct:.1f} %")

    def _comparison_failed(self, message: str) -> None:
        self.info.setText(f"f2: {message}")

    def _progress(self, done_total: tuple[int, int]) -> None:
        self.info.setText(f"analysing frame {done_total[0]} of {done_total[1]}")

    def show_curve(self, curve: RunCurve) -> None:
        """Slot: plot a reanalysed run's curve."""
        self.plots.smooth_window_s, self.plots.smooth_order = self.window.value(), self.order.value()
        self.plots.set_water(curve.water_g)
        self.plots.t_s.clear()
        self.plots.conc.clear()
        for t, c in zip(curve.t_s, curve.conc_g_per_kg):
            self.plots.add_frame(float(t), float(c))
        final = curve.conc_smooth_g_per_kg[-1] if len(curve.t_s) else math.nan
        self.info.setText(f"{len(curve.t_s)} frames analysed; final {final:.4f} g/kg = "
                          f"{final * curve.water_g / 1000:.4f} g released"
                          + "".join(f"\nwarning: {w}" for w in curve.warnings))

    def overlay_runs(self) -> None:
        """Add every selected run to the physical overlay (grams over hours)."""
        paths = self.selected_paths()
        if paths:
            self._overlay_in_background(lambda: [run_curve(p) for p in paths])

    def _overlay_in_background(self, compute) -> None:
        """Compute curves (analysing a run, simulating a mesh) off the GUI thread, then draw them."""
        if self.overlay_task is not None and self.overlay_task.running:
            self.info.setText("the overlay is still computing the previous curve")
            return
        self.overlay_task = BackgroundTask(lambda progress: compute(), self)
        self.overlay_task.finished.connect(self._overlay_ready)
        self.overlay_task.failed.connect(self.info.setText)
        self.info.setText("computing the overlay ...")
        self.overlay_task.start()

    def _overlay_ready(self, curves) -> None:
        for curve in curves:
            self.overlay.add(*curve)
        self.info.setText(f"overlay: {len(self.overlay.curves)} curves")
        self.views.setCurrentIndex(1)

    def overlay_prediction(self) -> None:
        """Add the mesh's predicted release through the active simulation calibration to the overlay."""
        if self.simcal is None:
            self.info.setText("no active simulation calibration: make one in the calibration wizard first")
            return
        mesh, simcal = self.mesh.text().strip(), self.simcal
        self._overlay_in_background(lambda: [prediction_curve(mesh, simcal)])

    def _design(self) -> None:
        path = self.selected_path()
        if path is not None:
            self.design_requested.emit(str(path))

    def _resume(self) -> None:
        path = self.selected_path()
        if path is None:
            return
        try:
            resumable(path)
        except UsageError as exc:
            self.info.setText(str(exc))
            return
        self.resume_requested.emit(str(path))

    def _finalise(self) -> None:
        """Finalise the selected interrupted run (``labapp.jobs.run.finalise``): asks first, with the reason its
        audit entry carries (required)."""
        path = self.selected_path()
        if path is None:
            return
        try:
            question = dialogs.finalise_question(path.name, len(read_run(path).frames))
        except StorageError as exc:
            self.info.setText(f"cannot finalise: {exc}")
            return
        reason = dialogs.ask_reason(self, question, required=True)
        if reason is None:
            return
        try:
            finalise(path, reason)
        except UsageError as exc:                  # no reason, no longer interrupted, nobody logged in
            self.info.setText(f"not finalised: {exc}")
            return
        self.refresh()
        self.select(path)

    def _verify(self) -> None:
        path = self.selected_path()
        if path is not None:
            lines = verify_folder(path).lines()
            self.info.setText("\n".join(lines[:11] + lines[-1:]))

    def _sign(self) -> None:
        path = self.selected_path()
        if path is not None and sign_record(path, self) is not None:
            self._verify()

    def _report(self) -> None:
        path = self.selected_path()
        if path is not None:
            try:
                out = save_report(path, self)
            except UsageError as exc:
                self.info.setText(f"no report: {exc}")
                return
            if out is not None:
                self.info.setText(f"report written: {out}")


def _is_record(path: Path) -> bool:
    try:
        read_run(path)
    except StorageError:
        return False
    return True
