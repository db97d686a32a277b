"""The Heidolph emulator on a real pseudo-terminal, and its thermal model."""
import time

import pytest
import serial

from drivers.sim.heidolph_emulator import HeidolphEmulator
from drivers.sim.hotplate_model import PlateState, ThermalParams, step


def _open(path):
    return serial.serial_for_url(path, baudrate=9600, bytesize=7, parity="E", stopbits=1, timeout=1.0)


def _ask(port, line):
    port.write(line.encode() + b"\r\n")
    reply = port.read_until(b"\n")
    time.sleep(0.1)
    return reply


@pytest.fixture
def emulator():
    emu = HeidolphEmulator(speed=1.0, seed=0, reply_delay_s=0.0)
    emu.start()
    yield emu
    emu.stop()


def test_reopen_after_a_7e1_client_left(emulator):
    # without restoring the terminal settings the second open fails with EINVAL
    for _ in range(3):
        port = _open(emulator.path)
        assert _ask(port, "IN_SP_1") == b"IN_SP_1 0.0\n"
        port.close()
        deadline = time.monotonic() + 120.0  # a wait, not a timing requirement: generous for a loaded machine
        while emulator.state.client_connected and time.monotonic() < deadline:
            time.sleep(0.01)


def test_old_then_new_line_ending_and_echo(emulator):
    port = _open(emulator.path)
    assert _ask(port, "STATUS") == b"STATUS 0\n"  # old protocol: \n\r; the \r is left over
    assert _ask(port, "PA_NEW") == b"\rPA_NEW\r\n"
    assert _ask(port, "OUT_SP_1 70") == b"OUT_SP_1 70.0\r\n"
    assert _ask(port, "START_1") == b"START_1\r\n"
    assert _ask(port, "STATUS") == b"STATUS 1\r\n"
    assert _ask(port, "IN_PV_1") .startswith(b"IN_PV_1 2")
    port.close()
    s = emulator.state
    assert (s.setpoint_c, s.heating, s.new_protocol, s.remote) == (70.0, True, True, True)


def test_missing_probe_reads_999_9(emulator):
    emulator.set_probe(False)
    port = _open(emulator.path)
    assert _ask(port, "IN_PV_1") == b"IN_PV_1 999.9\n"
    port.close()


def test_watchdog_stops_heating_after_silence():
    with HeidolphEmulator(watchdog_s=0.3, seed=0) as emu:
        port = _open(emu.path)
        for line in ("CC_ON", "START_1", "START_2"):
            _ask(port, line)
        assert emu.state.heating
        deadline = time.monotonic() + 120.0     # a wait for the watchdog (0.3 s of silence), generous for a loaded machine
        while emu.state.heating and time.monotonic() < deadline:
            time.sleep(0.01)
        s = emu.state
        assert s.pc_err and not s.heating and not s.stirring
        _ask(port, "STATUS")
        assert not emu.state.pc_err  # any command clears the display, remote operation stays
        port.close()


def test_time_acceleration_is_explicit():
    clock = [0.0]
    emu = HeidolphEmulator(speed=10.0, clock=lambda: clock[0])
    clock[0] = 2.0
    assert emu.state.sim_time_s == pytest.approx(20.0)
    emu.set_speed(100.0)
    clock[0] = 3.0
    assert emu.state.sim_time_s == pytest.approx(120.0)


def test_water_reaches_and_holds_the_setpoint():
    p = ThermalParams()
    s = PlateState(setpoint_c=70.0, heating=True, setpoint_rpm=150.0, stirring=True)
    temps = []
    for _ in range(360):
        s = step(s, 10.0, p)
        temps.append(s.water_c)
    assert max(temps) < 71.0
    assert all(abs(t - 70.0) < 0.5 for t in temps[120:])
    assert s.speed_rpm == 150.0


def test_idle_plate_cools_and_stirrer_ramps():
    p = ThermalParams(ramp_rpm_per_s=50.0)
    s = PlateState(plate_c=80.0, water_c=60.0, setpoint_rpm=150.0, stirring=True)
    s1 = step(s, 1.0, p)
    assert s1.speed_rpm == pytest.approx(50.0)
    s2 = step(s1, 3600.0, p)
    assert s2.plate_c < 25.0 and s2.water_c < 30.0


@pytest.mark.parametrize("kwargs, match", [({"tau_plate_s": 0}, "tau_plate_s must be > 0"),
                                           ({"ambient_c": 400}, "must be below plate_max_c")])
def test_params_are_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ThermalParams(**kwargs)


def test_emulator_arguments_are_checked():
    with pytest.raises(ValueError, match="speed must be > 0"):
        HeidolphEmulator(speed=0)
