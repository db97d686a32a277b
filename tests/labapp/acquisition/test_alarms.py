"""Failures the operator must see are published as typed alarms; an interrupted run stays resumable; a calibration
series refuses a level already captured and can redo the last one; every run starts in a fresh beaker."""
import csv
import threading
from types import SimpleNamespace

import pytest

from drivers.camera.base import CaptureMissed
from drivers.hotplate.base import HotplateReading
from labapp.acquisition.bench import Bench, BenchSession
from labapp.acquisition.calseries import CalibrationProcedure, RedoLevel, SeriesConfig
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Alarm, AlarmKind, Done, FrameStored, Message, Outcome, Prompt, PromptKind, Reading
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import BathSettings
from labapp.acquisition.simbench import SimulatedBench
from labapp.jobs.run import resumable
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run
from tests.labapp.acquisition.test_lab_procedures import FAST_BATH, _bench, _truth, calibration  # noqa: F401, F811
from tests.labapp.lab_fakes import SCENE, ModelHotplate, RenderCamera


def _collect(engine):
    events = []
    engine.subscribe(events.append)
    return events


def _alarms(events, kind=None):
    return [e for e in events if isinstance(e, Alarm) and (kind is None or e.kind == kind)]


def test_faults_and_an_excursion_raise_alarms_of_their_kind(tmp_path, calibration):  # noqa: F811
    clock = SteppedClock(start_s=5e9)
    t0 = [None]
    bench = _bench(clock, _truth(t0))
    engine = Engine(clock)
    events = _collect(engine)

    def inject(ev):
        if isinstance(ev, FrameStored) and ev.index == 3:
            bench.camera.faults[bench.camera.n + 1] = CaptureMissed
            bench.hotplate.fail_reads = 2
        if isinstance(ev, FrameStored) and ev.index == 8:
            bench.hotplate.temp_c -= 5.0                 # cold water poured in: 5 C below the setpoint
    engine.subscribe(inject)
    bench.on_drop = lambda t: t0.__setitem__(0, t)
    config = RunConfig(interval_s=60, max_duration_s=1200, stop_on_steady=False, auto_drop=True,
                       frame_bytes_estimate=100_000, low_space_bytes=0,
                       bath=BathSettings(stable_step_s=30, keepalive_s=0.01, excursion_c=1.5))
    proc = RunProcedure(config, bench, tmp_path, calibration)
    assert engine.run(proc) == "complete"
    kinds = {a.kind for a in _alarms(events)}
    assert {AlarmKind.CAMERA_FAULT, AlarmKind.LINK_FAULT, AlarmKind.TEMPERATURE_EXCURSION} <= kinds, kinds
    excursion = _alarms(events, AlarmKind.TEMPERATURE_EXCURSION)
    assert len(excursion) == 1 and "outside the setpoint 70 +/- 1.5 C" in excursion[0].message
    assert excursion[0].t_s is not None and excursion[0].t_s >= 8 * 60
    assert AlarmKind.REFERENCE_OFFSET not in kinds                 # clear water at the reference
    log_text = (proc.run.path / "events.log").read_text()
    assert "outside the setpoint" in log_text
    assert read_run(proc.run.path).meta["config"]["excursion_c"] == 1.5
    # the last reading published shows the plate switched off
    last = [e for e in events if isinstance(e, Reading)][-1]
    assert not last.heating and not last.stirring


def test_the_excursion_band_alarms_once_per_excursion():
    clock = SteppedClock(start_s=5e9)
    engine = Engine(clock)
    events = _collect(engine)
    session = BenchSession(Bench(RenderCamera(clock, lambda t: 0.0), ModelHotplate(clock)), engine, None)
    session.monitor = SimpleNamespace(fresh_s=2.5)   # watched only with a hotplate
    session.t0_unix_s = clock.now()
    session.watch_bath(70.0, 2.0)
    for probe_c in (70.1, 68.1, 67.0, 66.0, 69.0, 73.0, 72.5, 70.0):
        session._publish_reading(HotplateReading(probe_c + 5, probe_c, 150, 70.0, 150, True, True, clock.now()))
    alarms = _alarms(events, AlarmKind.TEMPERATURE_EXCURSION)
    assert [a.message for a in alarms] == ["bath at 67.0 C, outside the setpoint 70 +/- 2 C",
                                           "bath at 73.0 C, outside the setpoint 70 +/- 2 C"]
    backs = [e.message for e in events if isinstance(e, Message) and e.message.startswith("bath back")]
    assert backs == ["bath back within 70 +/- 2 C (69.0 C)", "bath back within 70 +/- 2 C (70.0 C)"]
    session.watch_bath(None, 2.0)                    # no setpoint: nothing to watch
    session._publish_reading(HotplateReading(30.0, 25.0, 150, 70.0, 150, True, True, clock.now()))
    assert len(_alarms(events)) == 2


def test_a_reference_that_is_not_clear_water_raises_an_alarm_before_the_drop(tmp_path, calibration):  # noqa: F811
    clock = SteppedClock(start_s=6e9)
    bench = _bench(clock, lambda t: 1.0)                        # dye left in the beaker: 1 g/kg before the drop
    engine = Engine(clock)
    events = _collect(engine)
    engine.subscribe(lambda e: engine.stop() if isinstance(e, Prompt) and e.prompt == PromptKind.DROP else None)
    proc = RunProcedure(RunConfig(frame_bytes_estimate=1000, bath=FAST_BATH), bench, tmp_path, calibration)
    assert engine.run(proc) == "stopped"
    ref = _alarms(events, AlarmKind.REFERENCE_OFFSET)
    assert len(ref) == 1 and "before the drop" in ref[0].message
    assert abs(float(ref[0].message.split("reads ")[1].split()[0]) - 1.0) < 0.05, ref[0].message
    assert events.index(ref[0]) < next(i for i, e in enumerate(events) if isinstance(e, Prompt))


def test_a_heat_timeout_says_what_happened_in_a_sentence(tmp_path, calibration):  # noqa: F811
    clock = SteppedClock(start_s=7e9)
    bench = Bench(RenderCamera(clock, lambda t: 0.0), ModelHotplate(clock, tau_s=1e6), simulated=True)
    engine = Engine(clock)
    events = _collect(engine)
    bath = BathSettings(setpoint_c=70.0, heat_timeout_s=600, stable_step_s=30, keepalive_s=0.01)
    proc = RunProcedure(RunConfig(frame_bytes_estimate=1000, bath=bath), bench, tmp_path, calibration)
    assert engine.run(proc) == "failed"
    (alarm,) = _alarms(events, AlarmKind.HEAT_TIMEOUT)
    assert "HotplateReading(" not in alarm.message and "HotplateReading(" not in str(engine.error)
    assert alarm.message.startswith("the bath did not hold 70 +/- 0.5 C for 120 s within the heating timeout of 600 s; "
                                    "the last reading was 21.0 C (probe), heating on at a setpoint of 70 C")
    assert "a setpoint below the bath's room temperature is never reached" in alarm.message


def test_an_interrupted_run_is_left_resumable_with_the_heating_off(tmp_path, calibration):  # noqa: F811
    clock = SteppedClock(start_s=8e9)
    t0 = [None]
    bench = _bench(clock, _truth(t0))
    bench.on_drop = lambda t: t0.__setitem__(0, t)
    engine = Engine(clock)
    engine.subscribe(lambda e: engine.interrupt() if isinstance(e, FrameStored) and e.index == 4 else None)
    outcomes = []
    engine.subscribe(lambda e: outcomes.append(e.outcome) if isinstance(e, Done) else None)
    config = RunConfig(interval_s=60, max_duration_s=3000, stop_on_steady=False, auto_drop=True,
                       frame_bytes_estimate=100_000, low_space_bytes=0, bath=FAST_BATH)
    proc = RunProcedure(config, bench, tmp_path, calibration)
    assert engine.run(proc) == Outcome.INTERRUPTED and outcomes == [Outcome.INTERRUPTED]
    assert bench.hotplate.log[-2:] == ["heating off", "close"] and not bench.hotplate.heating
    snap = resumable(proc.run.path)                     # refuses anything but an interrupted run
    assert snap.status == "interrupted" and len(snap.frames) == 5 and verify_run(proc.run.path).ok
    assert "heating off, the run can be resumed" in (proc.run.path / "events.log").read_text()


def _operator_series(tmp_path, answers):
    """A series on fake devices where the operator gives ``answers`` to the mass prompts, in turn."""
    clock = SteppedClock(start_s=9e9)
    state = {"mass": 0.0}
    bench = Bench(RenderCamera(clock, lambda t: state["mass"] / 0.5), ModelHotplate(clock), simulated=True,
                  on_add_mass=lambda m: state.update(mass=m))
    engine = Engine(clock)
    events = _collect(engine)
    queue = list(answers)

    def answer(ev):
        if isinstance(ev, Prompt) and ev.prompt == PromptKind.ADDED_MASS:
            value = queue.pop(0)
            threading.Timer(0.01, engine.answer, (PromptKind.ADDED_MASS, value)).start()
    engine.subscribe(answer)
    config = SeriesConfig(crop=SCENE.default_crop(), settle_s=0, reduce=1,
                          bath=BathSettings(stable_step_s=30, keepalive_s=0.02))
    proc = CalibrationProcedure(config, bench, tmp_path)
    return engine.run(proc), proc, events, queue


def test_a_series_refuses_a_level_already_captured_and_redoes_the_last_one(tmp_path):
    outcome, proc, events, left = _operator_series(tmp_path, [0.25, 0.25, 0.0, 0.5, RedoLevel(), 1.0, ""])
    assert outcome == "complete" and not left
    with open(proc.run.path / "masses.csv") as fh:
        rows = [(r["file"], float(r["added_mass_g"])) for r in csv.DictReader(fh)]
    # 0.25 twice and 0 again captured nothing; the redo replaced cal_002 (0.5 g) by cal_003
    assert rows == [("cal_000.jpg", 0.0), ("cal_001.jpg", 0.25), ("cal_003.jpg", 0.5), ("cal_004.jpg", 1.0)]
    snap = read_run(proc.run.path)
    assert [f.file for f in snap.frames] == [f"cal_{i:03d}.jpg" for i in range(5)] and verify_run(proc.run.path).ok
    log_text = (proc.run.path / "events.log").read_text()
    assert "0.25 g is a level already captured the cumulative 0.25 g; nothing captured" in log_text
    assert "level 0.5 g captured again by the operator: cal_003.jpg replaces cal_002.jpg in masses.csv" in log_text
    assert proc.calibration_path is not None and proc.calibration_path.is_file()
    prompts = [e for e in events if isinstance(e, Prompt)]
    assert len(prompts) == 7                               # asked again after each refusal and after the redo


def test_a_series_ended_too_early_raises_a_fit_alarm(tmp_path):
    outcome, proc, events, _ = _operator_series(tmp_path, [0.25, ""])
    assert outcome == "complete" and proc.calibration_path is None
    (alarm,) = _alarms(events, AlarmKind.FIT_FAILED)
    assert "only 2 levels captured; 3 are needed" in alarm.message


@pytest.mark.slow
def test_each_run_starts_in_a_fresh_beaker(tmp_path, calibration):  # noqa: F811
    sim = SimulatedBench(SteppedClock(start_s=1e9), sample="sphere", with_hotplate=False)
    bench = sim.bench()
    bench.on_drop(sim.clock.now())
    sim.clock.sleep(3600)
    assert sim.conc_at(sim.clock.now()) > 1.0                   # the previous object's dye
    sim.add_mass(0.5)
    assert bench.on_new_beaker is not None
    bench.on_new_beaker()
    assert sim.conc_at(sim.clock.now()) == 0.0 and sim.t_drop is None
    # a new run empties the beaker before it connects; a resumed one does not
    fresh = []
    clock = SteppedClock(start_s=1e10)
    fake = Bench(RenderCamera(clock, lambda t: 0.0), ModelHotplate(clock), simulated=True,
                 on_new_beaker=lambda: fresh.append(clock.now()))
    engine = Engine(clock)
    unsubscribe = engine.subscribe(lambda e: engine.interrupt() if isinstance(e, Prompt) else None)
    proc = RunProcedure(RunConfig(frame_bytes_estimate=1000, bath=FAST_BATH), fake, tmp_path, calibration)
    assert engine.run(proc) == Outcome.INTERRUPTED and len(fresh) == 1
    unsubscribe()
    engine.subscribe(lambda e: engine.stop() if isinstance(e, Prompt) else None)
    assert engine.run(RunProcedure.resume(proc.run.path, fake, calibration)) == "stopped" and len(fresh) == 1
