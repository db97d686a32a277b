"""What a run records of the hotplate is what the plate confirmed: a reading that is not fresh is stored empty, never
as the last values, and "switched off" only when the plate answered the commands and reads off. Fake devices on a
stepped clock; every wait is on an event."""
import threading
import time

from drivers.hotplate.base import HotplateError
from labapp.acquisition.bench import Bench
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Alarm, AlarmKind, FrameStored, Link
from labapp.acquisition.monitor import HotplateMonitor
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import BathSettings
from labapp.records.manifests import read_run
from tests.labapp.lab_fakes import ModelHotplate, RenderCamera

CEILING_S = 30.0
"""A ceiling that fails a hung wait only."""


class HangingHotplate(ModelHotplate):
    """A plate whose reads block while ``hung`` is set (a driver retrying a dead link inside ``read()``), and
    whose every command fails while ``dead`` is set."""

    def __init__(self, clock):
        super().__init__(clock)
        self.hung, self.released, self.dead = threading.Event(), threading.Event(), False

    def read(self):
        if self.hung.is_set():
            self.released.wait(CEILING_S)
        if self.dead:
            raise HotplateError("injected: no reply on /dev/fake")
        return super().read()

    def stop_heating(self):
        if self.dead:
            raise HotplateError("injected: no reply on /dev/fake")
        super().stop_heating()

    def stop_stirring(self):
        if self.dead:
            raise HotplateError("injected: no reply on /dev/fake")
        super().stop_stirring()


def _until(condition):
    deadline = time.monotonic() + CEILING_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        threading.Event().wait(0.005)


def _run(tmp_path, hotplate, clock, on_frame, n_frames=20):
    config = RunConfig(interval_s=10, max_duration_s=10 * n_frames, stop_on_steady=False, auto_drop=True,
                       frame_bytes_estimate=100_000, bath=BathSettings(setpoint_c=None, keepalive_s=0.02))
    proc = RunProcedure(config, Bench(RenderCamera(clock, lambda t: 0.0), hotplate, simulated=True), tmp_path)
    engine = Engine(clock)
    events = []
    engine.subscribe(events.append)
    engine.subscribe(lambda ev: on_frame(proc, engine, ev) if isinstance(ev, FrameStored) else None)
    return proc, engine, events


def test_a_reading_older_than_its_poll_interval_is_stored_empty(tmp_path):
    clock = SteppedClock(start_s=1e9)
    plate = HangingHotplate(clock)

    def on_frame(proc, engine, frame):
        monitor = proc.session.monitor
        if frame.index == 4:                    # the driver starts retrying a dead link inside read()
            plate.hung.set()
            _until(lambda: monitor.age_s() > monitor.fresh_s)
        elif frame.index == 9:                  # it answers again: the next frames have a fresh reading
            plate.hung.clear()
            plate.released.set()
            _until(lambda: monitor.fresh() is not None)
    proc, engine, _ = _run(tmp_path, plate, clock, on_frame)
    assert engine.run(proc) == "complete"
    frames = read_run(proc.run.path).frames
    assert all(f.plate_c is not None for f in frames[:5])
    assert all(f.plate_c is None and f.probe_c is None and f.speed_rpm is None for f in frames[5:10]), frames[3:11]
    assert all(f.plate_c is not None for f in frames[10:])
    csv_rows = (proc.run.path / "frames.csv").read_text().splitlines()
    assert csv_rows[6].split(",")[3:6] == ["", "", ""]            # frames.csv: empty cells, not the last values


def test_the_record_says_switched_off_only_when_the_plate_confirms_it(tmp_path):
    clock = SteppedClock(start_s=1e9)
    plate = HangingHotplate(clock)

    def on_frame(proc, engine, frame):
        if frame.index == 3:                    # the link dies, then SIGTERM (the window closing, Ctrl-C)
            plate.dead = True
            engine.interrupt()
    proc, engine, events = _run(tmp_path, plate, clock, on_frame)
    assert engine.run(proc) == "interrupted"
    log = (proc.run.path / "events.log").read_text()
    assert "heating and stirring could NOT be confirmed off" in log and "switch it off by hand" in log
    assert "switched off" not in log and "heating off" not in log
    assert "heating and stirring NOT confirmed off, the run can be resumed" in log
    assert proc.session.off_confirmed is False
    assert any(isinstance(e, Alarm) and e.kind == AlarmKind.NOT_CONFIRMED_OFF for e in events)


def test_a_confirmed_switch_off_is_recorded_as_such(tmp_path):
    clock = SteppedClock(start_s=1e9)
    plate = HangingHotplate(clock)

    def on_frame(proc, engine, frame):
        if frame.index == 3:
            engine.interrupt()
    proc, engine, _ = _run(tmp_path, plate, clock, on_frame)
    assert engine.run(proc) == "interrupted"
    log = (proc.run.path / "events.log").read_text()
    assert "heating and stirring switched off (the plate confirms" in log and "NOT" not in log
    assert "heating off, the run can be resumed" in log


def test_the_monitor_says_it_keeps_retrying_and_publishes_the_link(tmp_path):
    clock = SteppedClock(start_s=1e9)
    plate = ModelHotplate(clock)
    reports, links = [], []
    monitor = HotplateMonitor(plate, lambda *r: reports.append(r), poll_s=0.01, on_link=lambda ok, m: links.append(ok))
    assert monitor.poll() is not None and monitor.fresh() is not None
    plate.fail_reads = 2
    assert monitor.poll() is None and monitor.fresh() is None            # down: nothing current
    assert monitor.poll() is None
    (level, kind, message), = reports
    assert kind == "hotplate-link" and "retrying until it answers" in message and "unknown" in message
    assert monitor.poll() is not None
    assert links == [False, True] and "restored" in reports[-1][2]


def test_link_events_reach_subscribers(tmp_path):
    clock = SteppedClock(start_s=1e9)
    plate = HangingHotplate(clock)

    def on_frame(proc, engine, frame):
        if frame.index == 2:
            plate.fail_reads = 10 ** 6
            _until(lambda: not proc.session.monitor.link_ok)
        elif frame.index == 4:
            plate.fail_reads = 0
            _until(lambda: proc.session.monitor.link_ok)
    proc, engine, events = _run(tmp_path, plate, clock, on_frame, n_frames=8)
    assert engine.run(proc) == "complete"
    assert [e.ok for e in events if isinstance(e, Link)] == [False, True]
    kinds = [e.kind for e in events if isinstance(e, Alarm)]
    assert AlarmKind.LINK_FAULT in kinds and AlarmKind.LINK_RESTORED in kinds
