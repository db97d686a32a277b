"""The calibration wizard: the bench series (clear water, then add filament / enter mass / capture, repeat, fit,
save) and the simulation step (measured runs + their meshes -> ``simcal.json``, made active)."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtCore import Signal
from PySide6.QtGui import QPixmap
from PySide6.QtWidgets import (
    QFileDialog,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from design.files.meshio import MESH_SUFFIXES
from labapp.acquisition.settings import ADDED_MASS, parse_masses
from labapp.gui.bridge import BackgroundTask
from labapp.gui.fields import SettingBox, narrow_form
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.records.fileio import timestamp_name
from labapp.records.simcalset import SET_COLUMNS


class CalibrationWizard(QWidget):
    """Guides a calibration series. Emits ``start_requested``; while the engine asks for a mass, the operator
    enters it and presses "Capture" (``mass_entered(value)``), "Redo last level" (``redo_requested``: the
    last level is captured again and replaces its frame) or "Finish and fit" (``finish_requested``). A mass
    not above the last one is refused by the series, which asks again without capturing. The bath (water,
    temperature, stirring) is set in the device panel. ``simcal_activated(path)`` passes on the simulation
    step's."""

    start_requested = Signal()
    mass_entered = Signal(float)
    redo_requested = Signal()
    finish_requested = Signal()
    simcal_activated = Signal(str)

    def __init__(self, simulate: bool, data_dir: Path | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.simulation = SimulationStep(Path(data_dir) if data_dir is not None else Path.cwd())
        self.simulation.simcal_activated.connect(self.simcal_activated)
        self.masses = QLineEdit("0.25, 0.5, 0.875, 1.25, 1.75" if simulate else "")
        self.masses.setToolTip("cumulative masses added by the simulated bench by itself; empty: ask each time")
        self.masses.setEnabled(simulate)
        self.mass = SettingBox(ADDED_MASS)
        self.step_label = QLabel("1. set the crop in the live view  2. start: the clear-water frame is captured")
        self.step_label.setWordWrap(True)
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.start_button = QPushButton("Start series")
        self.capture_button = QPushButton("Capture")
        self.redo_button = QPushButton("Redo last level")
        self.redo_button.setToolTip("capture the last level again (a bubble, a hand in the picture); the new frame "
                                    "replaces it in masses.csv and the replacement is logged")
        self.finish_button = QPushButton("Finish and fit")
        self.start_button.clicked.connect(self.start_requested)
        self.capture_button.clicked.connect(self._capture)
        self.redo_button.clicked.connect(self.redo_requested)
        self.finish_button.clicked.connect(self.finish_requested)
        self.mass.problem_changed.connect(self._mass_checked)
        self._asking = False
        box = QGroupBox("calibration series (paper section 4.2)")
        form = narrow_form(box)
        form.addRow("simulated masses", self.masses)
        self.mass.add_to(form, "cumulative mass added")
        row = QHBoxLayout()
        for b in (self.start_button, self.capture_button, self.redo_button, self.finish_button):
            row.addWidget(b)
        layout = QVBoxLayout(self)
        layout.addWidget(box)
        layout.addLayout(row)
        layout.addWidget(self.step_label)
        layout.addWidget(self.result_label)
        layout.addWidget(self.simulation, 1)
        self.set_asking(False, "")

    def masses_g(self) -> tuple[float, ...]:
        """The cumulative masses the simulated bench adds by itself, g (empty: the operator enters each).

        Raises
        ------
        UsageError
            For an entry that is not a number.
        """
        return parse_masses(self.masses.text()) if self.masses.isEnabled() else ()

    def use_bench_calibration(self, path: Callable[[], str | None]) -> None:
        """Give the simulation step the active bench calibration: ``path()`` is its path (None: each run's
        own)."""
        self.simulation.bench_calibration = path

    def _capture(self) -> None:
        self.mass_entered.emit(self.mass.stored())

    def _mass_checked(self, problem: str) -> None:
        self.capture_button.setEnabled(self._asking and not problem)

    def set_asking(self, asking: bool, text: str) -> None:
        """Enable the capture/redo/finish buttons while the engine waits for a mass."""
        self._asking = asking
        self.capture_button.setEnabled(asking and not self.mass.problem())
        self.redo_button.setEnabled(asking)
        self.finish_button.setEnabled(asking)
        if text:
            self.step_label.setText(text)

    def show_result(self, text: str) -> None:
        """Show the outcome (calibration path or what went wrong)."""
        self.result_label.setText(text)


class SimulationStep(QWidget):
    """The simulation step (paper section 4.3): runs with their meshes and weighed masses in a table,
    ``labapp.jobs.calibrate_sim.calibrate_sim`` in the background, the leave-one-out figure, and "Make active".

    Emits ``simcal_activated(path)`` with the ``simcal.json`` the operator made active. ``bench_calibration``
    is a callable giving the active bench calibration's path (None: each run's own).
    """

    simcal_activated = Signal(str)

    def __init__(self, data_dir: Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.data_dir = Path(data_dir)
        self.bench_calibration: Callable[[], str | None] = lambda: None
        self.table = QTableWidget(0, len(SET_COLUMNS))
        self.table.setHorizontalHeaderLabels(["run (folder or curve CSV)", "mesh", "weighed mass (g, empty: run's)"])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)  # scrolls inside
        self.add_button, self.load_button = QPushButton("Add run + mesh..."), QPushButton("Load set CSV...")
        self.calibrate_button, self.activate_button = QPushButton("Calibrate"), QPushButton("Make active")
        self.add_button.clicked.connect(self._pick_row)
        self.load_button.clicked.connect(self._pick_set)
        self.calibrate_button.clicked.connect(self.calibrate)
        self.activate_button.clicked.connect(self.activate)
        self.activate_button.setEnabled(False)
        self.result = QLabel("measured runs of differently shaped objects (4 or more), each with its mesh")
        self.result.setWordWrap(True)
        self.figure = QLabel("")
        self.figure.setScaledContents(False)
        self.path: Path | None = None
        self.task: BackgroundTask | None = None
        box = QGroupBox("simulation calibration (paper section 4.3)")
        box.setToolTip("fits the simulation's time scale (seconds per mm) and mass scale (grams per mm^3) to "
                       "measured runs")
        inner = QVBoxLayout(box)
        inner.addWidget(self.table, 1)
        buttons = QGridLayout()           # two by two: the dock stays narrow
        for i, b in enumerate((self.add_button, self.load_button, self.calibrate_button, self.activate_button)):
            buttons.addWidget(b, i // 2, i % 2)
        inner.addLayout(buttons)
        inner.addWidget(self.result)
        inner.addWidget(self.figure, 2)
        QVBoxLayout(self).addWidget(box)

    def add_row(self, run: str | Path, mesh: str | Path, mass_g: float | None = None) -> None:
        """Append a run, its mesh and its weighed mass (None: the run's recorded mass)."""
        r = self.table.rowCount()
        self.table.insertRow(r)
        for c, text in enumerate((str(run), str(mesh), "" if mass_g is None else f"{mass_g:g}")):
            self.table.setItem(r, c, QTableWidgetItem(text))

    def _pick_row(self) -> None:
        run = QFileDialog.getExistingDirectory(self, "measured run", str(self.data_dir))
        if not run:
            return
        mesh, _ = QFileDialog.getOpenFileName(self, "its mesh", str(self.data_dir),
                                              f"meshes ({' '.join('*' + s for s in MESH_SUFFIXES)})")
        if mesh:
            self.add_row(run, mesh)

    def _pick_set(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "calibration set", str(self.data_dir), "CSV (*.csv)")
        if path:
            self.load_set(Path(path))

    def load_set(self, path: Path) -> None:
        """Fill the table from a ``run,mesh,object_mass_g`` file (paths made absolute)."""
        from labapp.records.simcalset import read_set

        for row in read_set(path):
            self.add_row(row.run.resolve(), row.mesh.resolve(), row.object_mass_g)

    def write_set(self, path: Path) -> Path:
        """The table as a set file (absolute paths)."""
        lines = [",".join(SET_COLUMNS)]
        for r in range(self.table.rowCount()):
            cells = [(self.table.item(r, c).text().strip() if self.table.item(r, c) else "") for c in range(3)]
            lines.append(",".join(str(Path(cells[i]).resolve()) if i < 2 else cells[i] for i in range(3)))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("\n".join(lines) + "\n")
        return path

    def calibrate(self) -> None:
        """Run ``calibrate_sim`` on the table into a new folder under ``DATA/simcal`` (in the background)."""
        if self.task is not None and self.task.running:
            return
        out = self.data_dir / "simcal" / timestamp_name()
        set_csv = self.write_set(out.with_name(out.name + "_set.csv"))
        bench = self.bench_calibration()

        def work(progress):
            return calibrate_sim(set_csv, bench, out, progress=lambda f, m: progress(m))
        self.task = BackgroundTask(work, self)
        self.task.progress.connect(self.result.setText)
        self.task.finished.connect(self._finished)
        self.task.failed.connect(self._failed)
        self.task.start()
        self.activate_button.setEnabled(False)
        self.result.setText(f"calibrating into {out} ...")

    def _failed(self, message: str) -> None:
        self.result.setText(f"calibration failed: {message}")

    def _finished(self, run) -> None:
        doc = run.doc
        self.path = run.path
        lines = [f"{doc['model']} model: {doc['seconds_per_mm']:.1f} s/mm, {doc['g_per_mm3'] * 1000:.4f} g/cm^3; "
                 "leave-one-out rel. RMSE " + ", ".join(f"{Path(r['mesh']).stem} {100 * r['rel_rmse']:.2f}%"
                                                        for r in doc["loo"])]
        lines += [f"{m}: mean {100 * v['loo_rel_rmse_mean']:.2f}%" for m, v in doc["models"].items()]
        if doc.get("band"):
            cov = doc["band"]["loo_coverage"]
            lines.append(f"{100 * doc['band']['level']:.0f}% bands: {100 * cov['fraction']:.0f}% of held-out points inside")
        self.result.setText("; ".join(lines) + f" ({run.path})")
        self.figure.setPixmap(QPixmap(str(run.path.with_name("simcal.png"))).scaledToWidth(700))
        self.activate_button.setEnabled(True)

    def activate(self) -> None:
        """Make the last calibration the active one."""
        if self.path is not None:
            self.simcal_activated.emit(str(self.path))
            self.result.setText(self.result.text() + " - now the active simulation calibration")
