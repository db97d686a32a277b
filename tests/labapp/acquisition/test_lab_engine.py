"""The Qt-free engine: procedure phases, events to subscribers, stop/abort, operator prompts, clocks."""
import threading
import time

import pytest

from labapp.acquisition.clock import ScaledClock, SteppedClock, WallClock, make_clock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Done, Message, Outcome, Phase, Prompt, PromptKind, StateChanged


class Counting:
    """Counts to ``n`` one simulated second at a time, publishing a progress event per step."""

    name = "counting"

    def __init__(self, n, fail_at=None, ask=False):
        self.n, self.fail_at, self.ask = n, fail_at, ask
        self.calls, self.answer = [], None

    def startup(self, engine):
        self.calls.append("startup")

    def execute(self, engine):
        self.calls.append("execute")
        if self.ask:
            self.answer = engine.ask(PromptKind.ADDED_MASS, "enter the mass")
        for k in range(self.n):
            if engine.should_stop():
                return
            if k == self.fail_at:
                raise RuntimeError("device gone")
            engine.emit(Message("info", f"step {k}", topic="progress"))
            engine.clock.sleep(1.0, engine.should_stop)

    def shutdown(self, engine, outcome):
        self.calls.append(f"shutdown:{outcome}")


def test_a_procedure_runs_its_phases_and_publishes_events():
    engine = Engine(SteppedClock(start_s=0.0))
    seen = []
    unsubscribe = engine.subscribe(seen.append)
    proc = Counting(5)
    assert engine.run(proc) == Outcome.COMPLETE
    assert proc.calls == ["startup", "execute", "shutdown:complete"]
    steps = [e for e in seen if isinstance(e, Message) and e.topic == "progress"]
    assert [e.message for e in steps] == [f"step {k}" for k in range(5)]
    assert [e.t_unix_s for e in steps] == [0.0, 1.0, 2.0, 3.0, 4.0]          # stamped with the engine's clock
    assert isinstance(seen[0], StateChanged) and seen[0].phase is Phase.STARTING
    assert seen[-1] == Done(Outcome.COMPLETE, "", t_unix_s=5.0)
    assert engine.clock.now() == 5.0
    unsubscribe()
    engine.run(Counting(1))
    assert isinstance(seen[-1], Done) and len([e for e in seen if isinstance(e, Message)]) == 5


def test_a_failure_is_published_and_shutdown_still_runs():
    engine = Engine(SteppedClock())
    errors = []
    engine.subscribe(lambda e: errors.append(e.message) if isinstance(e, Message) and e.level == "error" else None)
    proc = Counting(5, fail_at=2)
    assert engine.run(proc) == Outcome.FAILED
    assert proc.calls[-1] == "shutdown:failed" and "device gone" in errors[0]
    assert isinstance(engine.error, RuntimeError)


def test_a_failing_subscriber_does_not_stop_the_run():
    engine = Engine(SteppedClock())
    engine.subscribe(lambda e: 1 / 0)
    assert engine.run(Counting(3)) == Outcome.COMPLETE


def test_stop_and_abort_from_another_thread():
    engine = Engine(ScaledClock(speed=100.0))
    proc = Counting(10_000)
    engine.start(proc)
    with pytest.raises(RuntimeError, match="already running"):
        engine.start(Counting(1))
    time.sleep(0.05)
    engine.stop()
    assert engine.join(120) == Outcome.STOPPED and proc.calls[-1] == "shutdown:stopped"
    engine.start(Counting(10_000))
    engine.abort()
    assert engine.join(120) == Outcome.ABORTED


def test_the_operator_answers_a_prompt():
    engine = Engine(SteppedClock())
    prompts = threading.Event()
    engine.subscribe(lambda e: prompts.set() if isinstance(e, Prompt) else None)
    proc = Counting(1, ask=True)
    engine.start(proc)
    assert prompts.wait(120)
    engine.answer(PromptKind.ADDED_MASS, 0.25)
    assert engine.join(120) == Outcome.COMPLETE and proc.answer == 0.25


def test_a_stop_releases_a_waiting_prompt():
    engine = Engine(SteppedClock())
    proc = Counting(1, ask=True)
    engine.start(proc)
    time.sleep(0.05)
    engine.stop()
    assert engine.join(120) == Outcome.STOPPED and proc.answer is None


def test_clock_kinds():
    assert isinstance(make_clock(None), WallClock) and isinstance(make_clock(float("inf")), SteppedClock)
    scaled = make_clock(1000.0)
    t0 = scaled.now()
    scaled.sleep(20.0)                      # 20 simulated s = 20 ms of wall time
    assert 20.0 <= scaled.now() - t0 < 200.0
    with pytest.raises(ValueError, match="speed must be > 0"):
        ScaledClock(0.0)
