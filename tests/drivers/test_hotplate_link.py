"""HeidolphHotplate against the emulator over a real pseudo-terminal: control, faults, recovery."""
import subprocess
import sys
import textwrap
import time

import pytest

from drivers.hotplate import HeidolphHotplate, HotplateConfig, HotplateError
from drivers.sim.heidolph_emulator import HeidolphEmulator

CONFIG = HotplateConfig(timeout_s=0.3, backoff_s=0.1, backoff_max_s=0.4, retries=1, reconnect_attempts=6)


@pytest.fixture
def emulator():
    emu = HeidolphEmulator(speed=600.0, seed=1, reply_delay_s=0.005)
    emu.start()
    yield emu
    emu.stop()


@pytest.fixture
def plate(emulator):
    hp = HeidolphHotplate(emulator.path, config=CONFIG, keep_alive=False)
    hp.connect()
    yield hp
    hp.close()


def _wait(predicate, timeout_s=120.0):
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.05)
    return predicate()


def test_set_reach_hold_and_read_back(emulator, plate):
    plate.set_temperature(70.0)
    plate.set_speed(150.0)
    plate.start_heating()
    plate.start_stirring()
    assert _wait(lambda: abs(emulator.state.water_c - 70.0) < 0.5 and emulator.state.sim_time_s > 900)
    held = [plate.read() for _ in range(3)]
    for r in held:
        assert r.probe_c == pytest.approx(70.0, abs=0.6)
        assert (r.setpoint_c, r.setpoint_rpm, r.speed_rpm, r.heating, r.stirring) == (70.0, 150.0, 150.0, True, True)
        assert r.plate_c > r.probe_c
    plate.close()
    assert not emulator.state.heating and not emulator.state.stirring


def test_garbage_is_retried(emulator, plate):
    emulator.inject_garbage(1)
    plate.set_temperature(40.0)
    assert emulator.state.setpoint_c == 40.0


def test_silence_is_a_clear_error_and_then_recovers(emulator, plate):
    emulator.set_silent(True)
    with pytest.raises(HotplateError, match=r"no valid reply to 'IN_SP_1' after 2 attempts.*within 0.3 s"):
        plate._exchange("IN_SP_1")
    emulator.set_silent(False)
    assert plate.read().setpoint_c == 0.0


def test_slightly_late_reply_is_caught_by_the_retry(emulator, plate):
    emulator.set_reply_delay(0.45)
    plate.start_stirring()
    assert emulator.state.stirring


def test_very_slow_replies_are_a_clear_error_then_recover(emulator, plate):
    emulator.set_reply_delay(1.5)
    with pytest.raises(HotplateError, match="no valid reply to 'START_2' after 2 attempts.*within 0.3 s"):
        plate.start_stirring()
    emulator.set_reply_delay(0.0)
    time.sleep(3.2)  # the two late echoes arrive and are discarded before the next command
    plate.stop_stirring()
    assert not emulator.state.stirring


def test_dropped_link_reconnects_and_restores_state(emulator, plate):
    plate.set_temperature(70.0)
    plate.start_heating()
    emulator.drop_link(0.4)
    time.sleep(0.05)
    emulator.set_probe(True)
    plate.set_temperature(60.0)  # hits the dead line, reconnects with back-off, restores, then sets
    assert plate.reconnects == 1
    s = emulator.state
    assert s.heating and s.setpoint_c == 60.0 and s.watchdog_on


def test_pc_err_is_noticed_and_commanded_state_restored(emulator, plate):
    plate.set_temperature(70.0)
    plate.start_heating()
    emulator.trip_watchdog()
    assert not emulator.state.heating
    assert plate.read().heating
    assert plate.watchdog_trips == 1 and emulator.state.heating


def test_keep_alive_holds_off_the_plates_watchdog():
    with HeidolphEmulator(watchdog_s=0.8, seed=2) as emu:
        seen = []
        hp = HeidolphHotplate(emu.path, config=HotplateConfig(poll_interval_s=0.2, timeout_s=0.3),
                              on_reading=seen.append)
        hp.connect()
        hp.start_heating()
        time.sleep(2.0)
        assert emu.state.heating and not emu.state.pc_err and len(seen) >= 2
        hp.close()
        assert not emu.state.heating


CLIENT = textwrap.dedent("""
    import sys, time
    from drivers.hotplate import HeidolphHotplate, HotplateConfig
    hp = HeidolphHotplate(sys.argv[1], config=HotplateConfig(timeout_s=0.5), keep_alive=False)
    hp.connect()
    hp.set_temperature(70)
    hp.start_heating()
    hp.start_stirring()
    print("ready", flush=True)
    if sys.argv[2] == "hang":
        time.sleep(60)
""")


def test_heating_is_off_after_the_client_is_killed():
    with HeidolphEmulator(watchdog_s=0.5, seed=3) as emu:
        proc = subprocess.Popen([sys.executable, "-c", CLIENT, emu.path, "hang"], stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().strip() == "ready"
            assert emu.state.heating
            proc.kill()
            proc.wait(timeout=120)
        finally:
            proc.kill()
        assert _wait(lambda: not emu.state.heating)
        s = emu.state
        assert s.pc_err and not s.stirring


def test_heating_is_off_after_the_client_exits_without_close():
    with HeidolphEmulator(watchdog_s=60.0, seed=4) as emu:
        out = subprocess.run([sys.executable, "-c", CLIENT, emu.path, "exit"], capture_output=True, text=True,
                             timeout=120)
        assert out.stdout.strip() == "ready"
        assert "switching heating and stirring off" in out.stderr
        s = emu.state
        assert not s.heating and not s.stirring and not s.pc_err  # the atexit path, not the watchdog
