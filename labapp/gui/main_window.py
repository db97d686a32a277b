"""The bench application's main window: a thin face over the engine.

Every button calls the same Qt-free pieces the CLI uses (``Engine``, the jobs ``new_run``, ``resume_run`` and
``new_series``, ``PreviewProcedure``); engine events come in through the :class:`EngineBridge`. Nothing slow
runs in the GUI thread: benches are built in a worker thread, procedures run in the engine's, and closing
while something runs stops it and closes once it has finished.

The window wires its parts together: benches are built and kept by :mod:`labapp.gui.bench_builder` (the simulated
one by :mod:`labapp.gui.simulated_session`), the procedure is shown by :mod:`labapp.gui.run_display`, the forms'
settings are :mod:`labapp.gui.run_settings`'s, a run's duration changes through :mod:`labapp.gui.duration_change`,
and the frame (docks, menus, fitting to the screen) is :mod:`labapp.gui.window_layout`'s.
"""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QRect, Qt, QTimer
from PySide6.QtGui import QGuiApplication, QKeySequence
from PySide6.QtWidgets import QFileDialog, QMainWindow, QMessageBox, QTabWidget, QVBoxLayout, QWidget

from analysis import BenchCalibration
from labapp.acquisition.bench import Bench
from labapp.acquisition.calseries import CalibrationProcedure, RedoLevel
from labapp.acquisition.clock import make_clock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Alarm, AlarmKind, Done, Phase, Prompt, PromptKind, StateChanged
from labapp.acquisition.procedures import PreviewProcedure, RunConfig
from labapp.acquisition.simbench import SimulatedBench, resume_clock
from labapp.acquisition.status import RunStatus
from labapp.errors import UsageError
from labapp.gui import dialogs, persist
from labapp.gui.alarms import AlarmBanner
from labapp.gui.bench_builder import BenchBuilder
from labapp.gui.bridge import EngineBridge, LogBridge
from labapp.gui.calibration_wizard import CalibrationWizard
from labapp.gui.design_launcher import DesignLauncher
from labapp.gui.device_panel import SIMULATED, DevicePanel
from labapp.gui.duration_change import DurationChange
from labapp.gui.event_log import EventLog
from labapp.gui.fault_menu import add_fault_menu
from labapp.gui.live_view import LiveView
from labapp.gui.plate_poller import HeldProcedure, IdlePlatePoller
from labapp.gui.plots import PlotsPanel
from labapp.gui.run_browser import RunBrowser, interrupted_runs, resume_offer
from labapp.gui.run_controls import RunControls
from labapp.gui.run_display import RunDisplay, state_of
from labapp.gui.run_settings import RunSettings
from labapp.gui.simulated_session import SimulatedSession
from labapp.gui.window_layout import (
    LOG_HEIGHT_PX,
    ElidedLine,
    RunProgress,
    add_actions,
    add_dock,
    add_menu,
    fit_to_screen,
    scrolled,
    side_by_side,
)
from labapp.jobs.run import new_run, resumable, resume_run
from labapp.jobs.series import new_series

UI_MS = 100
BUSY = "the engine is busy; stop the current procedure first"


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
    sample : str
        The simulated bench's sample object.
    """

    def __init__(self, data_dir: Path, simulate: bool = False, speed: float | None = None,
                 sample: str = "pill") -> None:
        super().__init__()
        self.setWindowTitle("Shape from Release: bench" + (" (simulated)" if simulate else ""))
        self.data_dir = Path(data_dir)
        self.simulate, self.speed = simulate, speed if simulate else None
        self.settings = persist.app_settings()
        self.engine = Engine(make_clock(self.speed))
        self.status = RunStatus()
        self.engine.subscribe(self.status.update)       # before the bridge: the status is current when a signal lands
        self.bridge = EngineBridge(self.engine, self)
        self.plate_poller = IdlePlatePoller(self.engine)
        """Polls the connected bench's hotplate between procedures (the device panel stays current)."""
        self.simulated = SimulatedSession(sample, self.plate_poller)
        self.procedure = None
        self.crop: tuple[int, int, int] | None = None
        self._closed = False
        self._close_ready = False
        self._build_widgets()
        self._build_layout()
        self._build_menus()
        self._connect_signals()
        self._start_timers()
        self.status_line.set_line("idle")
        if simulate:
            self.crop = SimulatedBench.default_crop()
            self.live.set_geometry(*self.crop)
        self.restore_settings()
        self.fit_to_screen()
        self.resume_box: QMessageBox | None = None
        QTimer.singleShot(0, self.offer_resume)

    # -- layout -------------------------------------------------------------------------------------------
    def _build_widgets(self) -> None:
        self.devices = DevicePanel(self.simulate)
        self.controls = RunControls(self.simulate)
        self.wizard = CalibrationWizard(self.simulate, self.data_dir)
        self.browser = RunBrowser(self.data_dir)
        self.design = DesignLauncher(self.data_dir)
        self.live = LiveView()
        self.plots = PlotsPanel()
        self.messages = EventLog()
        self.progress = RunProgress()
        self.display = RunDisplay(self.status, self.live, self.plots, self.progress, self.browser, self)
        self.benches = BenchBuilder(self.devices, self.engine, self.plate_poller, self.simulated, self)
        self.forms = RunSettings(self.controls, self.devices, self.data_dir, self)
        self.duration_change = DurationChange(self.engine, lambda: self._closed, self)

    def _build_layout(self) -> None:
        self.bench_tabs = QTabWidget()
        for widget, title in ((self.devices, "Devices"), (self.controls, "Run"), (self.wizard, "Calibration")):
            self.bench_tabs.addTab(scrolled(widget), title)
        self.tabs = QTabWidget()
        self.tabs.addTab(side_by_side(self.live, self.plots), "Live")
        self.tabs.addTab(self.browser, "Runs")
        self.tabs.addTab(self.design, "Design")
        self.tabs.currentChanged.connect(self._tab_shown)
        self.alarms = AlarmBanner(self.plots)
        central = QWidget()
        column = QVBoxLayout(central)
        column.setContentsMargins(0, 0, 0, 0)
        column.addWidget(self.alarms)
        column.addWidget(self.tabs, 1)
        self.setCentralWidget(central)
        self.bench_dock = add_dock(self, "bench", self.bench_tabs, Qt.DockWidgetArea.LeftDockWidgetArea)
        self.log_dock = add_dock(self, "event log", self.messages, Qt.DockWidgetArea.BottomDockWidgetArea)
        self.resizeDocks([self.log_dock], [LOG_HEIGHT_PX], Qt.Orientation.Vertical)
        self.status_line = ElidedLine("")         # ends in "..." beside the progress bar, never under it
        self.statusBar().addWidget(self.status_line, 1)
        self.statusBar().addPermanentWidget(self.progress)

    def _build_menus(self) -> None:
        add_menu(self, "&File", (("Open run...", self.open_run, QKeySequence.StandardKey.Open),
                                 ("Load simulation calibration...", self.load_simcal, None),
                                 ("Load method...", self.forms.load_method, None),
                                 ("Save method...", self.forms.save_method, None),
                                 ("Quit", self.close, QKeySequence.StandardKey.Quit)))
        add_menu(self, "&Bench", (("Connect / preview", self.devices.connect_button.click, "F5"),  # the panel's
                                  ("Start run", self.controls.start_button.click, "F6"),    # buttons, from the
                                  ("Object dropped", self.controls.drop_button.click, "F7")))  # keyboard too
        if self.simulate:
            add_fault_menu(self, lambda: self.simulated.bench, self.on_message)
        self.view_menu = add_menu(self, "&View")
        for dock in (self.bench_dock, self.log_dock):
            self.view_menu.addAction(dock.toggleViewAction())
        self.view_menu.addSeparator()
        add_actions(self, self.view_menu, [(f"{name} tab", lambda checked=False, i=i: self.tabs.setCurrentIndex(i),
                                            f"Ctrl+{i + 1}") for i, name in enumerate(("Live", "Runs", "Design"))])

    def _connect_signals(self) -> None:
        self.bridge.frame.connect(self.display.on_frame)
        self.bridge.level.connect(self.display.on_level)
        self.log_bridge = LogBridge(loggers=("drivers", "labapp", "analysis"), parent=self)
        self.log_bridge.message.connect(self.on_message)
        self.bridge.preview.connect(self.display.on_preview)
        self.bridge.reading.connect(self.devices.show_reading)
        self.bridge.link.connect(self.devices.show_link)
        self.bridge.reference.connect(self.display.on_reference)
        self.bridge.state.connect(self.on_state)
        self.bridge.prompt.connect(self.on_prompt)
        self.bridge.message.connect(self.on_message)
        self.bridge.event.connect(self.display.on_event)
        self.bridge.done.connect(self.on_done)
        self.bridge.alarm.connect(self.alarms.raise_alarm)
        self.bridge.state.connect(self.controls.follow)
        self.controls.watch(self.devices.bath_fields)
        self.wizard.redo_requested.connect(self.redo_level)
        self.devices.connect_button.clicked.connect(self.connect_devices)
        self.controls.start_requested.connect(self.start_run)
        self.controls.drop_confirmed.connect(self.confirm_drop)
        self.controls.stop_requested.connect(self.stop)
        self.controls.abort_requested.connect(self.engine.abort)
        self.controls.change_requested.connect(self.change_duration)
        self.wizard.start_requested.connect(self.start_calibration)
        self.wizard.mass_entered.connect(self.answer_mass)
        self.wizard.finish_requested.connect(self.finish_calibration)
        self.browser.resume_requested.connect(self.resume_run)
        self.wizard.use_bench_calibration(self.controls.calibration_path)
        self.wizard.simcal_activated.connect(self.set_simcal)
        self.design.simcal_requested.connect(self.set_simcal)
        self.browser.design_requested.connect(self.design_from_run)
        self.live.crop_changed.connect(self.on_crop)
        self.benches.connecting.connect(self._set_connecting)
        for source in (self.benches, self.forms, self.duration_change):
            source.message.connect(self.on_message)

    def _start_timers(self) -> None:
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)
        self.timer.start(UI_MS)
        self.close_timer = QTimer(self)
        self.close_timer.timeout.connect(self._close_when_idle)

    def _tab_shown(self, index: int) -> None:
        if self.tabs.widget(index) is self.browser:
            self.browser.refresh()                    # frame counts and statuses as they are now

    def fit_to_screen(self, available: QRect | None = None) -> None:
        """Size the window to the screen's available area (:func:`labapp.gui.window_layout.fit_to_screen`)."""
        if available is None:
            screen = self.screen() or QGuiApplication.primaryScreen()
            available = screen.availableGeometry()
        fit_to_screen(self, available, self.bench_dock, self.bench_tabs)

    # -- settings ---------------------------------------------------------------------------------------------
    def restore_settings(self) -> None:
        """The last run's settings and the last simulation calibration, as the previous session left them."""
        self.forms.restore(self.settings)
        simcal = str(self.settings.value(persist.LAST_SIMCAL, "") or "")
        if simcal and Path(simcal).is_file():
            try:
                self.set_simcal(simcal)
            except Exception as exc:      # a file changed since: say so, start without it
                self.on_message("warning", f"the last simulation calibration {simcal} does not load: {exc}")

    # -- building benches ---------------------------------------------------------------------------------
    @property
    def building(self) -> bool:
        """True while a bench is being built in the background."""
        return self.benches.building

    def _set_connecting(self, busy: bool, doing: str = "connecting") -> None:
        self.devices.set_connecting(busy, doing)
        if busy:
            self.statusBar().showMessage(f"{doing}... (building the bench)")
        self.controls.hold_start(busy)

    def _engine_busy(self, building: bool = False) -> bool:
        """True, said in the event log, while a procedure runs (with ``building``: or a bench is being built);
        every action that starts a procedure asks first."""
        if self.engine.running or (building and self.building):
            self.on_message("warning", BUSY)
            return True
        return False

    def _start(self, procedure) -> bool:
        if self._engine_busy():
            return False
        self.procedure = procedure
        self.benches.use(getattr(procedure, "bench", None))
        self.engine.start(HeldProcedure(procedure, self.plate_poller))   # takes the hotplate from the idle poller
        self.controls.set_running(True)
        self.forms.set_locked(not isinstance(procedure, PreviewProcedure))
        return True

    # -- actions ------------------------------------------------------------------------------------------
    def connect_devices(self) -> None:
        """Connect, one preview frame, one reading (the bench built in a worker, the procedure in the engine's
        thread)."""
        if self._engine_busy():
            return
        self.benches.with_bench(lambda bench: self._start(PreviewProcedure(bench)), "connecting")

    def _calibration(self) -> BenchCalibration | None:
        path = self.controls.calibration_path()
        return BenchCalibration.load(path) if path else None

    def start_run(self) -> None:
        """Start a run with the run controls' settings (refused, with the reasons, while Start is disabled)."""
        found = self.controls.start_problems()
        if found:
            self.on_message("error", "cannot start: " + "; ".join(found))
            return
        if self._engine_busy():
            return
        try:
            config = self.controls.config(self.devices.bath().on_clock(self.engine.clock.speed))
            calibration = self._calibration()
        except Exception as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self.benches.with_bench(lambda bench: self._start_run(config, calibration, bench), "starting")

    def _start_run(self, config: RunConfig, calibration: BenchCalibration | None, bench: Bench) -> None:
        try:
            proc = new_run(config, bench, self.data_dir, calibration)
        except UsageError as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self.display.prepare(config)
        if calibration is not None:
            g = calibration.geometry
            self.live.set_geometry(g.x, g.y, g.size, g.grid, g.mirror_col)
        if self._start(proc):
            persist.remember_run(self.settings, config, self.controls.calibration_path())

    def resume_run(self, folder: str) -> None:
        """Resume acquisition into an interrupted run folder."""
        if self._engine_busy(building=True):
            return
        try:
            snap = resumable(folder)
            simulated = snap.record.simulated
            if simulated != (self.devices.camera_spec() == SIMULATED):
                raise UsageError(f"{folder} was recorded on a {'simulated' if simulated else 'real'} bench; "
                                 f"choose {'the simulated' if simulated else 'a real'} camera in the device panel")
            if simulated:
                self.engine.clock = resume_clock(Path(folder), self.speed)
                self.benches.keep_simulated(None)
            config = RunConfig.from_dict(snap.record.config) if snap.record.config else None
        except Exception as exc:
            self.on_message("error", f"cannot resume {folder}: {exc}")
            return
        self.benches.with_bench(lambda bench: self._resume_run(folder, config, bench), "resuming")

    def _resume_run(self, folder: str, config: RunConfig | None, bench: Bench) -> None:
        try:
            proc = resume_run(Path(folder), bench, self._calibration())
        except Exception as exc:
            self.on_message("error", f"cannot resume {folder}: {exc}")
            return
        self.display.prepare(config)
        self.tabs.setCurrentIndex(0)
        self._start(proc)

    def confirm_drop(self) -> None:
        """The operator dropped the object: time zero."""
        self.alarms.dismiss(AlarmKind.DROP)
        self.engine.answer(PromptKind.DROP, True)

    def stop(self) -> None:
        """Finish the current procedure cleanly."""
        self.engine.stop()

    def change_duration(self) -> None:
        """Change the recording run's maximum or minimum duration, with a reason (:mod:`labapp.gui.duration_change`)."""
        self.duration_change.ask(self.procedure, self.status.t_s)

    def start_calibration(self) -> None:
        """Start a calibration series (:func:`labapp.jobs.series.new_series`) with the crop of the live view,
        the device panel's bath and the wizard's masses."""
        try:
            masses, bath = self.wizard.masses_g(), self.devices.bath()
        except Exception as exc:
            self.wizard.show_result(f"cannot start: {exc}")
            return
        if self._engine_busy():
            return
        self.benches.with_bench(lambda bench: self._start_calibration(bench, masses, bath), "starting")

    def _start_calibration(self, bench: Bench, masses, bath) -> None:
        try:
            proc = new_series(bench, self.data_dir, self.live.geometry_px(), bath=bath, masses_g=masses,
                              clock_speed=self.engine.clock.speed)
        except Exception as exc:
            self.wizard.show_result(f"cannot start: {exc}")
            return
        self._start(proc)

    def answer_mass(self, mass_g: float) -> None:
        """The operator entered the cumulative mass for the next capture."""
        self.wizard.set_asking(False, f"capturing at {mass_g:g} g ...")
        self.engine.answer(PromptKind.ADDED_MASS, mass_g)

    def redo_level(self) -> None:
        """Capture the series' last level again (it replaces that level's frame)."""
        self.wizard.set_asking(False, "capturing the last level again ...")
        self.engine.answer(PromptKind.ADDED_MASS, RedoLevel())

    def finish_calibration(self) -> None:
        """No more levels: fit and save."""
        self.wizard.set_asking(False, "fitting ...")
        self.engine.answer(PromptKind.ADDED_MASS, "")

    def open_run(self, path: str | None = None) -> None:
        """Show any run folder (inside the data directory or not) in the run browser."""
        if not path:
            path = QFileDialog.getExistingDirectory(self, "open run", str(self.data_dir))
            if not path:
                return
        try:
            self.browser.open_folder(Path(path))
        except UsageError as exc:
            self.on_message("error", str(exc))
            return
        self.tabs.setCurrentWidget(self.browser)

    def load_simcal(self, path: str | None = None) -> None:
        """Make a ``simcal.json`` file the active simulation calibration."""
        if not path:
            path, _ = QFileDialog.getOpenFileName(self, "simulation calibration", str(self.data_dir),
                                                  "simulation calibration (simcal.json *.json)")
            if not path:
                return
        try:
            self.set_simcal(path)
        except UsageError as exc:
            self.on_message("error", str(exc))

    def offer_resume(self) -> None:
        """At startup: name the interrupted runs in the data directory and offer to resume the newest."""
        runs = interrupted_runs(self.data_dir)
        if not runs:
            return
        box = resume_offer(self, self.data_dir, runs)
        box.buttonClicked.connect(lambda button: self._resume_answer(button, runs))
        self.resume_box = box
        box.open()

    def _resume_answer(self, button, runs) -> None:
        role = self.resume_box.buttonRole(button)
        if role == QMessageBox.ButtonRole.RejectRole:
            return
        self.tabs.setCurrentWidget(self.browser)
        self.browser.refresh()
        self.browser.select(runs[0].path)
        if role == QMessageBox.ButtonRole.AcceptRole:
            self.resume_run(str(runs[0].path))

    # -- slots for engine events --------------------------------------------------------------------------
    def on_state(self, state: StateChanged) -> None:
        """Follow the procedure's phase."""
        self.controls.set_running(True, waiting_drop=state.phase == Phase.WAITING_DROP)  # Done ends it (on_done)
        if state.phase == Phase.OPENED:
            self.on_message("info", f"run folder {state.folder}")
            self.browser.refresh()                    # the new run is listed while it records

    def on_prompt(self, prompt: Prompt) -> None:
        """The engine asks the operator something."""
        if prompt.auto:
            return
        if prompt.prompt == PromptKind.DROP:
            self.controls.set_running(True, waiting_drop=True)
            self.alarms.raise_alarm(Alarm(AlarmKind.DROP, f"{prompt.text} (Object dropped, F7)"))
        elif prompt.prompt == PromptKind.ADDED_MASS:
            self.wizard.set_asking(True, prompt.text)

    def on_message(self, level: str, message: str) -> None:
        """Append an event to the log pane (a repeated warning collapses into one line)."""
        self.messages.add(level, message)

    def on_done(self, done: Done) -> None:
        """A procedure ended."""
        self.controls.set_running(False)
        self.forms.set_locked(False)
        self.wizard.set_asking(False, "")
        proc = self.procedure
        if isinstance(proc, CalibrationProcedure):
            if proc.calibration_path is not None:
                self.controls.set_calibration_path(proc.calibration_path)
                self.wizard.show_result(f"calibration saved: {proc.calibration_path} (now the active calibration)")
            else:
                self.wizard.show_result(f"series ended ({done.outcome}) without a calibration")
        self.on_message("info", f"{getattr(proc, 'name', 'procedure')} ended: {done.outcome}")
        self.alarms.dismiss(AlarmKind.DROP)
        if not isinstance(proc, PreviewProcedure) and proc is not None:
            folder = getattr(getattr(proc, "run", None), "path", None)
            self.alarms.raise_alarm(Alarm(AlarmKind.RUN_ENDED, f"{proc.name} {Path(folder).name if folder else ''} "
                                          f"ended: {done.outcome}" + (f" ({done.reason})" if done.reason else "")))
        self.browser.refresh()
        self.benches.poll_idle()

    def set_simcal(self, path: str) -> None:
        """Make a ``simcal.json`` the active simulation calibration of the design launcher and run browser
        (remembered for the next session)."""
        self.design.set_simcal(Path(path))
        self.browser.simcal = self.design.simcal
        self.settings.setValue(persist.LAST_SIMCAL, str(Path(path).resolve()))
        self.on_message("info", f"active simulation calibration: {path}")

    def design_from_run(self, path: str) -> None:
        """The run browser asks for a design from a run: the launcher takes it as its target."""
        self.design.use_target(path)
        self.tabs.setCurrentWidget(self.design)

    def on_crop(self, x: int, y: int, size: int) -> None:
        """The operator moved the crop."""
        self.crop = (x, y, size)

    def refresh(self) -> None:
        """~10 Hz: status line, run progress and the newest frame."""
        if not self.building and not self.close_timer.isActive():
            if self.statusBar().currentMessage():
                self.statusBar().clearMessage()      # the status line again, after "connecting..."
            self.status_line.set_line(self.status.line())
        self.display.refresh(self.engine.running, self.procedure)
        self.controls.show_state(*state_of(self.status, self.engine.running, self.engine.should_stop()))

    # -- closing --------------------------------------------------------------------------------------------
    def busy_work(self) -> list[str]:
        """What would be cut short by closing now."""
        work = []
        if self.engine.running:
            folder = getattr(getattr(self.procedure, "run", None), "path", None)
            work.append(dialogs.interrupt_effect(getattr(self.procedure, "name", "procedure"),
                                                 Path(folder).name if folder else ""))
        work += self.design.busy_work()
        if self.building:
            work.append("building the bench")
        return work

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt override)
        """Ask before cutting anything short; stop it and close once it has finished (never blocking)."""
        if not self._close_ready:
            work = self.busy_work()
            if work and not self.close_timer.isActive():
                if not dialogs.confirm(self, dialogs.close_question(work)):
                    event.ignore()
                    return
            if work:
                self.begin_close()
                event.ignore()
                return
        self.shutdown()
        super().closeEvent(event)

    def begin_close(self) -> None:
        """Stop everything that runs and close the window once it has all finished."""
        if self.engine.running:
            self.engine.interrupt()           # heating off; a run stays resumable
        self.design.stop_all()
        self.centralWidget().setEnabled(False)
        self.bench_dock.setEnabled(False)
        self.statusBar().showMessage("stopping... the window closes when the procedure, design or sweep has stopped")
        self.on_message("info", "stopping before quitting ...")
        self.close_timer.start(UI_MS)

    def _close_when_idle(self) -> None:
        if self.busy_work():
            return
        self.close_timer.stop()
        self._close_ready = True
        self.close()

    def shutdown(self) -> None:
        """Release the simulated bench and the bridge (also used by tests)."""
        self._closed = True
        self.timer.stop()
        self.close_timer.stop()
        self.bridge.detach()
        self.log_bridge.detach()
        self.benches.close()

