"""The release-measurement run (paper section 4.2) as a procedure the engine walks.

connect -> heat and wait until stable -> stir -> reference frame -> the operator drops the object (time
zero) -> a frame every ``interval_s`` with plate/probe temperature and stirring speed, each analysed live
-> stop on request, on steady state or at ``max_duration_s`` -> heating off. A frame's plate/probe/stirring
values are the hotplate's reading only while it is fresh (:meth:`labapp.acquisition.monitor.HotplateMonitor.fresh`);
with the link down or the reading older than its poll interval they are stored empty, never as the last values.

A run reopened after a crash (:meth:`RunProcedure.resume`) records the gap and continues into the same folder:
its stored frames are analysed again and published first (the window plots the whole history), and capture goes
on at once, without waiting for the bath: the object keeps dissolving in the beaker whatever its temperature, so
a frame not taken is release not measured. The note at the resume says so, with the bath's temperature, and the
excursion alarm marks the time the bath spends outside its band.
"""
from __future__ import annotations

import dataclasses
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from analysis import BenchCalibration, reference_offset
from labapp.acquisition.bench import Bench, BenchSession, ProcedureError, bath_c
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import (
    AlarmKind,
    FrameStored,
    Outcome,
    Phase,
    Preview,
    PromptKind,
    ReferenceStored,
    StateChanged,
)
from labapp.acquisition.live import LiveAnalyzer, is_steady
from labapp.acquisition.settings import (
    CHANGEABLE_DURING_RUN,
    FRAME_BYTES,
    INTERVAL,
    LOW_SPACE,
    MAX_DURATION,
    MIN_DURATION,
    OBJECT_MASS,
    REFERENCE_ALARM_G_PER_KG,
    RUN_SETTINGS,
    BathSettings,
    Setting,
    check_settings,
    from_record,
    to_record,
)
from labapp.errors import UsageError
from labapp.records import requests
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.fileio import check_disk_space, free_bytes
from labapp.records.manifests import read_run
from labapp.records.runrecord import RecordStatus
from labapp.records.storage import RunFolder, create_run, open_run

_STATUS = {outcome: RecordStatus(outcome) for outcome in Outcome}


def check_change(name: str, value: float, reason: str) -> Setting:
    """The declaration of ``name`` if it may change during a run to ``value`` (stored units) with ``reason``.

    Raises
    ------
    UsageError
        For a setting fixed at the start, no reason, or a value out of its range.
    """
    settings = {s.name: s for s in CHANGEABLE_DURING_RUN}
    if name not in settings:
        raise UsageError(f"{name} cannot change while a run records (only {', '.join(settings)} can); the other "
                         "settings are fixed at the start")
    if not reason or not reason.strip():
        raise UsageError(f"changing {name} during a run needs a reason (it is recorded in the audit trail)")
    settings[name].check(value, "change")
    return settings[name]


@dataclass(frozen=True)
class RunConfig:
    """Settings of one release run (stored in ``run.json``). Times in s, masses in g; the bath in ``bath``.

    Ranges and defaults are declared in :mod:`labapp.acquisition.settings` (:data:`RUN_SETTINGS`).
    """

    name: str = "run"
    interval_s: float = INTERVAL.default
    max_duration_s: float = MAX_DURATION.default
    stop_on_steady: bool = True
    min_duration_s: float = MIN_DURATION.default
    object_mass_g: float | None = OBJECT_MASS.default
    object_name: str = ""
    notes: str = ""
    auto_drop: bool = False
    frame_bytes_estimate: int | None = FRAME_BYTES.default
    low_space_bytes: int = LOW_SPACE.default
    bath: BathSettings = field(default_factory=BathSettings)

    def __post_init__(self) -> None:
        check_settings(self, RUN_SETTINGS)

    def to_dict(self) -> dict[str, Any]:
        """The settings as stored under ``config`` in ``run.json`` (the bath's fields alongside the run's)."""
        return to_record(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        """Rebuild a config stored in ``run.json`` (flat, or the bath under ``bath``; unknown keys ignored)."""
        return from_record(cls, data)


def _calibration_bytes(calibration: BenchCalibration) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "calibration.json"
        calibration.save(path)
        return path.read_bytes()


def _geometry_meta(calibration: BenchCalibration | None) -> dict[str, Any]:
    if calibration is None:
        return {}
    g = calibration.geometry
    return {"crop": {"x": g.x, "y": g.y, "size": g.size}, "grid": g.grid, "mirror_col": g.mirror_col,
            "reduce": calibration.reduce}


class RunProcedure:
    """One release run into a new run folder under ``data_dir`` (or resumed into an existing one).

    Parameters
    ----------
    config : RunConfig
    bench : Bench
        Camera, hotplate and (simulation) hooks.
    data_dir : Path
        Where the run folder is created; nothing is written outside it.
    calibration : BenchCalibration, optional
        Enables live analysis (concentration per frame) and the steady-state stop.
    """

    name = "run"

    def __init__(self, config: RunConfig, bench: Bench, data_dir: Path,
                 calibration: BenchCalibration | None = None) -> None:
        self.config, self.bench, self.data_dir = config, bench, Path(data_dir)
        self.calibration = calibration
        self.resume_path: Path | None = None
        self.record_extra: dict[str, Any] = {}
        """Further ``run.json`` fields of a new run (the method it follows: ``method``)."""
        self.run: RunFolder | None = None
        self.session: BenchSession | None = None
        self.analyzer = LiveAnalyzer(calibration) if calibration is not None else None
        self.t_s: list[float] = []
        self.conc: list[float] = []

    @classmethod
    def resume(cls, folder: Path, bench: Bench, calibration: BenchCalibration | None = None) -> RunProcedure:
        """A procedure continuing the run in ``folder`` with its stored settings (and stored calibration)."""
        snap = read_run(folder)
        config = RunConfig.from_dict(snap.record.config or {})
        cal_file = Path(folder) / "calibration.json"
        if calibration is None and cal_file.is_file():
            calibration = BenchCalibration.load(cal_file)
        proc = cls(config, bench, Path(folder).parent, calibration)
        proc.resume_path = Path(folder)
        return proc

    # -- engine hooks ------------------------------------------------------------------------------------
    def startup(self, engine: Engine) -> None:
        """Connect the devices, then open the run folder (new or resumed): a bench that cannot be reached
        leaves no new folder behind and an interrupted run untouched."""
        cfg = self.config
        n_frames = math.ceil(cfg.max_duration_s / cfg.interval_s)
        if self.resume_path is None:     # the data directory is made with the run folder: a bench not reached leaves none
            existing = next(p for p in (self.data_dir, *self.data_dir.parents) if p.exists())
            check_disk_space(existing, cfg.frame_bytes_estimate or self.bench.frame_bytes, n_frames)
        self.session = BenchSession(self.bench, engine, None, keepalive_s=cfg.bath.keepalive_s)
        if self.resume_path is None and self.bench.on_new_beaker is not None:
            self.bench.on_new_beaker()
        self.session.connect(cfg.bath.setpoint_c, cfg.bath.speed_rpm)
        if self.resume_path is not None:
            self.run = open_run(self.resume_path)
        else:
            meta = dict(kind="run", config=cfg.to_dict(), water_g=cfg.bath.water_g,
                        object_mass_g=cfg.object_mass_g, object_name=cfg.object_name, notes=cfg.notes,
                        interval_s=cfg.interval_s, simulated=self.bench.simulated, bench=self.bench.description,
                        **_geometry_meta(self.calibration), **self.record_extra)
            self.run = create_run(self.data_dir, cfg.name, meta)
            if self.calibration is not None:
                self.run.add_file("calibration.json", _calibration_bytes(self.calibration))
        engine.emit(StateChanged(Phase.OPENED, folder=str(self.run.path), resumed=self.resume_path is not None))
        self.session.t0_unix_s = self.run.record.t0_unix_s
        self.session.attach(self.run)
        self.t_s, self.conc = [], []

    def execute(self, engine: Engine) -> None:
        """Heat, reference, drop (unless resuming after the drop), then acquire until a stop criterion."""
        cfg, session, run = self.config, self.session, self.run
        if "reference.jpg" in run.record.files:
            self._use_reference()
            engine.emit(ReferenceStored(str(run.path / "reference.jpg")))
        self._replay(engine)
        if session.t0_unix_s is None:
            session.wait_bath(cfg.bath)
            if engine.should_stop():
                return
            session.start_stirring(cfg.bath.speed_rpm)  # the reference shows the stirred bath
            if "reference.jpg" not in run.record.files:
                self._capture_reference(engine)
            engine.emit(StateChanged(Phase.WAITING_DROP))
            dropped = engine.ask(PromptKind.DROP, "Drop the object into the beaker, then confirm.",
                                 auto=True if cfg.auto_drop else None)
            if not dropped or engine.should_stop():
                return
            session.t0_unix_s = engine.clock.now()
            run.update(t0_unix_s=session.t0_unix_s)
            session.note("info", "drop", "object dropped: time zero")
            audit(run.path, Action.DROP, "object dropped: time zero")
        else:
            self._note_resumed_bath()
            session.start_stirring(cfg.bath.speed_rpm)
            last = run.frames[-1].t_s if run.frames else 0.0
            run.add_gap(last, session.t_s(), "acquisition interrupted; resumed into the same folder")
        if self.bench.on_drop is not None:
            self.bench.on_drop(session.t0_unix_s)
        self._acquire(engine)

    def shutdown(self, engine: Engine, outcome: Outcome) -> None:
        """Heating off, devices closed, final status written (always runs); an interrupted run is released
        without a final status, so that it reads ``interrupted`` and can be resumed."""
        if self.session is not None:
            self.session.close()
        if self.run is not None:
            if outcome == Outcome.FAILED and engine.error is not None:
                self.run.event("error", "failed", f"{type(engine.error).__name__}: {engine.error}")
            if outcome == Outcome.INTERRUPTED:
                off = self.session is None or self.session.off_confirmed is not False
                self.run.event("warning", "interrupted", f"acquisition interrupted with {len(self.run.frames)} frames; "
                               + ("heating off" if off else "heating and stirring NOT confirmed off")
                               + ", the run can be resumed")
                self.run.update(writer_pid=None, writer_started=None)
            else:
                self.run.finish(_STATUS[outcome])
            self.run.close()

    # -- steps -------------------------------------------------------------------------------------------
    def _capture_reference(self, engine: Engine) -> None:
        cap = self.session.capture() or self.session.capture()
        if cap is None:
            raise ProcedureError("no reference frame: the camera failed twice")
        self.run.add_file("reference.jpg", cap.data)
        self.run.update(reference_file="reference.jpg", reference_t_unix_s=cap.t_unix_s)
        self.session.note("info", "reference", "reference frame (clear water) captured")
        self._use_reference()
        engine.emit(ReferenceStored(str(self.run.path / "reference.jpg")))

    def _replay(self, engine: Engine) -> None:
        """A resumed run's stored frames, analysed again (the live curve and the steady-state stop see the
        whole run) and published as :class:`FrameStored` events, oldest first."""
        water_kg = self.config.bath.water_g / 1000.0
        for index, frame in enumerate(self.run.frames):
            if engine.should_stop():
                return
            conc = unc = math.nan
            if self.analyzer is not None:
                try:
                    point = self.analyzer.analyze(self.run.path / frame.file)
                    conc, unc = point.conc_g_per_kg, point.uncertainty_g_per_kg
                except Exception as exc:
                    self.session.note("warning", "analysis", f"{frame.file}: could not analyse ({type(exc).__name__}: "
                                      f"{exc}); the frame is kept")
            self.t_s.append(frame.t_s)
            self.conc.append(conc)
            engine.emit(FrameStored(index, frame.file, str(self.run.path / frame.file), frame.t_s, index + 1,
                                    capture_t_unix_s=frame.t_unix_s, conc_g_per_kg=conc, uncertainty_g_per_kg=unc,
                                    released_g=conc * water_kg, plate_c=frame.plate_c, probe_c=frame.probe_c,
                                    speed_rpm=frame.speed_rpm))

    def _note_resumed_bath(self) -> None:
        """Say at a resume what the bath is and why capture goes on at once."""
        setpoint = self.config.bath.setpoint_c
        reading = self.session.fresh_reading()
        if setpoint is None or reading is None:
            return
        temp = bath_c(reading)
        if abs(temp - setpoint) <= self.config.bath.tolerance_c:
            self.session.note("info", "resume", f"resumed with the bath at {temp:.1f} C, within its setpoint")
            return
        self.session.note("warning", "resume", f"resumed with the bath at {temp:.1f} C, not at its setpoint {setpoint:g} C: "
                          "capture goes on at once while it heats back (the object keeps dissolving, a frame not "
                          "taken is release not measured); the excursion alarm marks the time outside the band",
                          AlarmKind.TEMPERATURE_EXCURSION)

    def _use_reference(self) -> None:
        """Anchor the live analysis on the reference frame, and check it as the offline analysis does: a
        reference that does not read as clear water on the calibration's zero level (beyond
        ``analysis.reference_offset``'s 3 sigma) is logged, and raises an alarm beyond
        :data:`labapp.acquisition.settings.REFERENCE_ALARM_G_PER_KG` (before the drop on a new run)."""
        if self.analyzer is None:
            return
        try:
            self.analyzer.set_reference(self.run.path / "reference.jpg")
        except Exception as exc:
            self.session.note("warning", "reference", f"reference frame unusable for live analysis "
                              f"({type(exc).__name__}: {exc}); the calibration's zero level is used",
                              AlarmKind.REFERENCE_OFFSET)
            return
        est, message = reference_offset(self.analyzer.reference_cells, self.calibration)
        if message:
            alarm = abs(est.conc_g_per_kg) > REFERENCE_ALARM_G_PER_KG
            hint = "; check the beaker holds clear water before the drop" if alarm and self.session.t0_unix_s is None else ""
            self.session.note("warning", "reference", message + hint, AlarmKind.REFERENCE_OFFSET if alarm else None)

    def _acquire(self, engine: Engine) -> None:
        cfg, session, clock = self.config, self.session, engine.clock
        engine.emit(StateChanged(Phase.ACQUIRING, folder=str(self.run.path), t0_unix_s=session.t0_unix_s))
        session.watch_bath(cfg.bath.setpoint_c, cfg.bath.excursion_c)
        slot = math.floor(max(session.t_s(), 0.0) / cfg.interval_s) + (1 if self.run.frames else 0)
        while not engine.should_stop():
            clock.sleep(session.t0_unix_s + slot * cfg.interval_s - clock.now(), engine.should_stop)
            if engine.should_stop():
                return
            self._frame(engine)
            slot = max(slot + 1, math.ceil(session.t_s() / cfg.interval_s))
            self._serve_requests()
            cfg = self.config        # a setting changed by a request applies from here
            if session.t_s() >= cfg.max_duration_s:
                session.note("info", "max-duration", f"maximum duration {cfg.max_duration_s:.0f} s reached")
                return
            if cfg.stop_on_steady and is_steady(self.t_s, self.conc, cfg.min_duration_s):
                session.note("info", "steady", f"steady state reached at t={self.t_s[-1]:.0f} s")
                return

    def change_setting(self, name: str, value: float, reason: str, operator: str | None = None) -> str:
        """Change a setting of the run being recorded (stored units), with ``reason``, as ``operator`` (default
        the current one): it applies from the next frame, ``run.json``'s settings hold it (a resume keeps it)
        and the audit trail says who changed what from what, when and why. Returns what changed, one line.

        Raises
        ------
        UsageError
            For a setting that cannot change during a run, no reason, a value out of range, or no run recording.
        labapp.records.operators.OperatorError
            When nobody is acting (no ``operator`` and no current operator).
        """
        setting = check_change(name, value, reason)
        if self.run is None or self.run.status != RecordStatus.RUNNING:
            raise UsageError("no run is recording; a setting changes only during a run")
        detail = (f"{name}: {setting.shown(getattr(self.config, name)):g} -> {setting.shown(value):g} "
                  f"{setting.display_unit}")
        audit(self.run.path, Action.CHANGE_SETTING, detail, reason=reason.strip(), operator=operator)
        self.config = dataclasses.replace(self.config, **{name: value})
        self.run.update(config=self.config.to_dict())
        return detail

    def _serve_requests(self) -> None:
        """Carry out the requests other processes left for this run (:mod:`labapp.records.requests`)."""
        for request, body in requests.claim(self.run.path):
            try:
                if body is None or body.get("action") != "change":
                    raise UsageError(f"{request.name} is not a request this run understands")
                detail = self.change_setting(str(body["name"]), float(body["value"]), str(body.get("reason") or ""),
                                             operator=str(body["operator"]))
            except (UsageError, KeyError, TypeError, ValueError) as exc:
                requests.answer(request, {"done": False, "why": str(exc)})
                continue
            requests.answer(request, {"done": True, "detail": detail})
            self.session.note("info", "setting", f"{detail}, by {body['operator']}: {body['reason']}")

    def _frame(self, engine: Engine) -> None:
        session, run = self.session, self.run
        cap = session.capture()
        if cap is None:
            return
        index = len(run.frames)
        suffix = Path(cap.file_name).suffix.lower() or ".jpg"
        name = f"frame_{index:06d}{suffix}"
        reading = session.fresh_reading()          # stale or link down: stored empty, never the last values
        t_s = cap.t_unix_s - session.t0_unix_s
        record = run.add_frame(name, cap.data, t_s, cap.t_unix_s,
                               reading.plate_c if reading else None, reading.probe_c if reading else None,
                               reading.speed_rpm if reading else None)
        for extra_name, data in cap.extra.items():
            run.add_file(f"frame_{index:06d}{Path(extra_name).suffix.lower()}", data)
        conc = unc = math.nan
        if self.analyzer is not None:
            try:
                point = self.analyzer.analyze(run.path / name)
                conc, unc = point.conc_g_per_kg, point.uncertainty_g_per_kg
            except Exception as exc:
                session.note("warning", "analysis", f"{name}: could not analyse ({type(exc).__name__}: {exc}); "
                             "the frame is kept, the run goes on")
        self.t_s.append(t_s)
        self.conc.append(conc)
        engine.emit(FrameStored(index, name, str(run.path / name), t_s, len(run.frames), capture_t_unix_s=cap.t_unix_s,
                                conc_g_per_kg=conc, uncertainty_g_per_kg=unc,
                                released_g=conc * self.config.bath.water_g / 1000.0 if not math.isnan(conc) else math.nan,
                                plate_c=record.plate_c, probe_c=record.probe_c, speed_rpm=record.speed_rpm,
                                last_error=session.last_error))
        if index % 25 == 0 and free_bytes(run.path) < self.config.low_space_bytes:
            session.note("warning", "disk-space", f"disk space low: {free_bytes(run.path) / 1e9:.2f} GB free")


class PreviewProcedure:
    """Connect the bench, publish one frame (``preview`` event with the image bytes) and one reading, close.

    Nothing is stored and the hotplate is not switched on: the device panel's "connect" check.
    """

    name = "preview"

    def __init__(self, bench: Bench) -> None:
        self.bench = bench
        self.session: BenchSession | None = None

    def startup(self, engine: Engine) -> None:
        """Connect camera and hotplate (no setpoints)."""
        self.session = BenchSession(self.bench, engine, None)
        self.session.connect(None, None)

    def execute(self, engine: Engine) -> None:
        """One frame, one reading."""
        cap = self.session.capture()
        if cap is not None:
            engine.emit(Preview(cap.data, cap.file_name, cap.t_unix_s))
        if self.session.monitor is not None:
            self.session.monitor.poll()

    def shutdown(self, engine: Engine, outcome: str) -> None:
        """Close the devices."""
        if self.session is not None:
            self.session.close()
