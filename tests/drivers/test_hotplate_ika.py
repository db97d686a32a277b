"""The IKA RCT / C-MAG table: byte pairs, then the driver against the emulator over a real pty."""
import time

import pytest
import serial

from drivers.hotplate import IKA_RCT, HeidolphHotplate, HotplateConfig, HotplateError, NamurHotplate
from drivers.sim.heidolph_emulator import HeidolphEmulator
from tests.drivers.scripted_port import scripted_plates

FAST = HotplateConfig(timeout_s=0.3, backoff_s=0.1, retries=1)
END = b" \r \n"  # IKA commands end in "blank CR LF"; replies in CR LF


@pytest.fixture
def plate(monkeypatch):
    yield from scripted_plates(monkeypatch, [(b"OUT_WD1@30" + END, b"30\r\n")], config=FAST, table=IKA_RCT)


READ = [(b"OUT_WD1@30" + END, b"30\r\n"), (b"IN_PV_1" + END, b"69.8 1\r\n"), (b"IN_PV_2" + END, b"73.1 2\r\n"),
        (b"IN_PV_4" + END, b"150 4\r\n"), (b"IN_SP_1" + END, b"70 1\r\n"), (b"IN_SP_4" + END, b"150 4\r\n")]


def test_unanswered_sets_are_read_back_and_replies_carry_the_channel(plate):
    hp = plate([(b"OUT_SP_1 70" + END, b""), (b"IN_SP_1" + END, b"70 1\r\n"),
                (b"OUT_SP_4 150" + END, b""), (b"IN_SP_4" + END, b"150 4\r\n"),
                (b"START_1" + END, b""), (b"START_4" + END, b"")] + READ)
    hp.set_temperature(70)
    hp.set_speed(150)
    hp.start_heating()
    hp.start_stirring()
    r = hp.read()  # re-arms the watchdog (OUT_WD1@30) first; no STATUS on IKA
    assert (r.probe_c, r.plate_c, r.speed_rpm, r.setpoint_c, r.setpoint_rpm) == (69.8, 73.1, 150, 70, 150)
    assert r.heating and r.stirring


def test_a_setpoint_the_plate_did_not_take_is_an_error(plate):
    hp = plate([(b"OUT_SP_1 70" + END, b""), (b"IN_SP_1" + END, b"25 1\r\n")])
    with pytest.raises(HotplateError, match=r"'OUT_SP_1 70' was not taken: IN_SP_1 reads back 25 C"):
        hp.set_temperature(70)


def test_a_reply_for_another_channel_is_retried(plate):
    hp = plate([(b"OUT_WD1@30" + END, b"30\r\n"), (b"IN_PV_1" + END, b"150 4\r\n"),
                (b"IN_PV_1" + END, b"69.8 1\r\n")] + READ[2:])
    assert hp.read().probe_c == 69.8


def test_limits_refuse_before_the_wire(plate):
    hp = plate([])
    with pytest.raises(HotplateError, match=r"OUT_SP_4: 700 rpm is outside the allowed range \[0, 600\] rpm"):
        hp.set_speed(700)


def _eventually(condition, within_s=120.0):
    deadline = time.monotonic() + within_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def _open(path):
    return serial.serial_for_url(path, baudrate=9600, bytesize=7, parity="E", stopbits=1, timeout=0.3)


def test_emulator_speaks_ika_bytes():
    with HeidolphEmulator(table=IKA_RCT, seed=0, reply_delay_s=0.0, noise_c=0.0) as emu:
        port = _open(emu.path)
        try:
            def ask(line):
                port.write(line.encode() + END)
                reply = port.read_until(b"\n")
                time.sleep(0.1)
                return reply

            assert ask("IN_SP_1") == b"0 1\r\n"
            assert ask("OUT_SP_1 55") == b""           # set commands are not answered (0.3 s timeout)
            assert ask("START_4") == b""
            assert ask("IN_SP_1") == b"55 1\r\n"
            assert ask("IN_PV_2").endswith(b" 2\r\n")
            assert ask("OUT_WD1@30") == b"30\r\n"
            assert ask("STATUS") == b""                # not an IKA command: ignored
        finally:
            port.close()
        s = emu.state
        assert (s.setpoint_c, s.stirring, s.heating, s.watchdog_on) == (55.0, True, False, True)


def test_round_trip_set_reach_read_back_and_off_on_close():
    with HeidolphEmulator(table=IKA_RCT, speed=200.0, seed=1, reply_delay_s=0.0) as emu:
        hp = HeidolphHotplate(emu.path, config=FAST, table=IKA_RCT, keep_alive=False)
        hp.connect()
        try:
            hp.set_temperature(70)
            hp.set_speed(150)
            hp.start_heating()
            hp.start_stirring()
            deadline = time.monotonic() + 120.0
            r = hp.read()
            while abs(r.probe_c - 70) > 1.0 and time.monotonic() < deadline:
                time.sleep(0.2)
                r = hp.read()
            assert abs(r.probe_c - 70) <= 1.0, r
            assert (r.setpoint_c, r.setpoint_rpm, r.speed_rpm) == (70, 150, 150)
            assert r.heating and r.stirring and r.plate_c > r.probe_c
            assert emu.state.watchdog_on
        finally:
            hp.close()  # STOP_1 and STOP_4 are unanswered: written, drained, then the port is closed
        assert _eventually(lambda: not emu.state.heating and not emu.state.stirring)


def test_emulated_ika_watchdog_stops_heating_after_silence():
    with HeidolphEmulator(table=IKA_RCT, watchdog_s=0.3, seed=0, reply_delay_s=0.0) as emu:
        hp = NamurHotplate(emu.path, config=FAST, table=IKA_RCT, keep_alive=False)
        hp.connect()  # arms OUT_WD1@30
        try:
            hp.start_heating()
            assert _eventually(lambda: emu.state.heating)
            assert _eventually(lambda: emu.state.pc_err and not emu.state.heating)
        finally:
            hp.close()
