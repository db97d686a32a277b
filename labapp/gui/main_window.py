"""The bench application's main window: a thin face over the engine.

Every button calls the same Qt-free pieces the CLI uses (``Engine``, the jobs ``new_run``, ``resume_run`` and
``new_series``, ``PreviewProcedure``); engine events come in through the :class:`EngineBridge`. Nothing slow
runs in the GUI thread: benches are built in a worker thread, procedures run in the engine's, and closing
while something runs stops it and closes once it has finished.
"""
from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np
from PySide6.QtCore import QRect, Qt, QTimer
from PySide6.QtGui import QAction, QGuiApplication, QKeySequence
from PySide6.QtWidgets import (
    QDockWidget,
    QFileDialog,
    QMainWindow,
    QMessageBox,
    QPlainTextEdit,
    QProgressBar,
    QScrollArea,
    QSplitter,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from analysis import BenchCalibration
from labapp.acquisition.bench import Bench
from labapp.acquisition.calseries import CalibrationProcedure, RedoLevel
from labapp.acquisition.clock import make_clock
from labapp.acquisition.devices import make_bench
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import (
    CalibrationLevel,
    Done,
    FrameStored,
    Message,
    Phase,
    Preview,
    Prompt,
    PromptKind,
    StateChanged,
)
from labapp.acquisition.methods import load_method, method_from_config, save_method
from labapp.acquisition.procedures import PreviewProcedure, RunConfig, RunProcedure
from labapp.acquisition.settings import CHANGEABLE_DURING_RUN, KEEPALIVE
from labapp.acquisition.simbench import SampleRelease, SimulatedBench, resume_clock, sample_release
from labapp.acquisition.status import RunStatus
from labapp.errors import UsageError
from labapp.gui import dialogs, persist
from labapp.gui.alarms import AlarmBanner
from labapp.gui.bridge import BackgroundTask, EngineBridge, LogBridge
from labapp.gui.calibration_wizard import CalibrationWizard
from labapp.gui.design_launcher import DesignLauncher
from labapp.gui.device_panel import SIMULATED, DevicePanel
from labapp.gui.live_view import LiveView
from labapp.gui.plate_poller import HeldProcedure, IdlePlatePoller
from labapp.gui.plots import PlotsPanel, hmm
from labapp.gui.run_browser import RunBrowser, interrupted_runs
from labapp.gui.run_controls import RunControls
from labapp.jobs.run import change_setting, new_run, resumable, resume_run
from labapp.jobs.series import new_series
from labapp.records.operators import OperatorError

UI_MS = 100
PREFERRED_SIZE = (1500, 950)
"""The window's size where the screen has room; smaller screens get their available area."""
TITLE_BAR_PX = 32
"""Room left for the window manager's title bar when fitting the window to the screen."""
LOG_HEIGHT_PX = 110
BENCH_DOCK_MAX_SHARE = 0.4
"""The bench dock takes at most this share of the window's width when the window is fitted to the screen."""
BENCH_DOCK_SLACK_PX = 12
"""Pixels the bench dock gets beyond its widest tab's minimum (the dock's own frame and splitter)."""
GAP_FACTOR, GAP_MIN_S = 5.0, 120.0
"""A frame arriving more than this many intervals, and at least this long, after the previous one marks a gap
on the plots (an accelerated simulation may lag its interval a little: that is no gap)."""


_RELEASES: dict[str, SampleRelease] = {}
"""Simulated samples' releases computed in this process's lifetime (the same object dissolves the same way)."""


def release_in_subprocess(sample: str) -> SampleRelease:
    """The simulated sample's release, computed once in a child process: its fast marching (scikit-fmm) holds
    the GIL for seconds, which in a thread of this process would freeze the window all the same."""
    if sample not in _RELEASES:
        with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
            _RELEASES[sample] = pool.submit(sample_release, sample).result()
    return _RELEASES[sample]


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
    sample : str
        The simulated bench's sample object.
    """

    def __init__(self, data_dir: Path, simulate: bool = False, speed: float | None = None,
                 sample: str = "pill") -> None:
        super().__init__()
        self.setWindowTitle("Shape from Release: bench" + (" (simulated)" if simulate else ""))
        self.data_dir = Path(data_dir)
        self.simulate, self.speed, self.sample = simulate, speed if simulate else None, sample
        self.settings = persist.app_settings()
        self.engine = Engine(make_clock(self.speed))
        self.status = RunStatus()
        self.engine.subscribe(self.status.update)       # before the bridge: the status is current when a signal lands
        self.bridge = EngineBridge(self.engine, self)
        self.plate_poller = IdlePlatePoller(self.engine)
        """Polls the connected bench's hotplate between procedures (the device panel stays current)."""
        self.bench_hotplate = None
        """The hotplate of the bench the last procedure used: the one polled while idle."""
        self.sim: SimulatedBench | None = None
        self._release: SampleRelease | None = None
        self.procedure = None
        self.run_config: RunConfig | None = None
        self.latest_frame: str | None = None
        self.crop: tuple[int, int, int] | None = None
        self.build_task: BackgroundTask | None = None
        self.change_task: BackgroundTask | None = None
        """A change of the recording run's duration waiting for the run's next frame (:meth:`change_duration`)."""
        self._then: Callable[[Bench], None] | None = None
        self._closed = False
        self._close_ready = False
        self._last_frame_t: float | None = None

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
        self.progress = QProgressBar()
        self.progress.setMaximumWidth(360)
        self.progress.setTextVisible(True)
        self.progress.hide()

        self.bench_tabs = QTabWidget()
        for widget, title in ((self.devices, "Devices"), (self.controls, "Run"), (self.wizard, "Calibration")):
            self.bench_tabs.addTab(_scrolled(widget), title)
        self.tabs = QTabWidget()
        self.tabs.addTab(self._live_page(), "Live")
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
        self.bench_dock = QDockWidget("bench", self)
        self.bench_dock.setObjectName("bench")
        self.bench_dock.setWidget(self.bench_tabs)
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.bench_dock)
        self.log_dock = QDockWidget("event log", self)
        self.log_dock.setObjectName("event log")
        self.log_dock.setWidget(self.messages)
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, self.log_dock)
        self.resizeDocks([self.log_dock], [LOG_HEIGHT_PX], Qt.Orientation.Vertical)
        self._menus()
        self.statusBar().addPermanentWidget(self.progress)

        self.bridge.frame.connect(self.on_frame)
        self.bridge.level.connect(self.on_level)
        self.log_bridge = LogBridge(loggers=("drivers", "labapp", "analysis"), parent=self)
        self.log_bridge.message.connect(self.on_message)
        self.bridge.preview.connect(self.on_preview)
        self.bridge.reading.connect(self.devices.show_reading)
        self.bridge.state.connect(self.on_state)
        self.bridge.prompt.connect(self.on_prompt)
        self.bridge.message.connect(self.on_message)
        self.bridge.event.connect(self.on_event)
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
        self.wizard.simulation.bench_calibration = lambda: self.controls.calibration.text().strip() or None
        self.wizard.simulation.simcal_activated.connect(self.set_simcal)
        self.design.simcal_requested.connect(self.set_simcal)
        self.browser.design_requested.connect(self.design_from_run)
        self.live.crop_changed.connect(self.on_crop)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)
        self.timer.start(UI_MS)
        self.close_timer = QTimer(self)
        self.close_timer.timeout.connect(self._close_when_idle)
        self.statusBar().showMessage("idle")
        if simulate:
            self.crop = SimulatedBench.default_crop()
            self.live.set_geometry(*self.crop)
        self.restore_settings()
        self.fit_to_screen()
        self.resume_box: QMessageBox | None = None
        QTimer.singleShot(0, self.offer_resume)

    # -- layout -------------------------------------------------------------------------------------------
    def _live_page(self) -> QWidget:
        split = QSplitter()
        split.addWidget(self.live)
        split.addWidget(self.plots)
        split.setStretchFactor(0, 1)
        split.setStretchFactor(1, 1)
        split.setChildrenCollapsible(False)
        return split

    def _menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        for text, slot, shortcut in (("Open run...", self.open_run, QKeySequence.StandardKey.Open),
                                     ("Load simulation calibration...", self.load_simcal, None),
                                     ("Load method...", self.load_method, None),
                                     ("Save method...", self.save_method, None),
                                     ("Quit", self.close, QKeySequence.StandardKey.Quit)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            if shortcut is not None:
                action.setShortcut(shortcut)
            file_menu.addAction(action)
        bench_menu = self.menuBar().addMenu("&Bench")       # the panel's buttons, from the keyboard too
        for text, button, shortcut in (("Connect / preview", self.devices.connect_button, "F5"),
                                       ("Start run", self.controls.start_button, "F6"),
                                       ("Object dropped", self.controls.drop_button, "F7")):
            action = QAction(text, self)
            action.setShortcut(QKeySequence(shortcut))
            action.triggered.connect(button.click)
            bench_menu.addAction(action)
        self.view_menu = self.menuBar().addMenu("&View")
        for dock in (self.bench_dock, self.log_dock):
            self.view_menu.addAction(dock.toggleViewAction())
        self.view_menu.addSeparator()
        for index, name in enumerate(("Live", "Runs", "Design")):
            action = QAction(f"{name} tab", self)
            action.setShortcut(QKeySequence(f"Ctrl+{index + 1}"))
            action.triggered.connect(lambda checked=False, i=index: self.tabs.setCurrentIndex(i))
            self.view_menu.addAction(action)

    def _tab_shown(self, index: int) -> None:
        if self.tabs.widget(index) is self.browser:
            self.browser.refresh()                    # frame counts and statuses as they are now

    def fit_to_screen(self, available: QRect | None = None) -> None:
        """Size the window to :data:`PREFERRED_SIZE`, or to the screen's available area (less a title bar) where
        that is smaller, and place it inside that area."""
        if available is None:
            screen = self.screen() or QGuiApplication.primaryScreen()
            available = screen.availableGeometry()
        width = min(PREFERRED_SIZE[0], available.width())
        height = min(PREFERRED_SIZE[1], available.height() - TITLE_BAR_PX)
        self.resize(width, height)
        self.move(available.x() + (available.width() - width) // 2,
                  available.y() + max(0, (available.height() - TITLE_BAR_PX - height) // 2))
        self.resizeDocks([self.bench_dock], [min(self._bench_width(), int(BENCH_DOCK_MAX_SHARE * width))],
                         Qt.Orientation.Horizontal)

    def _bench_width(self) -> int:
        """Width (px) at which the widest tab of the bench dock shows without a horizontal scroll bar."""
        areas = [self.bench_tabs.widget(i) for i in range(self.bench_tabs.count())]
        content = max(area.widget().minimumSizeHint().width() for area in areas)
        scroll_bar = max(area.verticalScrollBar().sizeHint().width() for area in areas)
        frames = self.bench_tabs.sizeHint().width() - self.bench_tabs.currentWidget().sizeHint().width()
        return content + scroll_bar + max(frames, 0) + BENCH_DOCK_SLACK_PX

    # -- settings ---------------------------------------------------------------------------------------------
    def restore_settings(self) -> None:
        """The last run's settings and the last simulation calibration, as the previous session left them."""
        last = persist.last_run(self.settings)
        if last is not None:
            self.apply_run_settings(*last)
        simcal = str(self.settings.value(persist.LAST_SIMCAL, "") or "")
        if simcal and Path(simcal).is_file():
            try:
                self.set_simcal(simcal)
            except Exception as exc:      # a file changed since: say so, start without it
                self.on_message("warning", f"the last simulation calibration {simcal} does not load: {exc}")

    def apply_run_settings(self, config: RunConfig, calibration: str, name: bool = True) -> None:
        """Show ``config``'s run and bath settings (not the object's; its name if ``name``) and ``calibration``
        in the forms."""
        c = self.controls
        if name:
            c.name.setText(config.name)
        c.interval.set_stored(config.interval_s)
        c.max_hours.set_stored(config.max_duration_s)
        c.stop_on_steady.setChecked(config.stop_on_steady)
        for name, box in self.devices.bath_fields.items():
            box.set_stored(getattr(config.bath, name))
        if not calibration or Path(calibration).is_file():
            c.calibration.setText(calibration)

    def current_run_settings(self) -> RunConfig:
        """The run controls' and device panel's settings (UsageError on a bad value)."""
        return self.controls.config(self.devices.bath())

    def save_method(self, path: str | None = None) -> Path | None:
        """Save the run and bath settings and the calibration as a method file
        (``labapp.acquisition.methods``: what ``sfr method save`` writes and ``sfr run --method`` runs)."""
        try:
            config = self.current_run_settings()
        except Exception as exc:
            self.on_message("error", f"cannot save the method: {exc}")
            return None
        if not path:
            folder = self.data_dir / "methods"
            folder.mkdir(parents=True, exist_ok=True)
            path, _ = QFileDialog.getSaveFileName(self, "save method", str(folder / f"{config.name}.json"),
                                                  "method (*.json)")
            if not path:
                return None
        path = Path(path).with_suffix(".json")
        calibration = self.controls.calibration.text().strip() or None
        try:
            saved = save_method(method_from_config(path.stem, config, calibration), path)
        except UsageError as exc:                    # MethodError, OperatorError: one line naming the problem
            self.on_message("error", f"cannot save the method: {exc}")
            return None
        self.on_message("info", f"method saved: {saved}")
        return saved

    def load_method(self, path: str | None = None) -> bool:
        """Fill the forms from a method file (its settings over the defaults, its calibration)."""
        if not path:
            path, _ = QFileDialog.getOpenFileName(self, "load method", str(self.data_dir / "methods"),
                                                  "method (*.json)")
            if not path:
                return False
        try:
            method = load_method(Path(path))
            config = method.apply(RunConfig())
        except UsageError as exc:
            self.on_message("error", str(exc))
            return False
        self.apply_run_settings(config, method.calibration_file or "", name=False)   # a method names no run
        if method.calibration_file and not Path(method.calibration_file).is_file():
            self.on_message("warning", f"{path}: its calibration {method.calibration_file} does not exist; choose one")
        self.on_message("info", f"method {method.name!r} loaded: {path}")
        return True

    def lock_settings(self, locked: bool) -> None:
        """Make the run's and the bath's settings read-only while a procedure records."""
        c, d = self.controls, self.devices
        for widget in (c.name, c.object_name, c.object_mass, c.interval, c.max_hours, c.notes, c.calibration,
                       *d.bath_fields.values()):
            widget.setReadOnly(locked)
        for widget in (c.stop_on_steady, c.auto_drop, d.camera, d.hotplate, d.connect_button):
            widget.setEnabled(not locked and (widget is not c.auto_drop or self.simulate))
        tip = "locked while a procedure records" if locked else ""
        for widget in (c.name, c.interval, c.max_hours, *d.bath_fields.values()):
            widget.setStatusTip(tip)

    # -- building benches ---------------------------------------------------------------------------------
    def make_bench(self) -> Bench:
        """The bench the device panel describes, built now in the calling thread (the simulated one is kept
        until the bath's water changes). The window itself builds benches through :meth:`with_bench`."""
        if self.devices.camera_spec() == SIMULATED:
            if not self._sim_current(self.devices.bath().water_g):
                self._set_sim(self._new_sim(self.devices.bath().water_g,
                                            self.devices.hotplate_spec() == SIMULATED, self.engine.clock))
            return self.sim.bench()
        return make_bench(self.devices.camera_spec(), self.devices.hotplate_spec(), self.devices.settings())

    def _sim_current(self, water_g: float) -> bool:
        return self.sim is not None and self.sim.scene.water_g == water_g

    def _new_sim(self, water_g: float, with_hotplate: bool, clock, release: SampleRelease | None = None
                 ) -> SimulatedBench:
        release = release or self._release
        return SimulatedBench(clock, release=release, sample=self.sample, with_hotplate=with_hotplate,
                              water_g=water_g)

    def _set_sim(self, sim: SimulatedBench | None) -> None:
        if self.sim is not None and self.sim is not sim:
            old = self.sim
            if old.hotplate is not None and old.hotplate is self.bench_hotplate:
                self.bench_hotplate = None         # the emulator goes, its port with it: the idle poller lets go
                threading.Thread(target=_release_then_close, args=(self.plate_poller, old), name="old-bench",
                                 daemon=True).start()    # of it first (up to a poll and a close: off this thread)
            else:
                old.close()
        self.sim = sim

    @property
    def building(self) -> bool:
        """True while a bench is being built in the background."""
        return self.build_task is not None and self.build_task.running

    def with_bench(self, then: Callable[[Bench], None], doing: str = "connecting") -> None:
        """Call ``then(bench)`` in the GUI thread with the device panel's bench, built in a worker thread (a
        simulated bench takes seconds to build; opening real devices may wait on a port)."""
        if self.building:
            self.on_message("warning", "still building the bench; wait for it to finish")
            return
        try:
            camera, hotplate, bath = self.devices.camera_spec(), self.devices.hotplate_spec(), self.devices.bath()
            cam_settings = self.devices.settings()
        except Exception as exc:
            self.on_message("error", f"cannot build the bench: {exc}")
            return
        if camera == SIMULATED and self._sim_current(bath.water_g):
            then(self.sim.bench())
            return
        clock = self.engine.clock

        def build(progress):
            if camera == SIMULATED:
                release = self._release or release_in_subprocess(self.sample)
                return self._new_sim(bath.water_g, hotplate == SIMULATED, clock, release)
            return make_bench(camera, hotplate, cam_settings)
        self._then = then
        self.build_task = BackgroundTask(build, self)
        self.build_task.finished.connect(self._bench_built)
        self.build_task.failed.connect(self._bench_failed)
        self._set_connecting(True, doing)
        self.build_task.start()

    def _bench_built(self, built) -> None:
        self._set_connecting(False)
        then, self._then = self._then, None
        if self._closed:
            if isinstance(built, SimulatedBench):
                built.close()
            return
        if isinstance(built, SimulatedBench):
            self._release = built.release             # the sample's release: computed once a session
            self._set_sim(built)
            built = built.bench()
        if then is not None:
            then(built)

    def _bench_failed(self, message: str) -> None:
        self._set_connecting(False)
        self._then = None
        self.on_message("error", f"cannot build the bench: {message}")

    def _set_connecting(self, busy: bool, doing: str = "connecting") -> None:
        button = self.devices.connect_button
        if busy:
            self._button_text = button.text()
            button.setText(f"{doing}...")
            self.statusBar().showMessage(f"{doing}... (building the bench)")
        else:
            button.setText(getattr(self, "_button_text", button.text()))
        button.setEnabled(not busy)
        if busy:
            self.controls.start_button.setEnabled(False)
        else:
            self.controls.update_start()

    def _start(self, procedure) -> bool:
        if self.engine.running:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return False
        self.procedure = procedure
        self.bench_hotplate = getattr(getattr(procedure, "bench", None), "hotplate", None)
        self.engine.start(HeldProcedure(procedure, self.plate_poller))   # takes the hotplate from the idle poller
        self.controls.set_running(True)
        self.lock_settings(not isinstance(procedure, PreviewProcedure))
        return True

    # -- actions ------------------------------------------------------------------------------------------
    def connect_devices(self) -> None:
        """Connect, one preview frame, one reading (the bench built in a worker, the procedure in the engine's
        thread)."""
        if self.engine.running:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return
        self.with_bench(lambda bench: self._start(PreviewProcedure(bench)), "connecting")

    def _calibration(self) -> BenchCalibration | None:
        text = self.controls.calibration.text().strip()
        return BenchCalibration.load(text) if text else None

    def start_run(self) -> None:
        """Start a run with the run controls' settings (refused, with the reasons, while Start is disabled)."""
        found = self.controls.start_problems()
        if found:
            self.on_message("error", "cannot start: " + "; ".join(found))
            return
        if self.engine.running:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return
        try:
            config = self.controls.config(self.devices.bath().on_clock(self.engine.clock.speed))
            calibration = self._calibration()
        except Exception as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self.with_bench(lambda bench: self._start_run(config, calibration, bench), "starting")

    def _start_run(self, config: RunConfig, calibration: BenchCalibration | None, bench: Bench) -> None:
        try:
            proc = new_run(config, bench, self.data_dir, calibration)
        except UsageError as exc:
            self.on_message("error", f"cannot start: {exc}")
            return
        self._prepare_plots(config)
        if calibration is not None:
            g = calibration.geometry
            self.live.set_geometry(g.x, g.y, g.size, g.grid, g.mirror_col)
        if self._start(proc):
            persist.remember_run(self.settings, config, self.controls.calibration.text().strip())

    def _prepare_plots(self, config: RunConfig | None) -> None:
        self.run_config = config
        self._last_frame_t = None
        self.plots.clear()
        if config is not None:
            self.plots.set_water(config.bath.water_g)
            self.plots.set_object_mass(config.object_mass_g)
            self.plots.set_setpoint_band(config.bath.setpoint_c, config.bath.tolerance_c)

    def resume_run(self, folder: str) -> None:
        """Resume acquisition into an interrupted run folder."""
        if self.engine.running or self.building:
            self.on_message("warning", "the engine is busy; stop the current procedure first")
            return
        try:
            snap = resumable(folder)
            simulated = snap.record.simulated
            if simulated != (self.devices.camera_spec() == SIMULATED):
                raise UsageError(f"{folder} was recorded on a {'simulated' if simulated else 'real'} bench; "
                                 f"choose {'the simulated' if simulated else 'a real'} camera in the device panel")
            if simulated:
                self.engine.clock = resume_clock(Path(folder), self.speed)
                self._set_sim(None)
            config = RunConfig.from_dict(snap.record.config) if snap.record.config else None
        except Exception as exc:
            self.on_message("error", f"cannot resume {folder}: {exc}")
            return
        self.with_bench(lambda bench: self._resume_run(folder, config, bench), "resuming")

    def _resume_run(self, folder: str, config: RunConfig | None, bench: Bench) -> None:
        try:
            proc = resume_run(Path(folder), bench, self._calibration())
        except Exception as exc:
            self.on_message("error", f"cannot resume {folder}: {exc}")
            return
        self._prepare_plots(config)
        self.tabs.setCurrentIndex(0)
        self._start(proc)

    def confirm_drop(self) -> None:
        """The operator dropped the object: time zero."""
        self.engine.answer(PromptKind.DROP, True)

    def stop(self) -> None:
        """Finish the current procedure cleanly."""
        self.engine.stop()

    def change_duration(self) -> None:
        """Change the recording run's maximum or minimum duration, with a reason (:func:`dialogs.ask_changes`),
        through ``labapp.jobs.run.change_setting`` as `sfr change` does: the request waits in a worker thread for
        the run's next frame, where the engine's thread applies it; the outcome comes back in :meth:`_changed`."""
        proc = self.procedure
        if not (self.engine.running and isinstance(proc, RunProcedure) and proc.run is not None):
            self.on_message("warning", "no run is recording: its duration changes only while it records")
            return
        if self.change_task is not None and self.change_task.running:
            self.on_message("warning", "a change is still waiting for the run's next frame")
            return
        folder = proc.run.path
        current = {s.name: getattr(proc.config, s.name) for s in CHANGEABLE_DURING_RUN}
        asked = dialogs.ask_changes(self, dialogs.change_question(folder.name, self.status.t_s),
                                    CHANGEABLE_DURING_RUN, current)
        if asked is None:
            return
        changes, reason = asked
        gone = lambda: self._closed or not self.engine.running     # noqa: E731 (the run ended: withdraw)

        def work(progress) -> tuple[list[str], str]:
            done = []
            for name, value in changes.items():
                try:
                    done.append(change_setting(folder, name, value, reason, should_stop=gone))
                except (UsageError, OperatorError) as exc:
                    return done, str(exc)
            return done, ""
        self.on_message("info", f"waiting for {folder.name}'s next frame to change its duration ...")
        self.change_task = BackgroundTask(work, self)
        self.change_task.finished.connect(self._changed)
        self.change_task.failed.connect(self._change_failed)
        self.change_task.start()

    def _changed(self, outcome: tuple[list[str], str]) -> None:
        """A change of the run's duration was answered: each change made in the event log, a refusal said."""
        done, refused = outcome
        for detail in done:
            self.on_message("info", f"changed {detail}")
        if refused:
            self.on_message("error", f"not changed: {refused}")
            if not self._closed:
                dialogs.tell(self, "change refused", refused)

    def _change_failed(self, message: str) -> None:
        self._changed(([], message))

    def start_calibration(self) -> None:
        """Start a calibration series (:func:`labapp.jobs.series.new_series`) with the crop of the live view,
        the device panel's bath and the wizard's masses."""
        try:
            masses, bath = self.wizard.masses_g(), self.devices.bath()
        except Exception as exc:
            self.wizard.show_result(f"cannot start: {exc}")
            return
        self.with_bench(lambda bench: self._start_calibration(bench, masses, bath), "starting")

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
        newest = runs[0]
        names = "\n".join(f"  {snap.path.name} ({len(snap.frames)} frames)" for snap in runs[:8])
        box = QMessageBox(QMessageBox.Icon.Question, "interrupted runs",
                          f"{len(runs)} run(s) in {self.data_dir} stopped without finishing:\n{names}\n\n"
                          f"Resume {newest.path.name} now? (Later: Runs tab, Resume acquisition.)", parent=self)
        self.resume_button = box.addButton("Resume newest", QMessageBox.ButtonRole.AcceptRole)
        box.addButton("Show in Runs", QMessageBox.ButtonRole.ActionRole)
        box.addButton("Not now", QMessageBox.ButtonRole.RejectRole)
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
    def on_frame(self, frame: FrameStored) -> None:
        """A run frame was stored: plot it, remember it for the live view."""
        self.latest_frame = frame.path
        interval = self.run_config.interval_s if self.run_config is not None else None
        if self._last_frame_t is not None and interval and \
                frame.t_s - self._last_frame_t > max(GAP_FACTOR * interval, GAP_MIN_S):
            self.plots.mark("gap", self._last_frame_t, "", end_s=frame.t_s)
        self._last_frame_t = frame.t_s
        self.plots.add_frame(frame.t_s, frame.conc_g_per_kg)
        self.browser.show_frames(Path(frame.path).parent, frame.n_frames)     # the Runs list counts live
        # the bath plot shows the reading logged with each frame: one time base with the release curve
        self.plots.add_reading(frame.t_s, frame.plate_c, frame.probe_c, frame.speed_rpm)

    def on_event(self, event) -> None:
        """Marks on the plots: the drop, a resume and steady state (faults and excursions: the alarm banner's)."""
        t = self.status.t_s
        if isinstance(event, StateChanged) and event.phase == Phase.ACQUIRING:
            if event.resumed:
                self.plots.mark("resume", t if t is not None else 0.0, "resumed")
            else:
                self.plots.mark("drop", 0.0, "drop")
        elif isinstance(event, Message) and t is not None and event.topic == "steady":
            self.plots.mark("steady", t, "steady state")

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
            self.browser.refresh()                    # the new run is listed while it records

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
        self.lock_settings(False)
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
        self.poll_idle()

    def poll_idle(self) -> None:
        """Poll the connected bench's hotplate while no procedure holds it (every keepalive of the engine's clock,
        off the GUI thread): the panel and the status line show the heater as it is after a run, and while idle."""
        if self._closed or self.bench_hotplate is None:
            return
        try:
            keepalive_s = self.devices.bath().keepalive_s
        except Exception:                          # a field being edited: the default period
            keepalive_s = KEEPALIVE.default
        self.plate_poller.hold(self.bench_hotplate, keepalive_s)

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
            self.statusBar().showMessage(self.status.line())
        self._show_progress()
        if self.latest_frame is not None:
            rgb = decode_preview(path=self.latest_frame)
            if rgb is not None:
                self.live.set_frame(rgb, Path(self.latest_frame).name)
            self.latest_frame = None

    def _show_progress(self) -> None:
        config, t = self.run_config, self.status.t_s
        if isinstance(self.procedure, RunProcedure):
            config = self.procedure.config      # the engine's: a duration changed during the run included
        recording = self.engine.running and config is not None and self.status.phase == Phase.ACQUIRING
        self.progress.setVisible(recording)
        if not recording or t is None:
            return
        total = config.max_duration_s
        self.progress.setRange(0, max(1, int(total)))
        self.progress.setValue(int(min(max(t, 0.0), total)))
        left = max(total - t, 0.0)
        self.progress.setFormat(f"{hmm(t)} of {hmm(total)}, {hmm(left)} left"
                                + (" at most (steady-state stop)" if config.stop_on_steady else ""))

    # -- closing --------------------------------------------------------------------------------------------
    def busy_work(self) -> list[str]:
        """What would be cut short by closing now."""
        work = []
        if self.engine.running:
            folder = getattr(getattr(self.procedure, "run", None), "path", None)
            work.append(dialogs.interrupt_effect(getattr(self.procedure, "name", "procedure"),
                                                 Path(folder).name if folder else ""))
        if self.design.busy:
            work.append(f"the design in {self.design.out_dir} (it stops at its next checkpoint; Design tab, "
                        "Resume... continues it)")
        if self.design.sweep.busy:
            work.append(f"the sweep in {self.design.sweep.sweep_dir} (running designs checkpoint, queued ones "
                        "do not start; Sweep again resumes it)")
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
        self.design.stop()
        self.design.sweep.stop()
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
        self.plate_poller.close()                 # heating and stirring off, as every close of the hotplate
        self._set_sim(None)


def _release_then_close(poller: IdlePlatePoller, sim: SimulatedBench) -> None:
    poller.release(sim.hotplate)
    sim.close()


def _scrolled(widget: QWidget) -> QScrollArea:
    """``widget`` in a scroll area: a long form never forces the dock wider or taller than the screen."""
    area = QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    area.setFrameShape(QScrollArea.Shape.NoFrame)
    area.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
    return area

