"""The bench application's main window: a thin face over the engine.

Every button calls the same Qt-free pieces the CLI uses (``Engine``, the jobs ``new_run``, ``resume_run`` and
``new_series``, ``PreviewProcedure``); engine events come in through the :class:`EngineBridge`.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QDockWidget, QMainWindow, QMessageBox, QPlainTextEdit, QSplitter, QTabWidget, QWidget

from analysis import BenchCalibration
from labapp.acquisition.bench import Bench
from labapp.acquisition.calseries import CalibrationProcedure
from labapp.acquisition.clock import make_clock
from labapp.acquisition.devices import make_bench
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import CalibrationLevel, Done, FrameStored, Phase, Preview, Prompt, PromptKind, StateChanged
from labapp.acquisition.procedures import PreviewProcedure
from labapp.acquisition.simbench import SimulatedBench, resume_clock
from labapp.acquisition.status import RunStatus
from labapp.errors import UsageError
from labapp.gui.bridge import EngineBridge, LogBridge
from labapp.gui.calibration_wizard import CalibrationWizard
from labapp.gui.design_launcher import DesignLauncher
from labapp.gui.device_panel import SIMULATED, DevicePanel
from labapp.gui.live_view import LiveView
from labapp.gui.plots import PlotsPanel
from labapp.gui.run_browser import RunBrowser
from labapp.gui.run_controls import RunControls
from labapp.jobs.run import new_run, resumable, resume_run
from labapp.jobs.series import new_series

UI_MS = 100


def decode_preview(data: bytes | None = None, path: str | None = None) -> np.ndarray | None:
    """An RGB (H, W, 3) uint8 image from JPEG bytes or a file (None if undecodable)."""
    if path is not None:
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    else:
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return None if bgr is None else np.ascontiguousarray(bgr[..., ::-1])


class MainWindow(QMainWindow):
    """Device panel, run controls, calibration wizard, run browser and design launcher around a live view
    and live plots.

    Parameters
    ----------
    data_dir : Path
        Where runs and calibration series are stored.
    simulate : bool
        Offer the simulated bench (SimulatedCamera + Heidolph emulator + a dissolving sample object).
    speed : float, optional
        Simulated time acceleration (``inf``: as fast as frames render).
    """

    def __init__(self, data_dir: Path, simulate: bool = False, speed: float | None = None,
                 sample: str = "pill") -> None:
        super().__init__()
        self.setWindowTitle("Shape from Release: bench" + (" (simulated)" if simulate else ""))
        self.data_dir = Path(data_dir)
        self.simulate, self.speed, self.sample = simulate, speed if simulate else None, sample
        self.engine = Engine(make_clock(self.speed))
        self.status = RunStatus()
        self.engine.subscribe(self.status.update)       # before the bridge: the status is current when a signal lands
        self.bridge = EngineBridge(self.engine, self)
        self.sim: SimulatedBench | None = None
        self.procedure = None
        self.latest_frame: str | None = None
        self.crop: tuple[int, int, int] | None = None

        self.devices = DevicePanel(simulate)
        self.controls = RunControls(simulate)
        self.wizard = CalibrationWizard(simulate, self.data_dir)
        self.browser = RunBrowser(self.data_dir)
        self.design = DesignLauncher(self.data_dir)
        self.live = LiveView()
        self.plots = PlotsPanel()
        self.messages = QPlainTextEdit()
        self.messages.setReadOnly(True)
        self.messages.setMaximumBlockCount(2000)

        tabs = QTabWidget()
        tabs.addTab(self.devices, "Devices")
        tabs.addTab(self.controls, "Run")
        tabs.addTab(self.wizard, "Calibration")
        self.tabs = QTabWidget()
        self.tabs.addTab(self._live_page(), "Live")
        self.tabs.addTab(self.browser, "Runs")
        self.tabs.addTab(self.design, "Design")
        self.setCentralWidget(self.tabs)
        dock = QDockWidget("bench", self)
        dock.setWidget(tabs)
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, dock)
        log_dock = QDockWidget("event log", self)
        log_dock.setWidget(self.messages)
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, log_dock)

        self.bridge.frame.connect(self.on_frame)
        self.bridge.level.connect(self.on_level)
        self.log_bridge = LogBridge(parent=self)          # driver reconnects/retries, engine warnings
        self.log_bridge.message.connect(self.on_message)
        self.bridge.preview.connect(self.on_preview)
        self.bridge.reading.connect(self.devices.show_reading)
        self.bridge.state.connect(self.on_state)
        self.bridge.prompt.connect(self.on_prompt)
        self.bridge.message.connect(self.on_message)
        self.bridge.done.connect(self.on_done)
        self.devices.connect_button.clicked.connect(self.connect_devices)
        self.controls.start_requested.connect(self.start_run)
        self.controls.drop_confirmed.connect(self.confirm_drop)
        self.controls.stop_requested.connect(self.stop)
        self.controls.abort_requested.connect(self.engine.abort)
        self.wizard.start_requested.connect(self.start_calibration)
        self.wizard.mass_entered.connect(self.answer_mass)
        self.wizard.finish_requested.connect(self.finish_calibration)
        self.browser.resume_requested.connect(self.resume_run)
        self.wizard.simulation.bench_calibration = lambda: self.controls.calibration.text().strip() or None
        self.wizard.simulation.simcal_activated.connect(self.set_simcal)
        self.browser.design_requested.connect(self.design_from_run)
        self.live.crop_changed.connect(self.on_crop)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)
        self.timer.start(UI_MS)
        self.statusBar().showMessage("idle")
        if simulate:
            self.crop = SimulatedBench.default_crop()
            self.live.set_geometry(*self.crop)

    def _live_page(self) -> QWidget:
        split = QSplitter()
        split.addWidget(self.live)
        split.addWidget(self.plots)
        split.setSizes([500, 500])
        return split

    # -- building benches ---------------------------------------------------------------------------------
    def make_bench(self) -> Bench:
        """The bench the device panel describes (the simulated one is kept until the bath's water changes)."""
        if self.devices.camera_spec() == SIMULATED:
            water_g = self.devices.bath().water_g
            if self.sim is not None and self.sim.scene.water_g != water_g:
                self.sim.close()
                self.sim = None
            if self.sim is None:
                self.sim = SimulatedBench(self.engine.clock, sample=self.sample,
                                          with_hotplate=self.devices.hotplate_spec() == SIMULATED, water_g=water_g)
            return self.sim.bench()
        return make_bench(self.devices.camera_spec(), self.devices.hotplate_spec(), self.devices.settings())

    def _start(self, procedure) -> bool:
        if self.engine.running:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return False
        self.procedure = procedure
        self.engine.start(procedure)
        self.controls.set_running(True)
        return True

    # -- actions ------------------------------------------------------------------------------------------
    def connect_devices(self) -> None:
        """Connect, one preview frame, one reading (in the engine's thread)."""
        try:
            self._start(PreviewProcedure(self.make_bench()))
        except (ValueError, ImportError, OSError) as exc:
            self.on_message("error", f"cannot build the bench: {exc}")

    def _calibration(self) -> BenchCalibration | None:
        text = self.controls.calibration.text().strip()
        return BenchCalibration.load(text) if text else None

    def start_run(self) -> None:
        """Start a run with the run controls' settings."""
        try:
            config = self.controls.config(self.devices.bath().on_clock(self.engine.clock.speed))
            calibration, bench = self._calibration(), self.make_bench()
        except Exception as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self.plots.clear()
        self.plots.set_water(config.bath.water_g)
        if calibration is not None:
            g = calibration.geometry
            self.live.set_geometry(g.x, g.y, g.size, g.grid, g.mirror_col)
        try:
            proc = new_run(config, bench, self.data_dir, calibration)
        except UsageError as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self._start(proc)

    def resume_run(self, folder: str) -> None:
        """Resume acquisition into an interrupted run folder."""
        if self.engine.running:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return
        try:
            simulated = resumable(folder).record.simulated
            if simulated != (self.devices.camera_spec() == SIMULATED):
                raise UsageError(f"{folder} was recorded on a {'simulated' if simulated else 'real'} bench; "
                                 f"choose {'the simulated' if simulated else 'a real'} camera in the device panel")
            if simulated:
                self.engine.clock = resume_clock(Path(folder), self.speed)
                if self.sim is not None:
                    self.sim.close()
                    self.sim = None
            proc = resume_run(Path(folder), self.make_bench(), self._calibration())
        except Exception as exc:
            self.on_message("error", f"cannot resume {folder}: {exc}")
            return
        self.plots.clear()
        self.tabs.setCurrentIndex(0)
        self._start(proc)

    def confirm_drop(self) -> None:
        """The operator dropped the object: time zero."""
        self.engine.answer(PromptKind.DROP, True)

    def stop(self) -> None:
        """Finish the current procedure cleanly."""
        self.engine.stop()

    def start_calibration(self) -> None:
        """Start a calibration series (:func:`labapp.jobs.series.new_series`) with the crop of the live view,
        the device panel's bath and the wizard's masses."""
        try:
            masses, bath = self.wizard.masses_g(), self.devices.bath()
            proc = new_series(self.make_bench(), self.data_dir, self.live.geometry_px(), bath=bath, masses_g=masses,
                              clock_speed=self.engine.clock.speed)
        except Exception as exc:
            self.wizard.show_result(f"cannot start: {exc}")
            return
        self._start(proc)

    def answer_mass(self, mass_g: float) -> None:
        """The operator entered the cumulative mass for the next capture."""
        self.wizard.set_asking(False, f"capturing at {mass_g:g} g ...")
        self.engine.answer(PromptKind.ADDED_MASS, mass_g)

    def finish_calibration(self) -> None:
        """No more levels: fit and save."""
        self.wizard.set_asking(False, "fitting ...")
        self.engine.answer(PromptKind.ADDED_MASS, "")

    # -- slots for engine events --------------------------------------------------------------------------
    def on_frame(self, frame: FrameStored) -> None:
        """A run frame was stored: plot it, remember it for the live view."""
        self.latest_frame = frame.path
        self.plots.add_frame(frame.t_s, frame.conc_g_per_kg)
        # the bath plot shows the reading logged with each frame: one time base with the release curve
        self.plots.add_reading(frame.t_s, frame.plate_c, frame.probe_c, frame.speed_rpm)

    def on_level(self, level: CalibrationLevel) -> None:
        """A calibration-series frame was stored: show it in the live view."""
        self.latest_frame = level.path

    def on_preview(self, preview: Preview) -> None:
        """Show a preview frame."""
        rgb = decode_preview(data=preview.data)
        if rgb is not None:
            self.live.set_frame(rgb, f"preview {preview.file}")

    def on_state(self, state: StateChanged) -> None:
        """Follow the procedure's phase."""
        self.controls.set_running(True, waiting_drop=state.phase == Phase.WAITING_DROP)  # Done ends it (on_done)
        if state.phase == Phase.OPENED:
            self.on_message("info", f"run folder {state.folder}")

    def on_prompt(self, prompt: Prompt) -> None:
        """The engine asks the operator something."""
        if prompt.auto:
            return
        if prompt.prompt == PromptKind.DROP:
            self.controls.set_running(True, waiting_drop=True)
            self.statusBar().showMessage(prompt.text)
        elif prompt.prompt == PromptKind.ADDED_MASS:
            self.wizard.set_asking(True, prompt.text)

    def on_message(self, level: str, message: str) -> None:
        """Append an event to the log pane."""
        self.messages.appendPlainText(f"{level.upper():7s} {message}")

    def on_done(self, done: Done) -> None:
        """A procedure ended."""
        self.controls.set_running(False)
        self.wizard.set_asking(False, "")
        proc = self.procedure
        if isinstance(proc, CalibrationProcedure):
            if proc.calibration_path is not None:
                self.controls.calibration.setText(str(proc.calibration_path))
                self.wizard.show_result(f"calibration saved: {proc.calibration_path} (now the active calibration)")
            else:
                self.wizard.show_result(f"series ended ({done.outcome}) without a calibration")
        self.on_message("info", f"{getattr(proc, 'name', 'procedure')} ended: {done.outcome}")
        self.browser.refresh()

    def set_simcal(self, path: str) -> None:
        """Make a ``simcal.json`` the active simulation calibration of the design launcher and run browser."""
        self.design.set_simcal(Path(path))
        self.browser.simcal = self.design.simcal
        self.on_message("info", f"active simulation calibration: {path}")

    def design_from_run(self, path: str) -> None:
        """The run browser asks for a design from a run: the launcher takes it as its target."""
        self.design.source.setText(path)
        self.tabs.setCurrentWidget(self.design)

    def on_crop(self, x: int, y: int, size: int) -> None:
        """The operator moved the crop."""
        self.crop = (x, y, size)

    def refresh(self) -> None:
        """~10 Hz: status line and the newest frame."""
        self.statusBar().showMessage(self.status.line())
        if self.latest_frame is not None:
            rgb = decode_preview(path=self.latest_frame)
            if rgb is not None:
                self.live.set_frame(rgb, Path(self.latest_frame).name)
            self.latest_frame = None

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt override)
        """Stop any procedure (heating off) and the simulated devices before closing."""
        if self.engine.running:
            if QMessageBox.question(self, "quit", "A procedure is running. Stop it and quit?") != \
                    QMessageBox.StandardButton.Yes:
                event.ignore()
                return
            self.engine.stop()
            self.engine.join(30)
        self.shutdown()
        super().closeEvent(event)

    def shutdown(self) -> None:
        """Release the simulated bench and the bridge (also used by tests)."""
        self.timer.stop()
        self.bridge.detach()
        self.log_bridge.detach()
        if self.sim is not None:
            self.sim.close()
            self.sim = None
